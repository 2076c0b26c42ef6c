// Rest detection: printed material that has come to rest leaves the solve (stage "reorder") and stands
// as fixed neighbours of the material still moving; motion nearby, a moving body or (wake_on_load) a
// growing load wakes it (stage "advect").
#include <tbb/parallel_sort.h>

#include <atomic>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void update_rest_partition(const Model& model, State& state, Workspace& workspace) {
  if (!model.settings.rest_detection) return;
  auto& fluid = state.fluid;
  const Real duration = model.settings.rest_duration;
  // Resting: from the top of the active range down, so a swap never moves an unvisited candidate.
  for (std::size_t i = state.active_count; i-- > 0;) {
    if (fluid.rest_time[i] < duration) continue;
    const std::size_t last = --state.active_count;
    if (i != last) fluid.swap(i, last);
    fluid.velocity[last] = Vec3::Zero();
    fluid.viscous_change[last] = Vec3::Zero();
    fluid.viscous_velocity[last] = Vec3::Zero();
    fluid.angular_velocity[last] = Vec3::Zero();
    fluid.kappa_density[last] = 0;
    fluid.kappa_divergence[last] = 0;
    fluid.kappa_tension[last] = 0;
    fluid.rest_load[last] = -1;  // measured at the next load check
  }
  // Waking: a resting particle whose clock was reset by motion nearby (update_rest_clocks). The
  // woken few are found in blocks, in parallel (a 20-layer wall rests 4·10⁵ particles), then moved in
  // index order, as one pass over them all would.
  if (!state.resting_woken) return;
  state.resting_woken = 0;
  constexpr std::size_t kBlock = 4096;
  const std::size_t first = state.active_count, count = fluid.size();
  const std::size_t blocks = (count - first + kBlock - 1) / kBlock;
  auto& woken_in = workspace.woken_in_block;
  woken_in.resize(blocks);
  parallel_for_each_index(blocks, [&](std::size_t b) {
    std::uint8_t any = 0;
    for (std::size_t j = first + b * kBlock, end = std::min(count, j + kBlock); j < end; ++j) any |= fluid.rest_time[j] < duration;
    woken_in[b] = any;
  }, 4);
  for (std::size_t b = 0; b < blocks; ++b) {
    if (!woken_in[b]) continue;
    // Each woken one goes to the first resting slot, whose particle (resting, not woken: those before
    // were moved already) takes its place.
    for (std::size_t j = first + b * kBlock, end = std::min(count, j + kBlock); j < end; ++j) {
      if (fluid.rest_time[j] >= duration) continue;
      if (j != state.active_count) fluid.swap(j, state.active_count);
      ++state.active_count;
    }
  }
}

