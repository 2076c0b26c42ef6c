// Surface tension as a continuum surface force after J. U. Brackbill, D. B. Kothe, C. Zemach, "A
// Continuum Method for Modeling Surface Tension", J. Comput. Phys. 100(2), 335–354, 1992:
//   f = σ κ ∇c   (N/m³),  c the colour (1 in the material, 0 in air), κ = 1/R1 + 1/R2,
// which integrates across the surface to σκ per area. With the material alone on particles (no air),
// the force is put where that integral belongs, on the outermost layer:
//   F_i = −σ κ_i A_i n̂_i,
// A_i the area the particle carries and n̂_i the outward normal. Spread over the layers below with
// Brackbill's ∇c as weight, the second layer's small and noisy ∇c (some point outwards) drove particles
// out of a droplet at rest (docs/architecture.md has the measurements).
//
// The outermost layer: particles with |∇c| > 0.2/h, ∇c_i = Σ_j V_j ∇W_ij + Σ_b V_b ∇W_ib (walls count as
// material, so a face lying on a wall is no surface), that have no neighbour of the material within 45°
// of their outward normal (the cone test of free-surface detection, Marrone et al. 2010).
//
// κ is not taken as −∇·n̂ (a second derivative of a one-sided sum, noisy where it matters most). On each
// layer particle a height function z = f(x, y) is fitted by weighted least squares to the layer
// particles on the same side within twice the support radius, in the frame of their weighted plane
// (the fit of the moving-least-squares surface methods, e.g. Sun, Zhang & Liew 2021), and
//   κ = −[(1 + f_y²) f_xx − 2 f_x f_y f_xy + (1 + f_x²) f_yy] / (1 + f_x² + f_y²)^{3/2}.
// Layer particles next to a wall are mirrored across its geometric surface into the fit: a 90° contact
// angle. Particle centres sit half a spacing inside the material's surface, so κ and A are moved out
// to it (exact on a sphere). The curvatures are then averaged over the layer with kernel weights.
// A_i = 1 / the layer's areal density, from its kernel sum against that of a flat layer of the rest
// lattice (csf_layer_kernel_sum()).
#include <Eigen/Dense>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph {

namespace {
// The height function is fitted over twice the support radius: over one support (two spacings) the
// lattice's steps on a curved surface made each particle's κ scatter by 5× its value.
constexpr Real kFitRadiusPerSupport = 2;
// Layer particles on the same side within the fit radius that a fit needs: a flat surface has about 50, a
// cube's corner 12.
constexpr std::size_t kMinimumFitSamples = 12;
// At most this many samples (the layer and its mirror at a wall have about 100 within the fit radius).
constexpr std::size_t kMaximumFitSamples = 256;
// surface_flag: 1 on the outermost layer, kFitted where the layer around the particle could be fitted.
constexpr std::uint8_t kFitted = 2;
}  // namespace

Real csf_layer_kernel_sum(KernelType kernel_type, Real support_radius, Real spacing) {
  // Σ_j W(|x_ij|) over a flat square layer of spacing d, the particle itself included, times d²: a
  // layer of areal density n then sums to n × this.
  return with_kernel(kernel_type, kFitRadiusPerSupport * support_radius, [&](const auto& fit_kernel) {
    const int reach = static_cast<int>(std::ceil(kFitRadiusPerSupport * support_radius / spacing)) + 1;
    double sum = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j) sum += double(fit_kernel.W(Vec3(Real(i) * spacing, Real(j) * spacing, 0).norm()));
    return Real(sum * spacing * spacing);
  });
}

