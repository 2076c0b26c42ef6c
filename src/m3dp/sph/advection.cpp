// Stage "advect": the particles move with their new velocities, and the step ends: the clock, the
// statistics and the check that nothing became NaN or exploded.
#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

namespace {
void check_state(const State& state, const Model& model) {
  const auto& fluid = state.fluid;
  const Real max_speed_squared = model.settings.max_speed * model.settings.max_speed;
  // Lowest index of a bad particle, or size() if none.
  // Active particles only: resting ones have not moved since they were checked.
  const std::size_t bad = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, state.active_count, 2048), fluid.size(),
      [&](const tbb::blocked_range<std::size_t>& range, std::size_t found) {
        for (std::size_t i = range.begin(); i != range.end() && i < found; ++i) {
          const Real speed_squared = fluid.velocity[i].squaredNorm();
          if (!fluid.position[i].allFinite() || !std::isfinite(speed_squared) || speed_squared > max_speed_squared) return i;
        }
        return found;
      },
      [](std::size_t a, std::size_t b) { return std::min(a, b); });
  if (bad == fluid.size()) return;
  const Vec3& p = fluid.position[bad];
  const Vec3& v = fluid.velocity[bad];
  throw SimulationError(fmt::format(
      "simulation became unstable at t = {:.6f} s (step {}, dt = {:.3g} s): particle {} at ({:.4g}, {:.4g}, {:.4g}) m "
      "has velocity ({:.4g}, {:.4g}, {:.4g}) m/s (limit {} m/s). Try a smaller max_time_step or cfl_factor.",
      state.time, state.step, static_cast<double>(state.time_step), fluid.id[bad], p.x(), p.y(), p.z(), v.x(), v.y(),
      v.z(), model.settings.max_speed));
}
}  // namespace

void advect_positions(const Model& /*model*/, State& state, Workspace& /*workspace*/) {
  auto& fluid = state.fluid;
  const Real time_step = state.time_step;
  parallel_for_each_index(state.active_count, [&](std::size_t i) { fluid.position[i] += time_step * fluid.velocity[i]; }, 1024);
}

void integrate_granular(const Model& /*model*/, State& state, Workspace& /*workspace*/) {
  auto& fluid = state.fluid;
  const Real time_step = state.time_step;
  parallel_for_each_index(state.active_count, [&](std::size_t i) {
    fluid.velocity[i] += time_step * fluid.acceleration[i];
    fluid.position[i] += time_step * fluid.velocity[i];
  }, 1024);
}

void finish_step(const Model& model, State& state, Workspace& /*workspace*/) {
  // Impulses were summed as forces of velocity updates applied over one step each.
  state.time += state.time_step;
  ++state.step;
  state.last_step.time_step = state.time_step;
  state.last_step.particles_at_rest = state.fluid.size() - state.active_count;
  check_state(state, model);
}

}  // namespace m3dp::sph::stages
