// Google Benchmark: neighbour search and one DFSPH step of a dam break at 10k and 100k particles.
// Each timed step starts from the same saved state (MuJoCo-style save/restore around batches).
#include <benchmark/benchmark.h>

#include <memory>

#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/simulation.hpp"

using namespace m3dp;

namespace {
std::unique_ptr<sim::Simulation> settled_dam_break(std::size_t particles) {
  sim::DamBreakSetup setup;
  setup.column_width = Real(0.5);
  setup.depth = Real(0.25);
  setup.particle_radius = sim::dam_break_radius_for_count(particles, setup.column_width, setup.depth);
  setup.end_time = 100;
  auto simulation = std::make_unique<sim::Simulation>(sim::dam_break_scene(setup));
  for (int i = 0; i < 10; ++i) simulation->step();  // a moving, non-lattice state
  return simulation;
}
}  // namespace

static void BM_NeighborSearch(benchmark::State& state) {
  auto simulation = settled_dam_break(static_cast<std::size_t>(state.range(0)));
  const auto& positions = simulation->solver().fluid().position;
  const Real support = simulation->solver().support_radius();
  sph::SpatialHashGrid grid;
  sph::NeighborLists lists;
  for (auto _ : state) {
    grid.build(positions, support);
    sph::find_neighbors(grid, positions, support, true, lists, /*sort_lists=*/false);  // as the solver does
    benchmark::DoNotOptimize(lists.counts.data());
  }
  state.counters["particles"] = static_cast<double>(positions.size());
  state.counters["neighbors_per_particle"] = static_cast<double>(lists.total()) / positions.size();
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(positions.size()));
}
BENCHMARK(BM_NeighborSearch)->Arg(10000)->Arg(100000)->Unit(benchmark::kMillisecond)->UseRealTime();

static void BM_DfsphStep(benchmark::State& state) {
  auto simulation = settled_dam_break(static_cast<std::size_t>(state.range(0)));
  const sph::State saved = simulation->solver().state();
  const sph::Workspace saved_workspace = simulation->solver().workspace();
  double iterations = 0;
  for (auto _ : state) {
    state.PauseTiming();
    simulation->solver().restore(saved, saved_workspace);
    state.ResumeTiming();
    iterations += simulation->step().density_iterations;
  }
  state.counters["particles"] = static_cast<double>(saved.fluid.size());
  state.counters["density_iterations"] = iterations / static_cast<double>(state.iterations());
  // 1 where the settled column keeps its neighbour lists (SkinnedNeighborSearch) instead of searching.
  state.counters["lists_kept"] = saved.skin_in_use ? 1 : 0;
  state.SetItemsProcessed(state.iterations() * static_cast<std::int64_t>(saved.fluid.size()));
}
BENCHMARK(BM_DfsphStep)->Arg(10000)->Arg(100000)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
