#pragma once
// How far the printed surface lies from the designed one (issue 39): the signed distance (m) from a
// point to the designed print, the union of its beads (each a 2D capsule, the rounded box, swept
// along its straight stretch of path), negative inside; evaluated at the printed mesh's vertices.
#include <span>
#include <vector>

#include "m3dp/quality/design.hpp"

namespace m3dp::quality {

class DesignDistance {
 public:
  /// Distances beyond `reach` (m) are reported as `reach` (far from every bead: nothing to compare).
  explicit DesignDistance(const Design& design, double reach = 0.05);
  /// The signed distance (m) from `point` to the design: < 0 inside a bead, > 0 outside all.
  [[nodiscard]] double operator()(const Vec3d& point) const;

 private:
  std::vector<Bead> beads_;
  double reach_;
  double cell_;                 // m, the buckets' size
  Vec3d origin_ = Vec3d::Zero();
  Eigen::Array3i cells_ = Eigen::Array3i::Zero();
  std::vector<std::vector<std::uint32_t>> buckets_;  // the beads whose box (grown by reach) meets each cell
};

/// The signed distance to a single bead (m).
[[nodiscard]] double signed_distance(const Bead& bead, const Vec3d& point);

/// The design's signed distance at each of `points` (m).
[[nodiscard]] std::vector<float> deviation_at(const DesignDistance& distance, std::span<const Vec3> points);

struct DeviationStatistics {
  std::size_t points = 0;
  double mean = 0;            // m, signed
  double p95 = 0, max = 0;    // m, of the magnitude
};
[[nodiscard]] DeviationStatistics statistics(std::span<const float> deviation);

/// The deviations counted in `bins` equal bins over [−range, range] (m), those beyond in the end bins.
struct Histogram {
  std::vector<double> edges;  // m, bins + 1
  std::vector<std::uint64_t> counts;
};
[[nodiscard]] Histogram histogram(std::span<const float> deviation, double range, std::size_t bins);

/// The scale a deviation is judged on: the design's thickest layer (m), what colour maps and
/// histograms span either side of zero.
[[nodiscard]] double deviation_range(const Design& design);

}  // namespace m3dp::quality
