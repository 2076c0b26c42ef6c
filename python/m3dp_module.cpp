// The Python API (import m3dp): a simulation stepped from the user's code, its state as numpy
// arrays, robots and print heads commanded between steps, and the run folder's outputs on request.
// Arrays of the state (particles, camera images) are read-only snapshots of the step they were read
// in, copied once a step; a kept one never changes under its holder.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/camera_rig.hpp"
#include "m3dp/sim/print_quality.hpp"
#include "m3dp/sim/run.hpp"
#include "m3dp/sim/session.hpp"
#include "m3dp/sim/simulation.hpp"

namespace py = pybind11;
namespace fs = std::filesystem;

namespace m3dp::python {

namespace {

/// A pose as numpy's [x, y, z, qx, qy, qz, qw] (m; a unit quaternion, ROS order).
py::array_t<double> pose_array(const Pose& pose) {
  py::array_t<double> out(7);
  auto values = out.mutable_unchecked<1>();
  for (int k = 0; k < 3; ++k) values(k) = pose.position[k];
  values(3) = pose.orientation.x();
  values(4) = pose.orientation.y();
  values(5) = pose.orientation.z();
  values(6) = pose.orientation.w();
  return out;
}

py::array_t<double> vector_array(const std::vector<double>& values) { return py::array_t<double>(values.size(), values.data()); }

Vec3 vec3_from(const std::vector<double>& values, const char* what) {
  if (values.size() != 3) throw Error(fmt::format("{}: expected 3 numbers, got {}", what, values.size()));
  return Vec3(Real(values[0]), Real(values[1]), Real(values[2]));
}

/// A read-only numpy array of `count` rows of `columns` values of T copied from `data`.
template <class T>
py::array read_only_copy(const T* data, std::size_t count, std::size_t columns) {
  std::vector<py::ssize_t> shape{static_cast<py::ssize_t>(count)};
  if (columns > 1) shape.push_back(static_cast<py::ssize_t>(columns));
  py::array_t<T> array(shape);
  if (count > 0) std::memcpy(array.mutable_data(), data, count * columns * sizeof(T));
  array.attr("flags").attr("writeable") = false;
  return array;
}

}  // namespace

/// One simulation and its run (sim::Session) with its arrays as numpy: m3dp.Simulation.
class PySimulation {
 public:
  PySimulation(const scene::Scene& scene, int threads) : session_(scene, threads) {}

  sim::Session& session() { return session_; }
  sim::Simulation& simulation() { return session_.simulation(); }
  /// The simulation, for a command (`what`): refused once closed.
  sim::Simulation& open_simulation(const char* what) { return session_.command(what); }
  const std::vector<std::string>& robot_names() const { return session_.robot_names(); }

  void step() { session_.step(); }
  void step_to(double time) {
    if (!std::isfinite(time)) throw Error("step_to: the time must be a number (s)");
    (void)open_simulation("step_to");
    // Without the GIL for a tenth of a second of steps at a time: taking it back every step would
    // wait out Python's switch interval (5 ms) whenever another thread runs Python.
    while (simulation().time() < time - 1e-12) {
      {
        py::gil_scoped_release released;
        const auto batch_end = std::chrono::steady_clock::now() + std::chrono::milliseconds(100);
        do session_.step();
        while (simulation().time() < time - 1e-12 && std::chrono::steady_clock::now() < batch_end);
      }
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    }
  }
  void record(const fs::path& directory, bool mcap) { session_.record(directory, mcap); }
  /// The summary as summary.json holds it (one serialiser), as a dict; again on later calls.
  py::object close() { return py::module_::import("json").attr("loads")(session_.close()); }

  /// The camera's images now; its point cloud in `points_frame` ("optical", "world"; none: the
  /// scene's <point_cloud> setting).
  py::dict camera_images(const std::string& name, const std::optional<std::string>& points_frame) {
    auto& rig = simulation().cameras();
    const std::size_t camera = session_.camera(name);
    const sensors::CameraSettings& settings = rig.settings(camera);
    using Frame = sensors::CameraSettings::PointCloud;
    Frame frame = settings.point_cloud;
    if (points_frame) {
      if (*points_frame == "optical") frame = Frame::optical;
      else if (*points_frame == "world") frame = Frame::world;
      else throw Error(fmt::format("camera '{}': points='{}' (expected 'optical', 'world' or None)", name, *points_frame));
      if (!sensors::has_depth(settings.type))
        throw Error(fmt::format("camera '{}' is a {}: it has no depth to make points of", name, sensors::camera_type_name(settings.type)));
    }
    py::dict result;
    const sensors::CameraImage* rendered = nullptr;
    session_.in_arena([&] { rendered = &rig.image(simulation(), camera); });
    const sensors::CameraImage& image = *rendered;
    const auto rows = static_cast<py::ssize_t>(image.height), columns = static_cast<py::ssize_t>(image.width);
    auto image_view = [&](const char* what, const auto* data, py::ssize_t channels) {
      py::array array = snapshot(fmt::format("camera {} {}", name, what), data, std::size_t(rows * columns), std::size_t(channels));
      return channels > 1 ? array.reshape({rows, columns, channels}) : array.reshape({rows, columns});
    };
    if (!image.rgb.empty()) result["rgb"] = image_view("rgb", image.rgb.data(), 3);
    if (!image.depth.empty()) result["depth"] = image_view("depth", image.depth.data(), 1);
    if (!image.segment.empty()) result["segmentation"] = image_view("segmentation", image.segment.data(), 1);
    const Pose camera_pose = rig.pose(simulation(), camera);
    std::vector<sensors::CloudPoint> points;
    if (frame != Frame::none && !image.depth.empty())
      sensors::point_cloud(image, sensors::Intrinsics::of(settings), points, frame == Frame::world ? sensors::optical_pose(camera_pose) : Pose{});
    py::array_t<float> xyz({static_cast<py::ssize_t>(points.size()), py::ssize_t(3)});
    py::array_t<std::uint16_t> segments(static_cast<py::ssize_t>(points.size()));
    auto xyz_values = xyz.mutable_unchecked<2>();
    auto segment_values = segments.mutable_unchecked<1>();
    for (std::size_t i = 0; i < points.size(); ++i) {
      xyz_values(i, 0) = points[i].x;
      xyz_values(i, 1) = points[i].y;
      xyz_values(i, 2) = points[i].z;
      segment_values(i) = points[i].segment;
    }
    result["points"] = xyz;
    result["point_segments"] = segments;
    result["points_frame"] = frame == Frame::world ? "world" : frame == Frame::optical ? "optical" : "none";
    result["pose"] = pose_array(camera_pose);
    result["optical_pose"] = pose_array(sensors::optical_pose(camera_pose));
    return result;
  }

