// The run as messages in Foxglove's schemas, made once and sent two ways: run.mcap (scene
// <output><mcap>true</mcap> or `m3dp run --record`), written as the run goes, and the live stream
// (<output><serve>PORT</serve> or `m3dp run --serve`), a Foxglove WebSocket server.
// Topics: /scene (every body, link and nozzle as frame-locked triangles in its own frame, the
// commanded paths; later the nozzles' extrusion colour and the printed material's newest mesh),
// /tf (world → every link, body, nozzle and camera frame), /particles (the fluid with its fields),
// /printed (the part of each path printed so far), /joints (each robot's), /run (the run's numbers),
// with print heads /quality (the print against its design, m3dp.QualityStats) and /quality/deviation
// (the printed mesh coloured by its distance to the designed surface) at each new printed mesh and
// the final state's, and per camera /camera/NAME/image, depth, segmentation, points and calibration (optical frame).
// The file gets a frame every <output><particles_period> of simulated time and each camera's images
// at its rate; the live stream the same at most RunOptions::live_rate per wall second each, and
// only on the topics someone is subscribed to.
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>

#include "m3dp/record/foxglove_messages.hpp"
#include "m3dp/record/foxglove_server.hpp"
#include "m3dp/record/mcap_writer.hpp"
#include "m3dp/sim/camera_rig.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/particle_cloud.hpp"
#include "m3dp/sim/print_quality.hpp"
#include "m3dp/sim/printed_body.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/sim/world_view.hpp"

