// summary.json (what the run did, the bodies' fluid forces, the nozzles', robots' and meshes'
// reports), written when the run ends however it ends, and scene.sdf, the scene's copy, at the start.
#include <cmath>
#include <nlohmann/json.hpp>

#include "m3dp/io/atomic_file.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

nlohmann::json summary_json(const RunSummary& summary, const Simulation& simulation) {
  nlohmann::json bodies = nlohmann::json::array();
  for (const auto& body : simulation.solver().bodies())
    bodies.push_back({{"name", body.name},
                      {"fluid_force_N", {body.fluid_force.x(), body.fluid_force.y(), body.fluid_force.z()}},
                      {"fluid_torque_Nm", {body.fluid_torque.x(), body.fluid_torque.y(), body.fluid_torque.z()}}});
  nlohmann::json meshes = nlohmann::json::array();
  for (const auto& mesh : summary.meshes)
      meshes.push_back({{"time_s", mesh.time},
                        {"file", std::filesystem::relative(mesh.file, std::filesystem::path(summary.output_directory)).generic_string()},
                        {"particles", mesh.particles},
                        {"triangles", mesh.triangles},
                        {"volume_m3", mesh.volume},
                        {"reused_particles", mesh.reused_particles},
                        {"tiles", mesh.tiles},
                        {"remeshed_tiles", mesh.remeshed_tiles},
                        {"seconds", mesh.seconds}});
  nlohmann::json nozzles = nlohmann::json::array();
  for (const auto& nozzle : summary.nozzles) {
    nlohmann::json entry = {{"name", nozzle.name},
                            {"layers_emitted", nozzle.layers_emitted},
                            {"particles_emitted", nozzle.particles_emitted},
                            {"steps_blocked", nozzle.steps_blocked},
                            {"volume_commanded_m3", nozzle.volume_commanded},
                            {"volume_emitted_m3", nozzle.volume_emitted},
                            {"volume_laid_m3", nozzle.volume_laid},
                            {"path_time_s", nozzle.path_time},
                            {"volume_lost_m3", nozzle.volume_lost},
                            {"blocked_time_s", nozzle.blocked_time}};
    if (nozzle.extrusion_pressure >= 0) {
      entry["volume_primed_m3"] = nozzle.volume_primed;
      entry["volume_in_bore_m3"] = nozzle.volume_in_bore;
      entry["extrusion_pressure_Pa"] = nozzle.extrusion_pressure;
      entry["extrusion_pressure_max_Pa"] = nozzle.extrusion_pressure_max;
    }
    if (nozzle.longest_blockage.duration > 0) {
      const Vec3& at = nozzle.longest_blockage.position;
      entry["longest_blockage"] = {{"start_s", nozzle.longest_blockage.start},
                                   {"duration_s", nozzle.longest_blockage.duration},
                                   {"position_m", {at.x(), at.y(), at.z()}}};
    }
    nozzles.push_back(entry);
  }
  const auto density_check = [](const RunSummary::DensityCheck& check) {
    return nlohmann::json{{"time_s", check.time},           {"particles", check.statistics.particles},
                          {"mean", check.statistics.mean},  {"median", check.statistics.median},
                          {"p99", check.statistics.p99},    {"max", check.statistics.max}};
  };
  nlohmann::json materials = nlohmann::json::array();
  for (const auto& phase : simulation.solver().parameters().phases)
    materials.push_back({{"name", phase.name}, {"rest_density_kg_m3", phase.density}});
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
  // Distances never measured (no other robot, no print) are null.
  auto finite_or_null = [](double value) { return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(); };
  for (std::size_t r = 0; r < summary.robots.size(); ++r)
    if (const auto& coordination = summary.robots[r].coordination)
      robots[r]["coordination"] = {{"waiting_time_s", coordination->waiting_time},
                                   {"slowed_time_s", coordination->slowed_time},
                                   {"decisions", coordination->decisions},
                                   {"conflicts", coordination->conflicts},
                                   {"blocked", coordination->blocked},
                                   {"least_robot_distance_m", finite_or_null(coordination->least_robot_distance)},
                                   {"least_print_distance_m", finite_or_null(coordination->least_print_distance)}};
  nlohmann::json coordinator;  // null: robots ran at full speed, uncoordinated
  if (const auto* coordination = simulation.coordination()) {
    const auto& settings = coordination->settings();
    coordinator = {{"period_s", settings.period},
                   {"horizon_s", settings.horizon},
                   {"samples", settings.samples},
                   {"robot_clearance_m", settings.robot_clearance},
                   {"print_clearance_m", settings.print_clearance},
                   {"priority", settings.priority}};
  }
  nlohmann::json recording;  // null: not recorded
  if (!summary.recording.file.empty())
    recording = {{"file", std::filesystem::relative(summary.recording.file, summary.output_directory).generic_string()},
                 {"messages", summary.recording.messages},
                 {"bytes", summary.recording.bytes},
                 {"chunks", summary.recording.chunks},
                 {"encode_seconds", summary.recording.encode_seconds}};
  nlohmann::json cameras = nlohmann::json::array();
  for (const auto& camera : summary.cameras)
    cameras.push_back({{"name", camera.name},
                       {"frames_written", camera.frames_written},
                       {"frames_rendered", camera.frames_rendered},
                       {"render_seconds", camera.render_seconds},
                       {"rays", camera.rays},
                       {"rays_per_second", camera.render_seconds > 0 ? double(camera.rays) / camera.render_seconds : 0.0}});
  nlohmann::json live;  // null: no live stream
  if (summary.live.port != 0)
    live = {{"port", summary.live.port},
            {"clients", summary.live.clients},
            {"messages_sent", summary.live.messages_sent},
            {"bytes_sent", summary.live.bytes_sent},
            {"messages_dropped", summary.live.messages_dropped}};
  nlohmann::json quality;  // null: not measured (no folder, no print heads, <quality_period> 0)
  if (const auto& measured = summary.quality) {
    if (measured->file.empty()) {
      quality = {{"note", measured->note}};
    } else {
      nlohmann::json shortfall;
      if (!measured->stood) shortfall = {{"layer", measured->shortfall_layer}, {"time_s", measured->shortfall_time}};
      nlohmann::json heads = nlohmann::json::array();
      for (const auto& head : measured->heads) {
        nlohmann::json head_shortfall;
        if (!head.stood) head_shortfall = {{"layer", head.shortfall_layer}, {"time_s", head.shortfall_time}};
        heads.push_back({{"name", head.name}, {"stood", head.stood}, {"shortfall", head_shortfall}});
      }
      quality = {{"file", measured->file},
                 {"layers", measured->layers},
                 {"sections", measured->sections},
                 {"width_m", measured->width},
                 {"design_width_m", measured->design_width},
                 {"height_m", measured->height},
                 {"design_height_m", measured->design_height},
                 {"fill_over_m3", measured->fill_over},
                 {"fill_under_m3", measured->fill_under},
                 {"fill_designed_m3", measured->fill_designed},
                 {"surface_deviation_p95_m", measured->deviation_p95},
                 {"surface_deviation_max_m", measured->deviation_max},
                 {"stood", measured->stood},
                 {"shortfall", shortfall},
                 {"heads", heads},
                 {"resolution_warning", measured->resolution_warning.empty() ? nlohmann::json() : nlohmann::json(measured->resolution_warning)}};
    }
  }
  return {
      {"scene", simulation.scene().file.string()},
      {"status", to_string(summary.status)},
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
      {"density_error",
       {{"definition", "rho/rho0 - 1 over all particles, measured from their positions at the end of a step, as in the "
                       "particle frames"},
        {"checks", summary.density.checks},
        {"last", density_check(summary.density.last)},
        {"worst_p99", density_check(summary.density.worst_p99)},
        {"worst_max", density_check(summary.density.worst_max)}}},
      {"volume_m3",
       {{"commanded", summary.volume.commanded},
        {"emitted", summary.volume.emitted},
        {"primed", summary.volume.primed},
        {"in_bores", summary.volume.in_bores},
        {"laid", summary.volume.laid},
        {"lost_at_nozzles", summary.volume.lost_at_nozzles},
        {"removed", summary.volume.removed},
        {"in_particles", summary.volume.in_particles},
        {"last_mesh", summary.meshes.empty() ? nlohmann::json() : nlohmann::json(summary.meshes.back().volume)},
        {"last_mesh_time_s", summary.meshes.empty() ? nlohmann::json() : nlohmann::json(summary.meshes.back().time)}}},
      {"solver_density_error_estimate", summary.solver_density_error},
      {"mean_density_iterations", summary.mean_density_iterations},
      {"mean_divergence_iterations", summary.mean_divergence_iterations},
      {"mean_viscosity_iterations", summary.mean_viscosity_iterations},
      {"granular", summary.granular},
      {"particles_at_rest", summary.particles_at_rest},
      {"frames_written", summary.frames_written},
      {"particle_frame_period_s", summary.frame_period},
      {"particle_frame_period_chosen", summary.frame_period_chosen},
      {"world_frames_written", summary.world_frames_written},
      {"particle_radius_m", simulation.solver().parameters().settings.particle_radius},
      {"boundary",
       {{"particles", summary.boundary_particles},
        {"static_particles", summary.static_boundary_particles},
        {"megabytes", summary.boundary_megabytes}}},
      {"materials", materials},
      {"bodies", bodies},
      {"nozzles", nozzles},
      {"robots", robots},
      {"coordinator", coordinator},
      {"meshes", meshes},
      {"meshes_skipped", summary.meshes_skipped},
      {"meshes_inserted", summary.meshes_inserted},  // joined the world as the printed body
      {"recording", recording},
      {"live", live},
      {"cameras", cameras},
      {"quality", quality},
  };
}

