// The run loop: the simulation steps to the end time under a schedule of observers, the outputs of
// kOutputs, and the summary says what happened (also when interrupted, or when the state blows up).
#include <fmt/format.h>

#include <cmath>

#include "m3dp/core/periodic.hpp"
#include "m3dp/core/error.hpp"
#include "m3dp/io/atomic_file.hpp"
#include "m3dp/sim/checkpoint.hpp"
#include "m3dp/sim/observer.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

namespace {
/// The run's outputs, in the order they observe: the density check first (the progress line shows
/// its measurement), the printed mesh after the frames (as the step's files), the timing table after
/// the outputs it times, pace last. They finish in any order, each filling its own section of the
/// summary, which summary.json then reports whole.
constexpr outputs::MakeOutput kOutputs[] = {
    outputs::make_density_check, outputs::make_particle_frames, outputs::make_world_frames, outputs::make_printed_mesh,
    outputs::make_camera_files,  outputs::make_run_messages,    outputs::make_quality_report, outputs::make_timing_table, outputs::make_state_hash, outputs::make_run_figures,
    outputs::make_progress_bar,  outputs::make_summary_file,    outputs::make_pace,
};
}  // namespace

std::string_view to_string(RunStatus status) {
  switch (status) {
    case RunStatus::completed: return "completed";
    case RunStatus::interrupted: return "interrupted";
    case RunStatus::failed: return "failed";
  }
  return "unknown";
}

namespace {
/// Writes the run folder's checkpoint.bin after this step: the outputs finish what is in flight and
/// save their part, then the simulation's state, then the caches are dropped, as a resumed run will
/// start without them.
void write_checkpoint(Simulation& simulation, ObserverSchedule& schedule, CheckpointRun run, const RunOptions& options) {
  simulation.prepare_checkpoint();  // first: the printed mesh in flight joins the world
  StateWriter observers;
  schedule.save(observers);
  run.time = simulation.time();
  run.step = simulation.solver().state().step;
  StateWriter out;
  run.save(out);
  simulation.save_state(out);
  out.section("outputs");
  out.put(observers.bytes());
  io::write_file_atomically(options.output_directory / kCheckpointFile, [&](std::ostream& stream) {
    stream.write(out.bytes().data(), static_cast<std::streamsize>(out.bytes().size()));
  }, true);
  simulation.drop_caches();
}
}  // namespace

struct Run::Impl {
  Simulation& simulation;
  RunOptions options;
  RunSummary summary;
  ObserverSchedule schedule;
  CheckpointRun checkpoint;
  Periodic next_checkpoint;
  bool finished = false;
};

Run::Run(Simulation& simulation, const RunOptions& options) : impl_(std::make_unique<Impl>(Impl{simulation, options, {}, {}, {}, {}})) {
  RunSummary& summary = impl_->summary;
  ObserverSchedule& schedule = impl_->schedule;
  CheckpointRun& checkpoint = impl_->checkpoint;
  const double end_time = options.until.value_or(simulation.scene().end_time);
  summary.end_time = end_time;
  summary.frame_period = scene::particle_frame_period(simulation.scene().output, end_time);
  summary.frame_period_chosen = !simulation.scene().output.particles_period.has_value();
  summary.output_directory = options.output_directory.string();
  summary.mass_initial = simulation.initial_fluid_mass();
  if (!options.output_directory.empty()) std::filesystem::create_directories(options.output_directory);

  for (const outputs::MakeOutput make : kOutputs)
    if (auto observer = make(simulation, options)) schedule.add(std::move(observer));
  checkpoint.scene_file = std::filesystem::absolute(simulation.scene().file);
  checkpoint.threads = options.threads;
  checkpoint.until = end_time;
  checkpoint.hash = options.hash;
  checkpoint.record = options.record;
  checkpoint.wait_for_meshes = options.wait_for_meshes;
  checkpoint.checkpoint_period = options.checkpoint_period.value_or(simulation.scene().output.checkpoint_period);
  checkpoint.live_rate = options.live_rate;
  if (checkpoint.checkpoint_period > 0 && options.output_directory.empty())
    throw Error("checkpoints need an output folder: the run writes checkpoint.bin there");
  if (options.resume) {
    // The caller made the simulation from the checkpoint's scene, with its options. Files a killed
    // writer left half-written under temporary names go first.
    io::remove_leftover_temporaries(options.output_directory);
    const std::string bytes = read_checkpoint_bytes(options.output_directory);
    StateReader in(bytes, (options.output_directory / kCheckpointFile).string());
    CheckpointRun saved;
    saved.load(in);
    if (!simulation.scene().file.empty() && file_hash(simulation.scene().file) != saved.scene_hash)
      throw InputError({simulation.scene().file.string(), 0},
                       fmt::format("the scene changed since the checkpoint in {} was written: it cannot be resumed", options.output_directory.string()));
    checkpoint.scene_hash = saved.scene_hash;
    simulation.load_state(in);
    in.section("outputs");
    std::string observers;
    in.get(observers);
    StateReader observers_in(observers, in.source());
    schedule.resume(simulation, observers_in);
  } else {
    if (checkpoint.checkpoint_period > 0 && !simulation.scene().file.empty()) checkpoint.scene_hash = file_hash(simulation.scene().file);
    schedule.start(simulation);
  }
  impl_->next_checkpoint.start(simulation.time(), checkpoint.checkpoint_period);
}

