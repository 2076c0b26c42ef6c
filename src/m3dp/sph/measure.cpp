#include "m3dp/sph/measure.hpp"

#include <algorithm>
#include <numeric>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

#include <tbb/parallel_reduce.h>

#include <functional>

namespace m3dp::sph {

void measure_density(const Solver& solver, std::vector<Real>& density) {
  const Model& model = solver.model();
  const auto& fluid = solver.fluid();
  const auto& boundary = solver.boundary();
  density.assign(fluid.size(), Real(0));
  if (fluid.size() == 0) return;
  const Real support = model.support_radius, support_squared = support * support;
  SpatialHashGrid fluid_grid, boundary_grid;
  fluid_grid.build(fluid.position, support);
  // Only the wall particles within a support radius of the fluid's box: a bed or a robot is often
  // far larger than the material on it.
  Eigen::AlignedBox<Real, 3> reach;
  for (const Vec3& position : fluid.position) reach.extend(position);
  reach.min().array() -= support;
  reach.max().array() += support;
  std::vector<Index> near;
  for (std::size_t b = 0; b < boundary.size(); ++b)
    if (reach.contains(boundary.position[b])) near.push_back(static_cast<Index>(b));
  boundary_grid.build(boundary.position, near, support);
  with_kernel(model.settings.kernel, support, [&](const auto& kernel) {
    parallel_for_each_index(fluid.size(), [&](std::size_t i) {
      const Vec3 position = fluid.position[i];
      Real fluid_sum = 0, wall_volume_sum = 0;
      fluid_grid.for_each_candidate(position, [&](Index, const Vec3& other) {
        const Real distance_squared = (position - other).squaredNorm();
        if (distance_squared < support_squared) fluid_sum += kernel.W(std::sqrt(distance_squared));
      });
      boundary_grid.for_each_candidate(position, [&](Index b, const Vec3& other) {
        const Real distance_squared = (position - other).squaredNorm();
        if (distance_squared < support_squared) wall_volume_sum += boundary.volume[b] * kernel.W(std::sqrt(distance_squared));
      });
      const Real rest_density = model.phases[fluid.phase[i]].density;
      density[i] = rest_density * (model.particle_volume * fluid_sum + wall_volume_sum);
    }, 512);
  });
}

double percentile_of_sorted(std::span<const double> sorted, double fraction) {
  const double rank = fraction * double(sorted.size() - 1);
  const auto below = static_cast<std::size_t>(rank);
  const std::size_t above = std::min(below + 1, sorted.size() - 1);
  return sorted[below] + (rank - double(below)) * (sorted[above] - sorted[below]);
}

DensityStatistics density_statistics(const Solver& solver, const std::vector<Real>& density) {
  DensityStatistics statistics;
  statistics.particles = density.size();
  if (density.empty()) return statistics;
  const auto& fluid = solver.fluid();
  std::vector<double> error(density.size());
  for (std::size_t i = 0; i < density.size(); ++i)
    error[i] = double(density[i]) / double(solver.model().phases[fluid.phase[i]].density) - 1;
  statistics.mean = std::accumulate(error.begin(), error.end(), 0.0) / double(error.size());
  statistics.max = *std::max_element(error.begin(), error.end());
  std::sort(error.begin(), error.end());
  statistics.median = percentile_of_sorted(error, 0.5);
  statistics.p99 = percentile_of_sorted(error, 0.99);
  return statistics;
}

std::size_t particles_in_bore(const Solver& solver, std::size_t nozzle) {
  const Model& model = solver.model();
  if (!model.nozzle_geometry[nozzle].has_bore()) return 0;
  const stages::BoreRegion bore(model, solver.state().nozzles[nozzle], nozzle);
  const auto& position = solver.fluid().position;
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, position.size(), 4096), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& range, std::size_t count) {
        Real depth = 0;
        for (std::size_t i = range.begin(); i != range.end(); ++i) count += bore.contains(position[i], depth) ? 1 : 0;
        return count;
      },
      std::plus<>());
}

}  // namespace m3dp::sph
