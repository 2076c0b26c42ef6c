// `m3dp bench`: a dam break at a chosen particle count; prints particle-steps per second and
// milliseconds per step for each stage (the same stages as timing.csv). `m3dp bench ur10_wall`
// runs the robot-printing demo whole (world, coupling and meshing included) and reports its
// real-time factor and stage times.
#include "bench_command.hpp"

#include <fmt/format.h>

#include <array>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <tuple>
#include <unistd.h>

#include "m3dp/core/memory.hpp"
#include "m3dp/core/parallel.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sph/measure.hpp"
#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/print_quality.hpp"
#include "m3dp/sim/run.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/sim/strand_deposition.hpp"

namespace m3dp::app {

void add_bench_options(CLI::App& command, BenchOptions& options) {
  command.add_option("scenario", options.scenario,
                     "dam_break (the solver alone), ur10_wall (robot printing, everything) or clay_print (a "
                     "Herschel-Bulkley clay at up to --max-viscosity, implicit viscosity) or wall_layers (a clay wall "
                     "of --layers layers: the cost of a step at the top layer against the second) or strand (a pressed "
                     "and a free mortar strand from a nozzle with a bore, and from the exit-plane inlet) or nozzle (a 5,000 Pa*s "
                     "paste from a 0.3 m nozzle onto a floor, as compared with SPlisHSPlasH) or plate (a short print on a 10 x 10 m "
                     "floor: setup time, boundary particles, memory) or construction (a 0.5 m square mortar wall of --layers "
                     "10 mm layers from a 20 mm nozzle, r = 1.5 mm: the real-time factor, iterations and stage times a layer)")
      ->check(CLI::IsMember({"dam_break", "ur10_wall", "clay_print", "wall_layers", "strand", "nozzle", "plate", "construction"}))
      ->capture_default_str();
  command.add_option("--scene", options.scene_file, "ur10_wall, nozzle, plate: scene file to run instead of the project's");
  command.add_option("--particles", options.particles, "Fluid particles in the dam-break column or the clay slab")
      ->capture_default_str();
  command.add_option("--record", options.record, "ur10_wall: record run.mcap as the scene says (scene), or on, or off")
      ->check(CLI::IsMember({"scene", "on", "off"}))
      ->capture_default_str();
  command.add_option("--layers", options.layers, "wall_layers, construction: layers of the wall")->capture_default_str();
  command.add_option("--seconds", options.seconds, "construction: simulated seconds to run (default: the whole wall); dam_break: run to this time instead of --steps");
  command.add_option("--max-viscosity", options.max_viscosity, "clay_print: cap of the clay's effective viscosity (Pa*s)")
      ->capture_default_str();
  command.add_option("--steps", options.steps, "Timed steps")->capture_default_str();
  command.add_option("--warmup", options.warmup_steps, "Steps before timing starts")->capture_default_str();
  command.add_option("--tolerance", options.density_tolerance, "Mean density error tolerance (fraction)")->capture_default_str();
  command.add_option("--cfl", options.cfl_factor, "CFL factor")->capture_default_str();
  command.add_option("--threads", options.threads, "Worker threads (0 = all cores)")->capture_default_str();
  command.add_option("--kernel", options.kernel, "cubic_spline or wendland_c2")->capture_default_str();
}

namespace {
int bench_ur10_wall(const BenchOptions& options) {
  const std::filesystem::path file =
      options.scene_file.empty() ? std::filesystem::path(M3DP_PROJECT_SCENES) / "ur10_wall.sdf" : std::filesystem::path(options.scene_file);
  scene::Scene scene = scene::load_scene(file);
  scene.output.write_particles = false;  // meshing stays: it is part of the goal
  if (options.record != "scene") scene.output.mcap = options.record == "on";
  sim::Simulation simulation(scene);
  sim::RunOptions run;
  run.output_directory = std::filesystem::temp_directory_path() / fmt::format("m3dp_bench_ur10_wall_{}", ::getpid());
  run.show_progress = false;
  fmt::print("ur10_wall: {} ({} threads), {:.1f} s simulated, meshing every {:.3g} s\n", file.string(),
             ThreadLimit::active_threads(), scene.end_time, scene.meshing.enabled ? double(scene.meshing.period) : 0.0);
  const sim::RunSummary summary = sim::run_simulation(simulation, run);
  // Stage means from the run's own timing table.
  std::ifstream timing(run.output_directory / "timing.csv");
  std::string line;
  std::getline(timing, line);
  std::vector<std::string> columns;
  for (std::stringstream header(line); std::getline(header, line, ',');) columns.push_back(line);
  std::vector<double> sums(columns.size(), 0.0);
  std::size_t rows = 0;
  while (std::getline(timing, line)) {
    std::stringstream row(line);
    for (std::size_t c = 0; c < columns.size() && std::getline(row, line, ','); ++c) sums[c] += std::atof(line.c_str());
    ++rows;
  }
  std::filesystem::remove_all(run.output_directory);
  fmt::print("{} in {:.2f} s wall: real-time factor {:.3g} (goal >= 1), {} steps ({:.2f} ms/step, mean dt {:.3g} ms), "
             "{} particles at the end, {:.3g} particle-steps/s\n",
             sim::to_string(summary.status), summary.wall_time, summary.real_time_factor, summary.steps, 1e3 * summary.wall_time / double(summary.steps),
             1e3 * summary.simulated_time / double(summary.steps), summary.particles, summary.particle_steps_per_second);
  fmt::print("meshes: {} written, {} skipped while busy; density iterations {:.2f}, divergence {:.2f} per step\n",
             summary.meshes_written, summary.meshes_skipped, summary.mean_density_iterations, summary.mean_divergence_iterations);
  if (!summary.recording.file.empty())
    fmt::print("recording: {} messages, {:.1f} MB in {} chunks, {:.3f} s wall to make and write ({:.1f} % of the run)\n",
               summary.recording.messages, 1e-6 * double(summary.recording.bytes), summary.recording.chunks,
               summary.recording.encode_seconds, 100 * summary.recording.encode_seconds / summary.wall_time);
  for (const auto& robot : summary.robots)
    fmt::print("robot {}: nozzle {:.3f} mm rms from the path (max {:.3f} mm), {} contacts with robots\n", robot.name,
               1e3 * robot.tracking_rms, 1e3 * robot.tracking_max, robot.contacts.with_robots);
  fmt::print("stage,ms_per_step\n");
  for (std::size_t c = 0; c < columns.size(); ++c)
    if (columns[c].starts_with("ms_")) fmt::print("{},{:.3f}\n", columns[c].substr(3), rows ? sums[c] / double(rows) : 0.0);
  return summary.status == sim::RunStatus::completed ? 0 : 1;
}
}  // namespace


/// What sets the CFL step (issue 57, goal 3): over windows of simulated time, the fastest particle's
/// speed after each step, where it is, and the speed that 99.9 % of the particles stay under; the
/// steps a CFL rule on that percentile would have taken say how much a few fast particles cost.
class SpeedLog {
 public:
  SpeedLog(double window_seconds, double cfl_factor, double particle_diameter)
      : window_(window_seconds), cfl_factor_(cfl_factor), diameter_(particle_diameter) {
    fmt::print("what sets the step (after each step: the fastest particle, its height, the 99.9th percentile's speed)\n");
    fmt::print("t_s,steps,mean_dt_ms,max_speed_m_s,fastest_z_m,p999_speed_m_s,steps_at_p999\n");
  }
  void add(const sph::State& state, double time_step) {
    const auto& velocity = state.fluid.velocity;
    speeds_.resize(velocity.size());
    double fastest = 0;
    std::size_t fastest_index = 0;
    for (std::size_t i = 0; i < velocity.size(); ++i) {
      speeds_[i] = velocity[i].norm();
      if (speeds_[i] > fastest) fastest = speeds_[i], fastest_index = i;
    }
    double percentile = 0;
    if (!speeds_.empty()) {
      const auto nth = speeds_.begin() + static_cast<std::ptrdiff_t>(0.999 * double(speeds_.size() - 1));
      std::nth_element(speeds_.begin(), nth, speeds_.end());
      percentile = *nth;
    }
    ++steps_;
    simulated_ += time_step;
    if (fastest > max_speed_) max_speed_ = fastest, fastest_z_ = velocity.empty() ? 0 : state.fluid.position[fastest_index].z();
    max_percentile_ = std::max(max_percentile_, percentile);
    // The step a CFL rule on the percentile would take (as the solver's rule, at most 5 ms).
    const double percentile_step = percentile > 1e-9 ? std::min(5e-3, cfl_factor_ * 0.4 * diameter_ / percentile) : 5e-3;
    percentile_steps_ += time_step / std::max(percentile_step, time_step);
    if (simulated_ >= window_ - 1e-12) flush(state.time);
  }
  void flush(double time) {
    if (steps_ == 0) return;
    fmt::print("{:.2f},{},{:.3f},{:.3f},{:.3f},{:.3f},{:.0f}\n", time, steps_, 1e3 * simulated_ / double(steps_), max_speed_,
               fastest_z_, max_percentile_, percentile_steps_);
    steps_ = 0, simulated_ = 0, max_speed_ = 0, fastest_z_ = 0, max_percentile_ = 0, percentile_steps_ = 0;
  }

