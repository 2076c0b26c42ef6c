// Stages "bodies" (the choice) and "neighbors": each step either keeps the neighbour lists of earlier
// steps (SkinnedNeighborSearch, for slow material) or searches the grids for every active particle.
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <functional>
#include <numeric>

#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

namespace {
/// Fast particles that kept neighbour lists tolerate (SkinnedNeighborSearch): each searches the grids
/// itself and all of them pairwise, so a few hundred cost less than a new search of every particle.
std::size_t most_movers(std::size_t active_count) {
  return std::clamp<std::size_t>(active_count / 64, 32, 1024);
}
/// Recent resting particles kept in a grid of their own before both resting grids are built again as
/// one: a full build costs every resting particle, a recent one its own count at each change, so ~√n.
std::size_t most_recent_resting(std::size_t resting_count) {
  return std::max<std::size_t>(256, 2 * static_cast<std::size_t>(std::sqrt(static_cast<double>(resting_count))));
}
}  // namespace

void choose_neighbor_search(const Model& model, State& state, Workspace& workspace) {
  const auto& settings = model.settings;
  const Real support = model.support_radius;
  const Real skin = settings.neighbor_skin * support;
  const std::size_t active = state.active_count;
  bool use_skin = state.skin_in_use;
  if (!(skin > 0)) {
    use_skin = false;
  } else if (use_skin) {
    // Kept lists searched anew in half of the last eight steps cost more than a search every step.
    if (std::popcount(state.recent_searches & 0xffu) >= 4) {
      use_skin = false;
      // Each switch rebuilds the fixed grids for the other cell size: where kept lists keep failing
      // soon (a print whose resting set changes every few steps), they are tried ever more rarely.
      const bool failed_soon = state.step - state.skin_since_step < 64;
      state.skin_backoff = failed_soon ? std::min(2 * state.skin_backoff, 4096) : 64;
      state.skin_cooldown = state.skin_backoff;
    }
  } else if (state.skin_cooldown > 0) {
    --state.skin_cooldown;
  } else {
    // Would kept lists last? A particle that moves more than skin/8 a step leaves its skin/2 within
    // four steps; a few of them (a falling strand) search for themselves, many force new searches.
    const Real step_limit = skin / 8 / state.time_step;
    const Real speed_limit_squared = step_limit * step_limit;
    const std::size_t fast = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, active, 4096), std::size_t(0),
        [&](const tbb::blocked_range<std::size_t>& range, std::size_t found) {
          for (std::size_t i = range.begin(); i != range.end(); ++i) found += state.fluid.velocity[i].squaredNorm() > speed_limit_squared;
          return found;
        },
        std::plus<std::size_t>());
    state.calm_steps = fast <= most_movers(active) ? state.calm_steps + 1 : 0;
    if (state.calm_steps >= 8) use_skin = true;
  }
  if (use_skin != state.skin_in_use) {
    state.skin_in_use = use_skin;
    state.skin_since_step = state.step;
    state.calm_steps = 0;
    state.recent_searches = 0;
    workspace.skinned_search.invalidate();
  }
  // Lists of radius support + skin need cells as large in every grid.
  const Real cell_size = use_skin ? support + skin : support;
  if (cell_size != workspace.search_cell_size) {
    workspace.search_cell_size = cell_size;
    workspace.static_boundary_dirty = true;
  }
}

