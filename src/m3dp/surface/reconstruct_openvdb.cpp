// The one translation unit that includes OpenVDB (slow to compile): particle fields on sparse
// grids and their iso-surfaces. See surface.hpp for the methods and their papers.
#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/ParticlesToLevelSet.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <openvdb/tree/LeafManager.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <chrono>
#include <cmath>
#include <mutex>
#include <numeric>

#include "m3dp/core/error.hpp"
#include "m3dp/sph/kernels.hpp"
#include "m3dp/sph/neighbor_search.hpp"
#include "m3dp/surface/anisotropic_yu_turk2013.hpp"
#include "m3dp/surface/mesh_tools.hpp"
#include "m3dp/surface/surface.hpp"

namespace m3dp::surface {

namespace {

using Clock = std::chrono::steady_clock;
double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

void initialize_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

/// Particle indices in Z-order of a coarse grid, so each thread's splats stay in a compact region
/// (fewer, denser leaf nodes to merge).
std::vector<Index> spatial_order(std::span<const Vec3> positions, Real cell_size) {
  std::vector<std::uint64_t> keys(positions.size());
  const Real inverse = Real(1) / cell_size;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, positions.size(), 4096), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const Vec3& p = positions[i];
      keys[i] = sph::morton_code(static_cast<std::int32_t>(std::floor(p.x() * inverse)),
                                 static_cast<std::int32_t>(std::floor(p.y() * inverse)),
                                 static_cast<std::int32_t>(std::floor(p.z() * inverse)));
    }
  });
  std::vector<Index> order(positions.size());
  std::iota(order.begin(), order.end(), Index(0));
  tbb::parallel_sort(order.begin(), order.end(),
                     [&](Index a, Index b) { return keys[a] < keys[b] || (keys[a] == keys[b] && a < b); });
  return order;
}

/// Adds splat(particle, accessors…) over all particles into per-thread grids merged by compSum.
/// The split tree is fixed (deterministic reduce), so the sums come out the same on every run.
template <class GridT, class Splat>
typename GridT::Ptr splat_particles(const std::vector<Index>& order, const openvdb::math::Transform::Ptr& transform,
                                    typename GridT::ValueType background, const Splat& splat) {
  struct Body {
    const std::vector<Index>* order;
    const Splat* splat;
    typename GridT::Ptr grid;
    openvdb::math::Transform::Ptr transform;
    typename GridT::ValueType background;

    Body(const std::vector<Index>* order_, const Splat* splat_, openvdb::math::Transform::Ptr transform_,
         typename GridT::ValueType background_)
        : order(order_), splat(splat_), grid(GridT::create(background_)), transform(transform_), background(background_) {
      grid->setTransform(transform);
    }
    Body(Body& other, tbb::split) : Body(other.order, other.splat, other.transform, other.background) {}
    void operator()(const tbb::blocked_range<std::size_t>& range) {
      typename GridT::Accessor accessor = grid->getAccessor();
      for (std::size_t n = range.begin(); n != range.end(); ++n) (*splat)((*order)[n], accessor);
    }
    void join(Body& other) { openvdb::tools::compSum(*grid, *other.grid); }
  };
  Body body(&order, &splat, transform, background);
  tbb::parallel_deterministic_reduce(tbb::blocked_range<std::size_t>(0, order.size(), 2048), body);
  return body.grid;
}

/// Index-space box of voxels whose centres lie within `half_extent` of `centre`.
openvdb::CoordBBox voxel_box(const Vec3& centre, const Vec3& half_extent, Real voxel_size) {
  const Real inverse = Real(1) / voxel_size;
  return openvdb::CoordBBox(openvdb::Coord(static_cast<int>(std::ceil((centre.x() - half_extent.x()) * inverse)),
                                           static_cast<int>(std::ceil((centre.y() - half_extent.y()) * inverse)),
                                           static_cast<int>(std::ceil((centre.z() - half_extent.z()) * inverse))),
                            openvdb::Coord(static_cast<int>(std::floor((centre.x() + half_extent.x()) * inverse)),
                                           static_cast<int>(std::floor((centre.y() + half_extent.y()) * inverse)),
                                           static_cast<int>(std::floor((centre.z() + half_extent.z()) * inverse))));
}

/// Particle list in the form ParticlesToLevelSet reads.
struct ParticleList {
  using PosType = openvdb::Vec3R;
  std::span<const Vec3> positions;
  Real radius;
  [[nodiscard]] std::size_t size() const { return positions.size(); }
  void getPos(std::size_t n, openvdb::Vec3R& xyz) const { xyz = openvdb::Vec3R(positions[n].x(), positions[n].y(), positions[n].z()); }
  void getPosRad(std::size_t n, openvdb::Vec3R& xyz, openvdb::Real& rad) const {
    getPos(n, xyz);
    rad = radius;
  }
};

