// The walls' share of the implicit viscosity (Weiler et al. 2018; see weiler2018.cpp): the friction
// the material exerts on each body, from the solved velocities.
#include <tbb/parallel_for.h>

#include "m3dp/sph/viscosity/weiler2018.hpp"

namespace m3dp::sph::stages::weiler2018 {

void add_wall_reaction(const Model& model, State& state, Workspace& workspace) {
  const Real time_step = state.time_step;
  const auto& fluid = state.fluid;
  const auto& velocity = fluid.velocity;
  const auto& boundary = state.boundary;
  const std::size_t count = state.active_count;
  const auto& boundary_lists = workspace.boundary_neighbors;
  const auto& system = workspace.viscosity_system;
  // Wall friction as a reaction on the bodies: the body feels −F_ib = (c_ib/Δt) x xᵀ (v_i − v_b).
  if (model.any_wall_friction && !state.bodies.empty()) {
    const Real inverse_time_step = Real(1) / time_step;
    for_each_wrench_chunk(state, workspace, count, [&](const tbb::blocked_range<std::size_t>& range, std::span<Wrench> wrenches) {
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
        const std::size_t boundary_first = boundary_lists.first(i);
        for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
          const Real coefficient = system.boundary_pair_coefficient[boundary_first + k];
          if (coefficient == 0) continue;
          const Index b = boundary_lists.indices[boundary_first + k];
          const Vec3 r = fluid.position[i] - boundary.position[b];
          const Vec3 force = (coefficient * inverse_time_step * r.dot(velocity[i] - boundary.velocity[b])) * r;
          Wrench& wrench = wrenches[boundary.body[b]];
          wrench.force += force;
          wrench.torque += (boundary.position[b] - state.bodies[boundary.body[b]].pose.position).cross(force);
        }
      }
    });
  }
}

}  // namespace m3dp::sph::stages::weiler2018
