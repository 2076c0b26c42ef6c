// Air drag after C. Gissler, S. Band, A. Peer, M. Ihmsen, M. Teschner, "Approximate Air-Fluid
// Interactions for SPH", VRIPHYS 2017: each particle at the surface feels the drag of the air
// streaming past it,
//   F_i = ½ ρ_air C_D(Re) A_i |u| u,    u = v_air − v_i,   Re = ρ_air |u| D / μ_air,
// with the drag coefficient of a sphere (Schiller & Naumann 1933: C_D = 24/Re (1 + 0.15 Re^0.687)
// below Re = 1000, 0.44 above), D the diameter of the sphere of the particle's volume and A its
// cross-section. Particles inside the material are shielded: A is scaled by the share of a full
// neighbourhood that is missing, max(0, 1 − n_i/n_full), as in Gissler et al.'s occlusion factor. The
// paper's droplet deformation (Taylor analogy breakup) is left out: drops here stay spherical.
#include <algorithm>
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph {

Real sphere_drag_coefficient(Real reynolds_number) {
  if (reynolds_number <= 0) return 0;
  if (reynolds_number >= 1000) return Real(0.44);
  return Real(24) / reynolds_number * (1 + Real(0.15) * std::pow(reynolds_number, Real(0.687)));
}

int full_neighbourhood_count(Real support_radius, Real spacing) {
  const int reach = static_cast<int>(std::ceil(support_radius / spacing));
  int count = 0;
  for (int i = -reach; i <= reach; ++i)
    for (int j = -reach; j <= reach; ++j)
      for (int k = -reach; k <= reach; ++k) {
        const Real distance = spacing * Vec3(Real(i), Real(j), Real(k)).norm();
        count += (distance > 0 && distance < support_radius) ? 1 : 0;
      }
  return count;
}

namespace stages {

void add_air_drag(const Model& model, State& state, Workspace& workspace) {
  const int full_neighbourhood = model.full_neighbourhood;
  const auto& settings = model.settings;
  if (!settings.air_drag) return;
  auto& fluid = state.fluid;
  const Real spacing = 2 * settings.particle_radius;
  // The sphere of one particle's volume d³.
  const Real sphere_diameter = spacing * std::cbrt(Real(6) / kPi);
  const Real cross_section = kPi * sphere_diameter * sphere_diameter / 4;
  parallel_for_each_index(state.active_count, [&](std::size_t i) {
    const Real exposure = std::clamp(1 - Real(fluid.neighbor_count[i]) / Real(full_neighbourhood), Real(0), Real(1));
    if (exposure <= 0) return;
    const Vec3 relative = settings.air_velocity - fluid.velocity[i];
    const Real speed = relative.norm();
    if (speed <= 0) return;
    const Real reynolds = settings.air_density * speed * sphere_diameter / settings.air_viscosity;
    const Real force = Real(0.5) * settings.air_density * sphere_drag_coefficient(reynolds) * exposure * cross_section * speed;
    fluid.acceleration[i] += (force / fluid.mass[i]) * relative;
  }, 1024);
}

}  // namespace stages
}  // namespace m3dp::sph

