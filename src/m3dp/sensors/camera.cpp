#include "m3dp/sensors/camera.hpp"

#include <cmath>

namespace m3dp::sensors {

const char* camera_type_name(CameraType type) {
  switch (type) {
    case CameraType::camera: return "camera";
    case CameraType::depth_camera: return "depth_camera";
    case CameraType::rgbd_camera: return "rgbd_camera";
  }
  return "camera";
}

Intrinsics Intrinsics::of(const CameraSettings& settings) {
  Intrinsics intrinsics;
  intrinsics.width = settings.width;
  intrinsics.height = settings.height;
  // SDF's horizontal_fov spans the image's width: fx = (w/2) / tan(fov/2); square pixels.
  intrinsics.fx = 0.5 * settings.width / std::tan(0.5 * settings.horizontal_fov);
  intrinsics.fy = intrinsics.fx;
  intrinsics.cx = 0.5 * settings.width;
  intrinsics.cy = 0.5 * settings.height;
  return intrinsics;
}

double Intrinsics::vertical_fov() const { return 2 * std::atan(0.5 * height / fy); }

Quat optical_to_camera() {
  // Columns: the optical x (right), y (down), z (forward) axes in the camera frame (x forward, z up).
  Mat3 rotation;
  rotation << 0, 0, 1,  //
      -1, 0, 0,         //
      0, -1, 0;
  return Quat(rotation);
}

Pose optical_pose(const Pose& camera_pose) { return camera_pose * Pose{Vec3::Zero(), optical_to_camera()}; }

std::optional<Eigen::Vector2d> project(const Intrinsics& intrinsics, const Vec3d& point_optical) {
  if (!(point_optical.z() > 0)) return std::nullopt;
  return Eigen::Vector2d(intrinsics.fx * point_optical.x() / point_optical.z() + intrinsics.cx,
                         intrinsics.fy * point_optical.y() / point_optical.z() + intrinsics.cy);
}

Vec3d ray_through(const Intrinsics& intrinsics, double u, double v) {
  return Vec3d((u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy, 1.0);
}

}  // namespace m3dp::sensors