namespace m3dp::sim::outputs {

namespace {

using Clock = std::chrono::steady_clock;

std::uint64_t nanoseconds(double time) { return static_cast<std::uint64_t>(std::llround(std::max(0.0, time) * 1e9)); }

record::Color kind_color(BodyKind kind) {
  switch (kind) {
    case BodyKind::static_body: return {0.55, 0.55, 0.58, 1};
    case BodyKind::free_body: return {0.85, 0.55, 0.2, 1};
    case BodyKind::robot_link: return {0.35, 0.5, 0.75, 1};
  }
  return {};
}
constexpr record::Color kPathColor{0.6, 0.6, 0.6, 0.6}, kPrintedColor{0.9, 0.3, 0.1, 1}, kMaterialColor{0.72, 0.6, 0.48, 1};
constexpr record::Color kNozzleIdle{0.3, 0.3, 0.3, 1}, kNozzleExtruding{0.9, 0.3, 0.1, 1};

/// /quality/deviation's colours: blue at −range (inside the design: under-filled), white at 0, red at
/// +range (outside it: over-filled), linear in between and clamped beyond; its metadata says so.
constexpr record::Color kUnderColor{0.23, 0.3, 0.75, 1}, kOnDesignColor{0.95, 0.95, 0.95, 1}, kOverColor{0.75, 0.1, 0.1, 1};
record::Color deviation_color(double deviation, double range) {
  const double t = std::clamp(deviation / range, -1.0, 1.0);
  const record::Color& end = t < 0 ? kUnderColor : kOverColor;
  const double f = std::abs(t);
  return {kOnDesignColor.r + f * (end.r - kOnDesignColor.r), kOnDesignColor.g + f * (end.g - kOnDesignColor.g),
          kOnDesignColor.b + f * (end.b - kOnDesignColor.b), 1};
}
/// Sections this far apart along each bead for /quality, as m3dp quality's default.
constexpr double kQualitySpacing = 0.01;  // m

/// The run's topics, in channel order, then each camera's; how the live stream treats each.
enum Topic : std::size_t { scene, transforms, particles, printed, joints, run, run_topic_count };
struct TopicInfo {
  std::string topic;
  std::string schema;
  record::Delivery delivery;
};
std::vector<TopicInfo> run_topics() {
  return {{"/scene", "foxglove.SceneUpdate", record::Delivery::latched},
          {"/tf", "foxglove.FrameTransforms", record::Delivery::latest},
          {"/particles", "foxglove.PointCloud", record::Delivery::latest},
          {"/printed", "foxglove.SceneUpdate", record::Delivery::latest},
          {"/joints", "m3dp.JointStates", record::Delivery::queued},
          {"/run", "m3dp.RunStats", record::Delivery::queued}};
}
constexpr std::size_t kNoTopic = ~std::size_t(0);
/// A camera's topics (kNoTopic: its type has none): /camera/NAME/image, depth, segmentation, points, calibration.
struct CameraTopics {
  std::size_t image = kNoTopic, depth = kNoTopic, segmentation = kNoTopic, points = kNoTopic, calibration = kNoTopic;
};

std::vector<record::PointField> camera_point_fields() {
  using Type = record::PointField::Type;
  return {{"x", 0, Type::float32},     {"y", 4, Type::float32},      {"z", 8, Type::float32},       {"red", 12, Type::uint8},
          {"green", 13, Type::uint8},  {"blue", 14, Type::uint8},    {"alpha", 15, Type::uint8},    {"segment", 16, Type::uint16}};
}

/// Where a message goes: the recording, the live stream.
struct Sinks {
  bool file = false, live = false;
};

class RunMessages final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the recording and live stream (run.mcap)"; }
  RunMessages(const std::filesystem::path& mcap_file, std::optional<std::uint16_t> serve_port, double period, double live_rate,
              const std::vector<scene::CameraEntry>& cameras, bool print_heads, const RunOptions& options)
      : period_(period), live_interval_(live_rate > 0 ? 1 / live_rate : 0), topics_(run_topics()) {
    for (const auto& camera : cameras) {
      const auto& settings = camera.settings;
      const std::string prefix = "/camera/" + settings.name + "/";
      auto add = [&](const std::string& name, const std::string& schema) {
        topics_.push_back({prefix + name, schema, record::Delivery::latest});
        return topics_.size() - 1;
      };
      CameraTopics ids;
      if (sensors::has_color(settings.type)) ids.image = add("image", "foxglove.RawImage");
      if (sensors::has_depth(settings.type)) ids.depth = add("depth", "foxglove.RawImage");
      ids.segmentation = add("segmentation", "foxglove.RawImage");
      if (sensors::has_depth(settings.type) && settings.point_cloud != sensors::CameraSettings::PointCloud::none)
        ids.points = add("points", "foxglove.PointCloud");
      ids.calibration = add("calibration", "foxglove.CameraCalibration");
      camera_topics_.push_back(ids);
    }
    if (print_heads) {
      quality_topic_ = topics_.size();
      topics_.push_back({"/quality", "m3dp.QualityStats", record::Delivery::latched});
      deviation_topic_ = topics_.size();
      topics_.push_back({"/quality/deviation", "foxglove.SceneUpdate", record::Delivery::latched});
    }
    mcap_file_ = mcap_file;
    if (serve_port) {
      std::vector<record::ServerChannel> channels;
      for (const TopicInfo& topic : topics_)
        channels.push_back({topic.topic, topic.schema, record::schema_descriptor_set(topic.schema), topic.delivery});
      record::ServerOptions server_options;
      server_options.port = *serve_port;
      server_options.http = options.http;
      live_ = std::make_unique<record::FoxgloveServer>(std::move(channels), server_options);
      fmt::print("m3dp: live at ws://127.0.0.1:{} (Foxglove or Lichtblick: Open connection, Foxglove WebSocket){}\n", live_->port(),
                 options.http ? fmt::format("; the viewer at http://127.0.0.1:{}/", live_->port()) : std::string());
      std::fflush(stdout);
    }
  }
  // Every step: the frames have their period, each camera its rate.
  [[nodiscard]] double period() const override { return 0; }

  void start(const Simulation& simulation) override {
    const auto began = Clock::now();
    if (!mcap_file_.empty()) {
      mcap_.emplace(mcap_file_);
      std::map<std::string, std::uint16_t> schema_ids;
      for (const TopicInfo& topic : topics_) {
        auto found = schema_ids.find(topic.schema);
        if (found == schema_ids.end())
          found = schema_ids.emplace(topic.schema, mcap_->add_schema(topic.schema, "protobuf", record::schema_descriptor_set(topic.schema))).first;
        mcap_channels_.push_back(mcap_->add_channel(topic.topic, "protobuf", found->second));
      }
    }
    prepare(simulation);
    const Sinks sinks{mcap_.has_value(), live_ != nullptr};
    send_scene(simulation, sinks);
    next_frame_.start(simulation.time(), period_);
    write_frame(simulation, nullptr, sinks);
    for (std::size_t c = 0; c < camera_topics_.size(); ++c) {
      next_camera_.emplace_back().start(simulation.time(), 1 / simulation.cameras().settings(c).update_rate);
      write_camera(simulation, c, sinks);
    }
    encode_seconds_ += seconds_since(began);
  }

