// Google Benchmark: surface reconstruction of ~10⁵ particles of a dam break (a free surface,
// splashes, walls) by each method. Counters: triangles, the field grid's memory and the process's
// peak resident memory.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <memory>

#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/surface/surface.hpp"

using namespace m3dp;

namespace {
struct Frame {
  std::vector<Vec3> positions;
  Real particle_radius = 0;
};

const Frame& dam_break_frame() {
  static const Frame frame = [] {
    sim::DamBreakSetup setup;
    setup.column_width = Real(0.5);
    setup.depth = Real(0.25);
    setup.particle_radius = sim::dam_break_radius_for_count(100000, setup.column_width, setup.depth);
    setup.end_time = 100;
    sim::Simulation simulation(sim::dam_break_scene(setup));
    for (int i = 0; i < 20; ++i) simulation.step();  // the column has started to fall
    return Frame{simulation.solver().fluid().position, setup.particle_radius};
  }();
  return frame;
}

double peak_resident_megabytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss / 1024.0;  // kB on Linux
}
}  // namespace

static void BM_Surface(benchmark::State& state) {
  const Frame& frame = dam_break_frame();
  surface::SurfaceSettings settings;
  settings.method = static_cast<surface::Method>(state.range(0));
  settings.particle_radius = frame.particle_radius;
  surface::SurfaceStats stats;
  std::size_t triangles = 0;
  for (auto _ : state) {
    const TriangleMesh mesh = surface::reconstruct_surface(frame.positions, settings, &stats);
    triangles = mesh.triangles.size();
    benchmark::DoNotOptimize(mesh.vertices.data());
  }
  state.SetLabel(std::string(surface::method_name(settings.method)));
  state.counters["particles"] = static_cast<double>(frame.positions.size());
  state.counters["surface_particles"] = static_cast<double>(stats.surface_particles);
  state.counters["triangles"] = static_cast<double>(triangles);
  state.counters["field_s"] = stats.field_seconds;
  state.counters["mesh_s"] = stats.mesh_seconds;
  state.counters["grid_MB"] = static_cast<double>(stats.grid_bytes) / 1e6;
  state.counters["peak_RSS_MB"] = peak_resident_megabytes();
}
BENCHMARK(BM_Surface)
    ->Arg(static_cast<int>(surface::Method::spherical))
    ->Arg(static_cast<int>(surface::Method::sph_blobby))
    ->Arg(static_cast<int>(surface::Method::zhu_bridson))
    ->Arg(static_cast<int>(surface::Method::anisotropic))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
