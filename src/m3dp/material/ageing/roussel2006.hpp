#pragma once
// Ageing of printable materials: the "time-variant" material of extrusion printing.
//
// Structural build-up (thixotropy) after N. Roussel, "A thixotropy model for fresh fluid concretes:
// theory, validation and applications", Cement and Concrete Research 36, 1797–1806, 2006, in the
// linear form used for printing (N. Roussel, "Rheological requirements for printable concretes",
// Cement and Concrete Research 112, 76–85, 2018):
//   τ0(t) = τ0,0 + A_thix · t,   t the time since the material left the nozzle,
// A_thix (Pa/s) ≈ 0.1–5 Pa/s for printable mortars and concretes.
// Optionally the viscosity parameter (μ, μp, K or μ0 of the rheology) grows linearly too:
//   μ(t) = μ(0) · (1 + viscosity_growth · t), viscosity_growth in 1/s.
#include <algorithm>

#include "m3dp/core/types.hpp"

namespace m3dp::material {

struct Ageing {
  Real structuration_rate = 0;  // A_thix, Pa/s
  Real viscosity_growth = 0;    // 1/s, relative growth rate of the viscosity parameter

  [[nodiscard]] bool enabled() const { return structuration_rate > 0 || viscosity_growth > 0; }
  /// τ0 at `age` seconds (Pa).
  [[nodiscard]] Real yield_stress(Real initial_yield_stress, Real age) const {
    return initial_yield_stress + structuration_rate * std::max(age, Real(0));
  }
  /// Factor on the rheology's viscosity parameter at `age` seconds.
  [[nodiscard]] Real viscosity_scale(Real age) const { return 1 + viscosity_growth * std::max(age, Real(0)); }
};

}  // namespace m3dp::material
