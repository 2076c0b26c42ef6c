#pragma once
// Scalar and small vector types used throughout M3DP.
// Real is float by default (build option M3DP_DOUBLE gives double): particle arrays are
// memory-bound, so half the bytes is most of the speed.
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <limits>
#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace m3dp {

#if defined(M3DP_USE_DOUBLE)
using Real = double;
#else
using Real = float;
#endif

using Vec3 = Eigen::Matrix<Real, 3, 1>;
/// A 3-vector padded to four lanes (w = 0): one SIMD register, so sweeps over neighbours load and
/// combine whole vectors (the solver's pressure sweeps).
using Vec4 = Eigen::Matrix<Real, 4, 1>;
inline Vec4 padded(const Vec3& vector) {
#if defined(__SSE2__) && !defined(M3DP_USE_DOUBLE)
  // Built in a register: GCC builds Vec4(x, y, z, 0) with four small stores to the stack and one wide
  // load, which cannot be forwarded and stalls (the CG's direction update spent 77 % of its time there).
  Vec4 result;
  _mm_store_ps(result.data(), _mm_setr_ps(vector.x(), vector.y(), vector.z(), 0.0f));
  return result;
#else
  return Vec4(vector.x(), vector.y(), vector.z(), Real(0));
#endif
}
using Vec3d = Eigen::Vector3d;
using Mat3 = Eigen::Matrix<Real, 3, 3>;
using Quat = Eigen::Quaternion<Real>;
using Index = std::uint32_t;

inline constexpr Real kPi = Real(3.14159265358979323846);

/// A rigid transform: world = orientation * local + position. SI units (m).
struct Pose {
  Vec3 position = Vec3::Zero();
  Quat orientation = Quat::Identity();

  [[nodiscard]] Vec3 apply(const Vec3& local_point) const { return orientation * local_point + position; }
  [[nodiscard]] Vec3 rotate(const Vec3& local_direction) const { return orientation * local_direction; }
  [[nodiscard]] Pose operator*(const Pose& child) const {
    return Pose{apply(child.position), (orientation * child.orientation).normalized()};
  }
  /// SDF convention: x y z roll pitch yaw, rotations applied as R = Rz(yaw) Ry(pitch) Rx(roll).
  static Pose from_xyz_rpy(Real x, Real y, Real z, Real roll, Real pitch, Real yaw) {
    Pose pose;
    pose.position = Vec3(x, y, z);
    pose.orientation = Quat(Eigen::AngleAxis<Real>(yaw, Vec3::UnitZ()) * Eigen::AngleAxis<Real>(pitch, Vec3::UnitY()) *
                            Eigen::AngleAxis<Real>(roll, Vec3::UnitX()));
    return pose;
  }
};

/// Axis-aligned box in world coordinates (m).
struct Aabb {
  Vec3 min = Vec3::Constant(std::numeric_limits<Real>::max());
  Vec3 max = Vec3::Constant(std::numeric_limits<Real>::lowest());

  [[nodiscard]] bool empty() const { return (min.array() > max.array()).any(); }
  [[nodiscard]] bool contains(const Vec3& point) const {
    return (point.array() >= min.array()).all() && (point.array() <= max.array()).all();
  }
  void extend(const Vec3& point) {
    min = min.cwiseMin(point);
    max = max.cwiseMax(point);
  }
  [[nodiscard]] Vec3 size() const { return max - min; }
};

}  // namespace m3dp
