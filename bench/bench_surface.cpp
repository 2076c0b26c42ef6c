// Google Benchmark: surface reconstruction of ~10⁵ particles of a dam break (a free surface,
// splashes, walls) by each method. Counters: triangles, the field grid's memory and the process's
// peak resident memory.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <cmath>
#include <memory>
#include <span>

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

namespace {
/// A printed wall, 250 × 4 particles a layer, 100 layers (10⁵ particles), in deposition order, each
/// particle shaken off the lattice by up to 0.15 spacings.
struct PrintedWall {
  std::vector<Vec3> positions;
  std::vector<std::uint64_t> ids;
  Real particle_radius = Real(0.001);
  static constexpr int kLength = 250, kWidth = 4, kLayers = 100;
};

const PrintedWall& printed_wall() {
  static const PrintedWall wall = [] {
    PrintedWall w;
    const Real spacing = 2 * w.particle_radius;
    for (int layer = 0; layer < PrintedWall::kLayers; ++layer)
      for (int along = 0; along < PrintedWall::kLength; ++along)
        for (int across = 0; across < PrintedWall::kWidth; ++across) {
          const Real phase = Real(w.positions.size() * 7);
          const Vec3 jitter = Real(0.15) * spacing * Vec3(std::sin(phase), std::cos(Real(1.3) * phase), std::sin(Real(2.1) * phase));
          w.ids.push_back(w.positions.size());
          w.positions.push_back(spacing * Vec3(along + Real(0.5), across + Real(0.5), layer + Real(0.5)) + jitter);
        }
    return w;
  }();
  return wall;
}
}  // namespace

// Meshing during a print (issue 4): the wall's first ~94k particles rest, the 4 × 40 particles
// behind the nozzle still move. Each iteration the nozzle moves on by 10 (40 particles): the oldest
// moving ones come to rest and are added to the kept field. whole_frame_s is the same frame
// reconstructed from scratch. Only the tiles (32 voxels) around what changed are meshed again.
static void BM_IncrementalSurface(benchmark::State& state) {
  const PrintedWall& wall = printed_wall();
  surface::SurfaceSettings settings;
  settings.method = static_cast<surface::Method>(state.range(0));
  settings.particle_radius = wall.particle_radius;
  constexpr std::size_t kMoving = 4 * 40;
  std::size_t resting = wall.positions.size() - 40 * kMoving;
  auto frame = [&](std::size_t rest) {
    const std::span<const Vec3> all(wall.positions);
    return std::make_pair(all.subspan(0, rest), all.subspan(rest, kMoving));
  };
  surface::IncrementalSurface incremental(settings);
  {
    const auto [rest, moving] = frame(resting);
    (void)incremental.reconstruct(moving, rest, std::span(wall.ids).subspan(0, resting));  // the first, whole field
  }
  surface::SurfaceStats stats;
  std::size_t triangles = 0;
  for (auto _ : state) {
    resting += 40;
    const auto [rest, moving] = frame(resting);
    const TriangleMesh mesh = incremental.reconstruct(moving, rest, std::span(wall.ids).subspan(0, resting), &stats);
    triangles = mesh.triangles.size();
    benchmark::DoNotOptimize(mesh.vertices.data());
  }
  const auto [rest, moving] = frame(resting);
  std::vector<Vec3> all(rest.begin(), rest.end());
  all.insert(all.end(), moving.begin(), moving.end());
  surface::SurfaceStats whole;
  const TriangleMesh whole_mesh = surface::reconstruct_surface(all, settings, &whole);
  state.SetLabel(std::string(surface::method_name(settings.method)));
  state.counters["particles"] = static_cast<double>(all.size());
  state.counters["added"] = static_cast<double>(stats.added_particles);
  state.counters["refreshed"] = static_cast<double>(stats.refreshed_kernels);
  state.counters["triangles"] = static_cast<double>(triangles);
  state.counters["whole_triangles"] = static_cast<double>(whole_mesh.triangles.size());
  state.counters["field_s"] = stats.field_seconds;
  state.counters["mesh_s"] = stats.mesh_seconds;
  state.counters["tiles"] = static_cast<double>(stats.mesh_tiles);
  state.counters["remeshed_tiles"] = static_cast<double>(stats.remeshed_tiles);
  state.counters["whole_frame_s"] = whole.field_seconds + whole.mesh_seconds;
}
BENCHMARK(BM_IncrementalSurface)
    ->Arg(static_cast<int>(surface::Method::spherical))
    ->Arg(static_cast<int>(surface::Method::sph_blobby))
    ->Arg(static_cast<int>(surface::Method::zhu_bridson))
    ->Arg(static_cast<int>(surface::Method::anisotropic))
    ->Iterations(20)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
