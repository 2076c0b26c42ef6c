// The run loop: steps to the end time, writes particle frames on schedule, timing per step,
// and a summary — also when interrupted (Ctrl-C) or when the state blows up.
#include <fmt/format.h>
#include <fmt/os.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "m3dp/core/error.hpp"
#include "m3dp/core/progress.hpp"
#include "m3dp/io/atomic_file.hpp"
#include "m3dp/io/vtk_writer.hpp"
#include "m3dp/sim/meshing_worker.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

namespace {

using Clock = std::chrono::steady_clock;

class ParticleFrameWriter {
 public:
  explicit ParticleFrameWriter(const std::filesystem::path& output_directory)
      : folder_(output_directory / "particles"), collection_(output_directory / "particles.pvd") {
    std::filesystem::create_directories(folder_);
  }

  void write(const sph::Solver& solver) {
    const auto& fluid = solver.fluid();
    pressure_.resize(fluid.size());
    for (std::size_t i = 0; i < fluid.size(); ++i) pressure_[i] = solver.pressure(i);
    const auto file = folder_ / fmt::format("particles_{:06}.vtu", collection_.size());
    io::write_vtu(file, fluid.position,
                  {io::PointArray::of("velocity", fluid.velocity), io::PointArray::of("density", fluid.density),
                   io::PointArray::of("pressure", pressure_), io::PointArray::of("material", fluid.phase),
                   io::PointArray::of("id", fluid.id), io::PointArray::of("birth_time", fluid.birth_time),
                   io::PointArray::of("viscosity", fluid.viscosity), io::PointArray::of("shear_rate", fluid.shear_rate),
                   io::PointArray::of("rest_time", fluid.rest_time),
                   io::PointArray::of("angular_velocity", fluid.angular_velocity)},
                  {{"particle_radius", solver.parameters().settings.particle_radius}, {"time", solver.time()}});
    collection_.add(solver.time(), file);
  }
  [[nodiscard]] std::size_t frames() const { return collection_.size(); }

 private:
  std::filesystem::path folder_;
  io::PvdCollection collection_;
  std::vector<Real> pressure_;
};

nlohmann::json summary_json(const RunSummary& summary, const Simulation& simulation, const MeshingWorker* meshing) {
  nlohmann::json bodies = nlohmann::json::array();
  for (const auto& body : simulation.solver().bodies())
    bodies.push_back({{"name", body.name},
                      {"fluid_force_N", {body.fluid_force.x(), body.fluid_force.y(), body.fluid_force.z()}},
                      {"fluid_torque_Nm", {body.fluid_torque.x(), body.fluid_torque.y(), body.fluid_torque.z()}}});
  nlohmann::json meshes = nlohmann::json::array();
  if (meshing)
    for (const auto& mesh : meshing->meshes())
      meshes.push_back({{"time_s", mesh.time},
                        {"file", std::filesystem::relative(mesh.file, std::filesystem::path(summary.output_directory)).generic_string()},
                        {"particles", mesh.particles},
                        {"triangles", mesh.triangles},
                        {"reused_particles", mesh.reused_particles},
                        {"tiles", mesh.tiles},
                        {"remeshed_tiles", mesh.remeshed_tiles},
                        {"seconds", mesh.seconds}});
  nlohmann::json nozzles = nlohmann::json::array();
  const auto& solver = simulation.solver();
  for (std::size_t n = 0; n < solver.state().nozzles.size(); ++n) {
    const auto& nozzle = solver.state().nozzles[n];
    nozzles.push_back({{"name", solver.parameters().nozzles[n].name},
                       {"layers_emitted", nozzle.layers_emitted},
                       {"particles_emitted", nozzle.particles_emitted},
                       {"steps_blocked", nozzle.blocked_layers}});
  }
  nlohmann::json robots = nlohmann::json::array();
  for (const auto& robot : summary.robots)
    robots.push_back({{"name", robot.name},
                      {"contacts_with_robots", robot.contacts.with_robots},
                      {"contacts_with_printed_material", robot.contacts.with_printed_material},
                      {"contacts_with_other", robot.contacts.with_other},
                      {"world_steps_in_contact", robot.contacts.steps_in_contact},
                      {"nozzle_tracking_rms_m", robot.tracking_rms},
                      {"nozzle_tracking_max_m", robot.tracking_max}});
  for (std::size_t r = 0; r < summary.robots.size(); ++r)
    if (const auto& base = summary.robots[r].base)
      robots[r]["base"] = {{"tracking_rms_m", base->tracking_rms},
                           {"tracking_max_m", base->tracking_max},
                           {"odometry_error_m", base->odometry_error},
                           {"distance_m", base->distance}};
  return {
      {"scene", simulation.scene().file.string()},
      {"status", summary.status},
      {"error", summary.error},
      {"simulated_time_s", summary.simulated_time},
      {"end_time_s", summary.end_time},
      {"steps", summary.steps},
      {"wall_time_s", summary.wall_time},
      {"real_time_factor", summary.real_time_factor},
      {"particle_steps_per_second", summary.particle_steps_per_second},
      {"particles", summary.particles},
      {"particles_emitted", summary.particles_emitted},
      {"particles_removed", summary.particles_removed},
      {"mass_initial_kg", summary.mass_initial},
      {"mass_emitted_kg", summary.mass_emitted},
      {"mass_lost_kg", summary.mass_lost},
      {"mass_final_kg", summary.mass_final},
      {"max_density_error", summary.max_density_error},
      {"mean_density_iterations", summary.mean_density_iterations},
      {"mean_divergence_iterations", summary.mean_divergence_iterations},
      {"mean_viscosity_iterations", summary.mean_viscosity_iterations},
      {"granular", summary.granular},
      {"particles_at_rest", summary.particles_at_rest},
      {"frames_written", summary.frames_written},
      {"particle_radius_m", simulation.solver().parameters().settings.particle_radius},
      {"bodies", bodies},
      {"nozzles", nozzles},
      {"robots", robots},
      {"meshes", meshes},
      {"meshes_skipped", meshing ? meshing->skipped() : 0},
  };
}

/// timing.csv's header: the step's figures, then a column per solver stage (sph::kStageNames) and the
/// simulation's own (coupling, world) and the output's.
std::string timing_header() {
  std::string header = "step,time_s,dt_s,particles,density_iterations,divergence_iterations,viscosity_iterations,density_error";
  for (const auto name : sph::kStageNames) header += fmt::format(",ms_{}", name);
  return header + ",ms_coupling,ms_world,ms_output,ms_total\n";
}

}  // namespace

