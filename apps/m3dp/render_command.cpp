// m3dp render RUN_DIR: a picture of a saved run at a time with the cameras' renderer, robot
// included: from one of the scene's cameras (where it was then, from cameras/NAME/frames.csv, or
// where it is fixed) or from any eye point looking at a target. The run's state at that time is its
// particle frame (particles.pvd), its world frame (world.pvd: links, bodies, nozzles) and the
// newest printed mesh before it (summary.json's meshes).
#include "render_command.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <fstream>
#include <sstream>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"
#include "m3dp/io/image_files.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/io/particle_reader.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/camera_rig.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::app {

namespace fs = std::filesystem;

void add_render_options(CLI::App& command, RenderOptions& options) {
  command.add_option("run", options.run, "A run folder (what m3dp run wrote)")->required()->check(CLI::ExistingDirectory);
  command.add_option("-o,--output", options.output, "The picture (PNG)")->capture_default_str();
  command.add_option("--time", options.time, "Simulated time in s (default: the last frame); the frame at or before it");
  command.add_option("--camera", options.camera, "One of the scene's cameras, where it was at that time");
  command.add_option("--eye", options.eye, "A free camera at X Y Z (m) ... (default: a view framing the robots and the print)")
      ->expected(3);
  command.add_option("--target", options.target, "... looking at X Y Z (m) (default: the middle of the robots and the print)")
      ->expected(3);
  command.add_option("--width", options.width, "The free camera's image width")->check(CLI::Range(16, 8192))->capture_default_str();
  command.add_option("--height", options.height, "The free camera's image height")->check(CLI::Range(16, 8192))->capture_default_str();
  command.add_option("--fov", options.fov_degrees, "The free camera's horizontal field of view (degrees)")
      ->check(CLI::Range(1.0, 170.0))
      ->capture_default_str();
  command.add_option("--threads", options.threads, "Worker threads (default: all cores)")->check(CLI::NonNegativeNumber);
}

namespace {

nlohmann::json read_json(const fs::path& file) {
  std::ifstream stream(file);
  if (!stream) throw Error(fmt::format("{}: cannot read it (is this a run folder?)", file.string()));
  return nlohmann::json::parse(stream, nullptr, true);
}

/// The entry of a collection at or before `time` (the first one if all are later); the last without a time.
const io::CollectionEntry& entry_at(const std::vector<io::CollectionEntry>& entries, std::optional<double> time, const fs::path& file) {
  if (entries.empty()) throw Error(fmt::format("{}: no frames", file.string()));
  if (!time) return entries.back();
  const io::CollectionEntry* chosen = &entries.front();
  for (const auto& entry : entries)
    if (entry.time <= *time + 1e-9) chosen = &entry;
  return *chosen;
}

Pose pose_of_fields(const std::map<std::string, std::vector<double>>& fields) {
  Pose pose;
  const auto position = fields.find("position"), orientation = fields.find("orientation_wxyz");
  if (position != fields.end() && position->second.size() == 3)
    pose.position = Vec3(Real(position->second[0]), Real(position->second[1]), Real(position->second[2]));
  if (orientation != fields.end() && orientation->second.size() == 4)
    pose.orientation = Quat(Real(orientation->second[0]), Real(orientation->second[1]), Real(orientation->second[2]),
                            Real(orientation->second[3])).normalized();
  return pose;
}

/// The camera frame (x forward, z up) at `eye` looking at `target`, z as near the world's up as it can be.
Pose look_at(const Vec3& eye, const Vec3& target) {
  const Vec3 forward = (target - eye).normalized();
  Vec3 up = Vec3::UnitZ();
  if (std::abs(forward.dot(up)) > Real(0.999)) up = Vec3::UnitX();
  const Vec3 left = up.cross(forward).normalized();
  Mat3 rotation;
  rotation.col(0) = forward;
  rotation.col(1) = left;
  rotation.col(2) = forward.cross(left);
  return Pose{eye, Quat(rotation)};
}

/// The box around what a picture is of: the robots' links and free bodies where they are, the
/// nozzles, the particles and the printed mesh (not static shapes: a floor of many metres would make
/// the print a dot). Empty if there is none of these.
Aabb subject_box(const sim::WorldLayout& layout, std::span<const Pose> bodies, std::span<const Pose> nozzles,
                 std::span<const Vec3> particles, const TriangleMesh* printed) {
  Aabb box;
  for (std::size_t b = 0; b < layout.bodies.size(); ++b)
    if (layout.bodies[b].kind != sim::BodyKind::static_body)
      for (const Vec3& vertex : layout.bodies[b].triangles.vertices) box.extend(bodies[b].apply(vertex));
  for (const Pose& nozzle : nozzles) box.extend(nozzle.position);
  for (const Vec3& position : particles) box.extend(position);
  if (printed)
    for (const Vec3& vertex : printed->vertices) box.extend(vertex);
  return box;
}

/// Where a scene camera was at `time`: its frames.csv row at or before it (the optical frame's
/// pose, turned back to the camera frame); none if the run has no frames of it.
std::optional<Pose> recorded_camera_pose(const fs::path& run, const std::string& name, double time) {
  std::ifstream csv(run / "cameras" / name / "frames.csv");
  if (!csv) return std::nullopt;
  std::string line;
  std::getline(csv, line);
  std::optional<Pose> pose;
  while (std::getline(csv, line)) {
    std::replace(line.begin(), line.end(), ',', ' ');
    std::istringstream row(line);
    double frame, at, x, y, z, w, qx, qy, qz;
    if (!(row >> frame >> at >> x >> y >> z >> w >> qx >> qy >> qz)) continue;
    if (pose && at > time + 1e-9) break;
    const Pose optical{Vec3(Real(x), Real(y), Real(z)), Quat(Real(w), Real(qx), Real(qy), Real(qz)).normalized()};
    pose = optical * Pose{Vec3::Zero(), sensors::optical_to_camera().conjugate()};
  }
  return pose;
}

}  // namespace

