#include "m3dp/sph/state.hpp"

#include <numeric>

namespace m3dp::sph {

void NozzleState::end_blockage(double now) {
  if (blocked_since < 0) return;
  const double duration = now - blocked_since;
  if (duration > longest_blockage.duration) longest_blockage = {blocked_since, duration, blocked_at};
  blocked_since = -1;
}

double StageTimes::total() const { return std::accumulate(ms.begin(), ms.end(), 0.0); }

StageTimes& StageTimes::operator+=(const StageTimes& other) {
  for (std::size_t s = 0; s < kStageCount; ++s) ms[s] += other.ms[s];
  return *this;
}

void Workspace::invalidate() {
  static_boundary_dirty = true;
  resting_grid_dirty = true;
  ++fixed_grids_version;
  skinned_search.invalidate();
  viscosity_system.coarse_level = stages::CoarseViscosityLevelHolder();
}

void Workspace::reserve(std::size_t capacity) {
  kappa.reserve(capacity);
  solver_position.reserve(capacity);
  solver_velocity.reserve(capacity);
  solver_wall_sums.reserve(capacity);
  resting_grid_subset.reserve(capacity);
  recent_resting_slots.reserve(capacity);
  recent_resting_ids.reserve(capacity);
  recent_resting_positions.reserve(capacity);
  sort_keys.reserve(capacity);
  permutation.reserve(capacity);
  scratch_vec3.reserve(capacity);
  scratch_real.reserve(capacity);
  scratch_u16.reserve(capacity);
  scratch_u64.reserve(capacity);
  fluid_neighbors.counts.reserve(capacity);
  fluid_neighbors.firsts.reserve(capacity);
  fluid_neighbors.indices.reserve(capacity * fluid_neighbors.stride);
  fluid_neighbors.staging.reserve(capacity * fluid_neighbors.stride);
  boundary_neighbors.counts.reserve(capacity);
  boundary_neighbors.firsts.reserve(capacity);
  boundary_neighbors.indices.reserve(capacity * boundary_neighbors.stride);
  boundary_neighbors.staging.reserve(capacity * boundary_neighbors.stride);
  auto& system = viscosity_system;
  system.fluid_pair_coefficient.reserve(capacity * fluid_neighbors.stride);
  system.boundary_pair_coefficient.reserve(capacity * boundary_neighbors.stride);
  system.inverse_diagonal.reserve(capacity);
  system.own_block.reserve(capacity);
  system.padded_operand.reserve(capacity);
  surface_normal.reserve(capacity);
  surface_flag.reserve(capacity);
  surface_curvature.reserve(capacity);
  elastic_stress.reserve(capacity);
  for (auto* vector : {&system.rhs, &system.residual, &system.preconditioned, &system.product, &system.start_velocity,
                       &system.aggregate_offset})
    vector->reserve(capacity);
}

}  // namespace m3dp::sph