RunSummary run_simulation(Simulation& simulation, const RunOptions& options) {
  RunSummary summary;
  const double end_time = options.until.value_or(simulation.scene().end_time);
  summary.end_time = end_time;
  summary.output_directory = options.output_directory.string();
  summary.mass_initial = simulation.initial_fluid_mass();
  const bool writing = !options.output_directory.empty();
  const auto& output = simulation.scene().output;

  std::optional<ParticleFrameWriter> frames;
  std::unique_ptr<MeshingWorker> meshing;
  const auto& meshing_settings = simulation.scene().meshing;
  std::FILE* timing = nullptr;
  std::filesystem::path timing_partial, timing_final;
  if (writing) {
    std::filesystem::create_directories(options.output_directory);
    if (output.write_particles) frames.emplace(options.output_directory);
    if (meshing_settings.enabled) {
      surface::SurfaceSettings surface = meshing_settings.surface;
      surface.particle_radius = simulation.solver().parameters().settings.particle_radius;
      meshing = std::make_unique<MeshingWorker>(surface, options.output_directory / "meshes", meshing_settings.format);
    }
    // The timing table grows during the run; it gets its real name only when complete.
    timing_final = options.output_directory / "timing.csv";
    timing_partial = options.output_directory / "timing.csv.partial";
    timing = std::fopen(timing_partial.c_str(), "w");
    if (!timing) throw Error("cannot write " + timing_partial.string());
    std::fputs(timing_header().c_str(), timing);
    std::error_code ignored;
    if (std::filesystem::exists(simulation.scene().file))
      std::filesystem::copy_file(simulation.scene().file, options.output_directory / "scene.sdf",
                                 std::filesystem::copy_options::overwrite_existing, ignored);
  }

  ProgressBar progress(stderr, options.show_progress);
  const auto wall_start = Clock::now();
  auto wall_seconds = [&] { return std::chrono::duration<double>(Clock::now() - wall_start).count(); };
  double next_frame_time = 0;
  double density_iterations_sum = 0, divergence_iterations_sum = 0, viscosity_iterations_sum = 0, particle_steps = 0;
  auto& solver = simulation.solver();

  auto write_frame_if_due = [&]() -> double {
    if (!frames || output.particles_period <= 0 || solver.time() + 1e-12 < next_frame_time) return 0;
    const auto start = Clock::now();
    frames->write(solver);
    next_frame_time += output.particles_period;
    while (next_frame_time <= solver.time()) next_frame_time += output.particles_period;
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  };

  double next_mesh_time = meshing_settings.period;
  std::shared_ptr<const TriangleMesh> inserted_mesh;
  double last_meshed_time = -1;
  // The particles the meshing block asks for: one material, one region, or all.
  std::optional<std::uint16_t> meshed_phase;
  for (std::size_t m = 0; m < simulation.scene().materials.size(); ++m)
    if (simulation.scene().materials[m].material.name == meshing_settings.material) meshed_phase = static_cast<std::uint16_t>(m);
  // Moving and resting particles apart: the worker keeps the resting ones' field between meshes.
  std::vector<Vec3> meshed_moving, meshed_resting;
  std::vector<std::uint64_t> meshed_resting_ids;
  auto submit_mesh = [&]() {
    const auto& fluid = solver.fluid();
    const std::size_t active = solver.state().active_count;
    meshed_moving.clear();
    meshed_resting.clear();
    meshed_resting_ids.clear();
    for (std::size_t i = 0; i < fluid.size(); ++i) {
      if ((meshed_phase && fluid.phase[i] != *meshed_phase) ||
          (meshing_settings.region && !meshing_settings.region->contains(fluid.position[i])))
        continue;
      if (i < active) {
        meshed_moving.push_back(fluid.position[i]);
      } else {
        meshed_resting.push_back(fluid.position[i]);
        meshed_resting_ids.push_back(fluid.id[i]);
      }
    }
    return meshing->submit(solver.time(), meshed_moving, meshed_resting, meshed_resting_ids);
  };
  auto mesh_if_due = [&]() {
    if (!meshing || solver.time() + 1e-12 < next_mesh_time) return;
    if (options.wait_for_meshes) meshing->wait_idle();
    if (submit_mesh()) last_meshed_time = solver.time();
    if (options.wait_for_meshes) meshing->wait_idle();
    while (next_mesh_time <= solver.time() + 1e-12) next_mesh_time += meshing_settings.period;
  };

  summary.status = "completed";
  try {
    write_frame_if_due();
    while (solver.time() < end_time - 1e-12) {
      if (options.stop_requested && options.stop_requested->load()) {
        summary.status = "interrupted";
        break;
      }
      const sph::StepStats& stats = simulation.step();
      const double output_ms = write_frame_if_due();
      mesh_if_due();
      if (meshing) {
        // The newest finished mesh joins the world as a collision body (replacing the previous one).
        auto newest = meshing->latest_mesh();
        if (newest && newest != inserted_mesh) {
          simulation.set_printed_mesh(*newest);
          inserted_mesh = std::move(newest);
          ++summary.meshes_inserted;
        }
      }
      const std::size_t particles = solver.fluid().size();
      particle_steps += static_cast<double>(particles);
      density_iterations_sum += stats.density_iterations;
      divergence_iterations_sum += stats.divergence_iterations;
      viscosity_iterations_sum += stats.viscosity_iterations;
      summary.max_density_error = std::max(summary.max_density_error, static_cast<double>(stats.density_error));
      if (timing) {
        fmt::print(timing, "{},{:.8g},{:.6g},{},{},{},{},{:.4g}", solver.state().step, solver.time(), stats.time_step, particles,
                   stats.density_iterations, stats.divergence_iterations, stats.viscosity_iterations, stats.density_error);
        for (const double ms : stats.stage_ms.ms) fmt::print(timing, ",{:.4f}", ms);
        fmt::print(timing, ",{:.4f},{:.4f},{:.4f},{:.4f}\n", simulation.last_coupling_ms(), simulation.last_world_ms(), output_ms,
                   stats.stage_ms.total() + simulation.last_coupling_ms() + simulation.last_world_ms() + output_ms);
      }
      progress.update({solver.time(), end_time, solver.state().step, static_cast<long long>(particles), wall_seconds()});
    }
  } catch (const SimulationError& error) {
    summary.status = "failed";
    summary.error = error.what();
  }

  if (meshing) {
    // The final state is always meshed (after the mesh in progress): nothing printed goes unmeshed.
    meshing->wait_idle();
    if (last_meshed_time < solver.time() && solver.fluid().size() > 0) {
      submit_mesh();
      meshing->wait_idle();
    }
    summary.meshes_written = meshing->meshes().size();
    summary.meshes_skipped = meshing->skipped();
    if (!meshing->error().empty() && summary.error.empty()) summary.error = meshing->error();
  }
  summary.wall_time = wall_seconds();
  summary.simulated_time = solver.time();
  summary.steps = solver.state().step;
  summary.real_time_factor = summary.wall_time > 0 ? summary.simulated_time / summary.wall_time : 0;
  summary.particle_steps_per_second = summary.wall_time > 0 ? particle_steps / summary.wall_time : 0;
  summary.particles = solver.fluid().size();
  summary.particles_at_rest = solver.fluid().size() - solver.state().active_count;
  summary.particles_removed = solver.state().particles_removed_total;
  summary.mass_emitted = solver.state().mass_emitted_total;
  summary.mass_lost = solver.state().mass_removed_total;
  summary.mass_final = solver.total_fluid_mass();
  summary.frames_written = frames ? frames->frames() : 0;
  for (const auto& nozzle : solver.state().nozzles) {
    summary.particles_emitted += nozzle.particles_emitted;
    summary.blocked_layers += nozzle.blocked_layers;
  }
  for (std::size_t r = 0; r < simulation.robots().size(); ++r) {
    RunSummary::Robot robot;
    robot.name = simulation.world().robot_name(simulation.robots()[r]);
    robot.contacts = simulation.world().robot_contacts(simulation.robots()[r]);
    if (simulation.world().has_diff_drive(simulation.robots()[r])) robot.base = simulation.world().base_report(simulation.robots()[r]);
    for (std::size_t h = 0; h < simulation.scene().print_heads.size(); ++h) {
      const auto& mount = simulation.scene().print_heads[h].mount;
      if (!mount || mount->robot != robot.name) continue;
      robot.tracking_rms = simulation.world().tool_tracking_rms(*simulation.print_head_tool(h));
      robot.tracking_max = simulation.world().tool_tracking_max(*simulation.print_head_tool(h));
    }
    summary.robots.push_back(robot);
  }
  summary.granular = solver.granular();
  if (summary.steps > 0) {
    summary.mean_density_iterations = density_iterations_sum / static_cast<double>(summary.steps);
    summary.mean_divergence_iterations = divergence_iterations_sum / static_cast<double>(summary.steps);
    summary.mean_viscosity_iterations = viscosity_iterations_sum / static_cast<double>(summary.steps);
  }
  progress.finish({solver.time(), end_time, solver.state().step, static_cast<long long>(summary.particles), summary.wall_time});

  if (writing) {
    std::fclose(timing);
    std::filesystem::rename(timing_partial, timing_final);
    io::write_text_atomically(options.output_directory / "summary.json", summary_json(summary, simulation, meshing.get()).dump(2) + "\n");
  }
  return summary;
}