namespace stages {

namespace {

struct LayerFit {
  bool fitted = false;  // enough samples for a fit
  Real curvature = 0;   // 1/m, of the centres' surface
  Vec3 outward;         // unit normal of the fitted surface
  Real kernel_sum = 0;  // Σ_j W over the layer, the particle included (its areal density × csf_layer_kernel_sum)
};

/// The height function fitted around particle i over the outermost-layer particles `layer` (within
/// fit_kernel's support). `colour_outward` (−∇c/|∇c|) orients the fit.
LayerFit fit_layer(const State& state, const Workspace& workspace, std::size_t i, const Vec3& colour_outward, std::span<const Index> layer,
                   Real fit_radius, const auto& fit_kernel) {
  const auto& fluid = state.fluid;
  const auto& walls = workspace.surface_layer;
  LayerFit fit;
  fit.outward = colour_outward;
  fit.kernel_sum = fit_kernel.W_zero();

  // The samples: positions relative to particle i and their kernel weights. Where the layer meets a
  // wall, its mirror image continues it (a right contact angle; the adhesion sets the rest): fitted
  // over half a patch, a sessile drop's rim got too little curvature, and with the wall in ∇c its
  // frame turned towards the wall, so that the rim's curvature came out inside out.
  struct Sample {
    Vec3 offset;
    Real weight;
  };
  std::array<Sample, kMaximumFitSamples> samples;
  std::size_t sample_count = 0;
  auto add = [&](const Vec3& offset) {
    const Real distance = offset.norm();
    if (distance >= fit_radius || sample_count == samples.size()) return Real(0);
    samples[sample_count++] = {offset, fit_kernel.W(distance)};
    return samples[sample_count - 1].weight;
  };
  auto add_mirror = [&](std::size_t j) {
    const Vec3 wall_normal = walls.wall_normal[j];
    if (wall_normal.squaredNorm() == 0) return;
    const Vec3 mirrored = fluid.position[j] - (2 * (fluid.position[j] - walls.wall_point[j]).dot(wall_normal)) * wall_normal;
    add(mirrored - fluid.position[i]);
  };
  add(Vec3::Zero());
  add_mirror(i);
  for (const Index j : layer) {
    // Only the same side of the material: across a sheet or a filament thinner than the fit radius,
    // the far face would be fitted as part of the near one.
    if (j == i || workspace.surface_normal[j].dot(workspace.surface_normal[i]) <= 0) continue;
    fit.kernel_sum += add(fluid.position[j] - fluid.position[i]);
    add_mirror(j);
  }
  // A patch too sparse to fit (a tip, a strand, spray) has no resolved curvature and gets no force.
  if (sample_count < kMinimumFitSamples) return fit;

  // The frame: the normal of the samples' weighted plane, on the side of −∇c.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  double weights = 0;
  for (std::size_t k = 0; k < sample_count; ++k) {
    centroid += double(samples[k].weight) * samples[k].offset.template cast<double>();
    weights += double(samples[k].weight);
  }
  centroid /= weights;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < sample_count; ++k) {
    const Eigen::Vector3d centred = samples[k].offset.template cast<double>() - centroid;
    covariance.noalias() += double(samples[k].weight) * centred * centred.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(covariance);
  Vec3 outward = eigen.eigenvectors().col(0).template cast<Real>();  // smallest eigenvalue first
  if (outward.dot(colour_outward) < 0) outward = -outward;
  const Vec3 helper = std::abs(outward.x()) < Real(0.6) ? Vec3::UnitX() : Vec3::UnitY();
  const Vec3 tangent_1 = outward.cross(helper).normalized();
  const Vec3 tangent_2 = outward.cross(tangent_1);

  using Matrix6 = Eigen::Matrix<double, 6, 6>;
  using Vector6 = Eigen::Matrix<double, 6, 1>;
  Matrix6 normal_matrix = Matrix6::Zero();
  Vector6 right_side = Vector6::Zero();
  const double inverse_h = 1.0 / double(fit_radius);
  for (std::size_t k = 0; k < sample_count; ++k) {
    const Vec3& offset = samples[k].offset;
    const double a = double(offset.dot(tangent_1)) * inverse_h, b = double(offset.dot(tangent_2)) * inverse_h;
    const Vector6 basis(a * a, a * b, b * b, a, b, 1);
    normal_matrix.noalias() += double(samples[k].weight) * basis * basis.transpose();
    right_side.noalias() += double(samples[k].weight) * double(offset.dot(outward)) * inverse_h * basis;
  }
  const Vector6 p = normal_matrix.ldlt().solve(right_side);
  const double f_xx = 2 * p[0], f_xy = p[1], f_yy = 2 * p[2], f_x = p[3], f_y = p[4];
  const double slope = 1 + f_x * f_x + f_y * f_y;
  const double curvature_in_h =
      -((1 + f_y * f_y) * f_xx - 2 * f_x * f_y * f_xy + (1 + f_x * f_x) * f_yy) / (slope * std::sqrt(slope));
  if (!std::isfinite(curvature_in_h)) return fit;
  fit.fitted = true;
  fit.curvature = Real(curvature_in_h * inverse_h);
  fit.outward = (outward - Real(f_x) * tangent_1 - Real(f_y) * tangent_2).normalized();
  return fit;
}

}  // namespace

void add_csf_surface_tension(const Model& model, State& state, Workspace& workspace) {
  const Real layer_kernel_sum = model.surface_tension_calibration.layer_kernel_sum;
  const auto& settings = model.settings;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const std::size_t count = state.active_count;
  const Real h = model.support_radius;
  const Real diameter = 2 * settings.particle_radius;
  const auto& fluid_lists = workspace.fluid_neighbors;
  const auto& boundary_lists = workspace.boundary_neighbors;

  // ∇c_i with rest volumes (as the calibration); walls count as material.
  auto& colour_gradient = workspace.surface_normal;
  colour_gradient.resize(fluid.size());
  std::fill(colour_gradient.begin() + static_cast<std::ptrdiff_t>(count), colour_gradient.end(), Vec3::Zero());
  parallel_for_each_index(count, [&](std::size_t i) { colour_gradient[i] = stages::colour_gradient(state, workspace, i); }, 512);

  // The outermost layer.
  auto& outermost = workspace.surface_flag;
  outermost.assign(fluid.size(), 0);
  workspace.surface_layer.wall_normal.assign(fluid.size(), Vec3::Zero());
  workspace.surface_layer.wall_point.resize(fluid.size());
  const Real threshold = Real(0.2) / h;
  const Real cone_cosine = Real(std::sqrt(0.5));
  parallel_for_each_index(count, [&](std::size_t i) {
    const Real magnitude = colour_gradient[i].norm();
    if (!(magnitude > threshold)) return;
    const Vec3 outward = -colour_gradient[i] / magnitude;
    const std::size_t first = fluid_lists.first(i);
    for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
      const Vec3 r = fluid.position[fluid_lists.indices[first + k]] - fluid.position[i];
      if (r.dot(outward) > cone_cosine * r.norm()) return;
    }
    // Walls are left out of the cone: the particle in the corner between a drop's side and the floor
    // would be hidden by the floor, and, without a pull, the drop's pressure pushed it out under the rim.
    // (A face lying on a wall is no surface: there ∇c, with the wall in it, stays under the threshold.)
    const std::size_t boundary_first = boundary_lists.first(i);
    outermost[i] = 1;
    // The wall next to it, if any: its direction (towards the wall particles) and a point of its
    // geometric surface, a radius in front of the nearest wall particle along it.
    Vec3 towards_wall = Vec3::Zero();
    for (Index k = 0; k < boundary_lists.counts[i]; ++k)
      towards_wall += workspace.boundary_pair_gradient[boundary_first + k] *
                      (fluid.position[i] - boundary.position[boundary_lists.indices[boundary_first + k]]);
    if (towards_wall.squaredNorm() == 0) return;
    const Vec3 wall_normal = towards_wall.normalized();
    Real nearest = std::numeric_limits<Real>::max();
    for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
      const Real along = (boundary.position[boundary_lists.indices[boundary_first + k]] - fluid.position[i]).dot(wall_normal);
      if (along > 0) nearest = std::min(nearest, along);
    }
    if (nearest == std::numeric_limits<Real>::max()) return;
    workspace.surface_layer.wall_normal[i] = wall_normal;
    workspace.surface_layer.wall_point[i] = fluid.position[i] + (nearest - settings.particle_radius) * wall_normal;
  }, 512);

  // The layer's neighbours within the fit radius: a grid of the layer alone.
  auto& layer = workspace.surface_layer;
  layer.indices.clear();
  for (std::size_t i = 0; i < count; ++i)
    if (outermost[i]) layer.indices.push_back(static_cast<Index>(i));
  layer.positions.resize(layer.indices.size());
  layer.area.resize(layer.indices.size());
  layer.outward.resize(layer.indices.size());
  for (std::size_t k = 0; k < layer.indices.size(); ++k) layer.positions[k] = fluid.position[layer.indices[k]];
  const Real fit_radius = kFitRadiusPerSupport * h;
  layer.grid.build(fluid.position, layer.indices, fit_radius);
  find_neighbors(layer.grid, layer.positions, fit_radius, false, layer.neighbors, false);

  auto& layer_curvature = workspace.scratch_real;
  layer_curvature.assign(fluid.size(), 0);
  auto& curvature = workspace.surface_curvature;
  curvature.assign(fluid.size(), 0);
  with_kernel(settings.kernel, fit_radius, [&](const auto& fit_kernel) {
    parallel_for_each_index(layer.indices.size(), [&](std::size_t k) {
      const std::size_t i = layer.indices[k];
      const Vec3 outward = -colour_gradient[i].normalized();
      LayerFit fit = fit_layer(state, workspace, i, outward, layer.neighbors.of(k), fit_radius, fit_kernel);
      // No surface of the material is rounder than a sphere of one spacing's radius.
      fit.curvature = std::clamp(fit.curvature, -2 / diameter, 2 / diameter);
      // From the centres' surface out to the material's, half a spacing further (exact on a sphere):
      // the curvature falls and the area grows with the radius.
      const Real growth = std::max(1 + fit.curvature * diameter / 4, Real(0.5));
      layer_curvature[i] = fit.curvature / growth;
      // A particle with few layer neighbours (a tip, a strand, a lone particle) would get the area of a
      // whole sparse patch; no particle carries more than twice its cross-section d².
      layer.area[k] = std::min(growth * growth * layer_kernel_sum / fit.kernel_sum, 2 * diameter * diameter);
      layer.outward[k] = fit.outward;
      if (fit.fitted) outermost[i] = kFitted;
    }, 16);
  });
  with_kernel(settings.kernel, h, [&](const auto& kernel) {
    // Kernel-weighted mean over the fitted particles of the layer on the same side. A particle whose own
    // patch was too sparse to fit takes its neighbours' curvature: without a pull of its own, the
    // material's Laplace pressure would push it out of the surface.
    parallel_for_each_index(count, [&](std::size_t i) {
      if (!outermost[i]) return;
      Real weighted = 0, weights = 0;
      if (outermost[i] == kFitted) {
        weighted = kernel.W_zero() * layer_curvature[i];
        weights = kernel.W_zero();
      }
      const std::size_t first = fluid_lists.first(i);
      for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
        const Index j = fluid_lists.indices[first + k];
        if (outermost[j] != kFitted || colour_gradient[j].dot(colour_gradient[i]) <= 0) continue;
        const Real weight = kernel.W((fluid.position[i] - fluid.position[j]).norm());
        weighted += weight * layer_curvature[j];
        weights += weight;
      }
      if (weights > 0) curvature[i] = weighted / weights;
    }, 512);
  });

  // The force acts on the outermost layer alone, each particle carrying the area of the layer around
  // it (1 / its areal density, moved out to the material's surface): F_i = −σ κ_i A_i n̂_i with n̂_i the
  // fitted surface's outward normal. Spread over the layers below with ∇c as weight (Brackbill's form),
  // the interior particles' small and noisy ∇c (some point outwards) drove particles out of a droplet
  // at rest.
  parallel_for_each_index(layer.indices.size(), [&](std::size_t k) {
    const std::size_t i = layer.indices[k];
    const FluidPhase& phase = model.phases[fluid.phase[i]];
    if (phase.surface_tension <= 0) return;
    fluid.acceleration[i] -= (phase.surface_tension * curvature[i] * layer.area[k] / fluid.mass[i]) * layer.outward[k];
  }, 256);
}

}  // namespace stages

}  // namespace m3dp::sph