  // A checkpoint: the recording flushed and its bookkeeping; a resumed run cuts run.mcap back to it.
  void save(StateWriter& out) override {
    out.put(mcap_.has_value());
    if (mcap_) mcap_->save(out);
    out.put(mcap_channels_);
    out.put(next_frame_.next_time);
    out.put(next_camera_);
    out.put(nozzle_extruding_);
    out.put(static_cast<std::uint64_t>(mesh_version_));
    out.put(last_time_);
    out.put(encode_seconds_);
  }
  void resume(const Simulation& simulation, StateReader& in) override {
    if (in.get<bool>() != !mcap_file_.empty()) in.fail("a recording where the run had none, or none where it had one");
    if (!mcap_file_.empty()) mcap_.emplace(mcap_file_, in);
    in.get(mcap_channels_);
    prepare(simulation);
    in.get(next_frame_.next_time);
    in.get(next_camera_);
    in.get(nozzle_extruding_);
    if (next_camera_.size() != camera_topics_.size() || nozzle_extruding_.size() != layout_.nozzles.size())
      in.fail("another set of cameras or nozzles than the scene has");
    mesh_version_ = in.get<std::uint64_t>();
    in.get(last_time_);
    in.get(encode_seconds_);
    if (live_) send_scene(simulation, Sinks{false, true});  // the recording has it; the live stream keeps it for its clients
  }

 private:
  /// What the messages are made from: the scene's layout, and the clocks of the real-time factor.
  void prepare(const Simulation& simulation) {
    wall_start_ = Clock::now();
    time_start_ = simulation.time();
    layout_ = world_layout(simulation);
    nozzle_extruding_.assign(layout_.nozzles.size(), -1);
    last_camera_live_.assign(camera_topics_.size(), Clock::time_point{});
  }

  /// The scene: bodies in their frames (frame-locked, so /tf moves them), nozzles, whole paths.
  void send_scene(const Simulation& simulation, const Sinks& sinks) {
    std::vector<record::SceneEntity> entities;
    for (const auto& body : layout_.bodies) {
      record::SceneEntity entity{body.name, body.own_frame() ? body.name : "world", kind_color(body.kind), &body.triangles, {}, 0, {}, {}};
      entity.metadata = {{"kind", body_kind_name(body.kind)}};
      if (!body.robot.empty()) entity.metadata.emplace_back("robot", body.robot);
      entities.push_back(std::move(entity));
    }
    for (const auto& path : layout_.paths) {
      record::SceneEntity entity{(path.base_path ? "base_path/" : "path/") + path.name, "world", kPathColor, nullptr, {}, 0.002, {}, {}};
      std::vector<Vec3> strip;
      for (const auto& vertex : path.vertices) strip.push_back(vertex.position);
      entity.line_strips.push_back(std::move(strip));
      entities.push_back(std::move(entity));
    }
    send(sinks, Topic::scene, nanoseconds(simulation.time()), record::encode_scene_update(simulation.time(), entities), "scene");
  }

 public:
  void observe(const Simulation& simulation, const StepReport& report) override {
    const auto began = Clock::now();
    const double time = simulation.time();
    if (next_frame_.take(time, period_)) {
      const Sinks sinks{mcap_.has_value(), live_due(began, last_live_frame_)};
      if (sinks.file || sinks.live) write_frame(simulation, &report.stats, sinks);
    }
    for (std::size_t c = 0; c < camera_topics_.size(); ++c) {
      if (!next_camera_[c].take(time, 1 / simulation.cameras().settings(c).update_rate)) continue;
      const Sinks sinks{mcap_.has_value(), live_due(began, last_camera_live_[c])};
      if (sinks.file || sinks.live) write_camera(simulation, c, sinks);
    }
    encode_seconds_ += seconds_since(began);
  }

