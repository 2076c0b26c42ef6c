// cameras/NAME/ for every camera of the scene, at its <update_rate> (images per simulated second):
//   rgb_NNNNNN.png           8-bit RGB (colour cameras)
//   depth_NNNNNN.npy         float32 metres along the optical axis, inf where nothing was hit (depth cameras)
//   depth_NNNNNN.png         16-bit millimetres, 0 where nothing was hit (ROS's 16UC1)
//   segmentation_NNNNNN.png  16-bit segment ids, named in legend.json
//   points_NNNNNN.ply        the point cloud: x y z, colour, segment (depth cameras whose <point_cloud> asks)
//   camera.json              intrinsics, clip, type, where it is mounted, the frame conventions
//   frames.csv               each frame's time and the optical frame's pose in the world
// The rendering is the simulation's camera rig (rendered once a step, shared with the recording).
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cmath>

#include "m3dp/io/atomic_file.hpp"
#include "m3dp/io/background_writer.hpp"
#include "m3dp/io/image_files.hpp"
#include "m3dp/sim/camera_rig.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {


nlohmann::json pose_json(const Pose& pose) {
  const Quat& q = pose.orientation;
  return {{"position_m", {pose.position.x(), pose.position.y(), pose.position.z()}}, {"orientation_wxyz", {q.w(), q.x(), q.y(), q.z()}}};
}

void write_point_cloud(const std::filesystem::path& file, const std::vector<sensors::CloudPoint>& points, bool world) {
  io::write_file_atomically(file, [&](std::ostream& stream) {
    stream << "ply\nformat binary_little_endian 1.0\ncomment m3dp camera point cloud, "
           << (world ? "world frame" : "optical frame (z forward, x right, y down)") << ", m\n"
           << "element vertex " << points.size() << "\n"
           << "property float x\nproperty float y\nproperty float z\n"
           << "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"
           << "property ushort segment\nproperty ushort padding\nend_header\n";
    stream.write(reinterpret_cast<const char*>(points.data()), static_cast<std::streamsize>(points.size() * sizeof(sensors::CloudPoint)));
  }, true);
}

