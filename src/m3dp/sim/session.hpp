#pragma once
// A simulation driven by its caller (the Python API, a C++ controller): one Simulation and its run
// (observers, summary) on threads of its own, the run's lifecycle (open until closed; a failed step
// fails it), and access by name to robots, print heads and cameras, with errors that say what the
// scene has. The Python module is bindings over it.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <tbb/task_arena.h>

#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/run.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

class Session {
 public:
  /// `threads`: the worker threads its steps use, 0 for every core; < 0 is an Error.
  Session(const scene::Scene& scene, int threads);
  /// Closes the run if still open (errors are dropped: close() is the place to hear of them).
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;

  // ---- the run ----
  /// One step and the outputs due after it. A state that blows up throws SimulationError and fails
  /// the run; later steps refuse. Error once closed.
  void step();
  /// From now on the run folder's outputs (frames, meshes, cameras, run.mcap if `mcap`, summary) go
  /// to `directory`, from the present; the outputs started before finish first.
  void record(const std::filesystem::path& directory, bool mcap);
  /// Ends the run: its outputs complete their files. Returns summary.json's text (the same on later calls).
  const std::string& close();
  [[nodiscard]] bool closed() const { return run_ == nullptr; }

  /// The simulation, to read.
  [[nodiscard]] Simulation& simulation() { return *simulation_; }
  [[nodiscard]] const Simulation& simulation() const { return *simulation_; }
  /// The simulation, to command (`what` names the command in the error): refused once closed, since
  /// nothing would step it again and a command silently dropped is worse than an error.
  Simulation& command(const char* what);

  // ---- by name (errors list the names the scene has) ----
  [[nodiscard]] const std::vector<std::string>& robot_names() const { return robot_names_; }
  [[nodiscard]] std::vector<std::string> head_names() const;
  [[nodiscard]] std::vector<std::string> camera_names() const;
  [[nodiscard]] std::size_t robot(const std::string& name) const;   // scene order
  [[nodiscard]] std::size_t head(const std::string& name) const;    // scene order
  [[nodiscard]] std::size_t camera(const std::string& name) const;  // the camera rig's order
  /// The print head robot `robot` carries: the one named, or its only one.
  [[nodiscard]] std::size_t robot_head(std::size_t robot, const std::optional<std::string>& head_name) const;

  // ---- commands by name ----
  /// `name` is a robot (its scene paths, or commands from outside holding still until commanded) or
  /// a print head on an ideal gantry (held where it is, or back to its path).
  void set_external_control(const std::string& name, bool external);
  /// A nozzle target for a print head (Simulation::command_head_target).
  void set_head_target(std::size_t head, const world::ToolTarget& target, const world::MotionLimits& limits);

  /// Runs `call` on the session's threads (what computes in parallel: images, measured density).
  template <class Call>
  auto in_arena(Call&& call) {
    return arena_.execute(std::forward<Call>(call));
  }

 private:
  void start_run(RunOptions options);
  RunSummary finish_run();

  tbb::task_arena arena_;
  int threads_ = 0;
  std::unique_ptr<Simulation> simulation_;
  std::unique_ptr<Run> run_;
  std::vector<std::string> robot_names_;
  std::string closed_summary_;  // summary.json's text, once closed
};

}  // namespace m3dp::sim