  void finish(const Simulation& simulation, RunSummary& summary) override {
    const auto began = Clock::now();
    if (last_time_ < simulation.time()) write_frame(simulation, nullptr, Sinks{mcap_.has_value(), live_ != nullptr});
    // The final state's mesh (made at the end, kept out of the world) closes the recording.
    if (const PrintedBody* body = simulation.printed_body())
      if (auto final_mesh = body->newest(); final_mesh && final_mesh != simulation.printed_mesh())
        send_printed_mesh(simulation, *final_mesh);
    if (mcap_) {
      mcap_->close();
      summary.recording = {mcap_file_.string(), mcap_->message_count(), mcap_->bytes_written(), mcap_->chunk_count(), 0};
    }
    if (live_) {
      live_->stop();
      const auto statistics = live_->statistics();
      summary.live = {live_->port(), statistics.clients, statistics.messages_sent, statistics.bytes_sent, statistics.messages_dropped};
    }
    encode_seconds_ += seconds_since(began);
    summary.recording.encode_seconds = encode_seconds_;
  }

 private:

  static double seconds_since(Clock::time_point began) { return std::chrono::duration<double>(Clock::now() - began).count(); }
  /// Whether the live stream may have another frame now (at most live_rate a wall second); marks it sent.
  bool live_due(Clock::time_point now, Clock::time_point& last) const {
    if (!live_ || now - last < std::chrono::duration<double>(live_interval_)) return false;
    last = now;
    return true;
  }

  /// Whether a message on `topic` would go anywhere (nobody subscribed: not made at all).
  bool wanted(const Sinks& sinks, std::size_t topic) const {
    return topic != kNoTopic && (sinks.file || (sinks.live && live_->subscribed(topic)));
  }

  void send(const Sinks& sinks, std::size_t topic, std::uint64_t stamp, std::string&& bytes, std::string_view key = {}) {
    if (sinks.file) mcap_->write(mcap_channels_[topic], stamp, bytes);
    // The scene is kept by the server for late clients even when nobody listens now.
    if (sinks.live && (live_->subscribed(topic) || topics_[topic].delivery == record::Delivery::latched))
      live_->publish(topic, stamp, std::make_shared<const std::string>(std::move(bytes)), key);
  }