class CameraFiles final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the camera pictures (cameras/)"; }
  explicit CameraFiles(std::filesystem::path folder) : folder_(std::move(folder)) {}
  // Every step: each camera has its own rate.
  [[nodiscard]] double period() const override { return 0; }

  void start(const Simulation& simulation) override {
    describe(simulation);
    observe_cameras(simulation);
  }

  void observe(const Simulation& simulation, const StepReport& /*report*/) override { observe_cameras(simulation); }

  // A checkpoint: every queued image on disk first; a resumed run lists the frames up to it again.
  void save(StateWriter& out) override {
    writer_.finish();
    for (const CameraOutput& output : cameras_) {
      out.put(output.due.next_time);
      out.put(static_cast<std::uint64_t>(output.frames));
      out.put(output.frames_csv);
    }
  }
  void resume(const Simulation& simulation, StateReader& in) override {
    describe(simulation);
    for (CameraOutput& output : cameras_) {
      in.get(output.due.next_time);
      output.frames = in.get<std::uint64_t>();
      in.get(output.frames_csv);
      io::write_text_atomically(output.folder / "frames.csv", output.frames_csv);
    }
  }

  void finish(const Simulation& simulation, RunSummary& summary) override {
    writer_.finish();  // every image on disk (or its error thrown) before the summary says so
    CameraRig& rig = simulation.cameras();
    for (std::size_t c = 0; c < cameras_.size(); ++c) {
      const CameraRig::Totals& totals = rig.totals(c);
      summary.cameras.push_back({rig.settings(c).name, cameras_[c].frames, totals.frames, totals.render_seconds, totals.rays});
    }
  }

 private:
  struct CameraOutput {
    std::filesystem::path folder;
    Periodic due;  // its next image
    std::size_t frames = 0;
    std::string frames_csv;
  };

  /// Each camera's folder with its camera.json and legend.json.
  void describe(const Simulation& simulation) {
    CameraRig& rig = simulation.cameras();
    nlohmann::json legend = nlohmann::json::array();
    for (const Segment& segment : rig.legend()) {
      nlohmann::json entry = {{"id", segment.id}, {"kind", segment.kind}, {"name", segment.name},
                              {"color_rgb", {segment.color.r, segment.color.g, segment.color.b}}};
      if (!segment.robot.empty()) entry["robot"] = segment.robot;
      if (segment.kind == "material") {
        entry["layer"] = segment.layer >= 0 ? nlohmann::json(segment.layer) : nlohmann::json();
        if (segment.layer >= 0) entry["layer_start_s"] = segment.layer_start;
      }
      legend.push_back(entry);
    }
    for (std::size_t c = 0; c < rig.size(); ++c) {
      const auto& settings = rig.settings(c);
      const auto folder = folder_ / settings.name;
      std::filesystem::create_directories(folder);
      const sensors::Intrinsics intrinsics = sensors::Intrinsics::of(settings);
      nlohmann::json camera = {
          {"name", settings.name},
          {"type", sensors::camera_type_name(settings.type)},
          {"width", settings.width},
          {"height", settings.height},
          {"horizontal_fov_rad", settings.horizontal_fov},
          {"vertical_fov_rad", intrinsics.vertical_fov()},
          {"fx", intrinsics.fx},
          {"fy", intrinsics.fy},
          {"cx", intrinsics.cx},
          {"cy", intrinsics.cy},
          {"near_m", settings.near},
          {"far_m", settings.far},
          {"update_rate_hz", settings.update_rate},
          {"noise", {{"type", settings.noise.enabled() ? "gaussian" : "none"}, {"mean", settings.noise.mean}, {"stddev", settings.noise.stddev}}},
          {"point_cloud", settings.point_cloud == sensors::CameraSettings::PointCloud::none      ? "none"
                          : settings.point_cloud == sensors::CameraSettings::PointCloud::optical ? "optical"
                                                                                                  : "world"},
          {"mounted_on", settings.robot.empty() ? nlohmann::json("world") : nlohmann::json(settings.robot + "/" + settings.link)},
          {"pose_in_mount", pose_json(settings.pose)},
          {"conventions",
           "camera frame: x forward, z up (SDF); images and point clouds: optical frame, z forward, x right, y down (REP 103); "
           "pixel (i, j) from the top left, its centre at (i + 0.5, j + 0.5); depth is along the optical axis"}};
      io::write_text_atomically(folder / "camera.json", camera.dump(2) + "\n");
      io::write_text_atomically(folder / "legend.json", legend.dump(2) + "\n");
      cameras_.push_back({folder, simulation.time(), 0, "frame,time_s,x_m,y_m,z_m,qw,qx,qy,qz\n"});
    }
  }

  void observe_cameras(const Simulation& simulation) {
    CameraRig& rig = simulation.cameras();
    const double time = simulation.time();
    for (std::size_t c = 0; c < cameras_.size(); ++c) {
      CameraOutput& output = cameras_[c];
      if (!output.due.take(time, 1 / rig.settings(c).update_rate)) continue;
      write_frame(simulation, rig, c, output);
    }
  }

  void write_frame(const Simulation& simulation, CameraRig& rig, std::size_t c, CameraOutput& output) {
    const auto& settings = rig.settings(c);
    // The images copied, encoded and written on the writer's thread.
    auto image = std::make_shared<const sensors::CameraImage>(rig.image(simulation, c));
    std::shared_ptr<const std::vector<sensors::CloudPoint>> points;
    if (!image->depth.empty() && settings.point_cloud != sensors::CameraSettings::PointCloud::none)
      points = std::make_shared<const std::vector<sensors::CloudPoint>>(rig.points(simulation, c));
    const std::string index = fmt::format("{:06}", output.frames);
    const Pose optical = sensors::optical_pose(rig.pose(simulation, c));
    const Quat& q = optical.orientation;
    output.frames_csv += fmt::format("{},{:.6f},{:.6f},{:.6f},{:.6f},{:.7f},{:.7f},{:.7f},{:.7f}\n", output.frames, simulation.time(),
                                     optical.position.x(), optical.position.y(), optical.position.z(), q.w(), q.x(), q.y(), q.z());
    ++output.frames;
    // frames.csv lists a frame once its files are written.
    writer_.submit([folder = output.folder, index, image, points, world = settings.point_cloud == sensors::CameraSettings::PointCloud::world,
                    frames_csv = output.frames_csv] {
      if (!image->rgb.empty()) io::write_png(folder / fmt::format("rgb_{}.png", index), image->width, image->height, 3, 8, image->rgb.data());
      io::write_png(folder / fmt::format("segmentation_{}.png", index), image->width, image->height, 1, 16, image->segment.data());
      if (!image->depth.empty()) write_depth(folder, index, *image);
      if (points) write_point_cloud(folder / fmt::format("points_{}.ply", index), *points, world);
      io::write_text_atomically(folder / "frames.csv", frames_csv);
    });
  }

  /// Depth as float32 metres (.npy) and 16-bit millimetres (PNG, 0 where nothing was hit).
  static void write_depth(const std::filesystem::path& folder, const std::string& index, const sensors::CameraImage& image) {
    io::write_npy(folder / fmt::format("depth_{}.npy", index), image.height, image.width, image.depth);
    std::vector<std::uint16_t> millimetres(image.depth.size());
    for (std::size_t p = 0; p < image.depth.size(); ++p)
      millimetres[p] = std::isfinite(image.depth[p]) ? static_cast<std::uint16_t>(std::clamp(std::lround(1000.0 * image.depth[p]), 1L, 65535L)) : 0;
    io::write_png(folder / fmt::format("depth_{}.png", index), image.width, image.height, 1, 16, millimetres.data());
  }

  std::filesystem::path folder_;
  std::vector<CameraOutput> cameras_;
  io::BackgroundWriter writer_{8};
};

}  // namespace

std::unique_ptr<RunObserver> make_camera_files(Simulation& simulation, const RunOptions& options) {
  if (options.output_directory.empty() || simulation.scene().cameras.empty()) return nullptr;
  return std::make_unique<CameraFiles>(options.output_directory / "cameras");
}

}  // namespace m3dp::sim::outputs
