#include "m3dp/quality/report.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>

namespace m3dp::quality {

namespace {
std::vector<LayerFigures> layer_figures(const Design& design, const std::vector<Section>& sections) {
  std::map<std::int32_t, LayerFigures> layers;
  std::map<std::int32_t, std::size_t> beads;
  for (const Bead& bead : design.beads) {
    LayerFigures& figures = layers[bead.layer];
    figures.layer = bead.layer;
    figures.design_width += bead.width;
    figures.design_height += bead.height;
    figures.design_area += bead.area;
    ++beads[bead.layer];
  }
  for (auto& [layer, figures] : layers) {
    const double count = double(beads[layer]);
    figures.design_width /= count;
    figures.design_height /= count;
    figures.design_area /= count;
    figures.width_min = figures.height_min = std::numeric_limits<double>::infinity();
    figures.width_max = figures.height_max = -std::numeric_limits<double>::infinity();
  }
  for (const Section& section : sections) {
    LayerFigures& figures = layers[section.layer];
    ++figures.stations;
    if (section.particles == 0) {
      ++figures.empty;
      continue;
    }
    figures.width += section.width;
    figures.height += section.height;
    figures.extent += section.extent;
    figures.area += section.area;
    figures.offset_across += section.offset_across;
    figures.offset_up += section.offset_up;
    figures.width_min = std::min(figures.width_min, section.width);
    figures.width_max = std::max(figures.width_max, section.width);
    figures.height_min = std::min(figures.height_min, section.height);
    figures.height_max = std::max(figures.height_max, section.height);
    if (std::abs(section.offset_across) > std::abs(figures.offset_across_max)) figures.offset_across_max = section.offset_across;
  }
  std::vector<LayerFigures> result;
  for (auto& [layer, figures] : layers) {
    const double measured = double(figures.stations - figures.empty);
    if (measured > 0) {
      figures.width /= measured;
      figures.height /= measured;
      figures.extent /= measured;
      figures.area /= measured;
      figures.offset_across /= measured;
      figures.offset_up /= measured;
    } else {
      figures.width_min = figures.width_max = figures.height_min = figures.height_max = 0;
    }
    result.push_back(figures);
  }
  return result;
}
}  // namespace

void check_measurable(const std::vector<HeadDesign>& designs) {
  for (const HeadDesign& head : designs) {
    double length = 0, widest = 0;
    const Bead* wide = nullptr;
    for (const Bead& bead : head.design.beads) {
      length += bead.length();
      if (bead.width > widest) widest = bead.width, wide = &bead;
    }
    if (wide && !(length >= widest))
      throw UnmeasurableDesign(fmt::format(
          "head '{}' extrudes along {:.3g} mm of path, less than its bead is wide ({:.3g} m: a section of {:.3g} m2, the flow over "
          "the path's speed, {:.3g} m high): a pour in place, or a print stopped before its bead was longer than wide, so the "
          "quality report has nothing to measure",
          head.name, 1e3 * length, widest, wide->area, wide->height));
  }
}

Report measure(const std::vector<HeadDesign>& designs, const Printed& printed, double spacing, double time) {
  check_measurable(designs);
  Report report;
  report.time = time;
  report.particle_diameter = printed.particle_diameter;
  report.particles = printed.positions.size();
  report.spacing = spacing;
  for (const HeadDesign& head : designs) {
    HeadReport entry;
    entry.name = head.name;
    entry.sections = measure_sections(head.design, printed, spacing);
    entry.layers = layer_figures(head.design, entry.sections);
    report.heads.push_back(std::move(entry));
  }
  const Design all = combined(designs);
  report.fill = measure_fill(all, Printed{printed.positions, {}, printed.particle_diameter});
  double thinnest = std::numeric_limits<double>::infinity();
  for (const Bead& bead : all.beads) thinnest = std::min(thinnest, bead.height);
  if (std::isfinite(thinnest) && thinnest < 2 * printed.particle_diameter)
    report.resolution_warning = fmt::format(
        "the design's thinnest layer, {:.2f} mm, is under two particle diameters ({:.2f} mm): its beads' widths and heights are "
        "measured at the resolution's limit; a <particle_radius> of {:.2f} mm or less resolves them",
        1e3 * thinnest, 2e3 * printed.particle_diameter, 1e3 * thinnest / 4);
  return report;
}

Design combined(const std::vector<HeadDesign>& designs) {
  Design all;
  for (const HeadDesign& head : designs) all.beads.insert(all.beads.end(), head.design.beads.begin(), head.design.beads.end());
  return all;
}

PrintHeights::PrintHeights(const std::vector<HeadDesign>& designs, double particle_diameter)
    : whole_(combined(designs), particle_diameter) {
  if (designs.size() > 1)
    for (const HeadDesign& head : designs) heads_.emplace_back(head.design, particle_diameter);
}

void PrintHeights::observe(double time, std::span<const Vec3> positions) {
  whole_.observe(time, positions);
  for (Buildability& head : heads_) head.observe(time, positions);
}

void PrintHeights::fill_in(Report& report) const {
  report.heights = whole_.history();
  report.shortfall = whole_.shortfall();
  for (std::size_t h = 0; h < report.heads.size(); ++h) {
    const Buildability& part = heads_.empty() ? whole_ : heads_.at(h);
    report.heads[h].heights = part.history();
    report.heads[h].shortfall = part.shortfall();
  }
}

void PrintHeights::save(StateWriter& out) const {
  whole_.save(out);
  out.put(heads_.size());
  for (const Buildability& head : heads_) head.save(out);
}

void PrintHeights::load(StateReader& in) {
  whole_.load(in);
  if (in.get<std::size_t>() != heads_.size()) in.fail("another number of print heads than the scene has");
  for (Buildability& head : heads_) head.load(in);
}

namespace {
/// A height history and its shortfall as quality.json's "height" object.
nlohmann::json height_json(const std::vector<HeightSample>& heights, const std::optional<Shortfall>& shortfall_found) {
  nlohmann::json history = nlohmann::json::array();
  for (const HeightSample& sample : heights) history.push_back({sample.time, sample.layer, sample.designed, sample.printed});
  nlohmann::json shortfall;  // null: it stood
  if (shortfall_found)
    shortfall = {{"time_s", shortfall_found->time},
                 {"layer", shortfall_found->layer},
                 {"designed_m", shortfall_found->designed},
                 {"printed_m", shortfall_found->printed}};
  return {{"definition", "the printed height against the design's laid by then, each particle frame: the design's "
                         "(the median over its footprint of each cell's top) and the printed (that times the median "
                         "over the footprint of each cell's highest material over the cell's designed top); it fell "
                         "short when below 90 % of the design's"},
          {"stood", !shortfall_found.has_value()},
          {"shortfall", shortfall},
          {"history_columns", {"time_s", "layer", "designed_m", "printed_m"}},
          {"history", history}};
}
}  // namespace

std::string report_json(const Report& report) {
  nlohmann::json heads = nlohmann::json::array();
  for (const HeadReport& head : report.heads) {
    nlohmann::json layers = nlohmann::json::array();
    for (const LayerFigures& layer : head.layers)
      layers.push_back({{"layer", layer.layer},
                        {"stations", layer.stations},
                        {"stations_empty", layer.empty},
                        {"design_width_m", layer.design_width},
                        {"design_height_m", layer.design_height},
                        {"design_area_m2", layer.design_area},
                        {"width_m", layer.width},
                        {"width_min_m", layer.width_min},
                        {"width_max_m", layer.width_max},
                        {"height_m", layer.height},
                        {"height_min_m", layer.height_min},
                        {"height_max_m", layer.height_max},
                        {"extent_m", layer.extent},
                        {"area_m2", layer.area},
                        {"offset_across_m", layer.offset_across},
                        {"offset_across_largest_m", layer.offset_across_max},
                        {"offset_up_m", layer.offset_up}});
    nlohmann::json entry = {{"name", head.name}, {"sections", head.sections.size()}, {"layers", layers}};
    if (!head.heights.empty()) entry["height"] = height_json(head.heights, head.shortfall);
    heads.push_back(std::move(entry));
  }
  const nlohmann::json json = {
      {"definition", "sections across each designed bead (a slicer's rounded box of the commanded flow over the speed and the "
                     "layer's height) every spacing along it, of the particles printed in its layer, each a cube of the particle "
                     "diameter; a layer's height is the rise of its top over the top of the layers under it (on the bed, its "
                     "extent), its extent its particles' bottom to top; fill on a grid of half the particle diameter; the design "
                     "is what was laid by the time measured"},
      {"time_s", report.time},
      {"particles", report.particles},
      {"particle_diameter_m", report.particle_diameter},
      {"spacing_m", report.spacing},
      {"fill_m3",
       {{"designed", report.fill.designed}, {"printed", report.fill.printed}, {"over", report.fill.over}, {"under", report.fill.under}}},
      {"heads", heads},
      {"resolution_warning", report.resolution_warning.empty() ? nlohmann::json() : nlohmann::json(report.resolution_warning)}};
  nlohmann::json result = json;
  if (report.deviation)
    result["surface_deviation_m"] = {{"definition", "the printed surface's signed distance to the designed one at its mesh's vertices "
                                                    "(> 0 outside the design), mean signed, 95th percentile and max of its magnitude"},
                                     {"vertices", report.deviation->points},
                                     {"mean", report.deviation->mean},
                                     {"p95", report.deviation->p95},
                                     {"max", report.deviation->max},
                                     {"histogram",
                                      {{"edges_m", report.deviation_histogram.edges}, {"counts", report.deviation_histogram.counts}}}};
  if (!report.heights.empty()) result["height"] = height_json(report.heights, report.shortfall);
  return result.dump(2) + "\n";
}

std::string report_csv(const Report& report) {
  std::string csv = "head,layer,x_m,y_m,z_m,particles,width_m,height_m,area_m2,offset_across_m,offset_up_m,extent_m\n";
  for (const HeadReport& head : report.heads)
    for (const Section& section : head.sections)
      csv += fmt::format("{},{},{:.6g},{:.6g},{:.6g},{},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g},{:.6g}\n", head.name, section.layer,
                         section.at.x(), section.at.y(), section.at.z(), section.particles, section.width, section.height, section.area,
                         section.offset_across, section.offset_up, section.extent);
  return csv;
}

}  // namespace m3dp::quality
