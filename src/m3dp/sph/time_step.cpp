// The time-step rule (stage "forces"): the largest step that keeps the CFL condition, the explicit
// viscosity's and the capillary waves' limits, and gravity's; granular mode's contact step; and the
// velocity update by this step's non-pressure accelerations.
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

Real max_speed_squared(const State& state, Real time_step) {
  const auto& fluid = state.fluid;
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, state.active_count, 1024), Real(0),
      [&](const tbb::blocked_range<std::size_t>& range, Real value) {
        for (std::size_t i = range.begin(); i != range.end(); ++i)
          value = std::max(value, (fluid.velocity[i] + time_step * fluid.acceleration[i]).squaredNorm());
        return value;
      },
      [](Real a, Real b) { return std::max(a, b); });
}

namespace {
/// The CFL (Courant) limit for particles as fast as √speed_squared, within the settings' largest step.
Real courant_limit(const Model& model, Real largest_step, Real speed_squared) {
  if (!(speed_squared > Real(1e-18))) return largest_step;
  return std::min(largest_step, model.settings.cfl_factor * Real(0.4) * model.particle_diameter / std::sqrt(speed_squared));
}
}  // namespace

void choose_time_step(const Model& model, State& state, Workspace& workspace) {
  const auto& settings = model.settings;
  const Real diameter = model.particle_diameter;
  TimeStepBound bound = TimeStepBound::largest;
  Real time_step = settings.max_time_step;
  // Each limit in turn; the last to lower the step is the one that set it.
  const auto limit = [&](Real candidate, TimeStepBound which) {
    if (candidate < time_step) time_step = candidate, bound = which;
  };
  // CFL on the velocity after the non-pressure forces.
  limit(courant_limit(model, settings.max_time_step, max_speed_squared(state, state.time_step)), TimeStepBound::courant);
  // Explicit viscosity: Morris et al. 1997's limit Δt ≤ 0.125 h²/ν, with the smoothing length h =
  // half the support radius = one particle diameter for our kernels. The implicit solver has none.
  // The calibration strengthens the sums (most at walls), so the limit tightens by the same factor.
  const Real largest_kinematic_viscosity = workspace.largest_kinematic_viscosity;
  if (settings.viscosity_solver == ViscositySolver::explicit_morris1997 && largest_kinematic_viscosity > 0)
    limit(Real(0.125) * diameter * diameter /
              (largest_kinematic_viscosity * std::max(model.viscosity_calibration.fluid, model.viscosity_calibration.boundary)),
          TimeStepBound::viscosity);
  // Capillary waves (Brackbill et al. 1992): Δt ≤ √(ρ d³ / (2π σ)).
  if (model.largest_surface_tension > 0)
    limit(std::sqrt(model.lightest_rest_density * diameter * diameter * diameter / (2 * kPi * model.largest_surface_tension)),
          TimeStepBound::capillary);
  // Body-force limit: from rest, gravity moves a particle at most 1 % of a spacing per step
  // (g Δt²/2 ≤ d/100). Larger steps leave a settling column more compression than the clamped,
  // push-only pressure solve removes cleanly, and deep columns start to ring.
  const Real gravity_norm = settings.gravity.norm();
  if (gravity_norm > 0) limit(std::sqrt(diameter / (50 * gravity_norm)), TimeStepBound::gravity);
  if (time_step < settings.min_time_step) time_step = settings.min_time_step, bound = TimeStepBound::smallest;
  state.time_step = time_step;
  state.last_step.time_step_bound = bound;
}

void choose_granular_time_step(const Model& model, State& state, Workspace& /*workspace*/) {
  // Contacts set the step; the CFL limit keeps a fast particle from passing through another.
  const Real time_step = courant_limit(model, std::min(model.settings.max_time_step, model.granular_time_step),
                                       max_speed_squared(state, 0));
  state.time_step = std::max(time_step, model.settings.min_time_step);
}

void integrate_accelerations(const Model& /*model*/, State& state, Workspace& /*workspace*/) {
  auto& fluid = state.fluid;
  const Real time_step = state.time_step;
  parallel_for_each_index(state.active_count, [&](std::size_t i) { fluid.velocity[i] += time_step * fluid.acceleration[i]; }, 1024);
}

}  // namespace m3dp::sph::stages
