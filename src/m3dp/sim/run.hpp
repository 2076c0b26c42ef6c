#pragma once
// A run: the simulation stepped to its end time under a schedule of observers (observer.hpp) that
// write the run folder, and the summary of what happened.
#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "m3dp/record/foxglove_server.hpp"
#include "m3dp/sim/coordination_erdmann1987.hpp"
#include "m3dp/sim/meshing_worker.hpp"
#include "m3dp/sph/measure.hpp"
#include "m3dp/sph/state.hpp"
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
  bool record = false;  // run.mcap even where the scene's <output><mcap> does not ask for it
  /// The live stream's port (a Foxglove WebSocket server on localhost; 0: any free port), where the
  /// scene's <output><serve> does not give one or to override it; none: no live stream.
  std::optional<std::uint16_t> serve_port;
  double live_rate = 20;  // frames per wall second the live stream sends at most
  /// Plain HTTP GETs on the live stream's port (the browser viewer's files); none: 404.
  std::function<std::optional<record::HttpFile>(std::string_view path)> http;
  /// At most this many simulated seconds per wall second (1: real time, to watch a run live); 0: as fast as it can.
  double pace = 0;
  /// A hash of the state after every step, in hashes.csv and on stdout (`m3dp run --hash`); the
  /// run then also waits for its meshes (wait_for_meshes), which is what makes it reproducible.
  bool hash = false;
  /// Simulated seconds between checkpoints (checkpoint.bin in the output folder, replaced each time);
  /// none: the scene's <output><checkpoint_period>; 0: none.
  std::optional<double> checkpoint_period;
  /// Go on from the output folder's checkpoint.bin (m3dp run --resume) instead of the scene's start:
  /// the simulation (made from the same scene) and every output take back their state and files.
  bool resume = false;
  int threads = 0;  // the worker threads the caller set (0: all cores), kept in a checkpoint
};

enum class RunStatus { completed, interrupted, failed };
[[nodiscard]] std::string_view to_string(RunStatus status);  // "completed", "interrupted", "failed"

struct RunSummary {
  RunStatus status = RunStatus::completed;
  std::string error;            // what failed, if status == failed (each failure, "; " between)
  /// Marks the run failed (also an interrupted one: what it wrote is not whole) and adds what failed.
  void fail(std::string_view what) {
    status = RunStatus::failed;
    error += error.empty() ? std::string(what) : "; " + std::string(what);
  }
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

  /// ρ/ρ0 − 1 over all particles, moving and resting, as measured from their positions at the end of a
  /// step (Simulation::measured_density): what the particle frames hold.
  struct DensityCheck {
    double time = -1;  // s; < 0: never measured
    sph::DensityStatistics statistics;
  };
  struct DensityReport {
    std::size_t checks = 0;    // at every particle frame (or a hundred times a run without frames) and the end
    DensityCheck last;         // at the end of the run
    DensityCheck worst_p99;    // the check with the largest 99th percentile
    DensityCheck worst_max;    // the check with the largest max
  } density;

  /// Where the printed volume went (m³): volume = mass / rest density, d³ a particle.
  struct VolumeBalance {
    double commanded = 0;        // the flow the paths or G-code asked of the nozzles: π D²/4 · U · flow scale · time
    double emitted = 0;          // particles the nozzles emitted, the bores' priming included
    double primed = 0;           // what filled the bores before their first layer (emitted, not commanded)
    double in_bores = 0;         // particles inside the nozzles' bores at the end
    double laid = 0;             // what left the exits: emitted − in_bores
    double lost_at_nozzles = 0;  // asked for while a nozzle was blocked, never emitted
    double removed = 0;          // particles that left the bounds
    double in_particles = 0;     // particles at the end, at their rest density
  } volume;                      // the last mesh's enclosed volume is meshes.back()'s

  struct Nozzle {
    std::string name;
    std::uint64_t layers_emitted = 0, particles_emitted = 0, steps_blocked = 0;
    double volume_commanded = 0, volume_emitted = 0, volume_lost = 0;  // m³
    double blocked_time = 0;                                           // s in all
    double volume_primed = 0;                                          // m³ that filled a bore (in volume_emitted)
    double volume_in_bore = 0, volume_laid = 0;                        // m³ in the bore at the end, and what left the exit
    double path_time = 0;                                              // s on its path's clock at the end (what it had laid by then)
    double extrusion_pressure = -1, extrusion_pressure_max = -1;       // Pa at the end and the largest; < 0: no bore
    sph::NozzleState::Blockage longest_blockage;                       // duration 0: never blocked
  };
  std::vector<Nozzle> nozzles;
  /// A nozzle blocked at least this long (s) at a stretch is a warning in the summary.
  static constexpr double kLongBlockage = 0.2;

