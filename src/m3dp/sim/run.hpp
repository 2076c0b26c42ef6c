#pragma once
// A run: the simulation stepped to its end time under a schedule of observers (observer.hpp) that
// write the run folder, and the summary of what happened.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "m3dp/sim/meshing_worker.hpp"
#include "m3dp/world/world.hpp"

namespace m3dp::sim {

class Simulation;

struct RunOptions {
  std::filesystem::path output_directory;       // empty: no files
  std::optional<double> until;                  // s; default the scene's end_time
  bool show_progress = true;
  const std::atomic<bool>* stop_requested = nullptr;  // set by a signal handler: stop cleanly
  /// Meshing normally runs beside the solver, so when a mesh reaches the world depends on wall-clock
  /// speed. True: the solver waits for each mesh, which then joins the world at the step it was asked
  /// for: reproducible runs (tests, comparisons), at the cost of the meshing time.
  bool wait_for_meshes = false;
};

enum class RunStatus { completed, interrupted, failed };
[[nodiscard]] std::string_view to_string(RunStatus status);  // "completed", "interrupted", "failed"

struct RunSummary {
  RunStatus status = RunStatus::completed;
  std::string error;            // what failed, if status == failed
  double simulated_time = 0;    // s
  double end_time = 0;          // s
  std::int64_t steps = 0;
  double wall_time = 0;         // s
  double real_time_factor = 0;  // simulated s per wall s
  std::size_t particles = 0;
  std::size_t particles_at_rest = 0;   // at the end: resting material, not simulated (rest detection)
  std::uint64_t particles_emitted = 0;
  std::uint64_t particles_removed = 0;
  std::uint64_t blocked_layers = 0;  // steps in which a due nozzle layer found no room (summed over nozzles)
  double mass_initial = 0, mass_emitted = 0, mass_lost = 0, mass_final = 0;  // kg
  double max_density_error = 0;      // largest mean relative density error after a density solve
  double mean_density_iterations = 0;
  double mean_divergence_iterations = 0;
  double mean_viscosity_iterations = 0;   // conjugate-gradient iterations of the implicit viscosity solve
  bool granular = false;                  // the materials are discrete spheres: no pressure or viscosity solve
  std::size_t frames_written = 0;
  std::vector<MeshingWorker::Mesh> meshes;  // surface meshes in meshes/ (scene <meshing>)
  std::size_t meshes_written = 0;
  std::size_t meshes_skipped = 0;    // requests that came while the mesher was still busy
  std::size_t meshes_inserted = 0;   // meshes put into the world as the printed-material collision body
  struct Robot {
    std::string name;
    world::RobotContacts contacts;
    double tracking_rms = 0, tracking_max = 0;  // m, nozzle vs its path target (robots that carry a print head)
    std::optional<world::BaseReport> base;      // mobile bases: path following and odometry
  };
  std::vector<Robot> robots;
  double particle_steps_per_second = 0;
  std::string output_directory;
};

/// Runs `simulation` to the end time (or until a stop request / failure), writing the run folder.
RunSummary run_simulation(Simulation& simulation, const RunOptions& options);

/// The one-screen text summary printed at the end of `m3dp run`.
std::string format_summary(const RunSummary& summary, const std::filesystem::path& output_directory);

}  // namespace m3dp::sim
