#pragma once
// Anisotropic kernels for surface reconstruction.
// J. Yu, G. Turk: "Reconstructing Surfaces of Particle-Based Fluids Using Anisotropic Kernels",
// ACM Transactions on Graphics 32(1), 2013. Section 3 (smoothed centres, eq. 6) and Section 4
// (weighted covariance, eq. 7–8; clamped singular values, eq. 11–12; kernel W(r, G) = σ det G P(‖G r‖), eq. 13).
#include <span>
#include <vector>

#include <Eigen/Core>

#include "m3dp/surface/surface.hpp"

namespace m3dp::surface {

/// One ellipsoidal kernel per particle: W_i(x) = det(G_i) P(‖G_i (x − centre_i)‖), P the cubic
/// spline of unit support, so each W_i integrates to one. An interior particle gets
/// G = I / kernel_radius, i.e. exactly the isotropic SPH kernel.
struct AnisotropicKernels {
  std::vector<Vec3> centre;                  // smoothed centres (m)
  std::vector<Eigen::Matrix3f> transform;    // G_i (1/m)
  std::vector<Real> determinant;             // det G_i (1/m³)
  std::vector<Vec3> half_extent;             // axis-aligned half size of the kernel's support (m)
  std::size_t sparse_particles = 0;          // particles that fell back to the isotropic kernel
};

/// Kernels of the particles `which` (all when empty), in that order; every particle counts as a
/// neighbour. `settings` must be resolved(). Runs in parallel.
[[nodiscard]] AnisotropicKernels compute_anisotropic_kernels(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                                             std::span<const Index> which = {});

}  // namespace m3dp::surface