void update_rest_clocks(const Model& model, State& state, Workspace& workspace) {
  if (!model.settings.rest_detection) return;
  const Real time_step = state.time_step;
  const auto& settings = model.settings;
  auto& fluid = state.fluid;
  const std::size_t active = state.active_count;
  const Real rest_speed_squared = settings.rest_speed * settings.rest_speed;
  const Real wake_speed_squared = settings.wake_speed * settings.wake_speed;
  const Real time = static_cast<Real>(state.time);
  const Real compressed = 1 + settings.rest_compression;
  auto wake = [&](std::size_t j) {
    std::atomic_ref<Real>(fluid.rest_time[j]).store(0, std::memory_order_relaxed);
    std::atomic_ref<int>(state.resting_woken).store(1, std::memory_order_relaxed);
  };
  // With none resting there is nothing to wake: no pass over the fast particles' lists.
  const bool any_resting = active < fluid.size();
  // Material a nozzle with a bore is still laying does not rest: within its lip's radius of its exit
  // the moving nozzle drags, bends and presses the strand (a rope hanging from it to the layer below,
  // still to be laid down, is not at rest however slow its foot). Two bores more cost a pressed strand
  // 1.6× and landed no more of a rope (docs/decisions.md).
  auto being_laid = [&](const Vec3& position) {
    for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
      if (!state.nozzles[n].extruding || !model.nozzle_geometry[n].has_bore()) continue;
      const NozzleSettings& nozzle = model.nozzles[n];
      const Real reach = std::max(nozzle.outer_diameter, nozzle.inner_diameter) / 2;
      if ((position - state.nozzles[n].pose.position).squaredNorm() < reach * reach) return true;
    }
    return false;
  };
  parallel_for_each_index(active, [&](std::size_t i) {
    const FluidPhase& phase = model.phases[fluid.phase[i]];
    const Real speed_squared = fluid.velocity[i].squaredNorm();
    // Only a yield-stress material can stop for good (any other creeps on); it rests while slow and
    // while its shear stress μ γ̇ stays below its (aged) yield stress.
    bool resting = false;
    // An elastic material never rests: its stress depends on where its neighbours are.
    // Nor while compressed (settings.rest_compression): it would stay so (wake_compressed_rest).
    if (!phase.elasticity.enabled && speed_squared < rest_speed_squared && fluid.density[i] <= compressed * phase.density &&
        !being_laid(fluid.position[i]))
      resting = unyielded(phase, fluid, i, time);
    // A negative clock (woken by load) keeps counting from where it is; motion cannot shorten the hold.
    fluid.rest_time[i] = resting ? fluid.rest_time[i] + time_step : std::min(fluid.rest_time[i], Real(0));
    if (any_resting && speed_squared > wake_speed_squared)
      for (const Index j : workspace.fluid_neighbors.of(i))
        if (j >= active) wake(j);
  }, 512);
  // A moving body's surface wakes the resting material it reaches (a robot, a dropped box).
  if (active == fluid.size() || workspace.moving_boundary_indices.empty()) return;
  const Real support_squared = model.support_radius * model.support_radius;
  parallel_for_each_index(workspace.moving_boundary_indices.size(), [&](std::size_t k) {
    const Index b = workspace.moving_boundary_indices[k];
    const Vec3 velocity = state.boundary.velocity[b];
    if (velocity.squaredNorm() <= wake_speed_squared) return;
    // Where the surface is now and where it will be in two steps: a fast body must not reach resting
    // material before it has woken (it would land inside particles that do not push back).
    for (const Vec3& position : {state.boundary.position[b], Vec3(state.boundary.position[b] + 2 * time_step * velocity)})
      for (const SpatialHashGrid* grid : {&workspace.resting_grid, &workspace.recent_resting_grid})
        grid->for_each_candidate(position, [&](Index j, const Vec3& p) {
          if (j >= active && (p - position).squaredNorm() < support_squared) wake(j);
        });
  }, 64);
}

void wake_loaded_rest(const Model& model, State& state, Workspace& workspace) {
  if (!model.settings.rest_detection || !model.settings.wake_on_load || state.time < state.next_load_check_time) return;
  state.next_load_check_time = state.time + 0.5 * model.settings.rest_duration;
  const auto& settings = model.settings;
  auto& fluid = state.fluid;
  const std::size_t count = fluid.size();
  const Real g = settings.gravity.norm();
  if (state.active_count == count || !(g > 0)) return;
  // Columns two particle diameters across, along gravity: the weight per area above each particle,
  // σ_v = g Σ m / w², from the top of its column down. One diameter is too noisy: the particles are
  // not on a lattice, and a d-wide column over a print's seam held twice its share.
  const Vec3 down = settings.gravity / g;
  const Vec3 across_u = down.unitOrthogonal();
  const Vec3 across_v = down.cross(across_u);
  const Real column_width = 2 * model.particle_diameter;
  const Real inverse_width = 1 / column_width;
  workspace.sort_keys.resize(count);
  workspace.permutation.resize(count);
  workspace.height.resize(count);
  parallel_for_each_index(count, [&](std::size_t i) {
    const Vec3& p = fluid.position[i];
    const auto column_u = static_cast<std::int64_t>(std::floor(p.dot(across_u) * inverse_width)) + (std::int64_t(1) << 31);
    const auto column_v = static_cast<std::int64_t>(std::floor(p.dot(across_v) * inverse_width)) + (std::int64_t(1) << 31);
    workspace.sort_keys[i] = (static_cast<std::uint64_t>(column_u) << 32) | (static_cast<std::uint64_t>(column_v) & 0xffffffffu);
    workspace.height[i] = -p.dot(down);
    workspace.permutation[i] = static_cast<Index>(i);
  }, 2048);
  const auto& key = workspace.sort_keys;
  const auto& height = workspace.height;
  tbb::parallel_sort(workspace.permutation.begin(), workspace.permutation.end(), [&](Index a, Index b) {
    return key[a] != key[b] ? key[a] < key[b] : (height[a] != height[b] ? height[a] > height[b] : a < b);
  });
  const Real load_per_mass = g * inverse_width * inverse_width;
  const Real time = static_cast<Real>(state.time);
  const std::size_t active = state.active_count;
  // Roussel 2018: a layer under a height H of material yields once ρ g H > √3 τ0 (unconfined).
  const Real unconfined = std::sqrt(Real(3));
  bool woken = false;
  std::size_t run_begin = 0;
  while (run_begin < count) {
    std::size_t run_end = run_begin + 1;
    while (run_end < count && key[workspace.permutation[run_end]] == key[workspace.permutation[run_begin]]) ++run_end;
    Real mass_above = 0;
    std::size_t deepest_loaded = run_begin;  // one past the deepest particle to wake in this column
    for (std::size_t n = run_begin; n < run_end; ++n) {
      const Index i = workspace.permutation[n];
      const Real load = load_per_mass * mass_above;
      mass_above += fluid.mass[i];
      if (i < active) continue;
      if (fluid.rest_load[i] < 0) {
        fluid.rest_load[i] = load;  // came to rest since the last check
        continue;
      }
      const FluidPhase& phase = model.phases[fluid.phase[i]];
      const Real yield_stress = phase.ageing.yield_stress(phase.rheology.yield_stress, time - fluid.birth_time[i]);
      if (load - fluid.rest_load[i] > Real(0.1) * yield_stress && load > unconfined * yield_stress) deepest_loaded = n + 1;
    }
    // The material above a loaded particle is what loads it: it must move too, or it hangs as a fixed block.
    for (std::size_t n = run_begin; n < deepest_loaded; ++n) {
      const Index i = workspace.permutation[n];
      if (i < active) continue;
      // A collapse starts slowly: the clock starts well below zero so that the particle is simulated
      // long enough for the flow to develop before slowness can put it to rest again.
      fluid.rest_time[i] = -settings.load_wake_duration;
      woken = true;
    }
    run_begin = run_end;
  }
  if (woken) state.resting_woken = 1;
}

