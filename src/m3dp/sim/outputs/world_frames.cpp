// world/world_NNNNNN.vtm every <output><particles_period> of simulated time (and at the start),
// listed in world.pvd beside particles.pvd: a multiblock of every body (static shapes, free bodies,
// robot links) as triangles in the world at that time, each nozzle, each path as a polyline (the
// whole of it and the part printed so far). Static bodies and whole paths are written once, to
// world/static/, and every frame's .vtm refers to them.
#include <fmt/format.h>

#include "m3dp/io/vtk_writer.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/sim/world_view.hpp"

namespace m3dp::sim::outputs {

namespace {

/// A block's name as a file name: letters, digits, '-', '.' and '_' kept, the rest '_'.
std::string file_name(const std::string& name) {
  std::string file;
  for (const char c : name) file += (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.' || c == '_') ? c : '_';
  return file + ".vtp";
}

std::vector<io::FieldTuple> pose_fields(const Pose& pose) {
  const Quat& q = pose.orientation;
  return {{"position", {pose.position.x(), pose.position.y(), pose.position.z()}}, {"orientation_wxyz", {q.w(), q.x(), q.y(), q.z()}}};
}

class WorldFrames final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the world frames (world.pvd)"; }
  WorldFrames(const std::filesystem::path& output_directory, double period)
      : folder_(output_directory / "world"), collection_(output_directory / "world.pvd"), period_(period) {}
  [[nodiscard]] double period() const override { return period_; }

  void start(const Simulation& simulation) override {
    write_static(simulation);
    write(simulation);
  }
  void observe(const Simulation& simulation, const StepReport& /*report*/) override { write(simulation); }
  void finish(const Simulation& /*simulation*/, RunSummary& summary) override { summary.world_frames_written = collection_.size(); }
  void save(StateWriter& out) override { collection_.save(out); }
  void resume(const Simulation& simulation, StateReader& in) override {
    write_static(simulation);
    collection_.load(in);
  }

 private:
  /// The layout, and the files of what does not move (static bodies, the paths).
  void write_static(const Simulation& simulation) {
    layout_ = world_layout(simulation);
    std::filesystem::create_directories(folder_ / "static");
    for (const auto& body : layout_.bodies) {
      if (body.link) continue;
      const auto file = folder_ / "static" / file_name(body.name);
      write_surface(file, body.triangles, body.fixed_pose, pose_fields(body.fixed_pose));
      static_blocks_.push_back({body.name, file});
    }
    for (const auto& path : layout_.paths) {
      const std::string name = (path.base_path ? "base_path/" : "path/") + path.name;
      const auto file = folder_ / "static" / file_name(name);
      write_path(file, path);
      static_blocks_.push_back({name, file});
    }
  }

  void write(const Simulation& simulation) {
    const WorldPoses poses = world_poses(simulation, layout_);
    const auto frame_folder = folder_ / fmt::format("{:06}", collection_.size());
    std::filesystem::create_directories(frame_folder);
    std::vector<io::Block> blocks = static_blocks_;
    for (std::size_t b = 0; b < layout_.bodies.size(); ++b) {
      const auto& body = layout_.bodies[b];
      if (!body.link) continue;
      const auto file = frame_folder / file_name(body.name);
      write_surface(file, body.triangles, poses.bodies[b], pose_fields(poses.bodies[b]));
      blocks.push_back({body.name, file});
    }
    for (std::size_t n = 0; n < layout_.nozzles.size(); ++n) {
      const auto& nozzle = layout_.nozzles[n];
      const auto& state = poses.nozzles[n];
      auto fields = pose_fields(state.pose);
      fields.push_back({"extruding", {state.extruding ? 1.0 : 0.0}});
      fields.push_back({"volume_rate", {state.volume_rate}});  // m³/s
      const auto file = frame_folder / file_name("nozzle/" + nozzle.name);
      write_surface(file, nozzle.triangles, state.pose, fields);
      blocks.push_back({"nozzle/" + nozzle.name, file});
    }
    for (std::size_t p = 0; p < layout_.paths.size(); ++p) {
      const auto& path = layout_.paths[p];
      if (path.base_path) continue;
      const auto file = frame_folder / file_name("printed/" + path.name);
      write_lines(file, printed_runs(path, poses.path_times[p]));
      blocks.push_back({"printed/" + path.name, file});
    }
    const auto vtm = folder_ / fmt::format("world_{:06}.vtm", collection_.size());
    io::write_vtm(vtm, blocks);
    collection_.add(poses.time, vtm);
  }

  void write_surface(const std::filesystem::path& file, const TriangleMesh& triangles, const Pose& pose,
                     std::vector<io::FieldTuple> fields) {
    points_.clear();
    for (const Vec3& vertex : triangles.vertices) points_.push_back(pose.apply(vertex));
    io::PolyData poly_data;
    poly_data.points = points_;
    poly_data.triangles = triangles.triangles;
    poly_data.field_data = std::move(fields);
    io::write_vtp(file, poly_data);
  }

  /// The whole path: each vertex with the time the head passes it and whether the move from it extrudes.
  void write_path(const std::filesystem::path& file, const PathView& path) {
    points_.clear();
    std::vector<Real> times;
    std::vector<std::uint8_t> extruding;
    std::vector<Index> line_points, line_ends;
    for (std::size_t v = 0; v < path.vertices.size(); ++v) {
      points_.push_back(path.vertices[v].position);
      times.push_back(static_cast<Real>(path.vertices[v].time));
      extruding.push_back(path.vertices[v].extruding ? 1 : 0);
      line_points.push_back(static_cast<Index>(v));
    }
    if (line_points.size() >= 2) line_ends.push_back(static_cast<Index>(line_points.size()));
    else line_points.clear();
    io::PolyData poly_data;
    poly_data.points = points_;
    poly_data.line_points = line_points;
    poly_data.line_ends = line_ends;
    poly_data.point_arrays = {io::PointArray::of("time", times), io::PointArray::of("extruding", extruding)};
    io::write_vtp(file, poly_data);
  }

  void write_lines(const std::filesystem::path& file, const std::vector<std::vector<Vec3>>& lines) {
    points_.clear();
    std::vector<Index> line_points, line_ends;
    for (const auto& line : lines) {
      for (const Vec3& point : line) {
        line_points.push_back(static_cast<Index>(points_.size()));
        points_.push_back(point);
      }
      line_ends.push_back(static_cast<Index>(line_points.size()));
    }
    io::PolyData poly_data;
    poly_data.points = points_;
    poly_data.line_points = line_points;
    poly_data.line_ends = line_ends;
    io::write_vtp(file, poly_data);
  }

  std::filesystem::path folder_;
  io::PvdCollection collection_;
  double period_;
  WorldLayout layout_;
  std::vector<io::Block> static_blocks_;
  std::vector<Vec3> points_;
};

}  // namespace

std::unique_ptr<RunObserver> make_world_frames(Simulation& simulation, const RunOptions& options) {
  const double period = frame_period(simulation, options);
  if (options.output_directory.empty() || !(period > 0)) return nullptr;
  return std::make_unique<WorldFrames>(options.output_directory, period);
}

}  // namespace m3dp::sim::outputs
