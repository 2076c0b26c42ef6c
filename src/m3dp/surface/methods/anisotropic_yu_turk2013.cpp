// The anisotropic method after J. Yu, G. Turk, "Reconstructing surfaces of particle-based fluids using
// anisotropic kernels", ACM Transactions on Graphics 32(1), 2013: smoothed centres and one ellipsoidal
// kernel per particle from its neighbourhood's covariance; the volume fraction of those kernels, with
// the surface at iso_level.
#include "m3dp/surface/methods/anisotropic_yu_turk2013.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/kernels.hpp"
#include "m3dp/sph/neighbors/neighbor_search.hpp"
#include "m3dp/surface/field.hpp"

namespace m3dp::surface {

namespace {

/// Yu & Turk's isotropic weight w(d) = 1 − (d / R)³ inside R (eq. 7's W_i).
Real covariance_weight(Real distance, Real radius) {
  const Real q = distance / radius;
  return q < 1 ? Real(1) - q * q * q : Real(0);
}

/// The largest singular value of the weighted covariance of a full cubic-lattice neighbourhood
/// (spacing 2r, radius R): the scale at which an interior particle's kernel is the isotropic one.
/// Yu & Turk's k_s plays this role; computing it keeps the kernels unit-free.
Real lattice_covariance_scale(Real spacing, Real radius) {
  const int reach = static_cast<int>(std::ceil(radius / spacing));
  double weight_sum = 0, second_moment = 0;
  for (int i = -reach; i <= reach; ++i)
    for (int j = -reach; j <= reach; ++j)
      for (int k = -reach; k <= reach; ++k) {
        const Vec3 offset(i * spacing, j * spacing, k * spacing);
        const Real weight = covariance_weight(offset.norm(), radius);
        weight_sum += weight;
        second_moment += weight * offset.x() * offset.x();
      }
  return static_cast<Real>(second_moment / weight_sum);
}

}  // namespace

AnisotropicKernels compute_anisotropic_kernels(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                               std::span<const Index> which) {
  std::vector<Vec3> queries;
  if (!which.empty()) {
    queries.resize(which.size());
    for (std::size_t n = 0; n < which.size(); ++n) queries[n] = positions[which[n]];
  }
  const std::span<const Vec3> query_positions = which.empty() ? positions : std::span<const Vec3>(queries);
  const std::size_t count = query_positions.size();
  AnisotropicKernels kernels;
  kernels.centre.resize(count);
  kernels.transform.resize(count);
  kernels.determinant.resize(count);
  kernels.half_extent.resize(count);
  if (count == 0) return kernels;

  const Real radius = settings.anisotropy_neighborhood;
  const Real support = settings.kernel_radius;
  const Real interior_scale = lattice_covariance_scale(2 * settings.particle_radius, radius);

  sph::SpatialHashGrid grid;
  grid.build(positions, radius);
  sph::NeighborLists neighbors;
  // Room for a full lattice neighbourhood (and some compression) from the start, so the search
  // does not run twice to grow its lists; sums only, so no sorting.
  const double lattice_neighbors = 4.0 / 3.0 * 3.14159265 * std::pow(radius / (2 * settings.particle_radius), 3);
  neighbors.stride = static_cast<Index>(1.3 * lattice_neighbors) + 16;
  sph::find_neighbors(grid, query_positions, radius, false, neighbors, false);  // includes the particle itself

  std::vector<unsigned char> sparse(count, 0);
  parallel_for_each_index(count, [&](std::size_t i) {
    const Vec3 position = query_positions[i];
    const auto list = neighbors.of(i);
    // Weighted mean (eq. 8's x_i^w) and the smoothed centre (eq. 6).
    double weight_sum = 0;
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const Index j : list) {
      const Real weight = covariance_weight((position - positions[j]).norm(), radius);
      weight_sum += weight;
      mean += weight * positions[j].cast<double>();
    }
    mean /= weight_sum;  // > 0: the particle itself has weight 1
    kernels.centre[i] = ((1 - settings.centre_smoothing) * position.cast<double>() + settings.centre_smoothing * mean).cast<Real>();

    // Isotropic fallback for thin neighbourhoods (splashes, single strands): a scaled sphere.
    Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
    Eigen::Vector3d scale = Eigen::Vector3d::Constant(settings.sparse_scale);
    if (static_cast<int>(list.size()) - 1 >= settings.min_neighbors) {
      Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
      for (const Index j : list) {
        const Real weight = covariance_weight((position - positions[j]).norm(), radius);
        const Eigen::Vector3d offset = positions[j].cast<double>() - mean;
        covariance += weight * offset * offset.transpose();
      }
      covariance /= weight_sum;
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver;
      solver.computeDirect(covariance);
      axes = solver.eigenvectors();
      const Eigen::Vector3d sigma = solver.eigenvalues().cwiseMax(0.0);  // ascending
      const double largest = sigma(2);
      // Clamp (eq. 11): no axis shorter than largest / k_r; then scale so the full lattice is 1.
      for (int k = 0; k < 3; ++k) scale(k) = std::max(sigma(k), largest / settings.max_anisotropy) / interior_scale;
      // Eigenvalues are variances: axis lengths go with their square roots. No axis longer than the
      // isotropic kernel's, so a kernel never reaches beyond the kernel radius.
      scale = scale.cwiseSqrt().cwiseMin(1.0);
    } else {
      sparse[i] = 1;
    }
    // G = (1/h) R diag(1/scale) Rᵀ; its support {x : ‖G x‖ ≤ 1} is an ellipsoid of semi-axes h·scale.
    const Eigen::Matrix3d transform = axes * (scale.cwiseInverse() / support).asDiagonal() * axes.transpose();
    kernels.transform[i] = transform.cast<float>();
    kernels.determinant[i] = static_cast<Real>(1.0 / (scale.prod() * support * support * support));
    // Axis-aligned bounds of the ellipsoid: half extent along e_a = h sqrt(Σ_k R_ak² scale_k²).
    const Eigen::Matrix3d squared_axes = axes.cwiseProduct(axes);
    kernels.half_extent[i] = (support * (squared_axes * scale.cwiseProduct(scale)).cwiseSqrt()).cast<Real>();
  });
  for (const unsigned char flag : sparse) kernels.sparse_particles += flag;
  return kernels;
}