  void write_frame(const Simulation& simulation, const sph::StepStats* stats, const Sinks& sinks) {
    const double time = simulation.time();
    const std::uint64_t stamp = nanoseconds(time);
    if (sinks.file) last_time_ = time;
    const WorldPoses poses = world_poses(simulation, layout_);
    if (sinks.live) live_->publish_time(stamp);

    if (wanted(sinks, Topic::transforms)) {
      // Frames: every link and free body in the world, each nozzle in what carries it.
      transforms_list_.clear();
      std::map<std::string, Pose> body_pose;
      for (std::size_t b = 0; b < layout_.bodies.size(); ++b) {
        if (!layout_.bodies[b].own_frame()) continue;
        transforms_list_.push_back({"world", layout_.bodies[b].name, poses.bodies[b]});
        body_pose[layout_.bodies[b].name] = poses.bodies[b];
      }
      for (std::size_t n = 0; n < layout_.nozzles.size(); ++n) {
        const auto& nozzle = layout_.nozzles[n];
        const Pose& pose = poses.nozzles[n].pose;
        if (nozzle.parent_frame == "world") {
          transforms_list_.push_back({"world", "nozzle/" + nozzle.name, pose});
        } else {
          const Pose& parent = body_pose.at(nozzle.parent_frame);
          const Quat to_parent = parent.orientation.conjugate();
          transforms_list_.push_back({nozzle.parent_frame, "nozzle/" + nozzle.name,
                                      Pose{to_parent * (pose.position - parent.position), (to_parent * pose.orientation).normalized()}});
        }
      }
      // Each camera's frame in the world (x forward, z up), and its optical frame (z forward) on it.
      for (std::size_t c = 0; c < camera_topics_.size(); ++c) {
        const std::string frame = "camera/" + simulation.cameras().settings(c).name;
        transforms_list_.push_back({"world", frame, simulation.cameras().pose(simulation, c)});
        transforms_list_.push_back({frame, frame + "/optical", Pose{Vec3::Zero(), sensors::optical_to_camera()}});
      }
      send(sinks, Topic::transforms, stamp, record::encode_frame_transforms(time, transforms_list_));
    }

    // A nozzle's entity again when it starts or stops extruding (its colour says which); the
    // printed material's newest mesh when there is a new one. Each kept under its id for late clients.
    for (std::size_t n = 0; n < layout_.nozzles.size(); ++n) {
      const int extruding = poses.nozzles[n].extruding ? 1 : 0;
      if (extruding == nozzle_extruding_[n]) continue;
      nozzle_extruding_[n] = extruding;
      const auto& nozzle = layout_.nozzles[n];
      const std::string id = "nozzle/" + nozzle.name;
      const record::SceneEntity entity{id, id, extruding ? kNozzleExtruding : kNozzleIdle, &nozzle.triangles, {}, 0,
                                       {{"extruding", extruding ? "true" : "false"}}, {}};
      send(Sinks{mcap_.has_value(), live_ != nullptr}, Topic::scene, stamp, record::encode_scene_update(time, {&entity, 1}), id);
    }
    if (simulation.printed_mesh() && simulation.printed_mesh_version() != mesh_version_) {
      mesh_version_ = simulation.printed_mesh_version();
      send_printed_mesh(simulation, *simulation.printed_mesh());
    }

    if (wanted(sinks, Topic::printed)) {
      std::vector<record::SceneEntity> printed;
      for (std::size_t p = 0; p < layout_.paths.size(); ++p)
        if (!layout_.paths[p].base_path)
          printed.push_back({"printed/" + layout_.paths[p].name, "world", kPrintedColor, nullptr, printed_runs(layout_.paths[p], poses.path_times[p]),
                             0.004, {}, {}});
      if (!printed.empty()) send(sinks, Topic::printed, stamp, record::encode_scene_update(time, printed));
    }

    if (wanted(sinks, Topic::particles)) {
      std::string cloud;
      encode_particle_cloud(simulation, cloud);
      send(sinks, Topic::particles, stamp, std::move(cloud));
    }

    if (wanted(sinks, Topic::joints))
      for (const auto robot : simulation.robots()) {
        const auto names = simulation.world().joint_names(robot);
        const auto& world = simulation.world();
        send(sinks, Topic::joints, stamp,
             record::encode_joint_states(time, world.robot_name(robot), names, world.joint_positions(robot), world.joint_velocities(robot),
                                         world.joint_efforts(robot)));
      }

    if (wanted(sinks, Topic::run)) send(sinks, Topic::run, stamp, record::encode_run_stats(run_stats(simulation, stats, poses)));
    // Each file frame ends a chunk, so a reader of a killed run sees every frame before it.
    if (sinks.file) mcap_->flush();
  }

  /// A new mesh of the printed material: as the scene's "printed_material", and measured against the
  /// design on /quality and /quality/deviation.
  void send_printed_mesh(const Simulation& simulation, const TriangleMesh& mesh) {
    const double time = simulation.time();
    const std::uint64_t stamp = nanoseconds(time);
    const Sinks all{mcap_.has_value(), live_ != nullptr};
    const record::SceneEntity entity{"printed_material", "world", kMaterialColor, &mesh, {}, 0, {{"kind", "printed_material"}}, {}};
    send(all, Topic::scene, stamp, record::encode_scene_update(time, {&entity, 1}), "printed_material");
    if (!wanted(all, quality_topic_) && !wanted(all, deviation_topic_)) return;
    const SurfaceQuality measured = surface_quality(simulation, mesh, kQualitySpacing);
    record::SceneEntity coloured{"printed_deviation", "world", kOnDesignColor, &mesh, {}, 0,
                                 {{"kind", "printed_deviation"},
                                  {"deviation_range_m", fmt::format("{}", measured.range)},
                                  {"colours", "the signed distance (m) to the designed surface: blue at -range (inside), white at 0, "
                                              "red at +range (outside), linear between, clamped beyond"}},
                                 {}};
    coloured.vertex_colors.reserve(measured.deviation.size());
    for (const float deviation : measured.deviation) coloured.vertex_colors.push_back(deviation_color(deviation, measured.range));
    send(all, deviation_topic_, stamp, record::encode_scene_update(time, {&coloured, 1}), "printed_deviation");
    send(all, quality_topic_, stamp, record::encode_quality_stats(quality_stats(measured, time, mesh.vertices.size())), "quality");
  }