openvdb::FloatGrid::Ptr spherical_field(std::span<const Vec3> positions, const SurfaceSettings& settings) {
  constexpr float kHalfWidthVoxels = 3;
  auto grid = openvdb::createLevelSet<openvdb::FloatGrid>(settings.voxel_size, kHalfWidthVoxels);
  openvdb::tools::ParticlesToLevelSet<openvdb::FloatGrid> raster(*grid);
  raster.setRmin(0.5);  // spheres smaller than 1.5 voxels are kept, not dropped as the default does
  raster.rasterizeSpheres(ParticleList{positions, settings.sphere_radius}, settings.sphere_radius);
  raster.finalize(true);
  return grid;
}

/// −Σ_j V_j W(x − x_j): negative inside, so the mesher's "inside = below the iso-value" holds.
openvdb::FloatGrid::Ptr blobby_field(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                     const openvdb::math::Transform::Ptr& transform) {
  const Real spacing = 2 * settings.particle_radius;
  const Real volume = spacing * spacing * spacing;
  const sph::CubicSplineKernel kernel(settings.kernel_radius);
  const Real voxel = settings.voxel_size;
  const Vec3 half_extent = Vec3::Constant(settings.kernel_radius);
  const auto order = spatial_order(positions, settings.kernel_radius);
  auto splat = [&](Index particle, openvdb::FloatGrid::Accessor& accessor) {
    const Vec3 centre = positions[particle];
    const openvdb::CoordBBox box = voxel_box(centre, half_extent, voxel);
    for (auto it = box.begin(); it; ++it) {
      const openvdb::Coord& ijk = *it;
      const Real distance = (Vec3(ijk.x() * voxel, ijk.y() * voxel, ijk.z() * voxel) - centre).norm();
      if (distance >= settings.kernel_radius) continue;
      accessor.setValue(ijk, accessor.getValue(ijk) - volume * kernel.W(distance));
    }
  };
  return splat_particles<openvdb::FloatGrid>(order, transform, 0.f, splat);
}

openvdb::FloatGrid::Ptr anisotropic_field(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                          const openvdb::math::Transform::Ptr& transform) {
  const AnisotropicKernels kernels = compute_anisotropic_kernels(positions, settings);
  const Real spacing = 2 * settings.particle_radius;
  const Real volume = spacing * spacing * spacing;
  const sph::CubicSplineKernel unit_kernel(1);
  const Real voxel = settings.voxel_size;
  const auto order = spatial_order(kernels.centre, settings.kernel_radius);
  auto splat = [&](Index particle, openvdb::FloatGrid::Accessor& accessor) {
    const Vec3 centre = kernels.centre[particle];
    const Eigen::Matrix3f& transform_g = kernels.transform[particle];
    const Real scale = volume * kernels.determinant[particle];
    const openvdb::CoordBBox box = voxel_box(centre, kernels.half_extent[particle], voxel);
    for (auto it = box.begin(); it; ++it) {
      const openvdb::Coord& ijk = *it;
      const Real q = (transform_g * (Vec3(ijk.x() * voxel, ijk.y() * voxel, ijk.z() * voxel) - centre)).norm();
      if (q >= 1) continue;
      accessor.setValue(ijk, accessor.getValue(ijk) - scale * unit_kernel.W(q));
    }
  };
  return splat_particles<openvdb::FloatGrid>(order, transform, 0.f, splat);
}

