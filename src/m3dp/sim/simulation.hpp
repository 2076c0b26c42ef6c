#pragma once
// Simulation: owns one of each module for a scene and runs the step of the architecture.
// run_simulation adds the loop around it: output schedule, progress bar, timing and summary.
#include <atomic>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "m3dp/coupling/fluid_body_coupling.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sph/solver.hpp"
#include "m3dp/world/world.hpp"

namespace m3dp::sim {

class Simulation {
 public:
  explicit Simulation(const scene::Scene& scene);

  /// One step: print heads follow their paths (robots through their controllers), the links' motion
  /// goes to the fluid, the fluid advances (adaptive dt), its forces go back to the links, and the
  /// world is stepped to the fluid's clock.
  const sph::StepStats& step();

  /// Puts `mesh` (e.g. the newest surface of the printed material) into the world as the static
  /// collision body "printed_material", replacing the previous one.
  void set_printed_mesh(const TriangleMesh& mesh);

  [[nodiscard]] const scene::Scene& scene() const { return scene_; }
  [[nodiscard]] sph::Solver& solver() { return solver_; }
  [[nodiscard]] const sph::Solver& solver() const { return solver_; }
  [[nodiscard]] double time() const { return solver_.time(); }
  [[nodiscard]] double initial_fluid_mass() const { return initial_fluid_mass_; }
  /// The rigid world: the scene's static shapes, bodies added by the caller, printed meshes.
  [[nodiscard]] world::World& world() { return world_; }
  [[nodiscard]] const world::World& world() const { return world_; }
  /// The world's robot for each of the scene's robots, in scene order.
  [[nodiscard]] const std::vector<world::RobotIndex>& robots() const { return robots_; }
  /// The tool a print head is mounted as, if a robot carries it.
  [[nodiscard]] std::optional<world::ToolIndex> print_head_tool(std::size_t head) const { return head_tools_.at(head); }
  /// The world's body for each of the scene's dynamic bodies, in scene order.
  [[nodiscard]] const std::vector<world::BodyIndex>& dynamic_bodies() const { return dynamic_bodies_; }
  [[nodiscard]] const coupling::FluidBodyCoupling& coupling() const { return *coupling_; }
  /// Wall-clock ms of the last step's coupling (both ways) and world steps.
  [[nodiscard]] double last_coupling_ms() const { return last_coupling_ms_; }
  [[nodiscard]] double last_world_ms() const { return last_world_ms_; }

 private:
  void add_robots();
  void update_print_heads();

  scene::Scene scene_;
  sph::Solver solver_;
  world::World world_;
  std::vector<world::RobotIndex> robots_;
  std::vector<world::BodyIndex> dynamic_bodies_;
  std::vector<std::optional<world::ToolIndex>> head_tools_;
  std::unique_ptr<coupling::FluidBodyCoupling> coupling_;
  double initial_fluid_mass_ = 0;
  double last_coupling_ms_ = 0, last_world_ms_ = 0;
};

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

struct RunSummary {
  std::string status;           // "completed", "interrupted" or "failed"
  std::string error;            // what failed, if status == "failed"
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
  std::size_t meshes_written = 0;    // surface meshes in meshes/ (scene <meshing>)
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