class SummaryFile final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the summary (summary.json)"; }
  SummaryFile(const Simulation& simulation, std::filesystem::path output_directory)
      : simulation_(&simulation), output_directory_(std::move(output_directory)) {}
  [[nodiscard]] double period() const override { return 0; }
  [[nodiscard]] bool is_output() const override { return false; }
  void start(const Simulation& simulation) override {
    std::error_code ignored;
    if (std::filesystem::exists(simulation.scene().file))
      std::filesystem::copy_file(simulation.scene().file, output_directory_ / "scene.sdf",
                                 std::filesystem::copy_options::overwrite_existing, ignored);
    write_running(simulation);
  }
  // While it runs, summary.json says so (never an earlier run's summary in the same folder), and how
  // far the last checkpoint got.
  void save(StateWriter& /*out*/) override { write_running(*simulation_); }
  void resume(const Simulation& simulation, StateReader& /*in*/) override { write_running(simulation); }
  void observe(const Simulation& /*simulation*/, const StepReport& /*report*/) override {}
  void report(const Simulation& simulation, RunSummary& summary) override {
    io::write_text_atomically(output_directory_ / "summary.json", summary_json_text(summary, simulation));
  }

 private:
  void write_running(const Simulation& simulation) const {
    const nlohmann::json running = {{"status", "running"},
                                    {"scene", simulation.scene().file.string()},
                                    {"simulated_time_s", simulation.time()},
                                    {"steps", simulation.solver().state().step}};
    io::write_text_atomically(output_directory_ / "summary.json", running.dump(2) + "\n");
  }

  const Simulation* simulation_;
  std::filesystem::path output_directory_;
};

}  // namespace

std::unique_ptr<RunObserver> make_summary_file(Simulation& simulation, const RunOptions& options) {
  if (options.output_directory.empty()) return nullptr;
  return std::make_unique<SummaryFile>(simulation, options.output_directory);
}

}  // namespace m3dp::sim::outputs

namespace m3dp::sim {
std::string summary_json_text(const RunSummary& summary, const Simulation& simulation) {
  return outputs::summary_json(summary, simulation).dump(2) + "\n";
}
}  // namespace m3dp::sim
