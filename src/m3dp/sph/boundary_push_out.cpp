// The walls' last line of defence (stage "advect"): pressure alone does not stop a lone, fast
// particle, so one whose centre crossed a geometric surface goes back onto it.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>

#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void keep_out_of_boundaries(const Model& model, State& state, Workspace& workspace) {
  // Pressure alone does not stop a lone, fast particle (a splash has too few fluid neighbours to
  // be over-dense at a wall), so a particle whose centre has crossed a geometric surface is moved
  // back onto it and loses its velocity into the wall. The crossing is read from the boundary share
  // Σ_b V_b W, which grows monotonically towards a wall: Newton steps along its gradient, which
  // work the same for any shape, edge or corner.
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const Real surface_share = model.boundary_share_at_surface;
  with_kernel(model.settings.kernel, model.support_radius, [&](const auto& kernel) {
    const Real inverse_time_step = Real(1) / state.time_step;
    for_each_wrench_chunk(state, workspace, state.active_count, [&](const tbb::blocked_range<std::size_t>& range, std::span<Wrench> wrenches) {
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
      // A few Newton steps: one lands short where the share is curved (edges, corners).
      for (int iteration = 0; iteration < 3; ++iteration) {
        const Vec3 position = fluid.position[i];
        Real share = 0, nearest_weight = 0;
        Index nearest = 0;
        Vec3 gradient = Vec3::Zero(), wall_velocity = Vec3::Zero();
        for (const Index b : workspace.boundary_neighbors.of(i)) {
          const Vec3 r = position - boundary.position[b];
          const auto [value, gradient_factor] = kernel.value_and_gradient_factor(r.norm());  // one square root
          const Real weight = boundary.volume[b] * value;
          // Selects, not a branch: which wall particle is nearest follows no order.
          nearest = weight > nearest_weight ? b : nearest;
          nearest_weight = std::max(weight, nearest_weight);
          share += weight;
          gradient += (boundary.volume[b] * gradient_factor) * r;
          wall_velocity += weight * boundary.velocity[b];
        }
        const Real gradient_squared = gradient.squaredNorm();
        if (share <= surface_share || gradient_squared <= 0) break;
        fluid.position[i] = position - ((share - surface_share) / gradient_squared) * gradient;
        const Vec3 away = -gradient / std::sqrt(gradient_squared);
        const Vec3 relative = fluid.velocity[i] - wall_velocity / share;  // share-weighted wall velocity
        const Real into_wall = relative.dot(away);
        if (into_wall < 0) {
          fluid.velocity[i] -= into_wall * away;
          // The wall took that momentum: count it in the body's force like the pressure forces.
          const Vec3 force = fluid.mass[i] * into_wall * away * inverse_time_step;
          Wrench& wrench = wrenches[boundary.body[nearest]];
          wrench.force += force;
          wrench.torque += (boundary.position[nearest] - state.bodies[boundary.body[nearest]].pose.position).cross(force);
        }
      }
      }
    });
  });
}

}  // namespace m3dp::sph::stages
