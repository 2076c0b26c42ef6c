// The spherical method: a union of spheres of radius R (default 1.5 r) around the particles, the
// narrow-band level set OpenVDB's ParticlesToLevelSet makes, gathered per leaf node; its surface is
// the spheres' skin.
#include <openvdb/tools/Prune.h>
#include <fmt/format.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <unordered_map>

#include "m3dp/core/error.hpp"
#include "m3dp/surface/field.hpp"

namespace m3dp::surface {

/// The union of spheres of radius `sphere_radius` (m) around `centres` as a narrow-band level set:
/// the values OpenVDB's ParticlesToLevelSet writes (each voxel within R + band of a centre holds
/// min_j |x − x_j| − R, active; a voxel at a centre's core is inactive inside), computed by gathering
/// rather than scattering. Spheres are sorted by the leaf node of their box's lowest corner (their
/// home), and each leaf is filled by one thread from the spheres of the homes below it, keeping the
/// smallest squared distance per voxel and taking one square root per voxel at the end. There are
/// no per-thread grids to merge and no tree look-ups per voxel: about four times faster than
/// ParticlesToLevelSet, whose per-thread grids and their union were most of the spherical
/// method's time (issue 4). Throws for a centre beyond the leaf keys' range.
openvdb::FloatGrid::Ptr union_of_spheres(std::span<const Vec3> centres, Real sphere_radius, Real voxel_size) {
  using LeafT = openvdb::FloatTree::LeafNodeType;
  constexpr int kLeafDim = static_cast<int>(LeafT::DIM);
  constexpr int kLeafLog2 = static_cast<int>(LeafT::LOG2DIM);
  auto grid = openvdb::createLevelSet<openvdb::FloatGrid>(voxel_size, kSphereBandVoxels);
  const float background = grid->background();
  // In voxel units and double precision, as ParticlesToLevelSet computes them.
  const double dx = voxel_size, radius = sphere_radius / dx, band = background / dx;
  const double reach = radius + band, reach_squared = reach * reach;
  const double core = std::max(0.0, radius - band), core_squared = core * core;
  // Index-space centres as OpenVDB's UniformScaleMap maps them: times the inverse, not divided.
  const double inverse_dx = 1.0 / dx;
  // Leaf keys hold 21 bits a coordinate: ±2^20 leaves of 8 voxels.
  const double max_index = double(1 << 20) * 8 - 64;
  auto box_of = [&](const Vec3& centre) {
    const openvdb::Vec3d p(centre.x() * inverse_dx, centre.y() * inverse_dx, centre.z() * inverse_dx);
    return openvdb::CoordBBox(openvdb::Coord(static_cast<int>(std::floor(p[0] - reach)), static_cast<int>(std::floor(p[1] - reach)),
                                             static_cast<int>(std::floor(p[2] - reach))),
                              openvdb::Coord(static_cast<int>(std::ceil(p[0] + reach)), static_cast<int>(std::ceil(p[1] + reach)),
                                             static_cast<int>(std::ceil(p[2] + reach))));
  };

  // A sphere's box is at most ⌈2 reach⌉ + 2 voxels wide, so it spans its lowest corner's leaf (its
  // "home") and at most leaf_span − 1 more on each axis (2 for the default spheres).
  const int box_width = static_cast<int>(std::ceil(2 * reach)) + 2;
  const int leaf_span = 1 + (box_width - 1 + kLeafDim - 1) / kLeafDim;
  auto home_of = [&](const Vec3& centre) {
    const openvdb::Coord low = box_of(centre).min();
    return openvdb::Coord(low.x() >> kLeafLog2, low.y() >> kLeafLog2, low.z() >> kLeafLog2);
  };
  for (const Vec3& centre : centres)
    if (!(std::abs(centre.x() * inverse_dx) < max_index && std::abs(centre.y() * inverse_dx) < max_index &&
          std::abs(centre.z() * inverse_dx) < max_index))
      throw Error(fmt::format("surface reconstruction: a particle at ({}, {}, {}) m is not finite or lies beyond the "
                              "grid's reach of {:.3g} m at voxel size {:.3g} m",
                              centre.x(), centre.y(), centre.z(), max_index * dx, dx));
  // Spheres sorted by home leaf; each home's spheres in one run.
  std::vector<std::pair<std::uint64_t, Index>> by_home(centres.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, centres.size(), 4096), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) by_home[i] = {coord_key(home_of(centres[i])), static_cast<Index>(i)};
  });
  tbb::parallel_sort(by_home.begin(), by_home.end());
  // Centres (in voxels) and boxes in that order, for the gather's sequential reads.
  struct SphereInVoxels {
    openvdb::Vec3d centre;
    openvdb::CoordBBox box;
  };
  std::vector<SphereInVoxels> spheres(centres.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, centres.size(), 4096), [&](const auto& range) {
    for (std::size_t n = range.begin(); n != range.end(); ++n) {
      const Vec3& centre = centres[by_home[n].second];
      spheres[n] = {openvdb::Vec3d(centre.x() * inverse_dx, centre.y() * inverse_dx, centre.z() * inverse_dx), box_of(centre)};
    }
  });
  std::unordered_map<std::uint64_t, std::pair<std::size_t, std::size_t>> home_run;  // key → [begin, end) in by_home
  std::vector<std::uint64_t> target_keys;  // every leaf a sphere may reach: each home and its + neighbours
  for (std::size_t n = 0; n < by_home.size();) {
    std::size_t end = n;
    while (end < by_home.size() && by_home[end].first == by_home[n].first) ++end;
    home_run.emplace(by_home[n].first, std::pair{n, end});
    const openvdb::Coord home = coord_of_key(by_home[n].first);
    for (int dx_leaf = 0; dx_leaf < leaf_span; ++dx_leaf)
      for (int dy_leaf = 0; dy_leaf < leaf_span; ++dy_leaf)
        for (int dz_leaf = 0; dz_leaf < leaf_span; ++dz_leaf) target_keys.push_back(coord_key(home.offsetBy(dx_leaf, dy_leaf, dz_leaf)));
    n = end;
  }
  tbb::parallel_sort(target_keys.begin(), target_keys.end());
  target_keys.erase(std::unique(target_keys.begin(), target_keys.end()), target_keys.end());

  std::vector<LeafT*> leaves(target_keys.size(), nullptr);  // null where no band reaches
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size(), 16), [&](const auto& range) {
    // Per voxel the smallest squared distance (voxels²) to a centre: |x − x_j| − R grows with it, so
    // the level set value needs one square root per voxel, not one per sphere and voxel.
    std::array<double, LeafT::SIZE> nearest_squared;
    for (std::size_t target = range.begin(); target != range.end(); ++target) {
      const openvdb::Coord leaf_coord = coord_of_key(target_keys[target]);
      const openvdb::Coord origin(leaf_coord.x() * kLeafDim, leaf_coord.y() * kLeafDim, leaf_coord.z() * kLeafDim);
      const openvdb::CoordBBox leaf_box(origin, origin.offsetBy(kLeafDim - 1));
      nearest_squared.fill(reach_squared);
      for (int dx_leaf = 1 - leaf_span; dx_leaf <= 0; ++dx_leaf)
        for (int dy_leaf = 1 - leaf_span; dy_leaf <= 0; ++dy_leaf)
          for (int dz_leaf = 1 - leaf_span; dz_leaf <= 0; ++dz_leaf) {
            const auto home = home_run.find(coord_key(leaf_coord.offsetBy(dx_leaf, dy_leaf, dz_leaf)));
            if (home == home_run.end()) continue;
            for (std::size_t n = home->second.first; n < home->second.second; ++n) {
              const SphereInVoxels& sphere = spheres[n];
              openvdb::CoordBBox box = sphere.box;
              box.intersect(leaf_box);
              if (box.empty()) continue;  // a sphere of a neighbouring home may not reach this leaf
              // Whole rows of the box, not only the voxels within reach: the minimum of squared
              // distances ignores the others, and a fixed-length loop needs no root per row.
              const openvdb::Vec3d& p = sphere.centre;
              const int row_length = box.max().z() - box.min().z() + 1;
              std::array<double, kLeafDim> z_squared;
              for (int k = 0; k < row_length; ++k) z_squared[k] = (box.min().z() + k - p[2]) * (box.min().z() + k - p[2]);
              for (int x = box.min().x(); x <= box.max().x(); ++x) {
                const double x2 = (x - p[0]) * (x - p[0]);
                if (x2 >= reach_squared) continue;
                for (int y = box.min().y(); y <= box.max().y(); ++y) {
                  const double x2y2 = x2 + (y - p[1]) * (y - p[1]);
                  if (x2y2 >= reach_squared) continue;
                  double* row = nearest_squared.data() + ((x - origin.x()) << (2 * kLeafLog2)) +
                                ((y - origin.y()) << kLeafLog2) + (box.min().z() - origin.z());
                  for (int k = 0; k < row_length; ++k) row[k] = std::min(row[k], x2y2 + z_squared[k]);
                }
              }
            }
          }
      auto leaf = std::make_unique<LeafT>(origin, background, false);
      bool any = false;
      for (openvdb::Index voxel = 0; voxel < LeafT::SIZE; ++voxel) {
        const double d2 = nearest_squared[voxel];
        if (d2 >= reach_squared) continue;  // no sphere's band reaches it
        if (d2 <= core_squared) {
          leaf->setValueOff(voxel, -background);  // deep inside a sphere, as ParticlesToLevelSet leaves it
          any = true;
          continue;
        }
        // ParticlesToLevelSet writes only values below the current one (the background at first).
        const auto distance = static_cast<float>(dx * (std::sqrt(d2) - radius));
        if (!(distance < background)) continue;
        leaf->setValueOn(voxel, distance);
        any = true;
      }
      if (any) leaves[target] = leaf.release();
    }
  });
  for (LeafT* leaf : leaves)
    if (leaf) grid->tree().addLeaf(leaf);  // the tree takes ownership
  openvdb::tools::pruneLevelSet(grid->tree());
  return grid;
}

namespace {

openvdb::FloatGrid::Ptr spherical_field(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                        const openvdb::math::Transform::Ptr& /*transform*/, SurfaceStats& stats, const FieldInputs& /*inputs*/) {
  // Cells of the deep region a voxel wider than a splat reaches: at 3.5 r the lattice fills cells too
  // unevenly (1 or 2 particles a side) for the 60 % rule, and no cell counts as interior.
  const Real reach = settings.sphere_radius + (kSphereBandVoxels + 1) * settings.voxel_size;
  const DeepRegion region = find_deep_region(positions, reach, settings.particle_radius);
  stats.surface_particles += region.contributing.size();
  std::vector<Vec3> near_surface(region.contributing.size());
  for (std::size_t n = 0; n < near_surface.size(); ++n) near_surface[n] = positions[region.contributing[n]];
  auto grid = union_of_spheres(near_surface, settings.sphere_radius, settings.voxel_size);
  fill_interior(*grid, region, settings.voxel_size, -static_cast<float>(grid->background()));
  return grid;
}

}  // namespace

extern const FieldMethod kSphericalMethod{Method::spherical, false, true, false, true, spherical_field};

}  // namespace m3dp::surface
