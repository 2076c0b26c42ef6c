#pragma once
// A pinhole camera as SDF describes it (<sensor type="camera|depth_camera|rgbd_camera">): the
// camera frame looks along +x with +z up (Gazebo's convention); images and point clouds use the
// optical frame of ROS REP 103 (z forward, x right, y down), whose origin is the camera's.
// Pixels are indexed from the top left; pixel (i, j) covers [i, i+1) × [j, j+1), its centre at +0.5.
#include <cstdint>
#include <optional>
#include <string>

#include "m3dp/core/types.hpp"

namespace m3dp::sensors {

enum class CameraType { camera, depth_camera, rgbd_camera };
[[nodiscard]] const char* camera_type_name(CameraType type);  // SDF's names
[[nodiscard]] inline bool has_color(CameraType type) { return type != CameraType::depth_camera; }
[[nodiscard]] inline bool has_depth(CameraType type) { return type != CameraType::camera; }

/// SDF <noise type="gaussian">: added to each colour channel (in [0, 1] units) of a colour image
/// and to each depth (m) of a depth image.
struct GaussianNoise {
  double mean = 0;
  double stddev = 0;
  std::uint64_t seed = 0;  // which noise: with the frame and the pixel, it picks each number
  [[nodiscard]] bool enabled() const { return stddev > 0 || mean != 0; }
};

struct CameraSettings {
  std::string name;
  CameraType type = CameraType::rgbd_camera;
  int width = 320, height = 240;       // pixels
  double horizontal_fov = 1.047;       // rad
  double near = 0.02, far = 10;        // m: what is hit closer or farther is not seen
  double update_rate = 10;             // images per second of simulated time
  GaussianNoise noise;
  bool shadows = true;                 // the key light casts shadows (one more ray a pixel)
  /// A point cloud of each depth image in the run's files and messages (20 bytes a pixel that saw
  /// something): in the optical frame, or in the world's (a scan that adds up across frames).
  enum class PointCloud { none, optical, world };
  PointCloud point_cloud = PointCloud::none;
  /// Where it is: on a robot link (`robot`/`link` not empty) at `pose` in the link frame, else at
  /// `pose` in the world.
  std::string robot, link;
  Pose pose;
};

/// The pinhole's intrinsics (pixels): square pixels, the principal point at the image's centre.
struct Intrinsics {
  double fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;
  [[nodiscard]] static Intrinsics of(const CameraSettings& settings);
  [[nodiscard]] double vertical_fov() const;  // rad
};

/// The rotation from the optical frame to the camera frame (x forward, z up).
[[nodiscard]] Quat optical_to_camera();
/// The optical frame's pose in the world, given the camera frame's.
[[nodiscard]] Pose optical_pose(const Pose& camera_pose);

/// Where `point_optical` (m, optical frame, z > 0) lands in the image (pixels, continuous).
[[nodiscard]] std::optional<Eigen::Vector2d> project(const Intrinsics& intrinsics, const Vec3d& point_optical);
/// The optical-frame direction through image point (u, v) (pixels, continuous), with z = 1.
[[nodiscard]] Vec3d ray_through(const Intrinsics& intrinsics, double u, double v);

}  // namespace m3dp::sensors
