#pragma once
// A printable material as a user looks it up: density in kg/m³, viscosities in Pa·s (dynamic
// viscosity, never kinematic: water at 20 °C is 998 kg/m³ and 1.0e-3 Pa·s), stresses in Pa.
#include <algorithm>
#include <cstdint>
#include <string>

#include "m3dp/core/types.hpp"
#include "m3dp/material/ageing/roussel2006.hpp"
#include "m3dp/material/elasticity/peer2018.hpp"
#include "m3dp/material/granular/cundall_strack1979.hpp"
#include "m3dp/material/rheology/generalized_newtonian.hpp"
#include "m3dp/material/vorticity/micropolar_bender2017.hpp"

namespace m3dp::material {

/// What a wall is to the material on it: a static wall (a print bed, a floor), a moving body (a
/// robot's link, a dropped box) or a nozzle's bore. Each has its own slip (Material::sticks_to).
enum class Wall : std::uint8_t { moving_body = 0, static_wall = 1, nozzle_bore = 2 };

struct Material {
  std::string name;
  std::string preset;                  // the preset it starts from (data/materials.xml); empty = none
  Real density = 1000;                 // kg/m³
  Rheology rheology;                   // μ(γ̇); Newtonian 1e-3 Pa·s by default
  Ageing ageing;                       // none by default
  Real boundary_viscosity = 0;         // Pa·s, friction against walls, bodies and the nozzle (0 = free slip)
  bool sticks_to_walls = false;        // no slip: walls see the material's own effective viscosity instead
  // No slip against static walls only (a bed holds what is laid on it): what a scene's printed
  // material takes in the engine when it sets no <boundary_viscosity> (scene::solver_parameters);
  // moving bodies then see boundary_viscosity.
  bool sticks_to_static_walls = false;
  // The nozzle's bore (a nozzle with walls): free slip by default, as El Abbaoui et al. 2024 found
  // printed concrete sections match best; true: no slip (the material's own viscosity at the bore).
  bool nozzle_no_slip = false;
  Real surface_tension = 0;            // N/m against air (water at 20 °C: 0.0728); 0 = none
  Real adhesion = 0;                   // N/m, work of adhesion to walls, σ(1 + cos θ) by Young–Dupré; 0 = none
  Granular granular;                   // enabled: discrete spheres with contacts instead of a fluid
  Micropolar micropolar;               // enabled: particles carry a micro-rotation (vorticity kept)
  Elasticity elasticity;               // enabled: a shear stress from the deformation of a reference shape

  [[nodiscard]] bool has_surface_forces() const { return surface_tension > 0 || adhesion > 0; }
  [[nodiscard]] bool has_wall_friction() const {
    return sticks_to_walls || sticks_to_static_walls || boundary_viscosity > 0 || nozzle_no_slip;
  }
  /// Whether the material does not slip on a wall of this kind.
  [[nodiscard]] bool sticks_to(Wall wall) const {
    switch (wall) {
      case Wall::nozzle_bore: return nozzle_no_slip;
      case Wall::static_wall: return sticks_to_walls || sticks_to_static_walls;
      case Wall::moving_body: return sticks_to_walls;
    }
    return false;
  }
  /// Viscosity (Pa·s) of the wall term for a particle of effective viscosity `particle_viscosity`
  /// against a wall of this kind: its own where it sticks, else the Navier slip's (none at a bore).
  [[nodiscard]] Real wall_viscosity(Real particle_viscosity, Wall wall) const {
    if (sticks_to(wall)) return particle_viscosity;
    return wall == Wall::nozzle_bore ? 0 : boundary_viscosity;
  }
  /// The largest wall viscosity of any kind of wall (a bound for the solves).
  [[nodiscard]] Real largest_wall_viscosity(Real particle_viscosity) const {
    return std::max({wall_viscosity(particle_viscosity, Wall::static_wall), wall_viscosity(particle_viscosity, Wall::moving_body),
                     wall_viscosity(particle_viscosity, Wall::nozzle_bore)});
  }
};

/// A Newtonian fluid of dynamic viscosity `viscosity` (Pa·s).
inline Material newtonian(std::string name, Real density, Real viscosity, Real boundary_viscosity = 0) {
  Material material;
  material.name = std::move(name);
  material.density = density;
  material.rheology.viscosity = viscosity;
  material.boundary_viscosity = boundary_viscosity;
  return material;
}

}  // namespace m3dp::material
