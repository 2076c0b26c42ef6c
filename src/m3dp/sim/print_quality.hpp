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

/// The simulation's printed material now against its heads' paths as they are (paths given at run
/// time included), a section every `spacing` (m).
[[nodiscard]] quality::Report print_quality(const Simulation& simulation, double spacing);

/// A print's report with its surface: `report` (sections and fill) gets the surface's deviation (the
/// particles' surface by the scene's meshing method, against `design`) and `heights`' history, and
/// the folder gets quality.json, quality.csv, quality_mesh.vtp (deviation_m) and quality_mesh.ply
/// (vertex quality). What m3dp quality and the in-run report write alike.
void complete_and_write_report(quality::Report& report, const scene::Scene& scene, const quality::Design& design,
                               std::span<const Vec3> positions, const quality::Buildability& heights,
                               const std::filesystem::path& folder);

}  // namespace m3dp::sim
