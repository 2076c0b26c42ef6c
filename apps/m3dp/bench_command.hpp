#pragma once
#include <CLI/CLI.hpp>

namespace m3dp::app {

struct BenchOptions {
  std::string scenario = "dam_break";  // dam_break or ur10_wall
  std::string scene_file;              // ur10_wall: the scene (default: the project's scenes/ur10_wall.sdf)
  std::size_t particles = 50000;
  int steps = 100;
  int warmup_steps = 20;
  double density_tolerance = 0.0005;  // fraction: 0.05 %
  double cfl_factor = 1.0;
  int threads = 0;
  std::string kernel = "cubic_spline";
  double max_viscosity = 1e4;         // Pa·s, clay_print and wall_layers
  int layers = 20;                    // wall_layers, construction
  double seconds = 0;                 // construction: simulated s to run; 0: the whole wall
  std::string record = "scene";       // ur10_wall: run.mcap as the scene says, or "on" or "off"
};

void add_bench_options(CLI::App& command, BenchOptions& options);
int bench_command(const BenchOptions& options);

}  // namespace m3dp::app
