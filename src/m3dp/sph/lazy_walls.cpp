// Stage "bodies": static walls made where the material comes (issue 41). A wide flat face of a static
// box or plane is a lattice of boundary particles (boundary_sampling's), split into tiles of
// kLazyTilePoints × kLazyTilePoints points; a tile's particles are appended, with their Akinci volumes,
// the first step a moving particle or an extruding nozzle's exit comes within reach of it (or
// Solver::add_particles puts material there). A 10 × 10 m floor under a print of a few cm² holds the
// particles of the tiles under the print.
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

Real lazy_wall_reach(const Model& model) {
  // A wall particle within a support (and a step's move, under a diameter) of the material takes part
  // in its sums, and its volume sums its neighbours a support further: all of those must be in.
  return 2 * model.support_radius + 2 * model.particle_diameter;
}

namespace {

/// A face's frame in the world: local = to_face (x − origin) has the face's sides along x and y and its
/// normal along z.
struct FaceFrame {
  Mat3 to_face;
  Vec3 origin;
};
FaceFrame face_frame(const State& state, const LazyWallFace& face) {
  const Pose& pose = state.bodies[face.body].pose;
  return {(pose.orientation.toRotationMatrix() * face.lattice.rotation).transpose(), pose.apply(face.lattice.offset)};
}

/// The tiles of `face` that the rectangle [low, high] (face coordinates, x and y) touches, as tile
/// index ranges (inclusive); empty when it misses the face's lattice.
struct TileSpan {
  int first_a = 0, last_a = -1, first_b = 0, last_b = -1;
};
TileSpan tiles_touched(const LazyWallFace& face, Real low_a, Real high_a, Real low_b, Real high_b) {
  const RectangleLattice& lattice = face.lattice;
  // Lattice index i sits at a = size_a (i / count_a − 1/2); clamped before the conversion, so that a
  // box far larger than the face stays in int's range.
  const auto index_range = [](Real low, Real high, Real size, int count, int first, int last) {
    const Real scale = Real(count) / std::max(size, Real(1e-30));
    const auto index = [&](Real value) { return std::clamp(value * scale + Real(0.5) * Real(count), Real(first - 1), Real(last + 1)); };
    return std::pair{std::max(first, static_cast<int>(std::floor(index(low)))), std::min(last, static_cast<int>(std::ceil(index(high))))};
  };
  const auto [from_a, to_a] = index_range(low_a, high_a, lattice.size_a, lattice.count_a, lattice.first_a, lattice.last_a);
  const auto [from_b, to_b] = index_range(low_b, high_b, lattice.size_b, lattice.count_b, lattice.first_b, lattice.last_b);
  if (from_a > to_a || from_b > to_b) return {};
  return {(from_a - lattice.first_a) / kLazyTilePoints, (to_a - lattice.first_a) / kLazyTilePoints, (from_b - lattice.first_b) / kLazyTilePoints,
          (to_b - lattice.first_b) / kLazyTilePoints};
}

/// Appends the particles of tile `tile` of face `f` (not made yet) and records it.
void append_tile(State& state, std::size_t f, std::size_t tile) {
  LazyWallFace& face = state.lazy_walls[f];
  auto& boundary = state.boundary;
  const Pose& pose = state.bodies[face.body].pose;
  face.made[tile] = 1;
  state.made_tiles.push_back(std::uint64_t(f) << 32 | tile);
  const LazyWallFace::Range range = face.tile_range(tile);
  for (int i = range.first_a; i <= range.last_a; ++i)
    for (int j = range.first_b; j <= range.last_b; ++j) {
      const Vec3 point = face.lattice.point(i, j);
      boundary.local_position.push_back(point);
      boundary.position.push_back(pose.apply(point));
      boundary.velocity.push_back(Vec3::Zero());
      boundary.body.push_back(face.body);
      boundary.wall_kind.push_back(material::Wall::static_wall);  // tiles are of static floors and walls
    }
}

/// The volumes of the particles appended from `first_new` on (and of their static neighbours).
void finish_tiles(const Model& model, State& state, Workspace& workspace, std::size_t first_new) {
  if (state.boundary.size() == first_new) return;
  sum_boundary_volumes(model, state, first_new, 0, true);
  workspace.static_boundary_dirty = true;
}

}  // namespace

void make_walls_within(const Model& model, State& state, Workspace& workspace, const Aabb& box) {
  if (state.lazy_walls.empty() || box.empty()) return;
  const std::size_t first_new = state.boundary.size();
  for (std::size_t f = 0; f < state.lazy_walls.size(); ++f) {
    const LazyWallFace& face = state.lazy_walls[f];
    const FaceFrame frame = face_frame(state, face);
    Aabb local;  // the box's corners in the face's frame
    for (int corner = 0; corner < 8; ++corner) {
      const Vec3 point((corner & 1) ? box.max.x() : box.min.x(), (corner & 2) ? box.max.y() : box.min.y(),
                       (corner & 4) ? box.max.z() : box.min.z());
      local.extend(frame.to_face * (point - frame.origin));
    }
    if (local.min.z() > 0 || local.max.z() < 0) continue;
    const TileSpan span = tiles_touched(face, local.min.x(), local.max.x(), local.min.y(), local.max.y());
    for (int a = span.first_a; a <= span.last_a; ++a)
      for (int b = span.first_b; b <= span.last_b; ++b) {
        const std::size_t tile = std::size_t(a) * std::size_t(face.tiles_b) + std::size_t(b);
        if (!face.made[tile]) append_tile(state, f, tile);
      }
  }
  finish_tiles(model, state, workspace, first_new);
}

