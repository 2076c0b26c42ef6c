#pragma once
// Internal to surface/: particle fields on sparse OpenVDB grids. Each reconstruction method fills one
// FieldMethod in its own file (methods/*.cpp, anisotropic_yu_turk2013.cpp); the table of them, the
// tiled mesher and the incremental cache are in reconstruct_openvdb.cpp. OpenVDB is slow to compile:
// only these files include it.
#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <array>
#include <chrono>
#include <cmath>
#include <mutex>
#include <span>
#include <string_view>
#include <vector>

#include "m3dp/surface/methods/anisotropic_yu_turk2013.hpp"
#include "m3dp/surface/surface.hpp"

namespace m3dp::surface {

using Clock = std::chrono::steady_clock;
inline double seconds_since(Clock::time_point start) { return std::chrono::duration<double>(Clock::now() - start).count(); }

inline void initialize_openvdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

/// Where the material is deep, the field is "inside" whatever the exact sums: only particles near
/// the surface need to be splatted, and the deep cells are filled with an inside value afterwards.
/// This makes the cost follow the surface rather than the volume (issue 4).
/// Cells have the size of the farthest reach of a particle's contribution. A cell is full when it
/// holds at least 60 % of a resting lattice's particles; interior when it and its 26 neighbours are
/// full (the surface cannot cross it); a particle contributes unless all 27 cells around its own
/// are interior (then no voxel it reaches can be near the surface).
struct DeepRegion {
  std::vector<Index> contributing;                 // particle indices, Z-ordered
  std::vector<std::array<std::int32_t, 3>> interior_cells;
  Real cell_size = 0;
};

DeepRegion find_deep_region(std::span<const Vec3> positions, Real cell_size, Real particle_radius);

/// Sets every voxel of the interior cells to `inside` (active), after the splats.
template <class GridT>
void fill_interior(GridT& grid, const DeepRegion& region, Real voxel_size, typename GridT::ValueType inside) {
  const double ratio = static_cast<double>(region.cell_size) / voxel_size;
  for (const auto& cell : region.interior_cells) {
    openvdb::Coord low, high;
    for (int k = 0; k < 3; ++k) {
      low[k] = static_cast<int>(std::ceil(cell[k] * ratio - 1e-9));
      high[k] = static_cast<int>(std::ceil((cell[k] + 1) * ratio - 1e-9)) - 1;
    }
    grid.tree().fill(openvdb::CoordBBox(low, high), inside, true);
  }
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
  // A fixed number of blocks (not of particles per block): few grids to merge, same split on every run.
  const std::size_t grain = std::max<std::size_t>(1024, order.size() / 8 + 1);
  tbb::parallel_deterministic_reduce(tbb::blocked_range<std::size_t>(0, order.size(), grain), body);
  return body.grid;
}

/// Index-space box of voxels whose centres lie within `half_extent` of `centre`.
inline openvdb::CoordBBox voxel_box(const Vec3& centre, const Vec3& half_extent, Real voxel_size) {
  const Real inverse = Real(1) / voxel_size;
  return openvdb::CoordBBox(openvdb::Coord(static_cast<int>(std::ceil((centre.x() - half_extent.x()) * inverse)),
                                           static_cast<int>(std::ceil((centre.y() - half_extent.y()) * inverse)),
                                           static_cast<int>(std::ceil((centre.z() - half_extent.z()) * inverse))),
                            openvdb::Coord(static_cast<int>(std::floor((centre.x() + half_extent.x()) * inverse)),
                                           static_cast<int>(std::floor((centre.y() + half_extent.y()) * inverse)),
                                           static_cast<int>(std::floor((centre.z() + half_extent.z()) * inverse))));
}

/// Calls visit(ijk, q) for every voxel centre x with q = ‖M (x − centre)‖ < 1: a sphere of radius R
/// for M = I/R, an anisotropic kernel's ellipsoid for M = G. Walks only the voxels inside: per
/// (i, j) column the z range solves |u + dz·m₃|² ≤ 1, so no time goes to the box's corners.
template <class Visit>
void for_each_voxel_in_ellipsoid(const Vec3& centre, const Eigen::Matrix3f& transform_m, const Vec3& half_extent,
                                 Real voxel_size, Visit&& visit) {
  const openvdb::CoordBBox box = voxel_box(centre, half_extent, voxel_size);
  const Vec3 column = transform_m.col(2);
  const Real a = column.squaredNorm();
  for (int i = box.min().x(); i <= box.max().x(); ++i)
    for (int j = box.min().y(); j <= box.max().y(); ++j) {
      const Vec3 u = transform_m * Vec3(i * voxel_size - centre.x(), j * voxel_size - centre.y(), -centre.z());
      // |u + z m₃|² < 1 with z the voxel's absolute height: a z² + 2 (u·m₃) z + |u|² − 1 < 0.
      const Real b = u.dot(column), c = u.squaredNorm() - 1;
      const Real discriminant = b * b - a * c;
      if (discriminant <= 0) continue;
      const Real root = std::sqrt(discriminant);
      const int k_low = static_cast<int>(std::ceil((-b - root) / a / voxel_size));
      const int k_high = static_cast<int>(std::floor((-b + root) / a / voxel_size));
      for (int k = k_low; k <= k_high; ++k) {
        const Real q = (u + (k * voxel_size) * column).norm();
        if (q < 1) visit(openvdb::Coord(i, j, k), q);
      }
    }
}

/// A coordinate triple (leaf or tile indices) packed into one key, 21 bits each offset to be
/// positive: ±2^20 on each axis. Keys order like the triples compared x first.
constexpr std::int64_t kKeyOffset = 1 << 20, kKeyMask = (1 << 21) - 1;
inline std::uint64_t coord_key(const openvdb::Coord& c) {
  return static_cast<std::uint64_t>(c.x() + kKeyOffset) << 42 | static_cast<std::uint64_t>(c.y() + kKeyOffset) << 21 |
         static_cast<std::uint64_t>(c.z() + kKeyOffset);
}
inline openvdb::Coord coord_of_key(std::uint64_t key) {
  return openvdb::Coord(static_cast<int>((static_cast<std::int64_t>(key >> 42) & kKeyMask) - kKeyOffset),
                        static_cast<int>((static_cast<std::int64_t>(key >> 21) & kKeyMask) - kKeyOffset),
                        static_cast<int>((static_cast<std::int64_t>(key) & kKeyMask) - kKeyOffset));
}

/// The kernels an anisotropic field splatted, and for which of its particles.
struct SplattedKernels {
  std::vector<Index> particles;
  AnisotropicKernels kernels;
};

/// Adds −sign · V W_i(x) of every kernel to a new grid (volume fractions are stored negated; sign −1
/// takes kernels back out, for incremental meshing). In anisotropic_yu_turk2013.cpp.
openvdb::FloatGrid::Ptr splat_anisotropic_kernels(const AnisotropicKernels& kernels, const SurfaceSettings& settings,
                                                  const openvdb::math::Transform::Ptr& transform, float sign);

/// Half-width of the spherical level set's narrow band, in voxels.
constexpr float kSphereBandVoxels = 2;
/// The union of spheres of radius `sphere_radius` (m) around `centres` as the narrow-band level set
/// ParticlesToLevelSet writes (methods/spherical.cpp).
openvdb::FloatGrid::Ptr union_of_spheres(std::span<const Vec3> centres, Real sphere_radius, Real voxel_size);

/// What a field may need besides its particles (incremental meshing).
struct FieldInputs {
  std::span<const Vec3> also_neighbours;  // particles whose field is made elsewhere but that kernels must see
  SplattedKernels* splatted = nullptr;    // receives the kernels an anisotropic field splatted
};

/// A reconstruction method: its field and how its fields behave.
struct FieldMethod {
  Method method;  // its name is surface.cpp's (method_name)
  // The field is a volume fraction, stored negated (surface at −iso_level; the fields of two particle
  // sets add up); otherwise a level set with its surface at 0 (two sets combine by union, min).
  bool volume_fraction = false;
  // The field of a set is its parts' fields combined: incremental meshing keeps the resting part's.
  // Otherwise the field is made whole every time.
  bool sum_over_particles = true;
  // A particle's contribution depends on its neighbours (anisotropic kernels): parts must see each other.
  bool kernels_see_neighbours = false;
  // A union of spheres leaves voxel-sized pockets between a lattice's spheres: fill them, drop small cavities.
  bool fills_pockets = false;
  /// The field of `positions` (resolved settings), on a grid of `transform`.
  openvdb::FloatGrid::Ptr (*field)(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                   const openvdb::math::Transform::Ptr& transform, SurfaceStats& stats,
                                   const FieldInputs& inputs) = nullptr;
};

/// The method's entry of the table in reconstruct_openvdb.cpp.
const FieldMethod& field_method(Method method);

}  // namespace m3dp::surface
