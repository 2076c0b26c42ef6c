#include "m3dp/sph/state.hpp"

#include <algorithm>
#include <numeric>

#include "m3dp/core/parallel.hpp"
#include "m3dp/core/state_io.hpp"

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
  settled_box_builds = ~std::uint64_t(0);  // the settled slots are another state's
  viscosity_system.coarse_level = stages::CoarseViscosityLevelHolder();
}

void Workspace::reserve(std::size_t capacity) {
  kappa.reserve(capacity);
  for (auto* vector : {&tension_system.residual, &tension_system.solution, &tension_system.direction, &tension_system.preconditioned,
                       &tension_system.product, &tension_system.inverse_diagonal})
    vector->reserve(capacity);
  tension_system.velocity_change.reserve(capacity);
  tension_system.at_surface.reserve(capacity);
  solver_position.reserve(capacity);
  solver_velocity.reserve(capacity);
  solver_wall_sums.reserve(capacity);
  resting_grid_subset.reserve(capacity);
  recent_resting_slots.reserve(capacity);
  recent_resting_ids.reserve(capacity);
  recent_resting_positions.reserve(capacity);
  sort_keys.reserve(capacity);
  resting_interface.slot_of.reserve(capacity);
  woken_in_block.reserve(capacity / 4096 + 1);
  resting_interface.fixed_part.reserve(capacity);
  resting_interface.fixed_part_version.reserve(capacity);
  permutation.reserve(capacity);
  scratch_vec3.reserve(capacity);
  scratch_real.reserve(capacity);
  scratch_u16.reserve(capacity);
  scratch_i32.reserve(capacity);
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

namespace m3dp::sph {

LazyWallFace::Range LazyWallFace::tile_range(std::size_t tile) const {
  const int tile_a = int(tile / std::size_t(tiles_b)), tile_b = int(tile % std::size_t(tiles_b));
  Range range;
  range.first_a = lattice.first_a + tile_a * kLazyTilePoints;
  range.last_a = std::min(lattice.last_a, range.first_a + kLazyTilePoints - 1);
  range.first_b = lattice.first_b + tile_b * kLazyTilePoints;
  range.last_b = std::min(lattice.last_b, range.first_b + kLazyTilePoints - 1);
  return range;
}

void save_state(const State& state, StateWriter& out) {
  out.section("sph.state 3");
  const_cast<FluidParticles&>(state.fluid).for_each_field([&](const auto& field) { out.put(field); });
  out.put(state.active_count);
  out.put(state.resting_woken);
  out.put(state.next_load_check_time);
  // The lazy walls' tiles made so far, before the arrays they lengthened.
  out.put(state.made_tiles);
  out.put(state.boundary.local_position);
  out.put(state.boundary.position);
  out.put(state.boundary.velocity);
  out.put(state.boundary.volume);
  out.put(state.boundary.body);
  out.put(static_cast<std::uint64_t>(state.bodies.size()));
  for (const BoundaryBody& body : state.bodies) {
    out.put(body.name);
    out.put(body.is_static);
    out.put(body.first_particle);
    out.put(body.particle_count);
    out.put(body.pose);
    out.put(body.local_bounds);
    out.put(body.near_fluid);
    out.put(body.linear_velocity);
    out.put(body.angular_velocity);
    out.put(body.fluid_force);
    out.put(body.fluid_torque);
  }
  out.put(state.nozzles);
  out.put(state.time);
  out.put(state.step);
  out.put(state.time_step);
  out.put(state.next_particle_id);
  out.put(state.particles_removed_total);
  out.put(state.mass_removed_total);
  out.put(state.mass_emitted_total);
  out.put(state.last_step);
  out.put(state.skin_in_use);
  out.put(state.calm_steps);
  out.put(state.skin_cooldown);
  out.put(state.skin_backoff);
  out.put(state.skin_since_step);
  out.put(state.recent_searches);
  out.put(state.neighbor_searches);
  out.put(state.previous_viscosity_iterations);
}

void load_state(StateReader& in, State& state) {
  in.section("sph.state 3");
  state.fluid.for_each_field([&](auto& field) { in.get(field); });
  const std::size_t count = state.fluid.size();
  state.fluid.for_each_field([&](const auto& field) {
    if (field.size() != count) in.fail("particle fields of different lengths");
  });
  state.fluid.watch_slots(0, 0);
  in.get(state.active_count);
  if (state.active_count > count) in.fail("more active particles than particles");
  in.get(state.resting_woken);
  in.get(state.next_load_check_time);
  // The walls the scene makes (without the lazy walls' tiles this state has made), then the tiles the
  // run had made, whose particles follow.
  std::size_t boundary_particles = state.boundary.size();
  for (const std::uint64_t made : state.made_tiles) boundary_particles -= state.lazy_walls[made >> 32].tile_range(made & 0xffffffffu).points();
  for (auto& face : state.lazy_walls) std::fill(face.made.begin(), face.made.end(), std::uint8_t(0));
  in.get(state.made_tiles);
  for (const std::uint64_t made : state.made_tiles) {
    const std::size_t face_index = made >> 32, tile = made & 0xffffffffu;
    if (face_index >= state.lazy_walls.size() || tile >= state.lazy_walls[face_index].made.size() || state.lazy_walls[face_index].made[tile])
      in.fail("a wall tile the scene does not have");
    state.lazy_walls[face_index].made[tile] = 1;
    boundary_particles += state.lazy_walls[face_index].tile_range(tile).points();
  }
  in.get(state.boundary.local_position);
  if (state.boundary.local_position.size() != boundary_particles) in.fail("another set of walls and bodies than the scene makes");
  in.get(state.boundary.position);
  in.get(state.boundary.velocity);
  in.get(state.boundary.volume);
  in.get(state.boundary.body);
  if (state.boundary.position.size() != boundary_particles || state.boundary.velocity.size() != boundary_particles ||
      state.boundary.volume.size() != boundary_particles || state.boundary.body.size() != boundary_particles)
    in.fail("another set of walls and bodies than the scene makes");
  state.boundary.wall_kind.resize(boundary_particles, material::Wall::static_wall);  // tiles are floors and walls
  const auto bodies = in.get<std::uint64_t>();
  if (bodies != state.bodies.size()) in.fail("a different number of boundary bodies than the scene makes");
  for (BoundaryBody& body : state.bodies) {
    in.get(body.name);
    in.get(body.is_static);
    in.get(body.first_particle);
    in.get(body.particle_count);
    in.get(body.pose);
    in.get(body.local_bounds);
    in.get(body.near_fluid);
    in.get(body.linear_velocity);
    in.get(body.angular_velocity);
    in.get(body.fluid_force);
    in.get(body.fluid_torque);
  }
  const std::size_t nozzles = state.nozzles.size();
  in.get(state.nozzles);
  if (state.nozzles.size() != nozzles) in.fail("a different number of nozzles than the scene makes");
  in.get(state.time);
  in.get(state.step);
  in.get(state.time_step);
  in.get(state.next_particle_id);
  in.get(state.particles_removed_total);
  in.get(state.mass_removed_total);
  in.get(state.mass_emitted_total);
  in.get(state.last_step);
  in.get(state.skin_in_use);
  in.get(state.calm_steps);
  in.get(state.skin_cooldown);
  in.get(state.skin_backoff);
  in.get(state.skin_since_step);
  in.get(state.recent_searches);
  in.get(state.neighbor_searches);
  in.get(state.previous_viscosity_iterations);
}

bool pack_padded(std::span<const Vec3> from, std::vector<Vec4>& to, std::size_t active, const Workspace& workspace,
                 Workspace::RestingCopy& copy) {
  const std::size_t copied_size = std::min(copy.size, to.size());
  const std::uint64_t copied_builds = copy.settled_builds;
  const bool resting_changed = copy.take(workspace.fixed_grids_version, from.size(), active) || to.size() != from.size();
  to.resize(from.size());
  parallel_for_each_index(active, [&](std::size_t i) { to[i] = padded(from[i]); }, 4096);
  if (!resting_changed) return false;
  workspace.for_each_unsettled_range(active, from.size(), copied_builds, copied_size, [&](std::size_t begin, std::size_t end) {
    if (end - begin > 4096) parallel_for_each_index(end - begin, [&](std::size_t k) { to[begin + k] = padded(from[begin + k]); }, 4096);
    else for (std::size_t i = begin; i < end; ++i) to[i] = padded(from[i]);
  });
  copy.settled_builds = workspace.settled_builds;
  return true;
}

}  // namespace m3dp::sph