 private:
  double window_, cfl_factor_, diameter_;
  std::vector<double> speeds_;
  std::uint64_t steps_ = 0;
  double simulated_ = 0, max_speed_ = 0, fastest_z_ = 0, max_percentile_ = 0, percentile_steps_ = 0;
};

/// A scene of bench/scenes run to its end (issue 41's cases): setup time, boundary particles and
/// memory, then the loop's time, steps, iterations a step and stage times, for comparison with a peer.
int bench_scene(const std::string& name, const BenchOptions& options) {
  const std::filesystem::path file = options.scene_file.empty()
                                         ? std::filesystem::path(M3DP_PROJECT_ROOT) / "bench" / "scenes" / (name + ".sdf")
                                         : std::filesystem::path(options.scene_file);
  const ResidentMemory memory_before = resident_memory();
  const auto setup_start = std::chrono::steady_clock::now();
  scene::Scene scene = scene::load_scene(file);
  scene.output.write_particles = false;
  sim::Simulation simulation(scene);
  const double setup_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - setup_start).count();
  const ResidentMemory memory_after = resident_memory();
  const auto& state = simulation.solver().state();
  fmt::print("{}: {} ({} threads), {:.2f} s simulated, particle radius {:.4g} m\n", name, file.string(), ThreadLimit::active_threads(),
             scene.end_time, double(scene.solver.particle_radius));
  fmt::print("setup: {:.3f} s, {} boundary particles, resident memory {:.0f} MB (+{:.0f} MB for the scene)\n", setup_seconds,
             state.boundary.size(), memory_after.now_megabytes, memory_after.now_megabytes - memory_before.now_megabytes);
  sph::StageTimes sum;
  double density = 0, divergence = 0, viscosity = 0;
  std::uint64_t steps = 0;
  std::array<std::uint64_t, sph::kTimeStepBoundNames.size()> bounds{};
  SpeedLog speeds(scene.end_time / 12, double(scene.solver.cfl_factor), 2 * double(scene.solver.particle_radius));
  const auto start = std::chrono::steady_clock::now();
  while (simulation.time() < scene.end_time - 1e-12) {
    const auto& stats = simulation.step();
    speeds.add(simulation.solver().state(), stats.time_step);
    ++bounds[static_cast<std::size_t>(stats.time_step_bound)];
    sum += stats.stage_ms;
    density += stats.density_iterations;
    divergence += stats.divergence_iterations;
    viscosity += stats.viscosity_iterations;
    ++steps;
  }
  speeds.flush(simulation.time());
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double n = double(std::max<std::uint64_t>(1, steps));
  fmt::print("loop: {:.3f} s for {} steps ({:.2f} ms/step, mean dt {:.3g} ms), {} particles and {} boundary particles at the end, "
             "peak resident memory {:.0f} MB\n",
             seconds, steps, 1e3 * seconds / n, 1e3 * simulation.time() / n, simulation.solver().fluid().size(), state.boundary.size(),
             resident_memory().peak_megabytes);
  fmt::print("iterations per step: density {:.2f}, divergence {:.2f}, viscosity {:.2f}\n", density / n, divergence / n, viscosity / n);
  std::string set_by;
  for (std::size_t b = 0; b < bounds.size(); ++b)
    if (bounds[b] > 0) set_by += fmt::format("{}{} {:.1f} %", set_by.empty() ? "" : ", ", sph::kTimeStepBoundNames[b], 100 * double(bounds[b]) / n);
  fmt::print("steps set by: {}\n", set_by);
  fmt::print("stage,ms_per_step\n");
  for (std::size_t s = 0; s < sph::kStageCount; ++s) fmt::print("{},{:.3f}\n", sph::kStageNames[s], sum.ms[s] / n);
  return 0;
}

