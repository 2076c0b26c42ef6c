#include <gtest/gtest.h>

#include <random>

#include "m3dp/sph/kernels.hpp"

using namespace m3dp;
using namespace m3dp::sph;

namespace {
// ∫ W dV by the midpoint rule on a fine grid over the support cube (double accumulation).
template <class Kernel>
double integrate(const Kernel& kernel) {
  const int cells = 80;
  const double h = kernel.support_radius;
  const double step = 2 * h / cells;
  double sum = 0;
  for (int i = 0; i < cells; ++i)
    for (int j = 0; j < cells; ++j)
      for (int k = 0; k < cells; ++k) {
        const Vec3 r(Real(-h + (i + 0.5) * step), Real(-h + (j + 0.5) * step), Real(-h + (k + 0.5) * step));
        sum += kernel.W(r.norm());
      }
  return sum * step * step * step;
}

template <class Kernel>
void check_gradient(const Kernel& kernel) {
  std::mt19937 random(7);
  std::uniform_real_distribution<float> coordinate(-1, 1);
  for (int n = 0; n < 200; ++n) {
    const Vec3 r = Vec3(coordinate(random), coordinate(random), coordinate(random)) * kernel.support_radius;
    const Vec3 gradient = kernel.gradW(r);
    // Antisymmetry: ∇W(−r) = −∇W(r), so pair forces cancel exactly (momentum conservation).
    EXPECT_EQ(kernel.gradW(Vec3(-r)), Vec3(-gradient));
    // Matches a central finite difference of W.
    const Real delta = kernel.support_radius * Real(1e-3);
    for (int axis = 0; axis < 3; ++axis) {
      Vec3 plus = r, minus = r;
      plus[axis] += delta;
      minus[axis] -= delta;
      const Real numeric = (kernel.W(plus.norm()) - kernel.W(minus.norm())) / (2 * delta);
      EXPECT_NEAR(gradient[axis], numeric, 2e-3 * kernel.W_zero() / kernel.support_radius) << "axis " << axis;
    }
    // Points toward the centre: W decreases outward.
    if (r.norm() < kernel.support_radius) {
      EXPECT_LE(gradient.dot(r), 0);
    }
  }
}
}  // namespace

TEST(Kernels, CubicSplineIsNormalised) {
  const double integral = integrate(CubicSplineKernel(Real(0.04)));
  std::printf("cubic spline: integral of W = %.5f (reference 1)\n", integral);
  EXPECT_NEAR(integral, 1.0, 2e-3);
}

TEST(Kernels, WendlandC2IsNormalised) {
  const double integral = integrate(WendlandC2Kernel(Real(0.04)));
  std::printf("Wendland C2: integral of W = %.5f (reference 1)\n", integral);
  EXPECT_NEAR(integral, 1.0, 2e-3);
}

TEST(Kernels, CompactSupport) {
  const CubicSplineKernel cubic(1);
  const WendlandC2Kernel wendland(1);
  EXPECT_EQ(cubic.W(1.0001f), 0);
  EXPECT_EQ(wendland.W(1.0001f), 0);
  EXPECT_EQ(cubic.gradW(Vec3(1.01f, 0, 0)), Vec3::Zero());
  EXPECT_EQ(wendland.gradW(Vec3(0, 1.01f, 0)), Vec3::Zero());
  EXPECT_GT(cubic.W(0.99f), 0);
}

TEST(Kernels, GradientsAreAntisymmetricAndConsistent) {
  check_gradient(CubicSplineKernel(Real(0.02)));
  check_gradient(WendlandC2Kernel(Real(0.02)));
}

TEST(Kernels, CubicLatticeSumsToRestDensity) {
  // Particles on a cubic lattice of spacing d with support 2d: Σ W · d³ ≈ 1, which is why a block
  // sampled at spacing 2r with mass ρ0 (2r)³ starts at rest density.
  const Real d = Real(0.01);
  const CubicSplineKernel kernel(2 * d);
  double sum = 0;
  for (int i = -2; i <= 2; ++i)
    for (int j = -2; j <= 2; ++j)
      for (int k = -2; k <= 2; ++k) sum += kernel.W(Vec3(i * d, j * d, k * d).norm());
  std::printf("cubic lattice: sum W d^3 = %.4f\n", sum * d * d * d);
  EXPECT_NEAR(sum * d * d * d, 1.0, 0.01);
}
