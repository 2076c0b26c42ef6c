// `m3dp bench`: a dam break at a chosen particle count; prints particle-steps per second and
// milliseconds per step for each stage (the same stages as timing.csv).
#include "bench_command.hpp"

#include <fmt/format.h>

#include <chrono>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::app {

void add_bench_options(CLI::App& command, BenchOptions& options) {
  command.add_option("--particles", options.particles, "Fluid particles in the dam-break column")->capture_default_str();
  command.add_option("--steps", options.steps, "Timed steps")->capture_default_str();
  command.add_option("--warmup", options.warmup_steps, "Steps before timing starts")->capture_default_str();
  command.add_option("--tolerance", options.density_tolerance, "Mean density error tolerance (fraction)")->capture_default_str();
  command.add_option("--cfl", options.cfl_factor, "CFL factor")->capture_default_str();
  command.add_option("--threads", options.threads, "Worker threads (0 = all cores)")->capture_default_str();
  command.add_option("--kernel", options.kernel, "cubic_spline or wendland_c2")->capture_default_str();
}

int bench_command(const BenchOptions& options) {
  ThreadLimit thread_limit(options.threads);
  sim::DamBreakSetup setup;
  setup.column_width = Real(0.5);
  setup.depth = Real(0.25);
  setup.particle_radius = sim::dam_break_radius_for_count(options.particles, setup.column_width, setup.depth);
  setup.end_time = 100;
  setup.kernel = options.kernel == "wendland_c2" ? sph::KernelType::wendland_c2 : sph::KernelType::cubic_spline;
  scene::Scene scene = sim::dam_break_scene(setup);
  scene.solver.density_tolerance = static_cast<Real>(options.density_tolerance);
  scene.solver.cfl_factor = static_cast<Real>(options.cfl_factor);
  sim::Simulation simulation(scene);
  auto& solver = simulation.solver();
  fmt::print("dam break: {} fluid + {} boundary particles, radius {:.4g} m, {} threads, tolerance {:.3g} %, CFL {}\n",
             solver.fluid().size(), solver.boundary().size(), setup.particle_radius, ThreadLimit::active_threads(),
             100 * options.density_tolerance, options.cfl_factor);
  for (int i = 0; i < options.warmup_steps; ++i) simulation.step();

  sph::StageTimes sum;
  double particle_steps = 0, density_iterations = 0, divergence_iterations = 0, simulated = 0;
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < options.steps; ++i) {
    const auto& stats = simulation.step();
    const auto& ms = stats.stage_ms;
    sum.bodies += ms.bodies; sum.remove += ms.remove; sum.emit += ms.emit; sum.reorder += ms.reorder;
    sum.neighbors += ms.neighbors; sum.density += ms.density; sum.divergence += ms.divergence;
    sum.forces += ms.forces; sum.pressure += ms.pressure; sum.advect += ms.advect;
    particle_steps += static_cast<double>(solver.fluid().size());
    density_iterations += stats.density_iterations;
    divergence_iterations += stats.divergence_iterations;
    simulated += stats.time_step;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double n = options.steps;
  fmt::print("{} steps in {:.3f} s: {:.3g} particle-steps/s, {:.2f} ms/step, mean dt {:.3g} s, real-time factor {:.3g}\n",
             options.steps, seconds, particle_steps / seconds, 1000 * seconds / n, simulated / n, simulated / seconds);
  fmt::print("iterations per step: density {:.2f}, divergence {:.2f}\n", density_iterations / n, divergence_iterations / n);
  fmt::print("stage,ms_per_step\n");
  const std::pair<const char*, double> stages[] = {
      {"bodies", sum.bodies},   {"remove", sum.remove},   {"emit", sum.emit},         {"reorder", sum.reorder},
      {"neighbors", sum.neighbors}, {"density", sum.density}, {"divergence", sum.divergence}, {"forces", sum.forces},
      {"pressure", sum.pressure}, {"advect", sum.advect}};
  for (const auto& [name, total] : stages) fmt::print("{},{:.3f}\n", name, total / n);
  return 0;
}

}  // namespace m3dp::app
