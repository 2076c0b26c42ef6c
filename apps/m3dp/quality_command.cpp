#include "quality_command.hpp"

#include <fmt/format.h>

#include <spawn.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "m3dp/core/error.hpp"
#include "m3dp/io/particle_reader.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/print_quality.hpp"

namespace m3dp::app {

namespace fs = std::filesystem;

void add_quality_options(CLI::App& command, QualityOptions& options) {
  command.add_option("run", options.run_folder, "A run folder (m3dp run -o, or sim.record)")->required();
  command.add_option("--spacing", options.spacing, "Metres between sections along each bead (default 0.01)")->check(CLI::PositiveNumber);
}

namespace {
/// summary.json's content, or null when there is none (or it does not parse).
nlohmann::json read_summary(const fs::path& folder) {
  const fs::path summary_file = folder / "summary.json";
  if (!fs::exists(summary_file)) return nullptr;
  std::ifstream stream(summary_file);
  std::stringstream text;
  text << stream.rdbuf();
  const auto summary = nlohmann::json::parse(text.str(), nullptr, false);
  return summary.is_discarded() ? nlohmann::json(nullptr) : summary;
}

/// Each head's path clock at `time` (s): summary.json's at the run's end when the frame is the run's
/// last (a robot may lag its path), else the frame's time.
double path_time_of(const nlohmann::json& summary, const std::string& head, double time) {
  if (!summary.is_object() || !summary.contains("simulated_time_s") || !summary["simulated_time_s"].is_number() ||
      std::abs(summary["simulated_time_s"].get<double>() - time) > 1e-6 || !summary.contains("nozzles") || !summary["nozzles"].is_array())
    return time;
  for (const auto& nozzle : summary["nozzles"])
    if (nozzle.is_object() && nozzle.value("name", "") == head && nozzle.contains("path_time_s") && nozzle["path_time_s"].is_number())
      return nozzle["path_time_s"].get<double>();
  return time;
}

/// The scene the run was made from: the one summary.json names (paths in it resolve from there), else
/// the run folder's copy.
fs::path run_scene(const fs::path& folder, const nlohmann::json& summary) {
  if (summary.is_object() && summary.contains("scene") && summary["scene"].is_string()) {
    const fs::path original = summary["scene"].get<std::string>();
    if (!original.empty() && fs::exists(original)) return original;
  }
  if (fs::exists(folder / "scene.sdf")) return folder / "scene.sdf";
  throw InputError({folder.string(), 0}, "not a run folder: no summary.json naming its scene and no scene.sdf (m3dp run -o writes them)");
}
/// Runs `python3 scripts/plot_quality.py` (Debian's matplotlib) on the report: quality.png. Returns
/// what went wrong, empty if nothing.
std::string plot_report(const fs::path& folder) {
  const fs::path script = fs::path(M3DP_PROJECT_ROOT) / "scripts" / "plot_quality.py";
  if (!fs::exists(script)) return fmt::format("{} is not here", script.string());
  const std::string python = "/usr/bin/python3", json = (folder / "quality.json").string(), csv = (folder / "quality.csv").string(),
                    png = (folder / "quality.png").string(), script_path = script.string();
  std::vector<char*> arguments{const_cast<char*>(python.c_str()), const_cast<char*>(script_path.c_str()), const_cast<char*>(json.c_str()),
                               const_cast<char*>(csv.c_str()), const_cast<char*>(png.c_str()), nullptr};
  pid_t child = 0;
  if (posix_spawn(&child, python.c_str(), nullptr, nullptr, arguments.data(), environ) != 0) return "python3 could not be started";
  int status = 0;
  if (waitpid(child, &status, 0) < 0 || !WIFEXITED(status) || WEXITSTATUS(status) != 0) return "the plotting script failed (see above)";
  return "";
}
}  // namespace

int quality_command(const QualityOptions& options) {
  const fs::path& folder = options.run_folder;
  if (!fs::is_directory(folder)) throw InputError({folder.string(), 0}, "no such run folder");
  const nlohmann::json summary = read_summary(folder);
  const scene::Scene scene = scene::load_scene(run_scene(folder, summary));
  if (scene.print_heads.empty())
    throw InputError({scene.file.string(), 0}, "the scene has no print heads: no path was designed to measure the print against");
  const fs::path frames = folder / "particles.pvd";
  if (!fs::exists(frames))
    throw InputError({folder.string(), 0}, "no particle frames (particles.pvd): the run wrote none; give the scene an "
                                           "<output><particles_period>");
  const auto entries = io::read_pvd(frames);
  if (entries.empty()) throw InputError({frames.string(), 0}, "the collection lists no particle frames");
  const io::ParticleFrame frame = io::read_particle_frame(entries.back().file);
  if (frame.layer.size() != frame.positions.size())
    throw InputError({entries.back().file.string(), 0}, "the particle frame has no \"layer\" array (each particle's print layer)");
  if (std::none_of(frame.layer.begin(), frame.layer.end(), [](std::int32_t layer) { return layer >= 0; }))
    throw InputError({entries.back().file.string(), 0}, "no particle in the last frame was printed by a head's path: nothing to measure");

  std::vector<toolpath::Trajectory> paths;
  for (const auto& head : scene.print_heads) paths.push_back(head.trajectory);
  const quality::Printed printed{frame.positions, frame.layer, 2 * double(scene.solver.particle_radius)};
  std::vector<quality::HeadDesign> designs = sim::head_designs(scene, paths);
  // Judged against what was laid by the last frame (a run stopped before its path ends), on each
  // path's clock (summary.json's at the run's end; else the frame's time).
  for (auto& head : designs) head.design = quality::laid_by(head.design, path_time_of(summary, head.name, entries.back().time));
  quality::Report report = quality::measure(designs, printed, options.spacing, entries.back().time);
  // The printed height against the design's, frame by frame (did it stand?), and the surface's
  // distance to the design at the end.
  const quality::Design all = quality::combined(designs);
  quality::PrintHeights buildability(designs, printed.particle_diameter);
  for (const auto& entry : entries) buildability.observe(entry.time, io::read_particle_frame(entry.file).positions);
  sim::complete_and_write_report(report, scene, all, frame.positions, buildability, folder);

  fmt::print("{}: the print at {:.3f} s ({} particles) against its design, a section every {:.1f} mm\n", folder.string(), report.time,
             report.particles, 1e3 * report.spacing);
  for (const auto& head : report.heads) {
    fmt::print("  print head '{}': {} sections\n", head.name, head.sections.size());
    fmt::print("    layer  width mm (design)    height mm (design)   off-path mm  top off mm  empty\n");
    for (const auto& layer : head.layers)
      fmt::print("    {:5}  {:6.2f} ({:6.2f})     {:6.2f} ({:6.2f})      {:+6.2f}      {:+6.2f}     {}/{}\n", layer.layer, 1e3 * layer.width,
                 1e3 * layer.design_width, 1e3 * layer.height, 1e3 * layer.design_height, 1e3 * layer.offset_across,
                 1e3 * layer.offset_up, layer.empty, layer.stations);
  }
  const auto& fill = report.fill;
  fmt::print("  fill: {:.2f} cm3 designed, {:.2f} cm3 printed; over-fill {:.2f} cm3, under-fill {:.2f} cm3\n", 1e6 * fill.designed,
             1e6 * fill.printed, 1e6 * fill.over, 1e6 * fill.under);
  if (report.heads.size() > 1)
    for (const auto& head : report.heads)
      fmt::print("  height of '{}': {}\n", head.name,
                 head.shortfall ? fmt::format("fell short of its design at layer {} ({:.2f} s: {:.1f} of {:.1f} mm)", head.shortfall->layer,
                                              head.shortfall->time, 1e3 * head.shortfall->printed, 1e3 * head.shortfall->designed)
                                : fmt::format("stood ({:.1f} mm printed of {:.1f} mm designed at the end)", 1e3 * head.heights.back().printed,
                                              1e3 * head.heights.back().designed));
  if (report.shortfall)
    fmt::print("  height: fell short of the design at layer {} ({:.2f} s: {:.1f} of {:.1f} mm)\n", report.shortfall->layer,
               report.shortfall->time, 1e3 * report.shortfall->printed, 1e3 * report.shortfall->designed);
  else
    fmt::print("  height: stood ({:.1f} mm printed of {:.1f} mm designed at the end)\n", 1e3 * report.heights.back().printed,
               1e3 * report.heights.back().designed);
  fmt::print("  surface off the design: mean {:+.2f} mm, 95th percentile {:.2f} mm, max {:.2f} mm over {} vertices "
             "(quality_mesh.ply, quality_mesh.vtp)\n",
             1e3 * report.deviation->mean, 1e3 * report.deviation->p95, 1e3 * report.deviation->max, report.deviation->points);
  std::fflush(stdout);
  if (const std::string failure = plot_report(folder); !failure.empty()) {
    fmt::print(stderr, "m3dp: error: quality.png not drawn: {}\n", failure);
    return 1;
  }
  fmt::print("  wrote quality.json, quality.csv and quality.png\n");
  return 0;
}

}  // namespace m3dp::app