int render_command(const RenderOptions& options) {
  ThreadLimit thread_limit(options.threads);
  const fs::path& run = options.run;
  const nlohmann::json summary = read_json(run / "summary.json");
  // The scene as run: its own file if it is still there (relative files resolve beside it), else the copy.
  fs::path scene_file = summary.value("scene", std::string());
  if (scene_file.empty() || !fs::exists(scene_file)) scene_file = run / "scene.sdf";
  const scene::Scene scene = scene::load_scene(scene_file);
  sim::Simulation simulation(scene);
  sim::CameraRig& rig = simulation.cameras();

  // The particles at the time asked, and everything else at that frame's time.
  const fs::path particles_pvd = run / "particles.pvd";
  io::ParticleFrame particles;
  double time = options.time.value_or(summary.value("simulated_time_s", 0.0));
  if (fs::exists(particles_pvd)) {
    const auto frames = io::read_pvd(particles_pvd);
    const auto& entry = entry_at(frames, options.time, particles_pvd);
    particles = io::read_particle_frame(entry.file);
    time = entry.time;
  }
  const auto& layout = rig.layout();
  std::vector<Pose> bodies;
  for (const auto& body : layout.bodies) bodies.push_back(body.fixed_pose);
  std::vector<Pose> nozzles(layout.nozzles.size());
  const fs::path world_pvd = run / "world.pvd";
  if (fs::exists(world_pvd)) {
    const auto frames = io::read_pvd(world_pvd);
    const auto& entry = entry_at(frames, time, world_pvd);
    for (const auto& block : io::read_vtm(entry.file)) {
      const auto body = std::find_if(layout.bodies.begin(), layout.bodies.end(), [&](const sim::BodyView& view) { return view.name == block.name; });
      if (body != layout.bodies.end() && body->link) bodies[std::size_t(body - layout.bodies.begin())] = pose_of_fields(io::read_field_data(block.file));
      for (std::size_t n = 0; n < layout.nozzles.size(); ++n)
        if (block.name == "nozzle/" + layout.nozzles[n].name) nozzles[n] = pose_of_fields(io::read_field_data(block.file));
    }
  }
  std::optional<TriangleMesh> printed;
  for (const auto& mesh : summary.value("meshes", nlohmann::json::array()))
    if (mesh.value("time_s", 1e300) <= time + 1e-9) printed = io::read_triangle_mesh(run / mesh.value("file", std::string()));
  rig.show({bodies, nozzles, particles.positions, particles.material, particles.layer, printed ? &*printed : nullptr});

  // The camera.
  sensors::CameraSettings settings;
  Pose camera_pose;
  std::string framed;  // how the view was chosen, when m3dp chose it
  if (!options.camera.empty()) {
    const auto found = std::find_if(scene.cameras.begin(), scene.cameras.end(),
                                    [&](const scene::CameraEntry& entry) { return entry.settings.name == options.camera; });
    if (found == scene.cameras.end()) {
      std::string names;
      for (const auto& entry : scene.cameras) names += (names.empty() ? "" : ", ") + entry.settings.name;
      throw Error(fmt::format("{}: the scene has no camera '{}'; its cameras: {}", scene_file.string(), options.camera,
                              names.empty() ? "none (use --eye and --target)" : names));
    }
    settings = found->settings;
    if (settings.type == sensors::CameraType::depth_camera) settings.type = sensors::CameraType::rgbd_camera;  // a picture of it
    if (const auto recorded = recorded_camera_pose(run, options.camera, time)) camera_pose = *recorded;
    else if (settings.robot.empty()) camera_pose = settings.pose;
    else throw Error(fmt::format("{}: camera '{}' rides on {}/{}, and the run has no cameras/{}/frames.csv to say where it was",
                                 run.string(), options.camera, settings.robot, settings.link, options.camera));
  } else {
    // Without --eye (or --target), a view of the robots and the print: from the front right and above
    // (as the viewer's), far enough back for their box to fill the picture's narrower angle.
    const Aabb box = subject_box(layout, bodies, nozzles, particles.positions, printed ? &*printed : nullptr);
    if ((options.eye.empty() || options.target.empty()) && box.empty())
      throw Error(fmt::format("{}: nothing to frame at {:.3f} s (no robot, free body, nozzle, particle or printed mesh); give --eye X Y Z "
                              "and --target X Y Z, or --camera NAME",
                              run.string(), time));
    const Vec3 middle = box.empty() ? Vec3::Zero() : Vec3((box.min + box.max) / 2);
    const Vec3 target = options.target.size() == 3 ? Vec3(Real(options.target[0]), Real(options.target[1]), Real(options.target[2])) : middle;
    Vec3 eye;
    if (options.eye.size() == 3) {
      eye = Vec3(Real(options.eye[0]), Real(options.eye[1]), Real(options.eye[2]));
    } else {
      const double radius = std::max(0.05, 0.5 * double((box.max - box.min).norm()));
      const double half_fov = options.fov_degrees * std::acos(-1.0) / 360;
      const double narrower = std::min(half_fov, std::atan(std::tan(half_fov) * options.height / options.width));
      eye = target + Vec3(Real(1), Real(-0.8), Real(0.6)).normalized() * Real(1.05 * radius / std::sin(narrower));
      framed = fmt::format("a view framing the robots and the print (--eye {:.3f} {:.3f} {:.3f} --target {:.3f} {:.3f} {:.3f})", eye.x(),
                           eye.y(), eye.z(), target.x(), target.y(), target.z());
    }
    if ((target - eye).norm() < Real(1e-6)) throw Error("m3dp render: --eye and --target are the same point");
    settings.name = "render";
    settings.type = sensors::CameraType::camera;
    settings.width = options.width;
    settings.height = options.height;
    settings.horizontal_fov = options.fov_degrees * std::acos(-1.0) / 180;
    settings.near = 0.005;
    settings.far = 1000;
    camera_pose = look_at(eye, target);
  }
  sensors::CameraImage image;
  rig.render(settings, camera_pose, 0, image);
  io::write_png(options.output, image.width, image.height, 3, 8, image.rgb.data());
  fmt::print("m3dp: {} at {:.3f} s ({} particles) from {} → {} ({}x{})\n", run.string(), time, particles.positions.size(),
             !options.camera.empty() ? "camera " + options.camera : !framed.empty() ? framed : std::string("the eye point"), options.output.string(), image.width, image.height);
  return 0;
}

}  // namespace m3dp::app
