#pragma once
// Elasticity after A. Peer, C. Gissler, S. Band, M. Teschner, "An Implicit SPH Formulation for
// Incompressible Linearly Elastic Solids", Computer Graphics Forum 37(6), 135–148, 2018: a corotated
// linear elastic stress from each particle's deformation gradient against its reference shape.
// Together with the material's viscosity this is a Kelvin–Voigt solid (it sags under load and springs
// back when unloaded); with a relaxation time the reference shape creeps towards the current one, so
// stress relaxes like a Maxwell fluid's (a paste that springs back quickly but flows over time).
#include "m3dp/core/types.hpp"

namespace m3dp::material {

struct Elasticity {
  bool enabled = false;
  Real shear_modulus = Real(1e4);  // Pa, G; Young's modulus E = 2G(1 + ν)
  Real poisson_ratio = Real(0.45); // ν, 0 ≤ ν < 0.5; soft pastes and gels are nearly incompressible
  Real relaxation_time = 0;        // s, τ of the stress relaxation; 0 = none (an elastic solid)

  /// Bulk modulus K = 2G(1 + ν) / (3(1 − 2ν)) (Pa).
  [[nodiscard]] Real bulk_modulus() const { return 2 * shear_modulus * (1 + poisson_ratio) / (3 * (1 - 2 * poisson_ratio)); }
  /// Young's modulus E = 2G(1 + ν) (Pa).
  [[nodiscard]] Real youngs_modulus() const { return 2 * shear_modulus * (1 + poisson_ratio); }
};

}  // namespace m3dp::material
