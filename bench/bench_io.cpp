// Google Benchmark: writing one particle frame of a 100k-particle dam break with the fields a run
// writes, in each encoding (zlib level; -1 = base64 alone). Reports the file's bytes.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <memory>
#include <unistd.h>

#include "m3dp/io/vtk_writer.hpp"
#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/simulation.hpp"

using namespace m3dp;

static void BM_WriteParticleFrame(benchmark::State& state) {
  sim::DamBreakSetup setup;
  setup.column_width = Real(0.5);
  setup.depth = Real(0.25);
  setup.particle_radius = sim::dam_break_radius_for_count(100000, setup.column_width, setup.depth);
  sim::Simulation simulation(sim::dam_break_scene(setup));
  for (int i = 0; i < 10; ++i) simulation.step();  // moving, non-lattice values
  const auto& fluid = simulation.solver().fluid();
  std::vector<Real> pressure(fluid.size());
  for (std::size_t i = 0; i < fluid.size(); ++i) pressure[i] = simulation.solver().pressure(i);
  const auto file = std::filesystem::temp_directory_path() / ("m3dp_bench_frame_" + std::to_string(::getpid()) + ".vtu");
  const io::VtuEncoding encoding{static_cast<int>(state.range(0))};
  for (auto _ : state)
    io::write_vtu(file, fluid.position,
                  {io::PointArray::of("velocity", fluid.velocity), io::PointArray::of("density", fluid.density),
                   io::PointArray::of("pressure", pressure), io::PointArray::of("material", fluid.phase),
                   io::PointArray::of("id", fluid.id), io::PointArray::of("birth_time", fluid.birth_time),
                   io::PointArray::of("viscosity", fluid.viscosity), io::PointArray::of("shear_rate", fluid.shear_rate),
                   io::PointArray::of("rest_time", fluid.rest_time), io::PointArray::of("angular_velocity", fluid.angular_velocity)},
                  {{"particle_radius", simulation.solver().parameters().settings.particle_radius}}, encoding);
  state.counters["particles"] = static_cast<double>(fluid.size());
  state.counters["bytes"] = static_cast<double>(std::filesystem::file_size(file));
  std::filesystem::remove(file);
}
BENCHMARK(BM_WriteParticleFrame)->Arg(-1)->Arg(1)->Arg(6)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
