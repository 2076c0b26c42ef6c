// What measuring a print against its design costs (issue 39's goal: 10⁵ particles in at most 0.5 s
// on two cores): a synthetic print, the demo's three-layer 0.24 m square wall (12 mm nozzle, 8 mm
// layers, a 13.7 mm bead) filled with particles on a lattice of 1.4 mm, about 10⁵ of them.
#include <benchmark/benchmark.h>

#include "m3dp/quality/deviation.hpp"
#include "m3dp/quality/report.hpp"

using namespace m3dp;

namespace {
struct SyntheticPrint {
  quality::Design design;
  std::vector<Vec3> positions;
  std::vector<std::int32_t> layers;
  double particle_diameter = 0.0014;
};

SyntheticPrint square_wall() {
  SyntheticPrint print;
  std::vector<toolpath::PathSegment> segments;
  const double side = 0.24, corner_x = 0.58, corner_y = -0.12;
  for (int layer = 0; layer < 3; ++layer) {
    const Real z = Real(0.008 * (layer + 1));
    const Vec3 corners[] = {{Real(corner_x), Real(corner_y), z}, {Real(corner_x + side), Real(corner_y), z},
                            {Real(corner_x + side), Real(corner_y + side), z}, {Real(corner_x), Real(corner_y + side), z}};
    for (int edge = 0; edge < 4; ++edge) {
      toolpath::PathSegment segment;
      segment.curve = toolpath::LineCurve{corners[edge], corners[(edge + 1) % 4]};
      segment.speed = Real(0.1);
      segments.push_back(segment);
    }
  }
  print.design = quality::design_of(toolpath::Trajectory(segments, 0), quality::Nozzle{0.012, 0.085, 0});
  const double d = print.particle_diameter;
  for (const quality::Bead& bead : print.design.beads) {
    const Vec3d tangent = (bead.end - bead.start).normalized(), across = Vec3d::UnitZ().cross(tangent);
    for (double s = d / 2; s < bead.length(); s += d)
      for (double y = -bead.width / 2 + d / 2; y < bead.width / 2; y += d)
        for (double z = bead.start.z() - bead.height + d / 2; z < bead.start.z(); z += d) {
          const Vec3d point = bead.start + s * tangent + y * across + Vec3d(0, 0, z - bead.start.z());
          if (!quality::inside(bead, point)) continue;
          print.positions.push_back(point.cast<Real>());
          print.layers.push_back(bead.layer);
        }
  }
  return print;
}

void BM_MeasurePrint(benchmark::State& state) {
  const SyntheticPrint print = square_wall();
  const quality::Printed printed{print.positions, print.layers, print.particle_diameter};
  const std::vector<quality::HeadDesign> designs{{"nozzle", print.design}};
  for (auto _ : state) {
    quality::Report report = quality::measure(designs, printed, 0.01, 0);
    benchmark::DoNotOptimize(report);
  }
  state.counters["particles"] = double(print.positions.size());
}
BENCHMARK(BM_MeasurePrint)->Unit(benchmark::kMillisecond);

void BM_SurfaceDeviation(benchmark::State& state) {
  // The design's signed distance at 10⁵ points (a printed mesh's vertices; here the particles).
  const SyntheticPrint print = square_wall();
  const quality::DesignDistance distance(print.design);
  for (auto _ : state) benchmark::DoNotOptimize(quality::deviation_at(distance, print.positions));
  state.counters["points"] = double(print.positions.size());
}
BENCHMARK(BM_SurfaceDeviation)->Unit(benchmark::kMillisecond);
}  // namespace

BENCHMARK_MAIN();
