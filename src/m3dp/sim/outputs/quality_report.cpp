// quality.json, quality.csv and quality_mesh.vtp/.ply: the print against its design (quality/), the
// printed height looked at every <output><quality_period> and the sections, fill and surface at the
// end; the same files `m3dp quality RUN_DIR` writes from the frames, and a section of the summary.
#include <algorithm>

#include "m3dp/quality/buildability.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/print_quality.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

/// Sections this far apart along each bead, as m3dp quality's default.
constexpr double kSpacing = 0.01;  // m

std::vector<toolpath::Trajectory> paths_of(const Simulation& simulation) {
  std::vector<toolpath::Trajectory> paths;
  for (std::size_t h = 0; h < simulation.scene().print_heads.size(); ++h) paths.push_back(simulation.head_path(h));
  return paths;
}

class QualityReport final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the quality report (quality.json)"; }
  QualityReport(const Simulation& simulation, std::filesystem::path folder)
      : folder_(std::move(folder)),
        period_(simulation.scene().output.quality_period),
        heights_(head_designs(simulation.scene(), paths_of(simulation)), double(simulation.solver().particle_diameter())) {}
  [[nodiscard]] double period() const override { return period_; }
  // The first look at the start, as the particle frames' first frame.
  void start(const Simulation& simulation) override { heights_.observe(simulation.time(), simulation.solver().fluid().position); }
  void observe(const Simulation& simulation, const StepReport& /*report*/) override {
    heights_.observe(simulation.time(), simulation.solver().fluid().position);
  }
  void save(StateWriter& out) override { heights_.save(out); }
  void resume(const Simulation& /*simulation*/, StateReader& in) override { heights_.load(in); }

  void finish(const Simulation& simulation, RunSummary& summary) override {
    RunSummary::Quality result;
    const auto& layers = simulation.solver().fluid().print_layer;
    if (std::none_of(layers.begin(), layers.end(), [](std::int32_t layer) { return layer >= 0; })) {
      result.note = "nothing was printed by a head's path";
      summary.quality = result;
      return;
    }
    if (heights_.whole().history().empty() || heights_.whole().history().back().time < simulation.time())
      heights_.observe(simulation.time(), simulation.solver().fluid().position);
    const std::vector<quality::HeadDesign> designs = designs_now(simulation);  // what was laid by now
    quality::Report report;
    try {
      report = measure_now(simulation, designs, kSpacing);
    } catch (const quality::UnmeasurableDesign& unmeasurable) {
      result.note = unmeasurable.what();  // skipped: the summary says why
      summary.quality = result;
      return;
    }
    complete_and_write_report(report, simulation.scene(), quality::combined(designs), simulation.solver().fluid().position, heights_,
                              folder_);
    result.file = "quality.json";
    double width = 0, design_width = 0, height = 0, design_height = 0, measured = 0;
    for (const auto& head : report.heads) {
      result.sections += head.sections.size();
      for (const auto& layer : head.layers) {
        const double count = double(layer.stations - layer.empty);
        if (count > 0) ++result.layers;  // layers with material
        width += layer.width * count;
        height += layer.height * count;
        design_width += layer.design_width * count;
        design_height += layer.design_height * count;
        measured += count;
      }
    }
    if (measured > 0) {
      result.width = width / measured, result.height = height / measured;
      result.design_width = design_width / measured, result.design_height = design_height / measured;
    }
    result.fill_over = report.fill.over, result.fill_under = report.fill.under, result.fill_designed = report.fill.designed;
    if (report.deviation) result.deviation_p95 = report.deviation->p95, result.deviation_max = report.deviation->max;
    result.stood = !report.shortfall.has_value();
    if (report.shortfall) result.shortfall_layer = report.shortfall->layer, result.shortfall_time = report.shortfall->time;
    for (const auto& head : report.heads)
      result.heads.push_back({head.name, !head.shortfall.has_value(), head.shortfall ? head.shortfall->layer : -1,
                              head.shortfall ? head.shortfall->time : 0.0});
    result.resolution_warning = report.resolution_warning;
    summary.quality = result;
  }

 private:
  std::filesystem::path folder_;
  double period_;
  quality::PrintHeights heights_;
};

}  // namespace

std::unique_ptr<RunObserver> make_quality_report(Simulation& simulation, const RunOptions& options) {
  if (options.output_directory.empty() || simulation.scene().print_heads.empty() || !(simulation.scene().output.quality_period > 0))
    return nullptr;
  return std::make_unique<QualityReport>(simulation, options.output_directory);
}

}  // namespace m3dp::sim::outputs
