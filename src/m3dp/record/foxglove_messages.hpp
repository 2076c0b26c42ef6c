#pragma once
// The run's messages in Foxglove's schemas (docs.foxglove.dev/docs/sdk/schemas), encoded as
// protobuf: scene entities (triangles and lines in a frame), frame transforms, point clouds, and
// M3DP's own run statistics and joint states. Every way out of a run (run.mcap, the live stream)
// sends these bytes; protobuf's headers stay in this module.
#include <array>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "m3dp/core/geometry.hpp"
#include "m3dp/core/types.hpp"

namespace m3dp::record {

/// The schema names M3DP writes ("foxglove.SceneUpdate", …, "m3dp.RunStats", "m3dp.JointStates").
[[nodiscard]] std::vector<std::string> schema_names();
/// A schema's protobuf FileDescriptorSet (its file and every file it imports): what MCAP schema
/// records and Foxglove WebSocket advertisements carry. Throws m3dp::Error for an unknown name.
[[nodiscard]] std::string schema_descriptor_set(std::string_view schema_name);

struct Color {
  double r = 0.6, g = 0.6, b = 0.6, a = 1;
};

/// One foxglove.SceneEntity: triangles and line strips in `frame_id` (frame-locked: it moves with the frame).
struct SceneEntity {
  std::string id;
  std::string frame_id = "world";
  Color color;
  const TriangleMesh* triangles = nullptr;           // in the frame (m); null: none
  std::vector<std::vector<Vec3>> line_strips;        // in the frame (m)
  double line_thickness = 0.003;                     // m
  std::vector<std::pair<std::string, std::string>> metadata;
  std::vector<Color> vertex_colors;  // one per vertex of `triangles` (then `color` is not used), or none
};
/// foxglove.SceneUpdate: these entities added or replaced, and the ids given deleted, at `time` (s).
[[nodiscard]] std::string encode_scene_update(double time, std::span<const SceneEntity> entities,
                                              std::span<const std::string> deleted_ids = {});

struct FrameTransform {
  std::string parent;
  std::string child;
  Pose pose;  // of the child in the parent (m)
};
/// foxglove.FrameTransforms at `time` (s).
[[nodiscard]] std::string encode_frame_transforms(double time, std::span<const FrameTransform> transforms);

/// A field of a foxglove.PointCloud's packed points.
struct PointField {
  enum class Type : int { uint8 = 1, uint16 = 3, uint32 = 5, float32 = 7, float64 = 8 };
  std::string name;
  std::uint32_t offset = 0;  // bytes into the point
  Type type = Type::float32;
};
/// foxglove.PointCloud at `time` (s) in `frame_id`: `point_count` points of `stride` bytes each,
/// which `pack(bytes)` writes into the message's data (point_count · stride bytes) in place.
void encode_point_cloud(double time, std::string_view frame_id, std::span<const PointField> fields, std::uint32_t stride,
                        std::size_t point_count, const std::function<void(char* bytes)>& pack, std::string& out);

/// foxglove.RawImage at `time` (s) in `frame_id`: `height` rows of `step` bytes in `encoding`
/// ("rgb8", "32FC1" metres of depth, "16UC1").
[[nodiscard]] std::string encode_raw_image(double time, std::string_view frame_id, std::uint32_t width, std::uint32_t height,
                                           std::string_view encoding, std::uint32_t step, std::string_view data);
/// foxglove.CameraCalibration of a pinhole without distortion: fx, fy, cx, cy in pixels.
[[nodiscard]] std::string encode_camera_calibration(double time, std::string_view frame_id, std::uint32_t width, std::uint32_t height,
                                                    double fx, double fy, double cx, double cy);

struct NozzleStatus {
  std::string name;
  bool extruding = false;
  double volume_rate = 0;  // m³/s
  Vec3 position = Vec3::Zero();
  double tracking_error = 0;  // m from the path's point now
  // Its volume balance so far (m³): asked for, out of the exit, in its bore now, lost while blocked,
  // and what filled its bore before its first layer.
  double volume_commanded = 0, volume_laid = 0, volume_in_bore = 0, volume_lost = 0, volume_primed = 0;
};
struct RunStats {
  double time = 0, real_time_factor = 0;
  std::uint64_t particles = 0, resting_particles = 0;
  double density_error_mean = 0, density_error_max = 0, time_step = 0;
  std::uint32_t pressure_iterations = 0;
  double step_ms = 0, neighbor_ms = 0, pressure_ms = 0, world_ms = 0;
  std::vector<NozzleStatus> nozzles;
  std::uint64_t step = 0;
  std::vector<double> material_density;  // kg/m³, by material index
  double particle_radius = 0;            // m
};
[[nodiscard]] std::string encode_run_stats(const RunStats& stats);

/// m3dp.QualityStats: the print against its design (quality/), each time its surface is meshed.
struct LayerQuality {
  std::string head;
  std::int32_t layer = 0;
  std::uint32_t sections = 0, empty = 0;
  double width = 0, design_width = 0, height = 0, design_height = 0;  // m
  double offset_across = 0, offset_up = 0;                            // m
};
struct QualityStats {
  double time = 0;
  std::uint64_t vertices = 0;
  double deviation_mean = 0, deviation_p95 = 0, deviation_max = 0, deviation_range = 0;  // m
  std::vector<double> histogram_edges;                                                  // m
  std::vector<std::uint64_t> histogram_counts;
  double fill_designed = 0, fill_over = 0, fill_under = 0;  // m³
  std::vector<LayerQuality> layers;
};
[[nodiscard]] std::string encode_quality_stats(const QualityStats& stats);

/// m3dp.JointStates: a robot's joints at `time` (s): positions (rad or m), velocities (rad/s or m/s)
/// and efforts (N·m or N), each in the order of `names`.
[[nodiscard]] std::string encode_joint_states(double time, std::string_view robot, std::span<const std::string> names,
                                              std::span<const double> positions, std::span<const double> velocities,
                                              std::span<const double> efforts);

}  // namespace m3dp::record