  /// What a camera is: intrinsics, size, clip, rate, where it is mounted and its pose now in both frames.
  py::dict camera_info(const std::string& name) {
    auto& rig = simulation().cameras();
    const std::size_t camera = session_.camera(name);
    const sensors::CameraSettings& settings = rig.settings(camera);
    const sensors::Intrinsics intrinsics = sensors::Intrinsics::of(settings);
    py::dict info;
    info["type"] = std::string(sensors::camera_type_name(settings.type));
    info["width"] = settings.width;
    info["height"] = settings.height;
    py::array_t<double> k({py::ssize_t(3), py::ssize_t(3)});
    auto values = k.mutable_unchecked<2>();
    const double matrix[3][3] = {{intrinsics.fx, 0, intrinsics.cx}, {0, intrinsics.fy, intrinsics.cy}, {0, 0, 1}};
    for (int row = 0; row < 3; ++row)
      for (int column = 0; column < 3; ++column) values(row, column) = matrix[row][column];
    info["K"] = k;
    info["horizontal_fov"] = settings.horizontal_fov;
    info["vertical_fov"] = intrinsics.vertical_fov();
    info["near"] = settings.near;
    info["far"] = settings.far;
    info["update_rate"] = settings.update_rate;
    info["depth_noise_stddev"] = settings.noise.stddev;
    info["robot"] = settings.robot;
    info["link"] = settings.link;
    const Pose camera_pose = rig.pose(simulation(), camera);
    info["pose"] = pose_array(camera_pose);
    info["optical_pose"] = pose_array(sensors::optical_pose(camera_pose));
    return info;
  }

  py::dict camera_legend() {
    py::dict legend;
    for (const sim::Segment& segment : simulation().cameras().legend()) {
      py::dict entry;
      entry["kind"] = segment.kind;
      entry["name"] = segment.name;
      if (!segment.robot.empty()) entry["robot"] = segment.robot;
      if (segment.layer >= 0) entry["layer"] = segment.layer;
      legend[py::int_(segment.id)] = entry;
    }
    return legend;
  }

  /// The array `key` of this step: copied from the state at its first read in a step, the same
  /// object for later reads in the step. A copy, not a view: the state's arrays are reordered and
  /// grown by the next step, and an array kept across it must not silently show other particles.
  template <class T>
  py::array snapshot(const std::string& key, const T* data, std::size_t count, std::size_t columns) {
    const std::int64_t step = simulation().solver().state().step;
    if (step != snapshot_step_) {
      snapshots_.clear();
      snapshot_step_ = step;
    }
    auto found = snapshots_.find(key);
    if (found == snapshots_.end()) found = snapshots_.emplace(key, read_only_copy(data, count, columns)).first;
    return found->second;
  }

  template <class Call>
  auto in_arena(Call&& call) {
    return session_.in_arena(std::forward<Call>(call));
  }