openvdb::FloatGrid::Ptr splat_anisotropic_kernels(const AnisotropicKernels& kernels, const SurfaceSettings& settings,
                                                  const openvdb::math::Transform::Ptr& transform, float sign) {
  const Real spacing = 2 * settings.particle_radius;
  const Real volume = spacing * spacing * spacing;
  const sph::CubicSplineKernel unit_kernel(1);
  const Real voxel = settings.voxel_size;
  std::vector<Index> order(kernels.centre.size());
  std::iota(order.begin(), order.end(), Index(0));
  auto splat = [&](Index particle, openvdb::FloatGrid::Accessor& accessor) {
    const Real scale = sign * volume * kernels.determinant[particle];
    for_each_voxel_in_ellipsoid(kernels.centre[particle], kernels.transform[particle], kernels.half_extent[particle], voxel,
                                [&](const openvdb::Coord& ijk, Real q) {
                                  const float weight = scale * unit_kernel.W(q);
                                  accessor.modifyValue(ijk, [weight](float& value) { value -= weight; });
                                });
  };
  return splat_particles<openvdb::FloatGrid>(order, transform, 0.f, splat);
}


namespace {

/// `also_neighbours`: particles whose field is made elsewhere but that the kernels of `positions`
/// must see as neighbours (incremental meshing). `splatted`, if given, receives the kernels.
openvdb::FloatGrid::Ptr anisotropic_field(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                          const openvdb::math::Transform::Ptr& transform, SurfaceStats& stats,
                                          const FieldInputs& inputs) {
  const std::span<const Vec3> also_neighbours = inputs.also_neighbours;
  SplattedKernels* splatted = inputs.splatted;
  // Kernels reach at most the kernel radius (their axes are capped at the isotropic one's), and
  // smoothing moves a centre by less than the neighbourhood radius times λ.
  const Real reach = settings.kernel_radius + settings.centre_smoothing * settings.anisotropy_neighborhood;
  DeepRegion region = find_deep_region(positions, reach, settings.particle_radius);
  stats.surface_particles += region.contributing.size();
  std::vector<Vec3> with_neighbours;  // `positions` first, so region.contributing indexes it unchanged
  if (!also_neighbours.empty()) {
    with_neighbours.reserve(positions.size() + also_neighbours.size());
    with_neighbours.assign(positions.begin(), positions.end());
    with_neighbours.insert(with_neighbours.end(), also_neighbours.begin(), also_neighbours.end());
  }
  AnisotropicKernels kernels = compute_anisotropic_kernels(
      also_neighbours.empty() ? positions : std::span<const Vec3>(with_neighbours), settings, region.contributing);
  auto grid = splat_anisotropic_kernels(kernels, settings, transform, 1.f);
  fill_interior(*grid, region, settings.voxel_size, -1.f);
  if (splatted) *splatted = SplattedKernels{std::move(region.contributing), std::move(kernels)};
  return grid;
}

}  // namespace

extern const FieldMethod kAnisotropicMethod{Method::anisotropic, true, true, true, false, anisotropic_field};

}  // namespace m3dp::surface
