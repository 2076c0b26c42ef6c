// Stage "remove": particles that left the scene's bounds are deleted and counted.
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void remove_out_of_bounds(const Model& model, State& state, Workspace& workspace) {
  const Aabb& bounds = model.settings.bounds;
  if (bounds.empty()) return;
  auto& fluid = state.fluid;
  // Resting particles do not move, so only active ones can have left.
  const std::size_t outside = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, state.active_count, 2048), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& range, std::size_t found) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) found += bounds.contains(fluid.position[i]) ? 0 : 1;
        return found;
      },
      std::plus<std::size_t>());
  if (outside == 0) return;
  // Swap-removal that keeps the active particles first: an active slot is refilled from the end of the
  // active range, whose slot is refilled from the end of the array.
  std::size_t count = fluid.size();
  for (std::size_t i = 0; i < state.active_count;) {
    if (bounds.contains(fluid.position[i])) {
      ++i;
      continue;
    }
    state.mass_removed_total += fluid.mass[i];
    const std::size_t last_active = --state.active_count;
    if (i != last_active) fluid.move(last_active, i);
    if (last_active != count - 1) fluid.move(count - 1, last_active);
    --count;
  }
  fluid.resize(count);
  state.particles_removed_total += outside;
  state.last_step.particles_removed = outside;
}

}  // namespace m3dp::sph::stages
