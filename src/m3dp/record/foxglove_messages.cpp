#include "m3dp/record/foxglove_messages.hpp"

#include <fmt/format.h>
#include <google/protobuf/descriptor.pb.h>

#include <cmath>
#include <map>
#include <set>

#include "foxglove/FrameTransforms.pb.h"
#include "foxglove/PointCloud.pb.h"
#include "foxglove/SceneUpdate.pb.h"
#include "foxglove/RawImage.pb.h"
#include "foxglove/CompressedImage.pb.h"
#include "foxglove/CameraCalibration.pb.h"
#include "m3dp/RunStats.pb.h"
#include "m3dp/core/error.hpp"

namespace m3dp::record {

namespace {

const std::map<std::string, const google::protobuf::Descriptor*, std::less<>>& descriptors() {
  static const std::map<std::string, const google::protobuf::Descriptor*, std::less<>> all = [] {
    std::map<std::string, const google::protobuf::Descriptor*, std::less<>> map;
    for (const auto* descriptor :
         {foxglove::SceneUpdate::descriptor(), foxglove::FrameTransforms::descriptor(), foxglove::PointCloud::descriptor(),
          foxglove::RawImage::descriptor(), foxglove::CompressedImage::descriptor(), foxglove::CameraCalibration::descriptor(),
          m3dp::RunStats::descriptor(), m3dp::JointStates::descriptor(), m3dp::QualityStats::descriptor()})
      map.emplace(descriptor->full_name(), descriptor);
    return map;
  }();
  return all;
}

/// `file` and what it imports, imports first (the order protoc's --include_imports writes).
void add_file(const google::protobuf::FileDescriptor* file, std::set<std::string>& added, google::protobuf::FileDescriptorSet& set) {
  if (!added.insert(file->name()).second) return;
  for (int d = 0; d < file->dependency_count(); ++d) add_file(file->dependency(d), added, set);
  file->CopyTo(set.add_file());
}

void set_timestamp(google::protobuf::Timestamp& timestamp, double time) {
  const double seconds = std::floor(time);
  timestamp.set_seconds(static_cast<std::int64_t>(seconds));
  timestamp.set_nanos(std::min(999'999'999, static_cast<int>(std::llround((time - seconds) * 1e9))));
}

void set_point(foxglove::Point3& point, const Vec3& position) {
  point.set_x(position.x());
  point.set_y(position.y());
  point.set_z(position.z());
}

void set_color(foxglove::Color& color, const Color& value) {
  color.set_r(value.r);
  color.set_g(value.g);
  color.set_b(value.b);
  color.set_a(value.a);
}

void set_identity(foxglove::Pose& pose) { pose.mutable_orientation()->set_w(1); }

std::string serialized(const google::protobuf::Message& message) {
  std::string bytes;
  if (!message.SerializeToString(&bytes)) throw Error(fmt::format("{}: cannot serialize", message.GetTypeName()));
  return bytes;
}

}  // namespace

std::vector<std::string> schema_names() {
  std::vector<std::string> names;
  for (const auto& [name, descriptor] : descriptors()) names.push_back(name);
  return names;
}

std::string schema_descriptor_set(std::string_view schema_name) {
  const auto found = descriptors().find(schema_name);
  if (found == descriptors().end()) throw Error(fmt::format("no schema called '{}'", schema_name));
  google::protobuf::FileDescriptorSet set;
  std::set<std::string> added;
  add_file(found->second->file(), added, set);
  return serialized(set);
}

std::string encode_scene_update(double time, std::span<const SceneEntity> entities, std::span<const std::string> deleted_ids) {
  foxglove::SceneUpdate update;
  for (const auto& id : deleted_ids) {
    auto& deletion = *update.add_deletions();
    set_timestamp(*deletion.mutable_timestamp(), time);
    deletion.set_type(foxglove::SceneEntityDeletion::MATCHING_ID);
    deletion.set_id(id);
  }
  for (const auto& entity : entities) {
    auto& out = *update.add_entities();
    set_timestamp(*out.mutable_timestamp(), time);
    out.set_frame_id(entity.frame_id);
    out.set_id(entity.id);
    out.set_frame_locked(true);
    for (const auto& [key, value] : entity.metadata) {
      auto& pair = *out.add_metadata();
      pair.set_key(key);
      pair.set_value(value);
    }
    if (entity.triangles && !entity.triangles->triangles.empty()) {
      auto& triangles = *out.add_triangles();
      set_identity(*triangles.mutable_pose());
      set_color(*triangles.mutable_color(), entity.color);
      if (!entity.vertex_colors.empty()) {
        if (entity.vertex_colors.size() != entity.triangles->vertices.size())
          throw Error(fmt::format("entity '{}': {} vertex colours for {} vertices", entity.id, entity.vertex_colors.size(),
                                  entity.triangles->vertices.size()));
        triangles.mutable_colors()->Reserve(static_cast<int>(entity.vertex_colors.size()));
        for (const Color& color : entity.vertex_colors) set_color(*triangles.add_colors(), color);
      }
      triangles.mutable_points()->Reserve(static_cast<int>(entity.triangles->vertices.size()));
      for (const Vec3& vertex : entity.triangles->vertices) set_point(*triangles.add_points(), vertex);
      triangles.mutable_indices()->Reserve(static_cast<int>(3 * entity.triangles->triangles.size()));
      for (const auto& triangle : entity.triangles->triangles)
        for (const Index vertex : triangle) triangles.add_indices(vertex);
    }
    for (const auto& strip : entity.line_strips) {
      if (strip.size() < 2) continue;
      auto& line = *out.add_lines();
      line.set_type(foxglove::LinePrimitive::LINE_STRIP);
      set_identity(*line.mutable_pose());
      line.set_thickness(entity.line_thickness);
      line.set_scale_invariant(false);
      set_color(*line.mutable_color(), entity.color);
      for (const Vec3& point : strip) set_point(*line.add_points(), point);
    }
  }
  return serialized(update);
}

std::string encode_frame_transforms(double time, std::span<const FrameTransform> transforms) {
  foxglove::FrameTransforms message;
  for (const auto& transform : transforms) {
    auto& out = *message.add_transforms();
    set_timestamp(*out.mutable_timestamp(), time);
    out.set_parent_frame_id(transform.parent);
    out.set_child_frame_id(transform.child);
    out.mutable_translation()->set_x(transform.pose.position.x());
    out.mutable_translation()->set_y(transform.pose.position.y());
    out.mutable_translation()->set_z(transform.pose.position.z());
    const Quat& q = transform.pose.orientation;
    out.mutable_rotation()->set_x(q.x());
    out.mutable_rotation()->set_y(q.y());
    out.mutable_rotation()->set_z(q.z());
    out.mutable_rotation()->set_w(q.w());
  }
  return serialized(message);
}

void encode_point_cloud(double time, std::string_view frame_id, std::span<const PointField> fields, std::uint32_t stride,
                        std::size_t point_count, const std::function<void(char* bytes)>& pack, std::string& out) {
  foxglove::PointCloud cloud;
  set_timestamp(*cloud.mutable_timestamp(), time);
  cloud.set_frame_id(std::string(frame_id));
  set_identity(*cloud.mutable_pose());
  cloud.set_point_stride(stride);
  for (const auto& field : fields) {
    auto& packed = *cloud.add_fields();
    packed.set_name(field.name);
    packed.set_offset(field.offset);
    packed.set_type(static_cast<foxglove::PackedElementField::NumericType>(field.type));
  }
  out.clear();
  if (!cloud.SerializeToString(&out)) throw Error("foxglove.PointCloud: cannot serialize");
  // The data field (6, length-delimited) appended to the serialized rest, so the points are packed
  // once, in place: protobuf reads fields in any order.
  const std::uint64_t bytes = static_cast<std::uint64_t>(point_count) * stride;
  out.push_back(static_cast<char>((6 << 3) | 2));
  for (std::uint64_t value = bytes;; value >>= 7) {
    if (value < 0x80) {
      out.push_back(static_cast<char>(value));
      break;
    }
    out.push_back(static_cast<char>((value & 0x7F) | 0x80));
  }
  const std::size_t start = out.size();
  out.resize(start + bytes);
  pack(out.data() + start);
}

std::string encode_raw_image(double time, std::string_view frame_id, std::uint32_t width, std::uint32_t height,
                             std::string_view encoding, std::uint32_t step, std::string_view data) {
  foxglove::RawImage image;
  set_timestamp(*image.mutable_timestamp(), time);
  image.set_frame_id(std::string(frame_id));
  image.set_width(width);
  image.set_height(height);
  image.set_encoding(std::string(encoding));
  image.set_step(step);
  image.set_data(std::string(data));
  return serialized(image);
}

std::string encode_camera_calibration(double time, std::string_view frame_id, std::uint32_t width, std::uint32_t height, double fx,
                                      double fy, double cx, double cy) {
  foxglove::CameraCalibration calibration;
  set_timestamp(*calibration.mutable_timestamp(), time);
  calibration.set_frame_id(std::string(frame_id));
  calibration.set_width(width);
  calibration.set_height(height);
  calibration.set_distortion_model("plumb_bob");
  for (int d = 0; d < 5; ++d) calibration.add_d(0);
  for (const double k : {fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0}) calibration.add_k(k);
  for (const double r : {1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0}) calibration.add_r(r);
  for (const double p : {fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0}) calibration.add_p(p);
  return serialized(calibration);
}

std::string encode_run_stats(const RunStats& stats) {
  m3dp::RunStats message;
  set_timestamp(*message.mutable_timestamp(), stats.time);
  message.set_time(stats.time);
  message.set_real_time_factor(stats.real_time_factor);
  message.set_particles(stats.particles);
  message.set_resting_particles(stats.resting_particles);
  message.set_density_error_mean(stats.density_error_mean);
  message.set_density_error_max(stats.density_error_max);
  message.set_time_step(stats.time_step);
  message.set_pressure_iterations(stats.pressure_iterations);
  message.set_step_ms(stats.step_ms);
  message.set_neighbor_ms(stats.neighbor_ms);
  message.set_pressure_ms(stats.pressure_ms);
  message.set_world_ms(stats.world_ms);
  for (const auto& nozzle : stats.nozzles) {
    auto& out = *message.add_nozzles();
    out.set_name(nozzle.name);
    out.set_extruding(nozzle.extruding);
    out.set_volume_rate(nozzle.volume_rate);
    out.set_x(nozzle.position.x());
    out.set_y(nozzle.position.y());
    out.set_z(nozzle.position.z());
    out.set_tracking_error(nozzle.tracking_error);
    out.set_volume_commanded(nozzle.volume_commanded);
    out.set_volume_laid(nozzle.volume_laid);
    out.set_volume_in_bore(nozzle.volume_in_bore);
    out.set_volume_lost(nozzle.volume_lost);
    out.set_volume_primed(nozzle.volume_primed);
  }
  message.set_step(stats.step);
  for (const double density : stats.material_density) message.add_material_density(density);
  message.set_particle_radius(stats.particle_radius);
  return serialized(message);
}

std::string encode_quality_stats(const QualityStats& stats) {
  m3dp::QualityStats message;
  set_timestamp(*message.mutable_timestamp(), stats.time);
  message.set_time(stats.time);
  message.set_vertices(stats.vertices);
  message.set_deviation_mean(stats.deviation_mean);
  message.set_deviation_p95(stats.deviation_p95);
  message.set_deviation_max(stats.deviation_max);
  message.set_deviation_range(stats.deviation_range);
  for (const double edge : stats.histogram_edges) message.add_histogram_edges(edge);
  for (const std::uint64_t count : stats.histogram_counts) message.add_histogram_counts(count);
  message.set_fill_designed(stats.fill_designed);
  message.set_fill_over(stats.fill_over);
  message.set_fill_under(stats.fill_under);
  for (const auto& layer : stats.layers) {
    auto& out = *message.add_layers();
    out.set_head(layer.head);
    out.set_layer(layer.layer);
    out.set_sections(layer.sections);
    out.set_empty(layer.empty);
    out.set_width(layer.width);
    out.set_design_width(layer.design_width);
    out.set_height(layer.height);
    out.set_design_height(layer.design_height);
    out.set_offset_across(layer.offset_across);
    out.set_offset_up(layer.offset_up);
  }
  return serialized(message);
}

std::string encode_joint_states(double time, std::string_view robot, std::span<const std::string> names,
                                std::span<const double> positions, std::span<const double> velocities,
                                std::span<const double> efforts) {
  m3dp::JointStates message;
  set_timestamp(*message.mutable_timestamp(), time);
  message.set_robot(std::string(robot));
  for (const auto& name : names) message.add_names(name);
  for (const double position : positions) message.add_positions(position);
  for (const double velocity : velocities) message.add_velocities(velocity);
  for (const double effort : efforts) message.add_efforts(effort);
  return serialized(message);
}

}  // namespace m3dp::record