 private:
  sim::Session session_;
  std::int64_t snapshot_step_ = -1;             // the step the snapshots are of
  std::map<std::string, py::array> snapshots_;  // arrays read in this step, by what they are
};

namespace {

std::size_t robot_index(PySimulation& self, const std::string& name) { return self.session().robot(name); }
std::size_t head_index(PySimulation& self, const std::string& name) { return self.session().head(name); }
std::size_t robot_head(PySimulation& self, std::size_t robot, const std::optional<std::string>& head_name) {
  return self.session().robot_head(robot, head_name);
}

/// A target for a print head (Simulation::command_head_target) from Python's arguments.
void command_target(PySimulation& self, std::size_t head, const std::vector<double>& position, const std::vector<double>& axis,
                    std::optional<double> max_speed, std::optional<double> max_acceleration, const char* what) {
  world::ToolTarget target;
  target.position = vec3_from(position, fmt::format("{} position", what).c_str());
  target.axis = vec3_from(axis, fmt::format("{} axis", what).c_str());
  world::MotionLimits limits;
  if (max_speed) limits.max_speed = *max_speed;
  if (max_acceleration) limits.max_acceleration = *max_acceleration;
  self.session().set_head_target(head, target, limits);
}

/// A <path> element given at run time; `name` (default: path.xml beside the scene) names it in
/// errors, and its files are relative to it.
scene::PathSegments read_path(PySimulation& self, const std::string& path, const std::optional<fs::path>& name) {
  return scene::load_path_from_string(path, name ? *name : self.simulation().scene().file.parent_path() / "path.xml");
}

/// Scene overrides from Python's {path: value} (in order): numbers as Python writes them (the
/// shortest text that reads back the same), booleans as true/false, text as it is.
std::vector<scene::SceneOverride> overrides_from(const std::optional<py::dict>& values) {
  std::vector<scene::SceneOverride> overrides;
  if (!values) return overrides;
  for (const auto& [path, value] : *values) {
    std::string text;
    if (py::isinstance<py::bool_>(value)) text = value.cast<bool>() ? "true" : "false";
    else if (py::isinstance<py::int_>(value) || py::isinstance<py::float_>(value) || py::isinstance<py::str>(value)) text = py::str(value);
    else throw Error(fmt::format("overrides['{}']: expected a number, a bool or text, got {}", py::str(path).cast<std::string>(),
                                 py::str(py::type::of(value).attr("__name__")).cast<std::string>()));
    overrides.push_back({py::str(path).cast<std::string>(), text});
  }
  return overrides;
}

/// m3dp.SceneWarning: what the scene reader warned of (an element ignored, a G-code command skipped).
PyObject* scene_warning = nullptr;

/// A simulation of `scene`, its warnings first given to Python's warnings module (file:line: what),
/// where `warnings.simplefilter("error")` turns them into exceptions.
std::unique_ptr<PySimulation> simulation_of(const scene::Scene& scene, int threads) {
  for (const auto& warning : scene.warnings) {
    const std::string text = fmt::format("{}: {}", warning.location.str(), warning.message);
    if (PyErr_WarnEx(scene_warning, text.c_str(), 1) != 0) throw py::error_already_set();
  }
  return std::make_unique<PySimulation>(scene, threads);
}

void translate_errors(py::module_& module) {
  scene_warning = PyErr_NewExceptionWithDoc("m3dp.SceneWarning", "A warning from the scene reader (file:line: what).",
                                            PyExc_UserWarning, nullptr);
  module.add_object("SceneWarning", py::handle(scene_warning));
  static py::exception<Error> error(module, "Error", PyExc_RuntimeError);
  static py::exception<SimulationError> simulation_error(module, "SimulationError", error.ptr());
  static py::exception<InputError> input_error(module, "InputError", error.ptr());
  static py::exception<quality::UnmeasurableDesign> unmeasurable(module, "UnmeasurableDesign", error.ptr());
  py::register_exception_translator([](std::exception_ptr thrown) {
    try {
      if (thrown) std::rethrow_exception(thrown);
    } catch (const InputError& problem) {
      // file and line of the first problem, for code that wants them; the message has them all.
      py::object instance = py::reinterpret_borrow<py::object>(input_error.ptr())(problem.what());
      if (!problem.diagnostics().empty()) {
        instance.attr("file") = problem.diagnostics().front().location.file;
        instance.attr("line") = problem.diagnostics().front().location.line;
      }
      PyErr_SetObject(input_error.ptr(), instance.ptr());
    } catch (const SimulationError& problem) {
      simulation_error(problem.what());
    } catch (const quality::UnmeasurableDesign& problem) {
      unmeasurable(problem.what());
    } catch (const Error& problem) {
      error(problem.what());
    }
  });
}

}  // namespace

}  // namespace m3dp::python

