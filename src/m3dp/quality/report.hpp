#pragma once
// A print's quality report (issue 39): each head's sections and their figures per layer against the
// design, and the whole print's over- and under-fill; as quality.json and quality.csv.
#include <string>
#include <vector>

#include <optional>

#include "m3dp/core/error.hpp"
#include "m3dp/quality/buildability.hpp"
#include "m3dp/quality/deviation.hpp"
#include "m3dp/quality/sections.hpp"

namespace m3dp::quality {

/// A head's design, by name.
struct HeadDesign {
  std::string name;
  Design design;
};

/// One layer of one head: its sections' figures against the design's.
struct LayerFigures {
  std::int32_t layer = 0;
  std::size_t stations = 0, empty = 0;         // sections, and those with nothing printed
  double design_width = 0, design_height = 0, design_area = 0;  // m, m, m² (the layer's beads, mean)
  double width = 0, width_min = 0, width_max = 0;               // m, over the sections with material
  double height = 0, height_min = 0, height_max = 0;            // m: the rise over the layers under it
  double extent = 0;                                            // m, mean: its particles' bottom to top
  double area = 0;                                              // m², mean
  double offset_across = 0, offset_across_max = 0;  // m: mean, and the largest by magnitude (signed)
  double offset_up = 0;                             // m, mean: its top off the designed top
};

struct HeadReport {
  std::string name;
  std::vector<Section> sections;
  std::vector<LayerFigures> layers;
  /// The head's own printed height against its design over the frames, when measured: which of
  /// several walls stood.
  std::vector<HeightSample> heights;
  std::optional<Shortfall> shortfall;
};

struct Report {
  double time = 0;               // s of simulated time the particles are of
  double particle_diameter = 0;  // m
  std::size_t particles = 0;
  double spacing = 0;            // m between stations
  std::vector<HeadReport> heads;
  Fill fill;                     // every head's design against all the printed material
  /// The printed surface's signed distance to the design at its mesh's vertices, when measured.
  std::optional<DeviationStatistics> deviation;
  Histogram deviation_histogram;  // of those distances, over ± deviation_range(design)
  /// The printed height against the design's over the frames (Buildability), when measured.
  std::vector<HeightSample> heights;
  std::optional<Shortfall> shortfall;
  /// Set when the design's thinnest layer is under two particle diameters: the widths and heights are
  /// then measured at the resolution's limit (a strand one or two particles thick), not resolved.
  std::string resolution_warning;
};

/// Every head's beads as one design (the fill, the surface's distance, the height).
[[nodiscard]] Design combined(const std::vector<HeadDesign>& designs);

/// The printed height against the design over time (Buildability) for the whole print and, with
/// several heads, for each head's part of it, looked at together (one head's part is the whole).
class PrintHeights {
 public:
  PrintHeights(const std::vector<HeadDesign>& designs, double particle_diameter);
  void observe(double time, std::span<const Vec3> positions);
  [[nodiscard]] const Buildability& whole() const { return whole_; }
  [[nodiscard]] const std::vector<Buildability>& heads() const { return heads_; }
  /// Into `report`: the whole print's history and shortfall, and each head's.
  void fill_in(Report& report) const;
  void save(StateWriter& out) const;
  void load(StateReader& in);

 private:
  Buildability whole_;
  std::vector<Buildability> heads_;
};

/// A design the report cannot measure: a head whose extruding path is shorter than its bead is wide
/// (a pour in place, a dab), whose beads are no beads (the commanded flow over a near-zero speed
/// designs a bead hundreds of metres wide). what() says which head and why.
class UnmeasurableDesign : public Error {
 public:
  using Error::Error;
};
/// Throws UnmeasurableDesign for such a design.
void check_measurable(const std::vector<HeadDesign>& designs);

/// Measures `printed` against the heads' designs, a section every `spacing` (m) along each bead.
/// Throws UnmeasurableDesign first for a design it cannot measure.
[[nodiscard]] Report measure(const std::vector<HeadDesign>& designs, const Printed& printed, double spacing, double time);

/// quality.json's text (SI units in the keys) and quality.csv's (a row per section).
[[nodiscard]] std::string report_json(const Report& report);
[[nodiscard]] std::string report_csv(const Report& report);

}  // namespace m3dp::quality