/// Zhu & Bridson 2005: φ(x) = |x − x̄| − r̄, x̄ = Σ k_i x_i / Σ k_i, k(s) = max(0, 1 − s²)³, s = |x − x_i| / R.
openvdb::FloatGrid::Ptr zhu_bridson_field(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                          const openvdb::math::Transform::Ptr& transform, std::size_t& grid_bytes) {
  const Real support = settings.kernel_radius;
  const Real voxel = settings.voxel_size;
  const Vec3 half_extent = Vec3::Constant(support);
  const auto order = spatial_order(positions, support);
  // x̄ needs Σk and Σk·x: a float grid and a Vec3 grid (OpenVDB registers no Vec4 float grid).
  auto splat_weight = [&](Index particle, openvdb::FloatGrid::Accessor& accessor) {
    const Vec3 centre = positions[particle];
    const openvdb::CoordBBox box = voxel_box(centre, half_extent, voxel);
    for (auto it = box.begin(); it; ++it) {
      const openvdb::Coord& ijk = *it;
      const Real s2 = (Vec3(ijk.x() * voxel, ijk.y() * voxel, ijk.z() * voxel) - centre).squaredNorm() / (support * support);
      if (s2 >= 1) continue;
      const Real one_minus = 1 - s2;
      accessor.setValue(ijk, accessor.getValue(ijk) + one_minus * one_minus * one_minus);
    }
  };
  auto splat_moment = [&](Index particle, openvdb::Vec3SGrid::Accessor& accessor) {
    const Vec3 centre = positions[particle];
    const openvdb::CoordBBox box = voxel_box(centre, half_extent, voxel);
    for (auto it = box.begin(); it; ++it) {
      const openvdb::Coord& ijk = *it;
      const Real s2 = (Vec3(ijk.x() * voxel, ijk.y() * voxel, ijk.z() * voxel) - centre).squaredNorm() / (support * support);
      if (s2 >= 1) continue;
      const Real one_minus = 1 - s2;
      const Real weight = one_minus * one_minus * one_minus;
      accessor.setValue(ijk, accessor.getValue(ijk) + openvdb::Vec3s(weight * centre.x(), weight * centre.y(), weight * centre.z()));
    }
  };
  auto weight = splat_particles<openvdb::FloatGrid>(order, transform, 0.f, splat_weight);
  auto moment = splat_particles<openvdb::Vec3SGrid>(order, transform, openvdb::Vec3s(0, 0, 0), splat_moment);

  const float outside = static_cast<float>(support);
  grid_bytes = weight->memUsage() + moment->memUsage();
  auto phi = openvdb::FloatGrid::create(outside);
  phi->setTransform(transform);
  phi->setTree(std::make_shared<openvdb::FloatTree>(weight->tree(), outside, openvdb::TopologyCopy()));
  openvdb::tree::LeafManager<openvdb::FloatTree> leaves(phi->tree());
  const Real mean_radius = settings.zhu_bridson_radius;
  tbb::parallel_for(leaves.leafRange(), [&](const openvdb::tree::LeafManager<openvdb::FloatTree>::LeafRange& range) {
    for (auto leaf = range.begin(); leaf; ++leaf) {
      const auto* weight_leaf = weight->tree().probeConstLeaf(leaf->origin());
      const auto* moment_leaf = moment->tree().probeConstLeaf(leaf->origin());
      for (auto value = leaf->beginValueOn(); value; ++value) {
        const auto offset = value.pos();
        const float weight_sum = weight_leaf->getValue(offset);
        const openvdb::Coord ijk = value.getCoord();
        if (!(weight_sum > 0) || moment_leaf == nullptr) {
          value.setValue(outside);
          continue;
        }
        const openvdb::Vec3s mean = moment_leaf->getValue(offset) / weight_sum;
        const Vec3 x(ijk.x() * voxel, ijk.y() * voxel, ijk.z() * voxel);
        value.setValue(static_cast<float>((x - Vec3(mean.x(), mean.y(), mean.z())).norm() - mean_radius));
      }
    }
  });
  return phi;
}

TriangleMesh extract_mesh(const openvdb::FloatGrid& grid, double isovalue) {
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(grid, points, triangles, quads, isovalue, /*adaptivity=*/0.0);
  TriangleMesh mesh;
  mesh.vertices.reserve(points.size());
  for (const auto& p : points) mesh.vertices.emplace_back(p.x(), p.y(), p.z());
  mesh.triangles.reserve(triangles.size() + 2 * quads.size());
  for (const auto& t : triangles) mesh.triangles.push_back({t[0], t[1], t[2]});
  for (const auto& q : quads) {
    mesh.triangles.push_back({q[0], q[1], q[2]});
    mesh.triangles.push_back({q[0], q[2], q[3]});
  }
  return mesh;
}

}  // namespace

TriangleMesh reconstruct_surface(std::span<const Vec3> positions, const SurfaceSettings& input_settings, SurfaceStats* stats) {
  const SurfaceSettings settings = input_settings.resolved();
  SurfaceStats local_stats;
  local_stats.particles = positions.size();
  TriangleMesh mesh;
  if (positions.empty()) {
    if (stats) *stats = local_stats;
    return mesh;
  }
  initialize_openvdb();
  auto start = Clock::now();
  const auto transform = openvdb::math::Transform::createLinearTransform(settings.voxel_size);
  openvdb::FloatGrid::Ptr field;
  double isovalue = 0;
  switch (settings.method) {
    case Method::spherical:
      field = spherical_field(positions, settings);
      break;
    case Method::sph_blobby:
      field = blobby_field(positions, settings, transform);
      isovalue = -settings.iso_level;
      break;
    case Method::anisotropic:
      field = anisotropic_field(positions, settings, transform);
      isovalue = -settings.iso_level;
      break;
    case Method::zhu_bridson:
      field = zhu_bridson_field(positions, settings, transform, local_stats.grid_bytes);
      break;
  }
  local_stats.active_voxels = field->activeVoxelCount();
  local_stats.grid_bytes = std::max<std::size_t>(local_stats.grid_bytes, field->memUsage());
  local_stats.field_seconds = seconds_since(start);

  start = Clock::now();
  mesh = extract_mesh(*field, isovalue);
  field.reset();
  remove_unused_vertices(mesh);
  // The mesher winds triangles one way for every field here; make them face outwards.
  if (signed_volume(mesh) < 0) flip_orientation(mesh);
  // Spheres leave closed pockets between them (a lattice cell's centre is √3 r from its corners):
  // each is a small inside-out shell. Pockets smaller than a particle are gaps, not holes in the material.
  if (settings.method == Method::spherical) {
    const Real spacing = 2 * settings.particle_radius;
    remove_small_cavities(mesh, spacing * spacing * spacing);
  }
  taubin_smooth(mesh, settings.smoothing_iterations, settings.smoothing_lambda, settings.smoothing_mu);
  local_stats.mesh_seconds = seconds_since(start);
  if (stats) *stats = local_stats;
  return mesh;
}

}  // namespace m3dp::surface
