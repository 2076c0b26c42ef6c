#pragma once
// Micropolar fluid after J. Bender, D. Koschier, T. Kugelstadt, M. Weiler, "A Micropolar Material
// Model for Turbulent SPH Fluids", ACM SIGGRAPH/Eurographics SCA 2017 (extended in IEEE TVCG 25(6), 2019):
// each particle carries a micro-rotation ω (rad/s) coupled to the flow's vorticity,
//   ρ Dv/Dt = … + μ_t ∇×ω,        ρ Θ Dω/Dt = μ_t (∇×v − 2ω)  (+ a smoothing of ω),
// which gives vortices back the rotation that numerical dissipation takes from them.
#include "m3dp/core/types.hpp"

namespace m3dp::material {

struct Micropolar {
  bool enabled = false;
  Real vortex_viscosity = Real(1e-3);  // Pa·s, μ_t: the coupling of micro-rotation and vorticity
  Real microinertia = 0;               // m², Θ; 0 = that of the sphere of one particle's volume, (2/5) R²
  Real angular_smoothing = Real(0.1);  // XSPH-type smoothing of ω towards its neighbours' (dimensionless, per step)
};

}  // namespace m3dp::material