namespace {
/// Keeps the two resting grids current (see Workspace::resting_grid).
void update_resting_grids(State& state, Workspace& workspace, Real cell_size) {
  auto& fluid = state.fluid;
  const std::size_t count = fluid.size();
  const std::size_t active_count = state.active_count;
  const std::size_t resting_count = count - active_count;
  const std::size_t most_recent = most_recent_resting(resting_count);
  // The settled grid holds while the recent ones stay few: the slots it holds that changed since (a
  // woken particle swapped out, a resting one in) leave it and join the recent ones (holes).
  auto& holes = workspace.settled_holes;
  bool settled_valid = !workspace.resting_grid_dirty && !fluid.touched_overflow && workspace.resting_grid.cell_size() == cell_size &&
                       active_count <= workspace.settled_begin && workspace.settled_end <= count;
  if (settled_valid && !fluid.touched_slots.empty()) {
    for (const Index slot : fluid.touched_slots) {
      workspace.resting_grid.remove_point(slot - workspace.settled_begin, slot);
      holes.push_back(slot);
    }
    fluid.touched_slots.clear();
    std::sort(holes.begin(), holes.end());
    holes.erase(std::unique(holes.begin(), holes.end()), holes.end());
  }
  if (settled_valid && (workspace.settled_begin - active_count) + (count - workspace.settled_end) + holes.size() > most_recent)
    settled_valid = false;
  bool changed = false;
  if (!settled_valid) {
    // The lowest resting slots stay recent: an emission moves the first resting particle to the end,
    // and would otherwise touch the settled slots at once.
    workspace.settled_begin = active_count + std::min(resting_count, most_recent / 2);
    workspace.settled_end = count;
    workspace.resting_grid_subset.resize(count - workspace.settled_begin);
    std::iota(workspace.resting_grid_subset.begin(), workspace.resting_grid_subset.end(), static_cast<Index>(workspace.settled_begin));
    workspace.resting_grid.build(fluid.position, workspace.resting_grid_subset, cell_size);
    fluid.watch_slots(workspace.settled_begin, workspace.settled_end);
    holes.clear();
    holes.reserve(FluidParticles::kMostTouched + most_recent);
    ++workspace.settled_builds;
    workspace.resting_grid_dirty = false;
    changed = true;
  }
  // The recent ones: compared particle by particle (a few hundred), built again when they differ.
  auto& subset = workspace.resting_grid_subset;
  subset.clear();
  for (std::size_t i = active_count; i < workspace.settled_begin; ++i) subset.push_back(static_cast<Index>(i));
  subset.insert(subset.end(), holes.begin(), holes.end());
  for (std::size_t i = workspace.settled_end; i < count; ++i) subset.push_back(static_cast<Index>(i));
  // Slots too: an emission of n particles moves the n lowest resting ones, in order, n slots up.
  bool recent_changed = changed || subset.size() != workspace.recent_resting_ids.size() ||
                        workspace.recent_resting_grid.cell_size() != cell_size ||
                        !std::equal(subset.begin(), subset.end(), workspace.recent_resting_slots.begin());
  for (std::size_t k = 0; k < subset.size() && !recent_changed; ++k)
    recent_changed = fluid.id[subset[k]] != workspace.recent_resting_ids[k] || fluid.position[subset[k]] != workspace.recent_resting_positions[k];
  if (recent_changed) {
    workspace.recent_resting_slots.assign(subset.begin(), subset.end());
    workspace.recent_resting_ids.resize(subset.size());
    workspace.recent_resting_positions.resize(subset.size());
    for (std::size_t k = 0; k < subset.size(); ++k) {
      workspace.recent_resting_ids[k] = fluid.id[subset[k]];
      workspace.recent_resting_positions[k] = fluid.position[subset[k]];
    }
    workspace.recent_resting_grid.build(fluid.position, subset, cell_size);
  }
  // Kept neighbour lists hold resting neighbours by slot: any change searches anew (an empty set that
  // stays empty is no change, so a nozzle's first layers keep their lists).
  if (changed || recent_changed) ++workspace.fixed_grids_version;
}
}  // namespace

void search_neighbors(const Model& model, State& state, Workspace& workspace) {
  const Real support = model.support_radius;
  const Real cell_size = workspace.search_cell_size;
  const auto& fluid = state.fluid;
  const std::size_t active_count = state.active_count;
  // The active particles in one grid, every step; the resting ones (neighbours too) in two others,
  // built again only when they changed (in a 20-layer wall print, 24.6k resting particles against 185
  // active ones, their grid had been most of the neighbour stage). Only the active ones query.
  // Lists stay in grid order, which is as deterministic; sorted by index they made the sweeps no faster.
  const std::span<const Vec3> active(fluid.position.data(), active_count);
  update_resting_grids(state, workspace, cell_size);
  if (state.skin_in_use) {
    SkinnedNeighborSearch::Inputs inputs;
    inputs.fluid_positions = fluid.position;
    inputs.fluid_ids = fluid.id;
    inputs.active_count = active_count;
    inputs.resting_grid = &workspace.resting_grid;
    inputs.recent_resting_grid = &workspace.recent_resting_grid;
    inputs.static_boundary_grid = &workspace.static_boundary_grid;
    inputs.moving_boundary_grid = &workspace.moving_boundary_grid;
    inputs.boundary_positions = state.boundary.position;
    inputs.moving_boundary_indices = workspace.moving_boundary_indices;
    inputs.fixed_grids_version = workspace.fixed_grids_version;
    const bool searched = workspace.skinned_search.update(inputs, support, cell_size - support, most_movers(active_count),
                                                       workspace.fluid_neighbors, workspace.boundary_neighbors);
    state.recent_searches = (state.recent_searches << 1) | (searched ? 1u : 0u);
    state.neighbor_searches += searched;
    return;
  }
  ++state.neighbor_searches;
  workspace.fluid_grid.build(active, cell_size);
  // Queries in the active grid's order: a cell's particles come together and share one candidate
  // gather (in index order they drift apart between reorderings).
  const std::span<const Index> query_order = workspace.fluid_grid.points_in_grid_order();
  const SpatialHashGrid* fluid_grids[] = {&workspace.fluid_grid, &workspace.resting_grid, &workspace.recent_resting_grid};
  find_neighbors(fluid_grids, active, support, true, workspace.fluid_neighbors, false, query_order);
  const SpatialHashGrid* boundary_grids[] = {&workspace.static_boundary_grid, &workspace.moving_boundary_grid};
  find_neighbors(boundary_grids, active, support, false, workspace.boundary_neighbors, false, query_order);
}

}  // namespace m3dp::sph::stages
