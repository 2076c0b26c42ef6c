#pragma once
// Whether a print stood (issue 39): its printed height against the design's over time, and the time
// and layer at which it fell short by more than a tolerance (a slump or a collapse). Over the part of
// the design's footprint laid by then (in cells two particles wide; a cell is laid once the nozzle
// has passed it by two bead widths), the printed height is the median of each cell's highest material
// and the designed one the median of the design's tops there: a splash or a strand hanging from the
// nozzle moves it little, a wall that sinks or spreads moves it all.
#include <optional>
#include <span>
#include <vector>

#include "m3dp/core/state_io.hpp"
#include "m3dp/quality/design.hpp"

namespace m3dp::quality {

struct HeightSample {
  double time = 0;          // s
  std::int32_t layer = -1;  // the last layer the design has laid by then (-1: none)
  double designed = 0;      // m, the design's height above the plate then
  double printed = 0;       // m: the design's height times the median over its footprint of each cell's printed/designed
};

struct Shortfall {
  double time = 0;          // s, when the printed height first fell short
  std::int32_t layer = -1;  // the layer the design had laid then
  double designed = 0, printed = 0;  // m
};

class Buildability {
 public:
  /// `tolerance`: the fraction of the designed height the print may fall short of before it counts
  /// as slumped (default 10 %).
  Buildability(const Design& design, double particle_diameter, double plate_z = 0, double tolerance = 0.1);
  /// The printed material at `time` (s).
  void observe(double time, std::span<const Vec3> positions);
  [[nodiscard]] const std::vector<HeightSample>& history() const { return history_; }
  /// The first time the print fell short of its design by more than the tolerance; none: it stood.
  [[nodiscard]] const std::optional<Shortfall>& shortfall() const { return shortfall_; }
  /// A checkpoint of what it has seen, and back.
  void save(StateWriter& out) const;
  void load(StateReader& in);

 private:
  Design design_;
  double cell_, plate_z_, tolerance_;
  struct Cell {
    Eigen::Vector2d centre;                            // m
    std::vector<std::pair<double, double>> laid;       // (s when the design has laid a bead over it, its top z in m)
  };
  std::vector<Cell> footprint_;  // the cells inside the design's beads
  std::vector<HeightSample> history_;
  std::optional<Shortfall> shortfall_;
};

}  // namespace m3dp::quality