/// Times `options.steps` steps after the warm-up and prints throughput, iterations and stage times.
void time_steps(sim::Simulation& simulation, const BenchOptions& options) {
  auto& solver = simulation.solver();
  for (int i = 0; i < options.warmup_steps; ++i) simulation.step();
  sph::StageTimes sum;
  double particle_steps = 0, density_iterations = 0, divergence_iterations = 0, viscosity_iterations = 0, simulated = 0;
  const std::uint64_t searches_before = solver.state().neighbor_searches;
  const auto start = std::chrono::steady_clock::now();
  for (int i = 0; i < options.steps; ++i) {
    const auto& stats = simulation.step();
    sum += stats.stage_ms;
    particle_steps += static_cast<double>(solver.fluid().size());
    density_iterations += stats.density_iterations;
    divergence_iterations += stats.divergence_iterations;
    viscosity_iterations += stats.viscosity_iterations;
    simulated += stats.time_step;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const double n = options.steps;
  fmt::print("{} steps in {:.3f} s: {:.3g} particle-steps/s, {:.2f} ms/step, mean dt {:.3g} s, real-time factor {:.3g}\n",
             options.steps, seconds, particle_steps / seconds, 1000 * seconds / n, simulated / n, simulated / seconds);
  fmt::print("iterations per step: density {:.2f}, divergence {:.2f}, viscosity {:.2f}\n", density_iterations / n,
             divergence_iterations / n, viscosity_iterations / n);
  fmt::print("neighbour searches: {} in {} steps (the others kept the lists, skin {} support radii)\n",
             solver.state().neighbor_searches - searches_before, options.steps, solver.parameters().settings.neighbor_skin);
  fmt::print("stage,ms_per_step\n");
  for (std::size_t s = 0; s < sph::kStageCount; ++s) fmt::print("{},{:.3f}\n", sph::kStageNames[s], sum.ms[s] / n);
}

int bench_clay_print(const BenchOptions& options) {
  sim::ClayPrintSetup setup;
  setup.slab_particles = options.particles;
  setup.max_viscosity = static_cast<Real>(options.max_viscosity);
  sim::Simulation simulation(sim::clay_print_scene(setup));
  const auto& solver = simulation.solver();
  const auto& clay = solver.parameters().phases.front();
  fmt::print("clay_print: {} clay particles (radius {:.3g} m) on a floor, a 10 mm nozzle printing on them; {} "
             "(tau0 {} Pa, K {} Pa*s^n, n {}), viscosity capped at {:.3g} Pa*s, steps up to {:.3g} s, {} threads\n",
             solver.fluid().size(), setup.particle_radius, clay.name, clay.rheology.yield_stress, clay.rheology.consistency,
             clay.rheology.flow_index, clay.rheology.max_viscosity, setup.time_step, ThreadLimit::active_threads());
  time_steps(simulation, options);
  Real largest = 0;
  double sum = 0;
  for (const Real mu : solver.fluid().viscosity) {
    largest = std::max(largest, mu);
    sum += mu;
  }
  fmt::print("effective viscosity at the end: mean {:.3g} Pa*s, largest {:.3g} Pa*s (goal: >= 1e6 particle-steps/s at "
             "1e4 Pa*s and >= 1 ms steps)\n",
             sum / double(std::max<std::size_t>(1, solver.fluid().size())), largest);
  return 0;
}

int bench_wall_layers(const BenchOptions& options) {
  sim::WallPrintSetup setup;
  setup.layers = options.layers;
  setup.max_viscosity = static_cast<Real>(options.max_viscosity);
  const scene::Scene scene = sim::wall_print_scene(setup);
  sim::Simulation simulation(scene);
  const auto& solver = simulation.solver();
  const double layer_time = 4 * double(setup.side) / double(setup.nozzle_speed);
  fmt::print("wall_layers: {} layers of clay (clay_paste, viscosity capped at {:.3g} Pa*s), {:.0f} mm square, {:.0f} mm "
             "layers, particle radius {:.3g} m, {:.1f} s per layer, {} threads\n",
             setup.layers, setup.max_viscosity, 1e3 * setup.side, 1e3 * setup.layer_height, setup.particle_radius, layer_time,
             ThreadLimit::active_threads());
  // Solver milliseconds per step, per layer (the world is trivial here).
  std::vector<double> milliseconds(static_cast<std::size_t>(setup.layers), 0.0), steps(milliseconds.size(), 0.0),
      active(milliseconds.size(), 0.0), resting(milliseconds.size(), 0.0), viscosity(milliseconds.size(), 0.0);
  std::vector<sph::StageTimes> stage_sums(milliseconds.size());
  const auto start = std::chrono::steady_clock::now();
  while (simulation.time() < scene.end_time) {
    const auto& stats = simulation.step();
    const auto layer = static_cast<std::size_t>(simulation.time() / layer_time);
    if (layer >= milliseconds.size()) continue;
    milliseconds[layer] += stats.stage_ms.total();
    stage_sums[layer] += stats.stage_ms;
    steps[layer] += 1;
    active[layer] += double(solver.state().active_count);
    resting[layer] += double(stats.particles_at_rest);
    viscosity[layer] += stats.viscosity_iterations;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  fmt::print("{:.1f} s simulated in {:.1f} s wall, {} particles at the end\n", simulation.time(), seconds, solver.fluid().size());
  fmt::print("layer,ms_per_step,active_particles,resting_particles,viscosity_iterations\n");
  for (std::size_t layer = 0; layer < milliseconds.size(); ++layer)
    if (steps[layer] > 0)
      fmt::print("{},{:.3f},{:.0f},{:.0f},{:.1f}\n", layer + 1, milliseconds[layer] / steps[layer], active[layer] / steps[layer],
                 resting[layer] / steps[layer], viscosity[layer] / steps[layer]);
  if (milliseconds.size() >= 2 && steps[1] > 0 && steps.back() > 0) {
    const double ratio = (milliseconds.back() / steps.back()) / (milliseconds[1] / steps[1]);
    fmt::print("cost of a step at layer {} / at layer 2: {:.2f} (goal <= 1.5)\n", setup.layers, ratio);
    fmt::print("stage,ms_per_step_layer_2,ms_per_step_layer_{}\n", setup.layers);
    const auto& first = stage_sums[1];
    const auto& last = stage_sums.back();
    const double n_first = steps[1], n_last = steps.back();
    for (std::size_t s = 0; s < sph::kStageCount; ++s)
      fmt::print("{},{:.3f},{:.3f}\n", sph::kStageNames[s], first.ms[s] / n_first, last.ms[s] / n_last);
  }
  return 0;
}

/// Issue 57's construction-scale wall: a 0.5 m square of 10 mm layers of a mortar (τ0 = 1.5 kPa,
/// μp = 10 Pa·s, 2,100 kg/m³) from a 20 mm nozzle at 0.1 m/s (a 32 mm bead, 20 s a layer) on a
/// no-slip 2 × 2 m floor, r = 1.5 mm. Per layer: the real-time factor, steps, moving particles,
/// density and viscosity iterations, and the main stages' ms a step; at the end the layers' heights
/// and widths as the quality report measures them.
int bench_construction(const BenchOptions& options) {
  const int layers = std::max(1, options.layers);
  const double layer_time = 20.0, end_time = options.seconds > 0 ? options.seconds : layers * layer_time + 1.0;
  const std::string text = fmt::format(R"(<?xml version="1.0"?>
<sdf version="1.9"><world name="construction_wall">
  <model name="floor"><static>true</static><link name="floor"><collision name="floor">
    <pose>0 0 -0.01 0 0 0</pose><geometry><box><size>2 2 0.02</size></box></geometry>
  </collision></link></model>
  <plugin name="m3dp" filename="m3dp">
    <solver><particle_radius unit="mm">1.5</particle_radius><end_time>{}</end_time>
      <bounds><min>-1 -1 -0.05</min><max>1 1 {}</max></bounds></solver>
    <material name="mortar"><density>2100</density>
      <rheology model="bingham"><yield_stress>1500</yield_stress><plastic_viscosity>10</plastic_viscosity></rheology>
      <boundary_viscosity>no_slip</boundary_viscosity></material>
    <print_head name="nozzle" material="mortar">
      <nozzle><inner_diameter unit="mm">20</inner_diameter><exit_speed>0.1019</exit_speed></nozzle>
      <path speed="0.1"><wall><corner>-0.25 -0.25 0.01</corner><size>0.5 0.5</size><layers>{}</layers><layer_height>0.01</layer_height></wall></path>
    </print_head>
    <output><particles>false</particles></output>
  </plugin>
</world></sdf>)", end_time, 0.1 + 0.01 * layers, layers);
  const scene::Scene scene = scene::load_scene_from_string(text, "construction_wall.sdf");
  sim::Simulation simulation(scene);
  const auto& solver = simulation.solver();
  fmt::print("construction: a 0.5 m square mortar wall (1.5 kPa, 10 Pa*s), {} layers of 10 mm from a 20 mm nozzle at 0.1 m/s, "
             "r = 1.5 mm, {:.0f} s simulated, {} threads\n",
             layers, end_time, ThreadLimit::active_threads());
  struct Layer {
    double steps = 0, simulated = 0, wall = 0, moving = 0, density = 0, viscosity = 0;
    double settled_builds = 0, resting_changes = 0;  // the settled resting grid built anew; the resting set changed
    double moving_below = 0, deepest = 0;  // moving particles in the layers under the one laid; how many layers down the deepest is
    double density_p99 = 0, density_max = 0;  // the whole print's ρ/ρ0 − 1 at the layer's end (moving and resting)
    sph::StageTimes stages;
  };
  std::vector<Layer> by_layer(static_cast<std::size_t>(layers));
  std::vector<Real> density;
  // The whole print's density where it stands (sph::measure_density), after each layer: resting
  // material keeps what it rested with, so compression left behind shows here, not in the solve's error.
  auto measure_layer_end = [&](int layer) {
    if (layer < 0 || layer >= layers) return;
    sph::measure_density(solver, density);
    const sph::DensityStatistics statistics = sph::density_statistics(solver, density);
    by_layer[static_cast<std::size_t>(layer)].density_p99 = statistics.p99;
    by_layer[static_cast<std::size_t>(layer)].density_max = statistics.max;
  };
  int last_layer = -1;
  auto start = std::chrono::steady_clock::now();
  while (simulation.time() < end_time - 1e-9) {
    const double before = simulation.time();
    const auto step_start = std::chrono::steady_clock::now();
    const std::uint64_t settled_before = solver.workspace().settled_builds, version_before = solver.workspace().fixed_grids_version;
    const auto& stats = simulation.step();
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - step_start).count();
    const int layer = solver.state().nozzles[0].print_layer;
    if (layer != last_layer) {
      const auto measure_start = std::chrono::steady_clock::now();
      measure_layer_end(last_layer);
      last_layer = layer;
      // Not the simulation's time: the bench's real-time factor is the engine's.
      start += std::chrono::steady_clock::now() - measure_start;
    }
    if (layer < 0 || layer >= layers) continue;
    Layer& entry = by_layer[static_cast<std::size_t>(layer)];
    entry.steps += 1;
    entry.simulated += simulation.time() - before;
    entry.wall += wall;
    entry.moving += double(solver.fluid().size() - stats.particles_at_rest);
    entry.density += stats.density_iterations;
    entry.viscosity += stats.viscosity_iterations;
    entry.stages += stats.stage_ms;
    entry.settled_builds += double(solver.workspace().settled_builds - settled_before);
    entry.resting_changes += double(solver.workspace().fixed_grids_version != version_before);
    // Where the moving material is: the bead being laid spans [0.01 layer, 0.01 (layer + 1)] m.
    const double base = 0.01 * layer, margin = 0.0015;
    double below = 0, lowest = base;
    const auto& position = solver.fluid().position;
    for (std::size_t i = 0; i < solver.state().active_count; ++i) {
      const double z = position[i].z();
      below += z < base - margin;
      lowest = std::min(lowest, z);
    }
    entry.moving_below += below;
    entry.deepest += (base - lowest) / 0.01;
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  measure_layer_end(last_layer);
  fmt::print("{:.1f} s simulated in {:.1f} s wall ({:.2f}x real time), {} particles at the end\n", simulation.time(), seconds,
             simulation.time() / seconds, solver.fluid().size());
  fmt::print("layer,real_time_factor,steps,moving_particles,density_iterations,viscosity_iterations,ms_per_step,ms_pressure,ms_viscosity,"
             "ms_neighbors,ms_other,settled_grid_builds,steps_resting_changed,moving_in_layers_below,deepest_moving_layers_down,"
             "print_density_p99_percent,print_density_max_percent\n");
  for (std::size_t l = 0; l < by_layer.size(); ++l) {
    const Layer& entry = by_layer[l];
    if (entry.steps == 0) continue;
    const double n = entry.steps;
    const double pressure = entry.stages[sph::Stage::density] + entry.stages[sph::Stage::pressure];
    const double rest = entry.stages.total() - pressure - entry.stages[sph::Stage::viscosity] - entry.stages[sph::Stage::neighbors];
    fmt::print("{},{:.2f},{:.0f},{:.0f},{:.1f},{:.1f},{:.2f},{:.2f},{:.2f},{:.2f},{:.2f},{:.0f},{:.0f},{:.0f},{:.2f},{:.2f},{:.2f}\n", l + 1,
               entry.simulated / entry.wall, n, entry.moving / n, entry.density / n, entry.viscosity / n, entry.stages.total() / n,
               pressure / n, entry.stages[sph::Stage::viscosity] / n, entry.stages[sph::Stage::neighbors] / n, rest / n,
               entry.settled_builds, entry.resting_changes, entry.moving_below / n, entry.deepest / n, 100 * entry.density_p99,
               100 * entry.density_max);
  }
  try {
    const quality::Report report = sim::print_quality(simulation, 0.01);
    fmt::print("layer,height_mm,design_height_mm,width_mm,design_width_mm\n");
    for (const auto& layer : report.heads.front().layers)
      if (layer.stations > layer.empty)
        fmt::print("{},{:.2f},{:.2f},{:.2f},{:.2f}\n", layer.layer + 1, 1e3 * layer.height, 1e3 * layer.design_height, 1e3 * layer.width,
                   1e3 * layer.design_width);
    fmt::print("fill: {:.1f} cm3 designed, {:.1f} over, {:.1f} under\n", 1e6 * report.fill.designed, 1e6 * report.fill.over,
               1e6 * report.fill.under);
  } catch (const quality::UnmeasurableDesign& unmeasurable) {
    fmt::print("quality: not measured: {}\n", unmeasurable.what());
  }
  return 0;
}

/// A pressed (g/D = 0.5, V/U = 1) and a free (g/D = 1.5, V/U = 1) strand of the demo's mortar (capped at
/// 10⁴ Pa·s), D = 10 mm, 8 particles across, a 0.2 m line, each from a nozzle with a bore (2 D, lip 3 D)
/// and from the exit-plane inlet: particle-steps per second in the strand's pass and the bore's cost.
int bench_strand(const BenchOptions& /*options*/) {
  namespace deposition = sim::deposition;
  const material::Material mortar = deposition::printable_mortar();
  fmt::print("strand: the printable mortar (1 kPa, 10 Pa*s, capped at 1e4 Pa*s), D = 10 mm, 8 particles across, U = 50 mm/s, a 0.2 m "
             "line, {} threads\n",
             ThreadLimit::active_threads());
  fmt::print("case,nozzle,steps,particles,particle_steps_per_s,ms_per_step,area_ratio,landed\n");
  for (const double gap : {0.5, 1.5}) {
    double seconds[2] = {0, 0};
    for (const double bore : {2.0, 0.0}) {
      deposition::StrandCase strand;
      strand.material = mortar;
      strand.gap_ratio = gap;
      strand.speed_ratio = 1;
      strand.bore_ratio = bore;
      const deposition::StrandResult result = deposition::lay_strand(strand);
      seconds[bore > 0 ? 0 : 1] = result.step_seconds;
      fmt::print("{},{},{},{},{:.3g},{:.3f},{:.4f},{:.2f}\n", gap <= 1 ? "pressed g/D=0.5" : "free g/D=1.5", bore > 0 ? "bore" : "inlet",
                 result.steps, result.particles, result.particle_steps / result.step_seconds,
                 1e3 * result.step_seconds / double(std::max<unsigned long long>(1, result.steps)),
                 result.area / deposition::nominal_area(strand), result.landed);
    }
    fmt::print("{}: the bore's pass costs {:.2f}x the inlet's\n", gap <= 1 ? "pressed" : "free", seconds[0] / seconds[1]);
  }
  return 0;
}

int bench_command(const BenchOptions& options) {
  ThreadLimit thread_limit(options.threads);
  if (options.scenario == "wall_layers") return bench_wall_layers(options);
  if (options.scenario == "ur10_wall") return bench_ur10_wall(options);
  if (options.scenario == "clay_print") return bench_clay_print(options);
  if (options.scenario == "strand") return bench_strand(options);
  if (options.scenario == "construction") return bench_construction(options);
  if (options.scenario == "nozzle" || options.scenario == "plate") return bench_scene(options.scenario, options);
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
  if (options.seconds > 0) {
    // To a simulated time, as compared with a peer: the steps it took and what set them.
    SpeedLog speeds(options.seconds / 10, options.cfl_factor, 2 * double(setup.particle_radius));
    std::uint64_t steps = 0;
    const auto start = std::chrono::steady_clock::now();
    while (simulation.time() < options.seconds - 1e-12) {
      const auto& stats = simulation.step();
      speeds.add(solver.state(), stats.time_step);
      ++steps;
    }
    speeds.flush(simulation.time());
    fmt::print("{:.3g} s simulated in {} steps, {:.2f} s wall\n", simulation.time(), steps,
               std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    return 0;
  }
  time_steps(simulation, options);
  return 0;
}

}  // namespace m3dp::app
