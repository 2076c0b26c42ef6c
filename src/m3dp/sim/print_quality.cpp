#include "m3dp/sim/print_quality.hpp"

#include "m3dp/io/atomic_file.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/io/vtk_writer.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/surface/surface.hpp"

namespace m3dp::sim {

namespace {
/// Bins of the surface deviation's histogram over ± the thickest layer.
constexpr std::size_t kHistogramBins = 40;
}  // namespace

std::vector<quality::HeadDesign> head_designs(const scene::Scene& scene, std::span<const toolpath::Trajectory> paths) {
  std::vector<quality::HeadDesign> designs;
  for (std::size_t h = 0; h < scene.print_heads.size(); ++h) {
    const auto& head = scene.print_heads[h];
    designs.push_back({head.name, quality::design_of(paths[h], quality::Nozzle{head.inner_diameter, head.exit_speed, 0})});
  }
  return designs;
}

std::vector<quality::HeadDesign> designs_now(const Simulation& simulation) {
  std::vector<toolpath::Trajectory> paths;
  for (std::size_t h = 0; h < simulation.scene().print_heads.size(); ++h) paths.push_back(simulation.head_path(h));
  std::vector<quality::HeadDesign> designs = head_designs(simulation.scene(), paths);
  // What each head had laid by now on its path's clock: a run stopped early is judged on that.
  for (std::size_t h = 0; h < designs.size(); ++h) designs[h].design = quality::laid_by(designs[h].design, simulation.path_time(h));
  return designs;
}

quality::Report measure_now(const Simulation& simulation, const std::vector<quality::HeadDesign>& designs, double spacing) {
  const auto& fluid = simulation.solver().fluid();
  const quality::Printed printed{fluid.position, fluid.print_layer, double(simulation.solver().particle_diameter())};
  return quality::measure(designs, printed, spacing, simulation.time());
}

quality::Report print_quality(const Simulation& simulation, double spacing) {
  return measure_now(simulation, designs_now(simulation), spacing);
}

SurfaceQuality surface_quality(const Simulation& simulation, const TriangleMesh& surface, double spacing) {
  const auto designs = designs_now(simulation);
  const quality::Design design = quality::combined(designs);
  SurfaceQuality result{measure_now(simulation, designs, spacing), {}, quality::deviation_range(design)};
  result.deviation = quality::deviation_at(quality::DesignDistance(design), surface.vertices);
  result.report.deviation = quality::statistics(result.deviation);
  result.report.deviation_histogram = quality::histogram(result.deviation, result.range, kHistogramBins);
  return result;
}

void complete_and_write_report(quality::Report& report, const scene::Scene& scene, const quality::Design& design,
                               std::span<const Vec3> positions, const quality::PrintHeights& heights,
                               const std::filesystem::path& folder) {
  surface::SurfaceSettings surface_settings = scene.meshing.surface;
  surface_settings.particle_radius = scene.solver.particle_radius;
  const TriangleMesh mesh = surface::reconstruct_surface(positions, surface_settings);
  const std::vector<float> deviation = quality::deviation_at(quality::DesignDistance(design), mesh.vertices);
  report.deviation = quality::statistics(deviation);
  report.deviation_histogram = quality::histogram(deviation, quality::deviation_range(design), kHistogramBins);
  heights.fill_in(report);
  io::write_ply_with_quality(folder / "quality_mesh.ply", mesh, deviation, "quality: the signed distance (m) to the designed print, > 0 outside it");
  const std::vector<Real> field(deviation.begin(), deviation.end());
  io::write_vtp(folder / "quality_mesh.vtp",
                io::PolyData{mesh.vertices, mesh.triangles, {}, {}, {io::PointArray::of("deviation_m", std::span<const Real>(field))}, {}});
  io::write_text_atomically(folder / "quality.json", quality::report_json(report));
  io::write_text_atomically(folder / "quality.csv", quality::report_csv(report));
}

}  // namespace m3dp::sim