Run::~Run() {
  if (!impl_->finished) (void)finish(RunStatus::interrupted);
}

double Run::end_time() const { return impl_->summary.end_time; }
bool Run::finished() const { return impl_->finished; }

void Run::step() {
  Impl& run = *impl_;
  if (run.finished) throw Error("the run has finished: it cannot step");
  if (run.summary.status == RunStatus::failed) throw SimulationError("the run failed and cannot go on: " + run.summary.error);
  Simulation& simulation = run.simulation;
  try {
    run.schedule.after_step(simulation, simulation.step());
    const double period = run.checkpoint.checkpoint_period;
    if (simulation.time() < run.summary.end_time - kTimeSlack && run.next_checkpoint.take(simulation.time(), period))
      write_checkpoint(simulation, run.schedule, run.checkpoint, run.options);
  } catch (const std::exception& error) {
    // The state blew up (SimulationError), or an output could not be written (a full disk, a file in
    // the way): the run is failed, and finish() still completes what every output has.
    run.summary.fail(error.what());
    throw;
  }
}

RunSummary Run::finish(RunStatus status) {
  Impl& run = *impl_;
  if (run.finished) return run.summary;
  run.finished = true;
  if (run.summary.status != RunStatus::failed) run.summary.status = status;
  run.schedule.finish(run.simulation, run.summary);
  // A run that ended has nothing to resume; an interrupted or failed one keeps its last checkpoint.
  if (run.summary.status == RunStatus::completed && run.checkpoint.checkpoint_period > 0) {
    std::error_code ignored;
    std::filesystem::remove(run.options.output_directory / kCheckpointFile, ignored);
  }
  return run.summary;
}

RunSummary run_simulation(Simulation& simulation, const RunOptions& options) {
  Run run(simulation, options);
  RunStatus status = RunStatus::completed;
  try {
    while (simulation.time() < run.end_time() - 1e-12) {
      if (options.stop_requested && options.stop_requested->load()) {
        status = RunStatus::interrupted;
        break;
      }
      run.step();
    }
  } catch (const std::exception&) {
    // Run::step marked the run failed with what happened; finish completes every output's files.
  }
  return run.finish(status);
}