  static record::QualityStats quality_stats(const SurfaceQuality& measured, double time, std::size_t vertices) {
    const quality::Report& report = measured.report;
    record::QualityStats stats;
    stats.time = time;
    stats.vertices = vertices;
    if (report.deviation) {
      stats.deviation_mean = report.deviation->mean;
      stats.deviation_p95 = report.deviation->p95;
      stats.deviation_max = report.deviation->max;
    }
    stats.deviation_range = measured.range;
    stats.histogram_edges = report.deviation_histogram.edges;
    stats.histogram_counts = report.deviation_histogram.counts;
    stats.fill_designed = report.fill.designed;
    stats.fill_over = report.fill.over;
    stats.fill_under = report.fill.under;
    for (const auto& head : report.heads)
      for (const auto& layer : head.layers)
        stats.layers.push_back({head.name, layer.layer, std::uint32_t(layer.stations), std::uint32_t(layer.empty), layer.width,
                                layer.design_width, layer.height, layer.design_height, layer.offset_across, layer.offset_up});
    return stats;
  }

  /// A camera's image, depth, segmentation, point cloud and calibration, in its optical frame.
  void write_camera(const Simulation& simulation, std::size_t c, const Sinks& sinks) {
    const CameraTopics& ids = camera_topics_[c];
    if (!wanted(sinks, ids.image) && !wanted(sinks, ids.depth) && !wanted(sinks, ids.segmentation) && !wanted(sinks, ids.points) &&
        !wanted(sinks, ids.calibration))
      return;
    CameraRig& rig = simulation.cameras();
    const sensors::CameraImage& image = rig.image(simulation, c);
    const double time = simulation.time();
    const std::uint64_t stamp = nanoseconds(time);
    const std::string frame = "camera/" + rig.settings(c).name + "/optical";
    const auto width = static_cast<std::uint32_t>(image.width), height = static_cast<std::uint32_t>(image.height);
    auto bytes_of = [](const auto& values) {
      return std::string_view(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(values[0]));
    };
    if (wanted(sinks, ids.image))
      send(sinks, ids.image, stamp, record::encode_raw_image(time, frame, width, height, "rgb8", 3 * width, bytes_of(image.rgb)));
    if (wanted(sinks, ids.depth))
      send(sinks, ids.depth, stamp, record::encode_raw_image(time, frame, width, height, "32FC1", 4 * width, bytes_of(image.depth)));
    if (wanted(sinks, ids.segmentation))
      send(sinks, ids.segmentation, stamp, record::encode_raw_image(time, frame, width, height, "16UC1", 2 * width, bytes_of(image.segment)));
    if (wanted(sinks, ids.points)) {
      const auto& points = rig.points(simulation, c);
      const bool world = rig.settings(c).point_cloud == sensors::CameraSettings::PointCloud::world;
      std::string cloud;
      record::encode_point_cloud(time, world ? "world" : frame, camera_fields_, sizeof(sensors::CloudPoint), points.size(),
                                 [&](char* out) { std::memcpy(out, points.data(), points.size() * sizeof(sensors::CloudPoint)); }, cloud);
      send(sinks, ids.points, stamp, std::move(cloud));
    }
    if (wanted(sinks, ids.calibration)) {
      const sensors::Intrinsics intrinsics = sensors::Intrinsics::of(rig.settings(c));
      send(sinks, ids.calibration, stamp,
           record::encode_camera_calibration(time, frame, width, height, intrinsics.fx, intrinsics.fy, intrinsics.cx, intrinsics.cy));
    }
    if (sinks.file) mcap_->flush();
  }