std::string format_summary(const RunSummary& summary, const std::filesystem::path& output_directory) {
  std::string text;
  text += fmt::format("Run {}: simulated {:.4f} of {:.4f} s in {} steps, {:.2f} s wall time\n", summary.status,
                      summary.simulated_time, summary.end_time, summary.steps, summary.wall_time);
  if (!summary.error.empty()) text += fmt::format("  error: {}\n", summary.error);
  text += fmt::format("  speed       {:.3g} x real time, {:.3g} particle-steps/s\n", summary.real_time_factor,
                      summary.particle_steps_per_second);
  text += fmt::format("  particles   {} now ({} at rest, not simulated), {} emitted, {} left the bounds\n", summary.particles,
                      summary.particles_at_rest, summary.particles_emitted,
                      summary.particles_removed);
  if (summary.blocked_layers > 0)
    text += fmt::format("  nozzles     a due layer found no room in front of its nozzle in {} steps (material backing up "
                        "under it; it left later)\n",
                        summary.blocked_layers);
  text += fmt::format("  mass        {:.6g} kg initial + {:.6g} emitted - {:.6g} lost = {:.6g} kg\n", summary.mass_initial,
                      summary.mass_emitted, summary.mass_lost, summary.mass_final);
  if (summary.granular)
    text += fmt::format("  solver      granular contacts (spring-dashpot), mean time step {:.3g} ms\n",
                        summary.steps > 0 ? 1e3 * summary.simulated_time / double(summary.steps) : 0.0);
  else
    text += fmt::format("  solver      {:.2f} density + {:.2f} divergence + {:.2f} viscosity iterations per step, max mean "
                        "density error {:.3f} %\n",
                        summary.mean_density_iterations, summary.mean_divergence_iterations, summary.mean_viscosity_iterations,
                        100 * summary.max_density_error);
  if (!output_directory.empty())
    text += fmt::format("  output      {} ({} particle frames; open particles.pvd in ParaView)\n", output_directory.string(),
                        summary.frames_written);
  for (const auto& robot : summary.robots)
    text += fmt::format("  robot       {}: nozzle {:.2f} mm rms from its path (max {:.2f} mm); contacts: {} with robots, {} "
                        "with printed material, {} other\n",
                        robot.name, 1e3 * robot.tracking_rms, 1e3 * robot.tracking_max, robot.contacts.with_robots,
                        robot.contacts.with_printed_material, robot.contacts.with_other);
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