std::string format_summary(const RunSummary& summary, const std::filesystem::path& output_directory) {
  std::string text;
  text += fmt::format("Run {}: simulated {:.4f} of {:.4f} s in {} steps, {:.2f} s wall time\n", to_string(summary.status),
                      summary.simulated_time, summary.end_time, summary.steps, summary.wall_time);
  if (!summary.error.empty()) text += fmt::format("  error: {}\n", summary.error);
  text += fmt::format("  speed       {:.3g} x real time, {:.3g} particle-steps/s\n", summary.real_time_factor,
                      summary.particle_steps_per_second);
  text += fmt::format("  particles   {} now ({} at rest, not simulated), {} emitted, {} left the bounds\n", summary.particles,
                      summary.particles_at_rest, summary.particles_emitted,
                      summary.particles_removed);
  text += fmt::format("  mass        {:.6g} kg initial + {:.6g} emitted - {:.6g} lost = {:.6g} kg\n", summary.mass_initial,
                      summary.mass_emitted, summary.mass_lost, summary.mass_final);
  if (summary.density.checks > 0) {
    const auto& last = summary.density.last.statistics;
    const auto& worst = summary.density.worst_max;
    text += fmt::format("  density     rho/rho0 - 1 of all {} particles at {:.3f} s: median {:+.2f} %, 99th percentile {:+.2f} %, "
                        "max {:+.2f} % (worst max {:+.2f} % at {:.3f} s; {} checks)\n",
                        last.particles, summary.density.last.time, 100 * last.median, 100 * last.p99, 100 * last.max,
                        100 * worst.statistics.max, worst.time, summary.density.checks);
  }
  const auto& volume = summary.volume;
  if (volume.commanded > 0 || volume.emitted > 0) {
    constexpr double kCm3 = 1e6;  // cm³ per m³
    // What was asked for against where it went: out of the exits, lost while blocked, and (nozzles
    // with a bore) what went into the bores beyond what primed them, which were filled apart.
    text += fmt::format("  volume      {:.4g} cm3 commanded: {:.4g} laid", kCm3 * volume.commanded, kCm3 * volume.laid);
    if (volume.primed > 0 || volume.in_bores > 0)
      text += fmt::format(", {:.4g} on its way through the bores", kCm3 * (volume.in_bores - volume.primed));
    text += fmt::format(", {:.4g} lost at blocked nozzles", kCm3 * volume.lost_at_nozzles);
    if (volume.primed > 0 || volume.in_bores > 0)
      text += fmt::format(" (the bores hold {:.4g}, {:.4g} of it filled them before the first layer)", kCm3 * volume.in_bores,
                          kCm3 * volume.primed);
    text += fmt::format("; {:.4g} left the bounds", kCm3 * volume.removed);
    if (!summary.meshes.empty() && volume.in_particles > 0) {
      const auto& last_mesh = summary.meshes.back();
      text += fmt::format("; last mesh ({:.3f} s) {:.4g} cm3, {:.1f} % of the particles' volume", last_mesh.time, kCm3 * last_mesh.volume,
                          100 * last_mesh.volume / volume.in_particles);
    }
    text += "\n";
  }
  if (const auto& quality = summary.quality; quality && !quality->file.empty())
    text += fmt::format("  quality     {} layers: beads {:.1f} mm wide, {:.1f} mm high (design {:.1f} x {:.1f}); fill {:.1f} cm3 over, "
                        "{:.1f} cm3 under of {:.1f}; surface off the design {:.1f} mm (p95); {} ({})\n",
                        quality->layers, 1e3 * quality->width, 1e3 * quality->height, 1e3 * quality->design_width,
                        1e3 * quality->design_height, 1e6 * quality->fill_over, 1e6 * quality->fill_under, 1e6 * quality->fill_designed,
                        1e3 * quality->deviation_p95,
                        quality->stood ? std::string("stood")
                                       : fmt::format("fell short at layer {} ({:.2f} s)", quality->shortfall_layer, quality->shortfall_time),
                        quality->file);
  if (const auto& quality = summary.quality; quality && quality->file.empty() && !quality->note.empty())
    text += fmt::format("  quality     not measured: {}\n", quality->note);
  if (const auto& quality = summary.quality; quality && quality->heads.size() > 1) {
    text += "  quality     by head:";
    for (const auto& head : quality->heads)
      text += head.stood ? fmt::format(" {} stood;", head.name)
                         : fmt::format(" {} fell short at layer {} ({:.2f} s);", head.name, head.shortfall_layer, head.shortfall_time);
    text.back() = '\n';
  }
  if (const auto& quality = summary.quality; quality && !quality->resolution_warning.empty())
    text += fmt::format("  warning     quality: {}\n", quality->resolution_warning);
  for (const auto& nozzle : summary.nozzles)
    if (nozzle.longest_blockage.duration >= RunSummary::kLongBlockage) {
      const Vec3& at = nozzle.longest_blockage.position;
      text += fmt::format("  warning     nozzle {} was blocked for {:.2f} s from {:.3f} s at ({:.3f}, {:.3f}, {:.3f}) m (material in "
                          "front of it); {:.2f} s blocked in all, {:.4g} cm3 of the flow asked for was never emitted\n",
                          nozzle.name, nozzle.longest_blockage.duration, nozzle.longest_blockage.start, at.x(), at.y(), at.z(),
                          nozzle.blocked_time, 1e6 * nozzle.volume_lost);
    } else if (nozzle.steps_blocked > 0) {
      text += fmt::format("  nozzle      {}: blocked in {} steps ({:.3f} s in all, at most {:.3f} s at a stretch); {:.4g} cm3 of the "
                          "flow asked for was never emitted\n",
                          nozzle.name, nozzle.steps_blocked, nozzle.blocked_time, nozzle.longest_blockage.duration,
                          1e6 * nozzle.volume_lost);
    }
  if (summary.granular)
    text += fmt::format("  solver      granular contacts (spring-dashpot), mean time step {:.3g} ms\n",
                        summary.steps > 0 ? 1e3 * summary.simulated_time / double(summary.steps) : 0.0);
  else
    text += fmt::format("  solver      {:.2f} density + {:.2f} divergence + {:.2f} viscosity iterations per step\n",
                        summary.mean_density_iterations, summary.mean_divergence_iterations, summary.mean_viscosity_iterations);
  if (!output_directory.empty()) {
    if (summary.frame_period > 0)
      text += fmt::format("  output      {} ({} particle frames, one every {:g} s{}; open particles.pvd{} in ParaView)\n",
                          output_directory.string(), summary.frames_written, summary.frame_period,
                          summary.frame_period_chosen
                              ? fmt::format(" (chosen for a {:g} s run: at most {:g} frames; <output><particles_period> sets it)",
                                            summary.end_time, scene::kDefaultMostParticleFrames)
                              : std::string(),
                          summary.world_frames_written > 0 ? " and world.pvd" : "");
    else
      text += fmt::format("  output      {} (no particle frames: <output><particles_period> is 0)\n", output_directory.string());
  }
  if (!summary.recording.file.empty())
    text += fmt::format("  recording   {}: {} messages, {:.1f} MB (Foxglove or Lichtblick: open the file; {:.2f} s to make and write)\n",
                        summary.recording.file, summary.recording.messages, 1e-6 * double(summary.recording.bytes),
                        summary.recording.encode_seconds);
  for (const auto& camera : summary.cameras)
    text += fmt::format("  camera      {}: {} frames in cameras/{}/, {:.2f} s rendering ({:.3g} rays/s)\n", camera.name, camera.frames_written,
                        camera.name, camera.render_seconds, camera.render_seconds > 0 ? double(camera.rays) / camera.render_seconds : 0.0);
  if (summary.live.port != 0)
    text += fmt::format("  live        ws://127.0.0.1:{}: {} clients, {} messages sent ({:.1f} MB), {} dropped for slow clients\n",
                        summary.live.port, summary.live.clients, summary.live.messages_sent, 1e-6 * double(summary.live.bytes_sent),
                        summary.live.messages_dropped);
  for (const auto& robot : summary.robots)
    text += fmt::format("  robot       {}: nozzle {:.2f} mm rms from its path (max {:.2f} mm); contacts: {} with robots, {} "
                        "with printed material, {} other\n",
                        robot.name, 1e3 * robot.tracking_rms, 1e3 * robot.tracking_max, robot.contacts.with_robots,
                        robot.contacts.with_printed_material, robot.contacts.with_other);
  for (const auto& robot : summary.robots)
    if (robot.coordination)
      text += fmt::format("  coordinated {}: waited {:.2f} s, slowed {:.2f} s; {} of {} decisions yielded{}; closest {:.0f} mm to a "
                          "robot, {:.0f} mm to the print\n",
                          robot.name, robot.coordination->waiting_time, robot.coordination->slowed_time,
                          robot.coordination->conflicts, robot.coordination->decisions,
                          robot.coordination->blocked > 0 ? fmt::format(" ({} blocked)", robot.coordination->blocked) : "",
                          1e3 * robot.coordination->least_robot_distance, 1e3 * robot.coordination->least_print_distance);
  for (const auto& robot : summary.robots)
    if (robot.base)
      text += fmt::format("  base        {}: drove {:.3f} m, {:.2f} mm rms from its path (max {:.2f} mm), odometry off by {:.2f} mm\n",
                          robot.name, robot.base->distance, 1e3 * robot.base->tracking_rms, 1e3 * robot.base->tracking_max,
                          1e3 * robot.base->odometry_error);
  if (summary.meshes_written + summary.meshes_skipped > 0)
    text += fmt::format("  meshes      {} written to meshes/ ({} skipped while the mesher was busy)\n", summary.meshes_written,
                        summary.meshes_skipped);
  return text;
}

}  // namespace m3dp::sim
