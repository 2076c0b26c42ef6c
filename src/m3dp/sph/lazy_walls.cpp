// Stage "bodies": static walls made where the material comes (issue 41). A wide flat face of a static
// box or plane is a lattice of boundary particles (boundary_sampling's), split into tiles of
// kLazyTilePoints × kLazyTilePoints points; a tile's particles are appended, with their Akinci volumes,
// the first step the material region (the fluid and the extruding nozzles) comes within reach of it.
// A 10 × 10 m floor under a print of a few cm² holds the particles of the tiles under the print.
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>

#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

Real lazy_wall_reach(const Model& model) {
  // A wall particle within a support (and a step's move, under a diameter) of the material takes part
  // in its sums, and its volume sums its neighbours a support further: all of those must be in.
  return 2 * model.support_radius + model.widest_nozzle / 2 + 2 * model.particle_diameter;
}

void make_walls_within(const Model& model, State& state, Workspace& workspace, const Aabb& box) {
  if (state.lazy_walls.empty() || box.empty()) return;
  auto& boundary = state.boundary;
  const std::size_t first_new = boundary.size();
  for (std::size_t f = 0; f < state.lazy_walls.size(); ++f) {
    LazyWallFace& face = state.lazy_walls[f];
    const RectangleLattice& lattice = face.lattice;
    const Pose& pose = state.bodies[face.body].pose;
    // The box in the face's frame (a, b along its sides, n along its normal): the bounds of its corners.
    const Mat3 to_face = (pose.orientation.toRotationMatrix() * lattice.rotation).transpose();
    const Vec3 origin = pose.apply(lattice.offset);
    Aabb local;
    for (int corner = 0; corner < 8; ++corner) {
      const Vec3 point((corner & 1) ? box.max.x() : box.min.x(), (corner & 2) ? box.max.y() : box.min.y(),
                       (corner & 4) ? box.max.z() : box.min.z());
      local.extend(to_face * (point - origin));
    }
    if (local.min.z() > 0 || local.max.z() < 0) continue;
    // Lattice index i sits at a = size_a (i / count_a − 1/2).
    const auto index_range = [](Real low, Real high, Real size, int count, int first, int last) {
      const Real scale = Real(count) / std::max(size, Real(1e-30));
      // Clamped before the conversion: a box far larger than the face stays in int's range.
      const auto index = [&](Real value) { return std::clamp(value * scale + Real(0.5) * Real(count), Real(first - 1), Real(last + 1)); };
      const int from = std::max(first, static_cast<int>(std::floor(index(low))));
      const int to = std::min(last, static_cast<int>(std::ceil(index(high))));
      return std::pair{from, to};
    };
    const auto [from_a, to_a] = index_range(local.min.x(), local.max.x(), lattice.size_a, lattice.count_a, lattice.first_a, lattice.last_a);
    const auto [from_b, to_b] = index_range(local.min.y(), local.max.y(), lattice.size_b, lattice.count_b, lattice.first_b, lattice.last_b);
    if (from_a > to_a || from_b > to_b) continue;
    for (int tile_a = (from_a - lattice.first_a) / kLazyTilePoints; tile_a <= (to_a - lattice.first_a) / kLazyTilePoints; ++tile_a)
      for (int tile_b = (from_b - lattice.first_b) / kLazyTilePoints; tile_b <= (to_b - lattice.first_b) / kLazyTilePoints; ++tile_b) {
        const std::size_t tile = std::size_t(tile_a) * std::size_t(face.tiles_b) + std::size_t(tile_b);
        if (face.made[tile]) continue;
        face.made[tile] = 1;
        state.made_tiles.push_back(std::uint64_t(f) << 32 | tile);
        const LazyWallFace::Range range = face.tile_range(tile);
        for (int i = range.first_a; i <= range.last_a; ++i)
          for (int j = range.first_b; j <= range.last_b; ++j) {
            const Vec3 point = lattice.point(i, j);
            boundary.local_position.push_back(point);
            boundary.position.push_back(pose.apply(point));
            boundary.velocity.push_back(Vec3::Zero());
            boundary.body.push_back(face.body);
            boundary.nozzle_bore.push_back(0);
          }
      }
  }
  if (boundary.size() == first_new) return;
  sum_boundary_volumes(model, state, first_new, 0, true);
  workspace.static_boundary_dirty = true;
}

void make_walls_near_material(const Model& model, State& state, Workspace& workspace) {
  Aabb region = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, state.fluid.size(), 4096), Aabb{},
      [&](const tbb::blocked_range<std::size_t>& range, Aabb box) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) box.extend(state.fluid.position[i]);
        return box;
      },
      [](Aabb a, const Aabb& b) {
        if (!b.empty()) {
          a.extend(b.min);
          a.extend(b.max);
        }
        return a;
      });
  for (std::size_t n = 0; n < state.nozzles.size(); ++n)
    if (state.nozzles[n].extruding) region.extend(state.nozzles[n].pose.position);
  workspace.material_region = region;
  if (state.lazy_walls.empty() || region.empty()) return;
  const Vec3 reach = Vec3::Constant(lazy_wall_reach(model));
  Aabb within;
  within.extend(region.min - reach);
  within.extend(region.max + reach);
  make_walls_within(model, state, workspace, within);
}

}  // namespace m3dp::sph::stages