PYBIND11_MODULE(m3dp, module) {
  using namespace m3dp;
  using m3dp::python::PySimulation;
  module.doc() = "M3DP: a simulator for robotic and mobile 3D printing (SPH material, DART robots, cameras).";
  python::translate_errors(module);

  module.def("resolve_scene", [](const fs::path& file, const std::optional<py::dict>& overrides) {
    std::string resolved = scene::read_scene_text(file, python::overrides_from(overrides));
    const scene::Scene loaded = scene::load_scene_from_string(resolved, file);
    py::dict result;
    result["text"] = std::move(resolved);
    std::vector<std::string> inputs;
    for (const auto& input : loaded.input_files) inputs.push_back(input.string());
    result["input_files"] = inputs;
    result["end_time"] = loaded.end_time;
    std::vector<std::string> heads;
    for (const auto& head : loaded.print_heads) heads.push_back(head.name);
    result["heads"] = heads;
    std::vector<std::string> noise_seeds;  // the paths of the plugin's noisy cameras' seeds, for a study's repeats
    for (const auto& camera : loaded.cameras)
      if (camera.in_plugin && camera.settings.noise.enabled()) noise_seeds.push_back(fmt::format("camera[{}].noise.seed", camera.settings.name));
    result["noise_seeds"] = noise_seeds;
    std::vector<std::string> warnings;
    for (const auto& warning : loaded.warnings) warnings.push_back(fmt::format("{}: {}", warning.location.str(), warning.message));
    result["warnings"] = warnings;
    return result;
  }, py::arg("scene"), py::arg("overrides") = py::none(),
     R"(Reads and checks a scene with values replaced by their path, without simulating it (InputError as
Simulation raises it). A path is element names joined by '.', a [key] picking an element by its
name="..." (or by index among its namesakes): material[mortar].rheology.yield_stress, print_head[head].
path.line.speed, solver.particle_radius; a first step the <world> has (model[floor], gravity) starts
at the world, any other at M3DP's plugin. An element not written is added where the path says.
Returns {text: the scene as read, input_files: the files it reads (URDF, G-code, waypoints, meshes),
end_time: s, heads: the print heads' names, noise_seeds: the paths of the seeds of the plugin's noisy
cameras, warnings: [file:line: what]}.)");

  py::class_<PySimulation>(module, "Simulation", R"(A scene's simulation, stepped by the caller.

Simulation(scene, threads=0, overrides=None): scene is an SDF world file (str or path); threads 0
uses every core; overrides replace scene values by their path, {"material[mortar].rheology.yield_stress":
300} (SI; see m3dp.resolve_scene), each checked as if written in the file.
Simulation.from_string(text, name="scene.sdf") reads the scene from a string (paths in it are
relative to the current folder). Errors in the scene raise m3dp.InputError with .file and .line.

Arrays of the state (particles, camera images) are read-only snapshots of the step they are read
in: copied at the first read in a step (later reads in the step return the same array), they never
change after; read them again after a step for the new state. Rows of the particle arrays read in
one step belong together (ids tells which particle a row is: the order changes between steps).)")
      .def(py::init([](const fs::path& file, int threads, const std::optional<py::dict>& overrides) {
             return python::simulation_of(scene::load_scene(file, python::overrides_from(overrides)), threads);
           }),
           py::arg("scene"), py::arg("threads") = 0, py::arg("overrides") = py::none())
      .def_static("from_string",
                  [](const std::string& text, const std::string& name, int threads) {
                    return python::simulation_of(scene::load_scene_from_string(text, name), threads);
                  },
                  py::arg("text"), py::arg("name") = "scene.sdf", py::arg("threads") = 0)
      .def("step", &PySimulation::step, py::call_guard<py::gil_scoped_release>(),
           "One step (adaptive time step): heads and robots move, the material flows, the world follows.")
      .def("step_to", &PySimulation::step_to, py::arg("time"),
           "Steps until the simulated time reaches `time` (s). Ctrl-C stops it between steps.")
      .def_property_readonly("time", [](PySimulation& self) { return self.simulation().time(); }, "Simulated time (s).")
      .def_property_readonly("steps", [](PySimulation& self) { return self.simulation().solver().state().step; })
      .def_property_readonly("end_time", [](PySimulation& self) { return self.simulation().scene().end_time; },
                             "The scene's end time (s); stepping past it is allowed.")
      .def_property_readonly("time_step", [](PySimulation& self) { return double(self.simulation().solver().state().time_step); },
                             "The last step's length (s).")
      .def("record", &PySimulation::record, py::arg("directory"), py::arg("mcap") = false,
           "Writes the run folder's outputs (frames, meshes, cameras, summary; run.mcap if mcap) from now on.")
      .def("close", &PySimulation::close, "Ends the run: outputs complete their files. Returns the summary as a dict.")
      .def("__enter__", [](py::object self) { return self; })
      .def("__exit__", [](PySimulation& self, py::args) { self.close(); })
      // ---- particles ----
      .def_property_readonly("particle_count", [](PySimulation& self) { return self.simulation().solver().state().fluid.position.size(); })
      .def_property_readonly("positions", [](PySimulation& self) {
        const auto& fluid = self.simulation().solver().state().fluid;
        return self.snapshot("positions", fluid.position.empty() ? nullptr : fluid.position.front().data(), fluid.position.size(), 3);
      }, "Particle positions (n, 3), m: a read-only snapshot of this step.")
      .def_property_readonly("velocities", [](PySimulation& self) {
        const auto& fluid = self.simulation().solver().state().fluid;
        return self.snapshot("velocities", fluid.velocity.empty() ? nullptr : fluid.velocity.front().data(), fluid.velocity.size(), 3);
      }, "Particle velocities (n, 3), m/s: a read-only snapshot of this step.")
      .def_property_readonly("density", [](PySimulation& self) {
        const auto* measured = self.in_arena([&] { return &self.simulation().measured_density(); });
        return self.snapshot("density", measured->density.data(), measured->density.size(), 1);
      }, "Each particle's density (n), kg/m³, measured where the particles are now (as the frames write it).")
      .def_property_readonly("material", [](PySimulation& self) {
        const auto& fluid = self.simulation().solver().state().fluid;
        return self.snapshot("material", fluid.phase.data(), fluid.phase.size(), 1);
      }, "Each particle's material (n): an index into material_names.")
      .def_property_readonly("ids", [](PySimulation& self) {
        const auto& fluid = self.simulation().solver().state().fluid;
        return self.snapshot("ids", fluid.id.data(), fluid.id.size(), 1);
      }, "Each particle's stable id (n): particles are reordered between steps; ids follow them.")
      .def_property_readonly("birth_time", [](PySimulation& self) {
        const auto& fluid = self.simulation().solver().state().fluid;
        return self.snapshot("birth_time", fluid.birth_time.data(), fluid.birth_time.size(), 1);
      }, "When each particle was emitted (n), s of simulated time.")
      .def_property_readonly("age", [](PySimulation& self) {
        const auto& state = self.simulation().solver().state();
        py::array_t<double> age(static_cast<py::ssize_t>(state.fluid.birth_time.size()));
        auto values = age.mutable_unchecked<1>();
        for (std::size_t i = 0; i < state.fluid.birth_time.size(); ++i) values(i) = state.time - double(state.fluid.birth_time[i]);
        return age;
      }, "Each particle's age (n), s: a copy.")
      .def_property_readonly("layer", [](PySimulation& self) {
        const auto& fluid = self.simulation().solver().state().fluid;
        return self.snapshot("layer", fluid.print_layer.data(), fluid.print_layer.size(), 1);
      }, "Each particle's print layer (n), 0 first: the layer its nozzle's path was on when it left (a path "
         "set at run time counts its own layers); -1: not printed by a path. A read-only snapshot of this step.")
      .def_property_readonly("particle_radius", [](PySimulation& self) { return double(self.simulation().solver().parameters().settings.particle_radius); },
                             "The particles' radius r (m); they sit 2r apart on a lattice.")
      .def_property_readonly("particle_volume", [](PySimulation& self) { return double(self.simulation().solver().model().particle_volume); },
                             "The volume one particle stands for at its rest density (m³): (2r)³.")
      .def_property_readonly("volume_m3", [](PySimulation& self) {
        const auto balance = self.simulation().volume_balance();
        py::dict result;
        result["commanded"] = balance.commanded;
        result["emitted"] = balance.emitted;
        result["primed"] = balance.primed;
        result["in_bores"] = balance.in_bores;
        result["laid"] = balance.laid;
        result["lost_at_nozzles"] = balance.lost_at_nozzles;
        result["removed"] = balance.removed;
        result["in_particles"] = balance.in_particles;
        return result;
      }, "Where the printed volume went so far (m³), as summary.json's volume_m3: commanded (asked of the nozzles), "
         "emitted (the bores' priming included), primed (what filled the bores before their first layer), in_bores "
         "(in the bores now), laid (left the exits: emitted - in_bores), lost_at_nozzles (asked while blocked, never "
         "emitted), removed (left the bounds), in_particles (now). commanded = laid + lost_at_nozzles + in_bores - "
         "primed, within a disc of particles a nozzle.")
      .def_property_readonly("printed_mesh", [](PySimulation& self) -> py::object {
        const auto& mesh = self.simulation().printed_mesh();
        if (!mesh) return py::none();
        py::dict result;
        py::array_t<float> vertices({static_cast<py::ssize_t>(mesh->vertices.size()), py::ssize_t(3)});
        auto vertex_values = vertices.mutable_unchecked<2>();
        for (std::size_t i = 0; i < mesh->vertices.size(); ++i)
          for (int k = 0; k < 3; ++k) vertex_values(i, k) = float(mesh->vertices[i][k]);
        py::array_t<std::uint32_t> triangles({static_cast<py::ssize_t>(mesh->triangles.size()), py::ssize_t(3)});
        auto triangle_values = triangles.mutable_unchecked<2>();
        for (std::size_t i = 0; i < mesh->triangles.size(); ++i)
          for (int k = 0; k < 3; ++k) triangle_values(i, k) = std::uint32_t(mesh->triangles[i][k]);
        result["vertices"] = vertices;
        result["triangles"] = triangles;
        result["meshes_made"] = self.simulation().printed_mesh_version();
        return result;
      }, "The printed material's surface as the rigid world holds it (the collision body robots meet): vertices "
         "(n, 3) m and triangles (m, 3), copies, and how many meshes have joined the world so far; None before the first "
         "or when the scene has no <meshing>. Made at the meshing period whether or not the run is recorded.")
      .def("quality", [](PySimulation& self, double spacing) {
        if (!(spacing > 0)) throw Error(fmt::format("quality: spacing = {} m (expected > 0)", spacing));
        const quality::Report report = self.in_arena([&] { return sim::print_quality(self.simulation(), spacing); });
        py::dict result = py::module_::import("json").attr("loads")(quality::report_json(report));
        py::list heads = result["heads"];
        for (std::size_t h = 0; h < report.heads.size(); ++h) {
          const auto& sections = report.heads[h].sections;
          const auto count = static_cast<py::ssize_t>(sections.size());
          py::array_t<std::int32_t> layer(count);
          py::array_t<double> at({count, py::ssize_t(3)}), width(count), height(count), extent(count), area(count), across(count), up(count);
          py::array_t<std::int64_t> particles(count);
          for (py::ssize_t i = 0; i < count; ++i) {
            const auto& section = sections[std::size_t(i)];
            layer.mutable_at(i) = section.layer;
            for (py::ssize_t k = 0; k < 3; ++k) at.mutable_at(i, k) = section.at[k];
            width.mutable_at(i) = section.width;
            height.mutable_at(i) = section.height;
            extent.mutable_at(i) = section.extent;
            area.mutable_at(i) = section.area;
            across.mutable_at(i) = section.offset_across;
            up.mutable_at(i) = section.offset_up;
            particles.mutable_at(i) = std::int64_t(section.particles);
          }
          py::dict arrays;
          arrays["layer"] = layer;
          arrays["at_m"] = at;
          arrays["width_m"] = width;
          arrays["height_m"] = height;
          arrays["extent_m"] = extent;
          arrays["area_m2"] = area;
          arrays["offset_across_m"] = across;
          arrays["offset_up_m"] = up;
          arrays["particles"] = particles;
          heads[h].attr("__setitem__")("section_arrays", arrays);
        }
        return result;
      }, py::arg("spacing") = 0.01,
         "The print now against each head's path as it is (paths given at run time included): quality.json's figures "
         "(per head and layer: designed and measured width, height, area, offsets; the fill's designed, printed, over "
         "and under volumes, m³; a layer's height is its rise over the layers under it, its extent its particles' bottom "
         "to top; the design is what each head had laid by now), and per head section_arrays, numpy arrays of every section "
         "every `spacing` m along the beads (layer, at_m, width_m, height_m, extent_m, area_m2, offset_across_m, offset_up_m, "
         "particles: 0 where nothing is).")
      .def_property_readonly("head_names", [](PySimulation& self) {
        std::vector<std::string> names;
        for (const auto& head : self.simulation().scene().print_heads) names.push_back(head.name);
        return names;
      }, "The scene's print heads, by name, in scene order.")
      .def_property_readonly("material_names", [](PySimulation& self) {
        std::vector<std::string> names;
        for (const auto& entry : self.simulation().scene().materials) names.push_back(entry.material.name);
        return names;
      })
      // ---- moving bodies as the material sees them ----
      .def_property_readonly("bodies", [](PySimulation& self) {
        py::dict bodies;
        for (const auto& body : self.simulation().solver().state().bodies) {
          if (body.is_static) continue;
          py::dict entry;
          entry["pose"] = python::pose_array(body.pose);
          entry["force"] = python::vector_array({body.fluid_force.x(), body.fluid_force.y(), body.fluid_force.z()});
          entry["torque"] = python::vector_array({body.fluid_torque.x(), body.fluid_torque.y(), body.fluid_torque.z()});
          bodies[py::str(body.name)] = entry;
        }
        return bodies;
      }, "Every moving body (free bodies, robot links, nozzle barrels) by name: pose [x y z qx qy qz qw], "
         "and the material's force (N) and torque (N·m, about its origin) on it over the last step.")
      // ---- robots ----
      .def_property_readonly("robots", &PySimulation::robot_names)
      .def("joint_names", [](PySimulation& self, const std::string& robot) {
        return self.simulation().world().joint_names(self.simulation().robots()[python::robot_index(self, robot)]);
      }, py::arg("robot"))
      .def("joint_positions", [](PySimulation& self, const std::string& robot) {
        return python::vector_array(self.simulation().world().joint_positions(self.simulation().robots()[python::robot_index(self, robot)]));
      }, py::arg("robot"), "rad (or m), in joint_names order.")
      .def("joint_velocities", [](PySimulation& self, const std::string& robot) {
        return python::vector_array(self.simulation().world().joint_velocities(self.simulation().robots()[python::robot_index(self, robot)]));
      }, py::arg("robot"), "rad/s (or m/s).")
      .def("joint_efforts", [](PySimulation& self, const std::string& robot) {
        return python::vector_array(self.simulation().world().joint_efforts(self.simulation().robots()[python::robot_index(self, robot)]));
      }, py::arg("robot"), "N·m (or N) the joints' motors exerted over the last world step.")
      .def("link_poses", [](PySimulation& self, const std::string& robot) {
        const world::World& world = self.simulation().world();
        const auto index = self.simulation().robots()[python::robot_index(self, robot)];
        py::dict poses;
        for (const auto& link : world.link_names(index))
          if (const auto pose = world.robot_link_pose(index, link)) poses[py::str(link)] = python::pose_array(*pose);
        return poses;
      }, py::arg("robot"), "Each link's pose in the world, [x y z qx qy qz qw].")
      .def("base_pose", [](PySimulation& self, const std::string& robot) {
        return python::pose_array(self.simulation().world().base_pose(self.simulation().robots()[python::robot_index(self, robot)]));
      }, py::arg("robot"))
      .def("set_external_control", [](PySimulation& self, const std::string& name, bool external) {
        self.session().set_external_control(name, external);
      }, py::arg("robot"), py::arg("external") = true,
         "True: the robot (or a print head on an ideal gantry) leaves its scene paths and holds still until commanded, "
         "not extruding unless set_extrusion says so; False: back to its scene paths (where they are at the present time), "
         "travelling there without extruding. The commands below switch it to external control themselves.")
      .def("set_coordination", [](PySimulation& self, bool on) { self.open_simulation("set_coordination").set_coordination(on); }, py::arg("on") = true,
         "Switches the multi-robot coordinator on (with the scene's <coordinator> settings, or the defaults) or off "
         "(every robot follows its paths at full speed from where they are).")
      .def_property_readonly("coordination", [](PySimulation& self) -> py::object {
        const auto* coordination = self.simulation().coordination();
        if (!coordination) return py::none();
        py::dict robots;
        for (std::size_t r = 0; r < self.robot_names().size(); ++r) {
          const auto& report = coordination->reports()[r];
          py::dict entry;
          entry["rate"] = report.rate;
          entry["waiting_time"] = report.waiting_time;
          entry["slowed_time"] = report.slowed_time;
          entry["decisions"] = report.decisions;
          entry["conflicts"] = report.conflicts;
          entry["blocked"] = report.blocked;
          entry["least_robot_distance"] = report.least_robot_distance;
          entry["least_print_distance"] = report.least_print_distance;
          robots[py::str(self.robot_names()[r])] = entry;
        }
        return robots;
      }, "Per robot, what the coordinator did so far: its path clock's rate now (1 full speed, 0 waiting), "
         "waiting_time and slowed_time (s), decisions, conflicts (decisions it yielded at), blocked, and the least "
         "distances (m) to another robot and to the print at its decisions. None when the coordinator is off.")
      .def("contacts", [](PySimulation& self, const std::string& robot) {
        const auto& contacts = self.simulation().world().robot_contacts(self.simulation().robots()[python::robot_index(self, robot)]);
        py::dict result;
        result["with_robots"] = contacts.with_robots;
        result["with_printed_material"] = contacts.with_printed_material;
        result["with_other"] = contacts.with_other;
        result["world_steps_in_contact"] = contacts.steps_in_contact;
        return result;
      }, py::arg("robot"), "Contact points the robot's links have had so far (summed over world steps), by what they touched.")
      .def("external_control", [](PySimulation& self, const std::string& robot) {
        return self.simulation().world().external_control(self.simulation().robots()[python::robot_index(self, robot)]);
      }, py::arg("robot"))
      .def("set_joint_targets", [](PySimulation& self, const std::string& robot, const std::vector<double>& targets) {
        self.open_simulation("set_joint_targets").world().command_joint_targets(self.simulation().robots()[python::robot_index(self, robot)], targets);
      }, py::arg("robot"), py::arg("targets"), "Joint position targets (rad or m, joint_names order), held until the next command.")
      .def("set_nozzle_target", [](PySimulation& self, const std::string& robot, const std::vector<double>& position,
                                   const std::vector<double>& axis, std::optional<std::string> head, std::optional<double> max_speed,
                                   std::optional<double> max_acceleration) {
        (void)self.open_simulation("set_nozzle_target");
        python::command_target(self, python::robot_head(self, python::robot_index(self, robot), head), position, axis, max_speed,
                               max_acceleration, "set_nozzle_target");
      }, py::arg("robot"), py::arg("position"), py::arg("axis") = std::vector<double>{0, 0, -1}, py::arg("head") = py::none(),
         py::arg("max_speed") = py::none(), py::arg("max_acceleration") = py::none(),
         "Where the robot's nozzle exit should go (m, world) and where it should point (the material leaves along it): "
         "along a straight line within max_speed (m/s, default 0.25) and max_acceleration (m/s², default 2.5), through "
         "the robot's inverse kinematics; held until the next command. A target out of reach raises m3dp.Error. The "
         "head extrudes only when set_extrusion says so.")
      .def("set_head_target", [](PySimulation& self, const std::string& head, const std::vector<double>& position,
                                 const std::vector<double>& axis, std::optional<double> max_speed, std::optional<double> max_acceleration) {
        (void)self.open_simulation("set_head_target");
        python::command_target(self, python::head_index(self, head), position, axis, max_speed, max_acceleration, "set_head_target");
      }, py::arg("head"), py::arg("position"), py::arg("axis") = std::vector<double>{0, 0, -1}, py::arg("max_speed") = py::none(),
         py::arg("max_acceleration") = py::none(),
         "set_nozzle_target by the print head's name: for a head on a robot, and for one on an ideal gantry (which goes "
         "there itself; a target outside the scene's bounds raises m3dp.Error). set_external_control(head, False) sends a "
         "gantry head back to its path.")
      .def("set_base_velocity", [](PySimulation& self, const std::string& robot, double speed, double turn_rate) {
        self.open_simulation("set_base_velocity").world().command_base_velocity(self.simulation().robots()[python::robot_index(self, robot)], speed, turn_rate);
      }, py::arg("robot"), py::arg("speed"), py::arg("turn_rate"), "A mobile base's forward speed (m/s) and turn rate (rad/s).")
      // ---- print heads ----
      .def_property_readonly("print_heads", [](PySimulation& self) {
        std::vector<std::string> names;
        for (const auto& head : self.simulation().scene().print_heads) names.push_back(head.name);
        return names;
      })
      .def("nozzle", [](PySimulation& self, const std::string& head) {
        const auto state = self.simulation().nozzle_state(python::head_index(self, head));
        py::dict result;
        result["pose"] = python::pose_array(state.pose);
        result["velocity"] = python::vector_array({state.velocity.x(), state.velocity.y(), state.velocity.z()});
        result["extruding"] = state.extruding;
        result["volume_rate"] = double(state.volume_rate);
        result["flow_scale"] = double(state.flow_scale);
        // A nozzle with a bore: the pump's push (N along the axis, this step) and that over the bore's section (Pa, smoothed).
        const auto& engine = self.simulation().solver().state().nozzles[python::head_index(self, head)];
        result["extrusion_force"] = double(engine.extrusion_force);
        result["extrusion_pressure"] = double(engine.extrusion_pressure);
        // Its share of the volume balance so far (m³), and whether the space before its exit is blocked now.
        result["volume_commanded_m3"] = engine.volume_commanded;
        result["volume_emitted_m3"] = double(engine.particles_emitted) * double(self.simulation().solver().model().particle_volume);
        result["volume_lost_m3"] = engine.volume_lost;
        result["volume_primed_m3"] = engine.volume_primed;
        result["volume_in_bore_m3"] = self.simulation().nozzle_volumes(python::head_index(self, head)).in_bores;
        result["blocked"] = engine.blocked_since >= 0;
        result["blocked_time_s"] = engine.blocked_time;
        // Who moves it (its path, external commands, or its way back to its path) and, under a
        // target, where it is asked to be now on its way and whether it has arrived.
        const std::size_t index = python::head_index(self, head);
        result["control"] = std::string(sim::Simulation::to_string(self.simulation().head_control(index)));
        if (const auto* target = self.simulation().head_target(index)) {
          const Eigen::Vector3d goal = target->target(), on_the_way = target->position();
          result["target"] = python::vector_array({goal.x(), goal.y(), goal.z()});
          result["target_now"] = python::vector_array({on_the_way.x(), on_the_way.y(), on_the_way.z()});
          result["arrived"] = target->arrived();
        }
        return result;
      }, py::arg("head"), "The nozzle exit's pose (material leaves along its −z), velocity (m/s), whether it extrudes, "
                          "its flow (m³/s), that flow over the nominal, for a nozzle with a bore the pump's "
                          "extrusion force (N) and pressure (Pa; 0 without a bore), the volume it was asked for, "
                          "emitted, lost, that primed its bore and in its bore now (m³), whether it is blocked now and for how long it was in all (s).")
      .def("set_extrusion", [](PySimulation& self, const std::string& head, std::optional<bool> extruding, std::optional<double> flow_scale) {
        sim::Simulation::HeadCommand command;
        command.extruding = extruding;
        if (flow_scale) command.flow_scale = Real(*flow_scale);
        self.open_simulation("set_extrusion").command_head(python::head_index(self, head), command);
      }, py::arg("head"), py::arg("extruding") = py::none(), py::arg("flow_scale") = py::none(),
         "Extrusion on or off and the flow as a fraction of the nominal; None: as the head's path says.")
      .def("set_path", [](PySimulation& self, const std::string& head, const std::string& path, bool append,
                          std::optional<fs::path> name) {
        (void)self.open_simulation("set_path");
        scene::PathSegments read = python::read_path(self, path, name);
        self.simulation().set_head_path(python::head_index(self, head), std::move(read.segments), read.start_time, append);
      }, py::arg("head"), py::arg("path"), py::arg("append") = false, py::arg("name") = py::none(),
         "A new path for the print head, as the scene's <path> element (lines, polylines, circles, helices, walls, "
         "<gcode file=…>, <waypoints file=…>): it replaces the path from now on (the head travels from where it is "
         "to its first point), or with append=True follows the path's end. Its start_time attribute is a delay from "
         "now. Files are relative to `name` (default: beside the scene file), which errors also name. The robot "
         "carrying the head goes back to following its path. world.pvd and run.mcap keep drawing the first path.")
      .def("set_base_path", [](PySimulation& self, const std::string& robot, const std::string& path, bool append,
                               std::optional<fs::path> name) {
        (void)self.open_simulation("set_base_path");
        scene::PathSegments read = python::read_path(self, path, name);
        self.simulation().set_base_path(python::robot_index(self, robot), std::move(read.segments), read.start_time, append);
      }, py::arg("robot"), py::arg("path"), py::arg("append") = false, py::arg("name") = py::none(),
         "A new path for a mobile base (a <path> element, z ignored), as set_path does for a print head; the base "
         "follows it with its tracking controller on odometry.")
      // ---- cameras ----
      .def_property_readonly("cameras", [](PySimulation& self) {
        std::vector<std::string> names;
        for (const auto& camera : self.simulation().scene().cameras) names.push_back(camera.settings.name);
        return names;
      })
      .def("camera", &PySimulation::camera_images, py::arg("name"), py::arg("points") = py::none(),
           "The camera's image now (rendered once a step): rgb (h, w, 3) uint8, depth (h, w) float32 m along the optical "
           "axis (inf: nothing), segmentation (h, w) uint16 (see camera_legend); points (m, 3) float32 and point_segments "
           "of the depth image, in points_frame: points='optical' or 'world' for any depth camera, None as the scene's "
           "<point_cloud> says (none: empty); pose (the SDF camera frame: x forward, z up) and optical_pose (x right, "
           "y down, z forward: the frame the images and K are in), [x y z qx qy qz qw] in the world. Images are "
           "read-only snapshots of this step.")
      .def("camera_info", &PySimulation::camera_info, py::arg("name"),
           "What the camera is: type, width, height, K (3×3 pinhole intrinsics, pixels, the optical frame), horizontal and "
           "vertical fov (rad), near and far clip (m), update_rate (images per simulated s), depth_noise_stddev (m), the "
           "robot and link it is on (empty: fixed in the world), and its pose now in the SDF camera frame (x forward, "
           "z up) and the optical frame (z forward, x right, y down).")
      .def("camera_legend", &PySimulation::camera_legend, "What each segmentation id is: kind, name, robot, layer.");
}
