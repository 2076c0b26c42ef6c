#include "m3dp/sim/session.hpp"

#include <fmt/format.h>

#include <algorithm>

#include "m3dp/core/error.hpp"
#include "m3dp/sim/camera_rig.hpp"

namespace m3dp::sim {

namespace {
int checked_threads(int threads) {
  if (threads < 0) throw Error(fmt::format("threads = {}: expected 0 (every core) or a number of threads ≥ 1", threads));
  return threads;
}

/// The index of `name` in `names`, or an Error that lists them (`what`: "robot", "print head", ...).
std::size_t index_of(const std::vector<std::string>& names, const std::string& name, const char* what, const char* plural) {
  const auto found = std::find(names.begin(), names.end(), name);
  if (found == names.end())
    throw Error(fmt::format("no {} '{}' in the scene ({}: {})", what, name, plural, names.empty() ? "none" : fmt::format("{}", fmt::join(names, ", "))));
  return static_cast<std::size_t>(found - names.begin());
}
}  // namespace

Session::Session(const scene::Scene& scene, int threads)
    : arena_(checked_threads(threads) > 0 ? threads : tbb::task_arena::automatic), threads_(threads) {
  arena_.execute([&] {
    simulation_ = std::make_unique<Simulation>(scene);
    start_run({});
  });
  for (const auto& robot : scene.robots) robot_names_.push_back(robot.name);
}

Session::~Session() {
  try {
    (void)close();
  } catch (...) {
    // A destructor must not throw; close() was the place to hear of it.
  }
}

void Session::start_run(RunOptions options) {
  options.show_progress = false;
  options.threads = threads_;
  // A robot's commands from outside (ExternalCommand) are not in checkpoints, so a session writes none.
  options.checkpoint_period = 0;
  // The printed mesh joins the world at the step it was asked for, recorded or not: the physics
  // does not depend on whether, or how fast, outputs are written.
  options.wait_for_meshes = true;
  run_ = std::make_unique<Run>(*simulation_, options);
}

RunSummary Session::finish_run() {
  RunSummary summary;
  arena_.execute([&] { summary = run_->finish(RunStatus::completed); });
  return summary;
}

Simulation& Session::command(const char* what) {
  if (!run_) throw Error(fmt::format("{}: the simulation is closed", what));
  return *simulation_;
}

void Session::step() {
  (void)command("step");
  arena_.execute([&] { run_->step(); });
}

void Session::record(const std::filesystem::path& directory, bool mcap) {
  (void)command("record");
  if (directory.empty()) throw Error("record: an output folder is needed");
  RunOptions options;
  options.output_directory = directory;
  options.record = mcap;
  (void)finish_run();
  arena_.execute([&] { start_run(options); });
}

const std::string& Session::close() {
  if (run_) {
    const RunSummary result = finish_run();
    closed_summary_ = summary_json_text(result, *simulation_);
    run_.reset();
  }
  return closed_summary_;
}

std::vector<std::string> Session::head_names() const {
  std::vector<std::string> names;
  for (const auto& head : simulation_->scene().print_heads) names.push_back(head.name);
  return names;
}

std::vector<std::string> Session::camera_names() const {
  std::vector<std::string> names;
  const CameraRig& rig = simulation_->cameras();
  for (std::size_t camera = 0; camera < rig.size(); ++camera) names.push_back(rig.settings(camera).name);
  return names;
}

std::size_t Session::robot(const std::string& name) const { return index_of(robot_names_, name, "robot", "robots"); }
std::size_t Session::head(const std::string& name) const { return index_of(head_names(), name, "print head", "print heads"); }
std::size_t Session::camera(const std::string& name) const { return index_of(camera_names(), name, "camera", "cameras"); }

std::size_t Session::robot_head(std::size_t robot, const std::optional<std::string>& head_name) const {
  const std::string& robot_name = robot_names_.at(robot);
  const auto& heads = simulation_->scene().print_heads;
  for (std::size_t head = 0; head < heads.size(); ++head) {
    if (!heads[head].mount || heads[head].mount->robot != robot_name) continue;
    if (head_name && heads[head].name != *head_name) continue;
    if (simulation_->print_head_tool(head)) return head;
  }
  throw Error(fmt::format("robot '{}' carries no print head{}", robot_name, head_name ? fmt::format(" '{}'", *head_name) : ""));
}

void Session::set_external_control(const std::string& name, bool external) {
  Simulation& simulation = command("set_external_control");
  if (std::find(robot_names_.begin(), robot_names_.end(), name) != robot_names_.end()) {
    simulation.world().set_external_control(simulation.robots()[robot(name)], external);
    return;
  }
  // A print head on an ideal gantry: held where it is, or back to its path.
  std::size_t head_index = 0;
  try {
    head_index = head(name);
  } catch (const Error&) {
    throw Error(fmt::format("set_external_control: no robot or print head '{}' in the scene (robots: {}; print heads: {})", name,
                            fmt::join(robot_names_, ", "), fmt::join(head_names(), ", ")));
  }
  if (const auto carrier = simulation.robot_of_head(head_index))
    throw Error(fmt::format("print head '{}' is on robot '{}': switch the robot", name, robot_names_.at(*carrier)));
  if (!external) return simulation.release_head(head_index);
  const auto state = simulation.nozzle_state(head_index);
  simulation.command_head_target(head_index, world::ToolTarget{state.pose.position, state.pose.orientation * Vec3(0, 0, -1)}, {});
}

void Session::set_head_target(std::size_t head_index, const world::ToolTarget& target, const world::MotionLimits& limits) {
  command("set_head_target").command_head_target(head_index, target, limits);
}

}  // namespace m3dp::sim
