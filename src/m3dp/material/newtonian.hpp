#pragma once
// Newtonian fluid: constant dynamic viscosity.
// Units as a user looks them up: density in kg/m³, dynamic viscosity μ in Pa·s (water at 20 °C:
// 998 kg/m³, 1.0e-3 Pa·s). The solver works with kinematic viscosity ν = μ/ρ (m²/s).
#include <string>

#include "m3dp/core/types.hpp"

namespace m3dp::material {

struct NewtonianMaterial {
  std::string name;
  Real density = 1000;                 // kg/m³
  Real dynamic_viscosity = Real(1e-3); // Pa·s
  Real boundary_viscosity = 0;         // Pa·s, friction against walls, bodies and the nozzle (0 = free slip)

  [[nodiscard]] Real kinematic_viscosity() const { return dynamic_viscosity / density; }
  [[nodiscard]] Real boundary_kinematic_viscosity() const { return boundary_viscosity / density; }
};

}  // namespace m3dp::material