  double solver_density_error = 0;   // the pressure solve's own largest mean error estimate (moving particles, mid-step)
  double mean_density_iterations = 0;
  double mean_divergence_iterations = 0;
  double mean_viscosity_iterations = 0;   // conjugate-gradient iterations of the implicit viscosity solve
  bool granular = false;                  // the materials are discrete spheres: no pressure or viscosity solve
  std::size_t frames_written = 0;
  double frame_period = 0;                // s between particle frames (0: none)
  bool frame_period_chosen = false;       // chosen for the run's length: the scene gave no <particles_period>
  std::size_t world_frames_written = 0;   // world/*.vtm in world.pvd
  struct Recording {
    std::string file;                     // run.mcap; empty: not recorded
    std::uint64_t messages = 0, bytes = 0;
    std::uint32_t chunks = 0;
    double encode_seconds = 0;            // wall s spent making and sending the run's messages (file and live)
  } recording;
  struct Camera {
    std::string name;
    std::size_t frames_written = 0;       // image sets in cameras/NAME/
    std::size_t frames_rendered = 0;      // by the rig (files and recording share each)
    double render_seconds = 0;            // wall s rendering
    std::uint64_t rays = 0;
  };
  std::vector<Camera> cameras;
  struct Live {
    std::uint16_t port = 0;               // 0: no live stream
    std::size_t clients = 0;              // connected over the run
    std::uint64_t messages_sent = 0, bytes_sent = 0;
    std::uint64_t messages_dropped = 0;   // unsent when newer ones came (slow clients)
  } live;
  std::vector<MeshingWorker::Mesh> meshes;  // surface meshes in meshes/ (scene <meshing>)
  std::size_t meshes_written = 0;
  std::size_t meshes_skipped = 0;    // requests that came while the mesher was still busy
  std::size_t meshes_inserted = 0;   // meshes put into the world as the printed-material collision body
  struct Robot {
    std::string name;
    world::RobotContacts contacts;
    double tracking_rms = 0, tracking_max = 0;  // m, nozzle vs its path target (robots that carry a print head)
    std::optional<world::BaseReport> base;      // mobile bases: path following and odometry
    std::optional<CoordinationReport> coordination;  // when the coordinator ran
  };
  std::vector<Robot> robots;
  /// The print against its design (quality/, the in-run report in quality.json): none when the run
  /// wrote no folder, has no print heads or its <quality_period> is 0.
  struct Quality {
    std::string file;                    // quality.json; empty: not measured
    std::string note;                    // why not, when it could not be
    std::size_t layers = 0, sections = 0;  // layers with material, sections in all
    double width = 0, design_width = 0;  // m, the sections' mean and the design's (all layers)
    double height = 0, design_height = 0;
    double fill_over = 0, fill_under = 0, fill_designed = 0;  // m³
    double deviation_p95 = 0, deviation_max = 0;              // m, the surface off the design
    bool stood = true;
    std::int32_t shortfall_layer = -1;
    double shortfall_time = 0;           // s
    std::string resolution_warning;      // quality::Report's: the layers are too thin for the particles
    struct Head {                        // each print head's own wall: stood, or where it fell short
      std::string name;
      bool stood = true;
      std::int32_t shortfall_layer = -1;
      double shortfall_time = 0;  // s
    };
    std::vector<Head> heads;
  };
  std::optional<Quality> quality;
  double particle_steps_per_second = 0;
  // The walls' particles (static bodies, moving bodies and nozzles) and the megabytes their arrays hold.
  std::size_t boundary_particles = 0, static_boundary_particles = 0;
  double boundary_megabytes = 0;
  std::string output_directory;
};

/// A run stepped by its caller: its observers start (or resume from the checkpoint) when it is
/// made, watch each step, and complete their files in finish(). run_simulation steps it to the end;
/// the Python API steps it as the user's code asks.
class Run {
 public:
  Run(Simulation& simulation, const RunOptions& options);
  /// An unfinished run finishes as interrupted.
  ~Run();
  Run(const Run&) = delete;
  Run& operator=(const Run&) = delete;

  /// One simulation step, the observers due after it, and a checkpoint if one is due. What throws
  /// (the state blew up, an output could not be written) marks the run failed and is rethrown.
  void step();
  /// The observers complete their files and the summary (once; later calls return it again).
  /// `status` is the run's unless a step failed.
  RunSummary finish(RunStatus status);
  [[nodiscard]] double end_time() const;  // s: RunOptions::until or the scene's
  [[nodiscard]] bool finished() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// Runs `simulation` to the end time (or until a stop request / failure), writing the run folder.
RunSummary run_simulation(Simulation& simulation, const RunOptions& options);

/// The summary as summary.json holds it (JSON text, SI units in the keys): the file's, and what the
/// Python API's close() returns.
std::string summary_json_text(const RunSummary& summary, const Simulation& simulation);

/// The one-screen text summary printed at the end of `m3dp run`.
std::string format_summary(const RunSummary& summary, const std::filesystem::path& output_directory);

}  // namespace m3dp::sim