void make_walls_near_material(const Model& model, State& state, Workspace& workspace) {
  const auto& fluid = state.fluid;
  const auto box_of = [&](std::size_t begin, std::size_t end) {
    return tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(begin, end, 4096), Aabb{},
        [&](const tbb::blocked_range<std::size_t>& range, Aabb box) {
          for (std::size_t i = range.begin(); i != range.end(); ++i) box.extend(fluid.position[i]);
          return box;
        },
        [](Aabb a, const Aabb& b) {
          if (!b.empty()) {
            a.extend(b.min);
            a.extend(b.max);
          }
          return a;
        });
  };
  // The resting particles' box again only when they changed (they do not move): the active ones'
  // every step. The settled ones' box is taken once a build of their grid, then only the slots that
  // build can have changed are added (a woken particle's slot keeps its place in the box: the box
  // may be larger than the material, never smaller).
  const std::size_t active = state.active_count, count = fluid.size();
  if (workspace.resting_box_of.take(workspace.fixed_grids_version, count, active)) {
    const bool settled_in_place = active <= workspace.settled_begin && workspace.settled_begin <= workspace.settled_end &&
                                  workspace.settled_end <= count;
    if (!settled_in_place) {
      workspace.resting_box = box_of(active, count);
    } else {
      if (workspace.settled_box_builds != workspace.settled_builds) {
        workspace.settled_box = box_of(workspace.settled_begin, workspace.settled_end);
        workspace.settled_box_builds = workspace.settled_builds;
      }
      Aabb box = workspace.settled_box;
      workspace.for_each_unsettled_range(active, count, workspace.settled_builds, count, [&](std::size_t begin, std::size_t end) {
        if (end - begin > 4096) {
          const Aabb part = box_of(begin, end);
          if (!part.empty()) box.extend(part.min), box.extend(part.max);
        } else {
          for (std::size_t i = begin; i < end; ++i) box.extend(fluid.position[i]);
        }
      });
      workspace.resting_box = box;
    }
  }
  Aabb region = box_of(0, active);
  if (!workspace.resting_box.empty()) {
    region.extend(workspace.resting_box.min);
    region.extend(workspace.resting_box.max);
  }
  for (std::size_t n = 0; n < state.nozzles.size(); ++n)
    if (state.nozzles[n].extruding) region.extend(state.nozzles[n].pose.position);
  workspace.material_region = region;
  if (state.lazy_walls.empty() || region.empty()) return;
  // Tiles within reach of each moving particle and each extruding nozzle's exit, not of the region's
  // whole box: a wall printed around a wide floor's edge needs the tiles under it, not those it
  // encloses. Resting particles had their tiles made while they moved.
  const Real reach = lazy_wall_reach(model);
  auto& wanted = workspace.lazy_wall_wanted;
  wanted.resize(state.lazy_walls.size());
  const std::size_t first_new = state.boundary.size();
  for (std::size_t f = 0; f < state.lazy_walls.size(); ++f) {
    const LazyWallFace& face = state.lazy_walls[f];
    const FaceFrame frame = face_frame(state, face);
    wanted[f].assign(face.made.size(), 0);
    const auto want_around = [&](const Vec3& position, Real extra) {
      const Vec3 local = frame.to_face * (position - frame.origin);
      if (std::abs(local.z()) > reach + extra) return;
      const TileSpan span = tiles_touched(face, local.x() - reach - extra, local.x() + reach + extra, local.y() - reach - extra,
                                          local.y() + reach + extra);
      for (int a = span.first_a; a <= span.last_a; ++a)
        for (int b = span.first_b; b <= span.last_b; ++b) {
          const std::size_t tile = std::size_t(a) * std::size_t(face.tiles_b) + std::size_t(b);
          // Several threads may mark one tile: each stores the same 1.
          if (!face.made[tile]) std::atomic_ref<std::uint8_t>(wanted[f][tile]).store(1, std::memory_order_relaxed);
        }
    };
    parallel_for_each_index(state.active_count, [&](std::size_t i) { want_around(fluid.position[i], 0); }, 4096);
    for (std::size_t n = 0; n < state.nozzles.size(); ++n)
      if (state.nozzles[n].extruding) want_around(state.nozzles[n].pose.position, model.widest_nozzle / 2);
    // In the tiles' order, whichever thread marked them: the same particles on any number of threads.
    for (std::size_t tile = 0; tile < face.made.size(); ++tile)
      if (wanted[f][tile]) append_tile(state, f, tile);
  }
  finish_tiles(model, state, workspace, first_new);
}

}  // namespace m3dp::sph::stages
