// The summary's figures: sums over the steps (iterations, particle-steps, the solver's largest density
// error estimate) and, when the run ends, the state's totals, the volume balance, the nozzles' and the
// robots' reports.
#include <algorithm>
#include <array>
#include <chrono>

#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

class RunFigures final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the run's figures"; }
  [[nodiscard]] bool is_output() const override { return false; }
  void start(const Simulation& /*simulation*/) override { wall_start_ = std::chrono::steady_clock::now(); }
  // The sums go on across a resume; the wall time counts the run's segments, not the time it stood.
  void save(StateWriter& out) override {
    out.put(std::array<double, 7>{wall_seconds(), steps_, particle_steps_, density_iterations_, divergence_iterations_,
                                  viscosity_iterations_, max_density_error_});
  }
  void resume(const Simulation& /*simulation*/, StateReader& in) override {
    const auto values = in.get<std::array<double, 7>>();
    wall_start_ = std::chrono::steady_clock::now() -
                  std::chrono::duration_cast<std::chrono::steady_clock::duration>(std::chrono::duration<double>(values[0]));
    steps_ = values[1], particle_steps_ = values[2], density_iterations_ = values[3];
    divergence_iterations_ = values[4], viscosity_iterations_ = values[5], max_density_error_ = values[6];
  }

  void observe(const Simulation& simulation, const StepReport& report) override {
    const sph::StepStats& stats = report.stats;
    ++steps_;
    particle_steps_ += static_cast<double>(simulation.solver().fluid().size());
    density_iterations_ += stats.density_iterations;
    divergence_iterations_ += stats.divergence_iterations;
    viscosity_iterations_ += stats.viscosity_iterations;
    max_density_error_ = std::max(max_density_error_, static_cast<double>(stats.density_error));
  }

  void finish(const Simulation& simulation, RunSummary& summary) override {
    const auto& solver = simulation.solver();
    const auto& state = solver.state();
    summary.wall_time = wall_seconds();
    summary.simulated_time = solver.time();
    summary.steps = state.step;
    summary.real_time_factor = summary.wall_time > 0 ? summary.simulated_time / summary.wall_time : 0;
    summary.particle_steps_per_second = summary.wall_time > 0 ? particle_steps_ / summary.wall_time : 0;
    summary.solver_density_error = max_density_error_;
    summary.particles = solver.fluid().size();
    summary.particles_at_rest = solver.fluid().size() - state.active_count;
    summary.particles_removed = state.particles_removed_total;
    summary.mass_emitted = state.mass_emitted_total;
    summary.mass_lost = state.mass_removed_total;
    summary.mass_final = solver.total_fluid_mass();
    const auto& boundary = state.boundary;
    summary.boundary_particles = boundary.size();
    for (const Index body : boundary.body) summary.static_boundary_particles += state.bodies[body].is_static ? 1 : 0;
    const auto bytes = [](const auto& array) { return double(array.capacity() * sizeof(array[0])); };
    summary.boundary_megabytes = 1e-6 * (bytes(boundary.local_position) + bytes(boundary.position) + bytes(boundary.velocity) +
                                         bytes(boundary.volume) + bytes(boundary.body) + bytes(boundary.wall_kind));
    for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
      sph::NozzleState nozzle = state.nozzles[n];
      nozzle.end_blockage(solver.time());  // one that lasts to the end counts too
      summary.particles_emitted += nozzle.particles_emitted;
      summary.blocked_layers += nozzle.blocked_layers;
      RunSummary::Nozzle report;
      report.name = solver.parameters().nozzles[n].name;
      report.layers_emitted = nozzle.layers_emitted;
      report.particles_emitted = nozzle.particles_emitted;
      report.steps_blocked = nozzle.blocked_layers;
      const Simulation::VolumeBalance volumes = simulation.nozzle_volumes(n);
      report.volume_commanded = volumes.commanded;
      report.volume_emitted = volumes.emitted;
      report.volume_lost = volumes.lost_at_nozzles;
      report.blocked_time = nozzle.blocked_time;
      report.volume_primed = volumes.primed;
      report.volume_in_bore = volumes.in_bores;
      report.volume_laid = volumes.laid;
      report.path_time = simulation.path_time(n);
      if (solver.model().nozzle_geometry[n].has_bore()) {
        report.extrusion_pressure = nozzle.extrusion_pressure;
        report.extrusion_pressure_max = nozzle.extrusion_pressure_max;
      }
      report.longest_blockage = nozzle.longest_blockage;
      summary.nozzles.push_back(report);
    }
    const Simulation::VolumeBalance balance = simulation.volume_balance();
    summary.volume.commanded = balance.commanded;
    summary.volume.emitted = balance.emitted;
    summary.volume.primed = balance.primed;
    summary.volume.in_bores = balance.in_bores;
    summary.volume.laid = balance.laid;
    summary.volume.lost_at_nozzles = balance.lost_at_nozzles;
    summary.volume.removed = balance.removed;
    summary.volume.in_particles = balance.in_particles;
    const auto& world = simulation.world();
    for (std::size_t r = 0; r < simulation.robots().size(); ++r) {
      const world::RobotIndex index = simulation.robots()[r];
      RunSummary::Robot robot;
      robot.name = world.robot_name(index);
      robot.contacts = world.robot_contacts(index);
      if (world.has_diff_drive(index)) robot.base = world.base_report(index);
      if (const auto* coordination = simulation.coordination()) robot.coordination = coordination->reports()[r];
      for (std::size_t h = 0; h < simulation.scene().print_heads.size(); ++h) {
        const auto& mount = simulation.scene().print_heads[h].mount;
        if (!mount || mount->robot != robot.name) continue;
        robot.tracking_rms = world.tool_tracking_rms(*simulation.print_head_tool(h));
        robot.tracking_max = world.tool_tracking_max(*simulation.print_head_tool(h));
      }
      summary.robots.push_back(robot);
    }
    summary.granular = solver.granular();
    if (steps_ > 0) {
      // Over the steps of this run (a resumed one's included).
      summary.mean_density_iterations = density_iterations_ / steps_;
      summary.mean_divergence_iterations = divergence_iterations_ / steps_;
      summary.mean_viscosity_iterations = viscosity_iterations_ / steps_;
    }
  }

 private:
  [[nodiscard]] double wall_seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start_).count(); }

  std::chrono::steady_clock::time_point wall_start_;
  double steps_ = 0, particle_steps_ = 0, density_iterations_ = 0, divergence_iterations_ = 0, viscosity_iterations_ = 0;
  double max_density_error_ = 0;
};

}  // namespace

std::unique_ptr<RunObserver> make_run_figures(Simulation& /*simulation*/, const RunOptions& /*options*/) {
  return std::make_unique<RunFigures>();
}

}  // namespace m3dp::sim::outputs
