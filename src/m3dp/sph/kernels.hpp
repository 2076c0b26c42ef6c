#pragma once
// SPH smoothing kernels in 3D. `support_radius` is the radius where W falls to zero
// (SPlisHSPlasH convention h = 4 × particle radius), q = r / support_radius.
#include <cmath>

#include "m3dp/core/types.hpp"

namespace m3dp::sph {

enum class KernelType { cubic_spline, wendland_c2 };

/// W(r) and (dW/dr)/r of one distance.
struct KernelValueAndGradient {
  Real value;
  Real gradient_factor;
};

/// Cubic B-spline (Monaghan 1992) on compact support [0, h].
struct CubicSplineKernel {
  Real support_radius;
  Real value_coefficient;     // 8 / (π h³)
  Real gradient_coefficient;  // 48 / (π h³)

  explicit CubicSplineKernel(Real h)
      : support_radius(h), value_coefficient(Real(8) / (kPi * h * h * h)), gradient_coefficient(Real(48) / (kPi * h * h * h)) {}

  [[nodiscard]] Real W(Real distance) const {
    const Real q = distance / support_radius;
    if (q <= Real(0.5)) return value_coefficient * (Real(6) * q * q * q - Real(6) * q * q + Real(1));
    if (q <= Real(1)) {
      const Real one_minus_q = Real(1) - q;
      return value_coefficient * Real(2) * one_minus_q * one_minus_q * one_minus_q;
    }
    return 0;
  }
  [[nodiscard]] Real W_zero() const { return value_coefficient; }

  /// (dW/dr) / r, so that ∇_i W(x_i − x_j) = gradient_factor(|r|) · r for r = x_i − x_j.
  /// Solvers store it per neighbour pair once a step and rebuild ∇W from r without a square root.
  [[nodiscard]] Real gradient_factor(Real distance) const {
    const Real q = distance / support_radius;
    if (q <= Real(0.5)) return gradient_coefficient * (Real(3) * q - Real(2)) / (support_radius * support_radius);
    if (q > Real(1)) return 0;
    const Real one_minus_q = Real(1) - q;
    return -gradient_coefficient * one_minus_q * one_minus_q / (distance * support_radius);
  }

  /// ∇_i W(x_i − x_j) for r = x_i − x_j.
  [[nodiscard]] Vec3 gradW(const Vec3& r) const { return gradient_factor(r.norm()) * r; }

  /// W and gradient_factor together, as the density pass needs both for every pair: one q, and both
  /// pieces of the spline evaluated and selected rather than branched on (which side of q = 1/2 a
  /// neighbour lies is too irregular to predict).
  [[nodiscard]] KernelValueAndGradient value_and_gradient_factor(Real distance) const {
    const Real inverse_support = Real(1) / support_radius;
    const Real q = distance * inverse_support;
    const Real one_minus_q = Real(1) - q;
    const bool inner = q <= Real(0.5);
    const Real value = inner ? value_coefficient * (Real(6) * q * q * q - Real(6) * q * q + Real(1))
                             : value_coefficient * Real(2) * one_minus_q * one_minus_q * one_minus_q;
    const Real gradient = inner ? gradient_coefficient * (Real(3) * q - Real(2)) * inverse_support * inverse_support
                                : -gradient_coefficient * one_minus_q * one_minus_q * inverse_support / distance;
    if (q > Real(1)) return {0, 0};
    return {value, gradient};
  }
};

/// Wendland C2 (Wendland 1995; Dehnen & Aly 2012): smoother, no pairing instability.
struct WendlandC2Kernel {
  Real support_radius;
  Real value_coefficient;  // 21 / (2π h³)
  Real gradient_coefficient;  // -20 · 21 / (2π h⁵)

  explicit WendlandC2Kernel(Real h)
      : support_radius(h),
        value_coefficient(Real(21) / (Real(2) * kPi * h * h * h)),
        gradient_coefficient(Real(-20) * Real(21) / (Real(2) * kPi * h * h * h * h * h)) {}

  [[nodiscard]] Real W(Real distance) const {
    const Real q = distance / support_radius;
    if (q >= Real(1)) return 0;
    const Real one_minus_q = Real(1) - q;
    const Real squared = one_minus_q * one_minus_q;
    return value_coefficient * squared * squared * (Real(1) + Real(4) * q);
  }
  [[nodiscard]] Real W_zero() const { return value_coefficient; }

  /// (dW/dr) / r, so that ∇_i W(x_i − x_j) = gradient_factor(|r|) · r.
  [[nodiscard]] Real gradient_factor(Real distance) const {
    const Real q = distance / support_radius;
    if (q >= Real(1)) return 0;
    const Real one_minus_q = Real(1) - q;
    return gradient_coefficient * one_minus_q * one_minus_q * one_minus_q;
  }
  [[nodiscard]] Vec3 gradW(const Vec3& r) const { return gradient_factor(r.norm()) * r; }
  [[nodiscard]] KernelValueAndGradient value_and_gradient_factor(Real distance) const { return {W(distance), gradient_factor(distance)}; }
};

/// Calls `body(kernel)` with the concrete kernel type, so per-pair code is inlined (no per-pair dispatch).
template <class Body>
decltype(auto) with_kernel(KernelType type, Real support_radius, Body&& body) {
  switch (type) {
    case KernelType::wendland_c2:
      return body(WendlandC2Kernel(support_radius));
    case KernelType::cubic_spline:
    default:
      return body(CubicSplineKernel(support_radius));
  }
}

}  // namespace m3dp::sph
