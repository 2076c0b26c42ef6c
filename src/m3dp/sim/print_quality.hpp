#pragma once
// The quality module (quality/) on a scene and a simulation: each print head's design from its path
// and nozzle, and the printed material measured against them (sim.quality(), m3dp quality).
#include <filesystem>
#include <span>
#include <vector>

#include "m3dp/quality/report.hpp"
#include "m3dp/scene/scene.hpp"

namespace m3dp::sim {

class Simulation;

/// Every print head's design: its path (one per head, in scene order) laid by its nozzle, on a plate at z = 0.
[[nodiscard]] std::vector<quality::HeadDesign> head_designs(const scene::Scene& scene, std::span<const toolpath::Trajectory> paths);
/// The heads' designs as laid by now: each head's path (as the simulation has it) up to its path clock.
[[nodiscard]] std::vector<quality::HeadDesign> designs_now(const Simulation& simulation);

/// The simulation's printed material now against its heads' paths as they are (paths given at run
/// time included), a section every `spacing` (m).
[[nodiscard]] quality::Report print_quality(const Simulation& simulation, double spacing);
/// The same against `designs` (designs_now's, made once by a caller that needs them too).
[[nodiscard]] quality::Report measure_now(const Simulation& simulation, const std::vector<quality::HeadDesign>& designs, double spacing);

/// The print now against its design on its printed surface (a mesh of it): the sections and fill of
/// print_quality, the surface's deviation at each vertex and its statistics and histogram; what
/// run.mcap and the live stream carry on /quality and /quality/deviation.
struct SurfaceQuality {
  quality::Report report;
  std::vector<float> deviation;  // m, at each of the surface's vertices
  double range = 0;              // m, quality::deviation_range of the design
};
[[nodiscard]] SurfaceQuality surface_quality(const Simulation& simulation, const TriangleMesh& surface, double spacing);

/// A print's report with its surface: `report` (sections and fill) gets the surface's deviation (the
/// particles' surface by the scene's meshing method, against `design`) and `heights`' histories, and
/// the folder gets quality.json, quality.csv, quality_mesh.vtp (deviation_m) and quality_mesh.ply
/// (vertex quality). What m3dp quality and the in-run report write alike.
void complete_and_write_report(quality::Report& report, const scene::Scene& scene, const quality::Design& design,
                               std::span<const Vec3> positions, const quality::PrintHeights& heights,
                               const std::filesystem::path& folder);

}  // namespace m3dp::sim