  record::RunStats run_stats(const Simulation& simulation, const sph::StepStats* stats, const WorldPoses& poses) const {
    record::RunStats run;
    run.time = simulation.time();
    const double wall = seconds_since(wall_start_);
    run.real_time_factor = wall > 0 ? (run.time - time_start_) / wall : 0;
    run.particles = simulation.solver().fluid().size();
    run.resting_particles = run.particles - simulation.solver().state().active_count;
    const auto& density = simulation.measured_density().statistics;
    run.density_error_mean = density.mean;
    run.density_error_max = density.max;
    if (stats) {
      run.time_step = stats->time_step;
      run.pressure_iterations = static_cast<std::uint32_t>(stats->density_iterations + stats->divergence_iterations);
      run.step_ms = stats->stage_ms.total();
      run.neighbor_ms = stats->stage_ms[sph::Stage::neighbors];
      run.pressure_ms = stats->stage_ms[sph::Stage::pressure] + stats->stage_ms[sph::Stage::divergence];
      run.world_ms = simulation.last_world_ms();
    }
    for (std::size_t n = 0; n < layout_.nozzles.size(); ++n) {
      const Vec3 wanted = simulation.head_path(n).sample(simulation.path_time(n)).position;
      const Simulation::VolumeBalance volumes = simulation.nozzle_volumes(n);
      run.nozzles.push_back({layout_.nozzles[n].name, poses.nozzles[n].extruding, poses.nozzles[n].volume_rate, poses.nozzles[n].pose.position,
                             double((poses.nozzles[n].pose.position - wanted).norm()), volumes.commanded, volumes.laid, volumes.in_bores,
                             volumes.lost_at_nozzles, volumes.primed});
    }
    run.step = static_cast<std::uint64_t>(simulation.solver().state().step);
    for (const auto& phase : simulation.solver().parameters().phases) run.material_density.push_back(phase.density);
    run.particle_radius = simulation.solver().parameters().settings.particle_radius;
    return run;
  }

  double period_, live_interval_;  // s simulated; s wall
  std::vector<TopicInfo> topics_;
  std::vector<CameraTopics> camera_topics_;  // per camera of the scene
  std::size_t quality_topic_ = kNoTopic, deviation_topic_ = kNoTopic;  // with print heads
  std::vector<record::PointField> camera_fields_ = camera_point_fields();
  Periodic next_frame_;
  std::vector<Periodic> next_camera_;
  std::vector<Clock::time_point> last_camera_live_;
  std::filesystem::path mcap_file_;
  std::optional<record::McapWriter> mcap_;
  std::vector<std::uint16_t> mcap_channels_;  // per topic
  std::unique_ptr<record::FoxgloveServer> live_;
  WorldLayout layout_;
  std::vector<int> nozzle_extruding_;  // -1 before the first frame
  std::size_t mesh_version_ = 0;
  std::vector<record::FrameTransform> transforms_list_;
  Clock::time_point wall_start_, last_live_frame_{};
  double time_start_ = 0, last_time_ = -1, encode_seconds_ = 0;
};

}  // namespace

std::unique_ptr<RunObserver> make_run_messages(Simulation& simulation, const RunOptions& options) {
  const auto& output = simulation.scene().output;
  const bool record = !options.output_directory.empty() && (options.record || output.mcap);
  const std::optional<std::uint16_t> serve_port = options.serve_port ? options.serve_port : output.serve_port;
  if (!record && !serve_port) return nullptr;
  if (record) std::filesystem::create_directories(options.output_directory);
  // Frames at the particle period; a scene without particle frames is recorded 20 times a second.
  const double frame_period = outputs::frame_period(simulation, options);
  return std::make_unique<RunMessages>(record ? options.output_directory / "run.mcap" : std::filesystem::path(), serve_port,
                                       frame_period > 0 ? frame_period : 0.05, options.live_rate,
                                       simulation.scene().cameras, !simulation.scene().print_heads.empty(), options);
}

}  // namespace m3dp::sim::outputs