void wake_compressed_rest(const Model& model, State& state, Workspace& workspace) {
  // Every fourth step: resting material pressed for a few steps more costs nothing, the sums do.
  if (!model.settings.rest_detection || state.step % 4 != 0) return;
  auto& fluid = state.fluid;
  const std::size_t active = state.active_count, count = fluid.size();
  if (active == 0 || active == count) return;
  // Resting particles are fixed neighbours: the density solves push the moving ones off them
  // (Workspace::RestingInterface), but the viscosity solve and the corrections after it may still
  // press one together, and it would stay so. Only those that moving material touches (this step's
  // interface) can have changed.
  const auto& near = workspace.resting_interface.particles;
  // The moving particles where this step left them (the neighbour search's own grid is from before
  // the step, and not built at all while it keeps its lists).
  workspace.moved_grid.build(std::span<const Vec3>(fluid.position.data(), active), model.support_radius);
  const Real support_squared = model.support_radius * model.support_radius;
  const Real compressed = 1 + model.settings.rest_compression;  // ρ/ρ0
  const auto& boundary = state.boundary;
  std::atomic<int> woken{0};
  with_kernel(model.settings.kernel, model.support_radius, [&](const auto& kernel) {
    parallel_for_each_index(near.size(), [&](std::size_t k) {
      const std::size_t j = near[k];
      const Vec3 position = fluid.position[j];
      // Its density where everything is now, as measure_density sums it.
      Real fluid_sum = 0, wall_volume_sum = 0;
      for (const SpatialHashGrid* grid : {&workspace.moved_grid, &workspace.resting_grid, &workspace.recent_resting_grid})
        grid->for_each_candidate(position, [&](Index, const Vec3& other) {
          const Real distance_squared = (position - other).squaredNorm();
          if (distance_squared < support_squared) fluid_sum += kernel.W(std::sqrt(distance_squared));
        });
      for (const SpatialHashGrid* grid : {&workspace.static_boundary_grid, &workspace.moving_boundary_grid})
        grid->for_each_candidate(position, [&](Index b, const Vec3& wall) {
          const Real distance_squared = (position - wall).squaredNorm();
          if (distance_squared < support_squared) wall_volume_sum += boundary.volume[b] * kernel.W(std::sqrt(distance_squared));
        });
      if (model.particle_volume * fluid_sum + wall_volume_sum <= compressed) return;
      fluid.rest_time[j] = 0;
      woken.store(1, std::memory_order_relaxed);
    }, 512);
  });
  if (woken.load()) state.resting_woken = 1;
}

}  // namespace m3dp::sph::stages
