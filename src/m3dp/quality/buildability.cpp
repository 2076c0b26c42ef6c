#include "m3dp/quality/buildability.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

namespace m3dp::quality {

namespace {
/// Whether (x, y) lies over a bead's footprint (its width about its straight stretch).
bool over(const Bead& bead, const Eigen::Vector2d& point) {
  const Eigen::Vector2d start = bead.start.head<2>(), end = bead.end.head<2>();
  const Eigen::Vector2d along = end - start;
  const double length = along.norm();
  if (length <= 0) return false;
  const double s = (point - start).dot(along / length);
  if (s < 0 || s > length) return false;
  const Eigen::Vector2d across(-along.y() / length, along.x() / length);
  return std::abs((point - start).dot(across)) <= bead.width / 2;
}
}  // namespace

Buildability::Buildability(const Design& design, double particle_diameter, double plate_z, double tolerance)
    : design_(design), cell_(2 * particle_diameter), plate_z_(plate_z), tolerance_(tolerance) {
  Eigen::Vector2d low = Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity()), high = -low;
  for (const Bead& bead : design_.beads) {
    low = low.cwiseMin(bead.start.head<2>().cwiseMin(bead.end.head<2>()) - Eigen::Vector2d::Constant(bead.width));
    high = high.cwiseMax(bead.start.head<2>().cwiseMax(bead.end.head<2>()) + Eigen::Vector2d::Constant(bead.width));
  }
  if (design_.beads.empty()) return;
  for (double x = low.x() + cell_ / 2; x < high.x(); x += cell_)
    for (double y = low.y() + cell_ / 2; y < high.y(); y += cell_) {
      const Eigen::Vector2d centre(x, y);
      if (std::any_of(design_.beads.begin(), design_.beads.end(), [&](const Bead& bead) { return over(bead, centre); }))
        footprint_.push_back(centre);
    }
}

void Buildability::observe(double time, std::span<const Vec3> positions) {
  HeightSample sample;
  sample.time = time;
  // What the design has laid by now: its finished beads' tops.
  for (const Bead& bead : design_.beads)
    if (bead.end_time <= time + 1e-9) {
      sample.designed = std::max(sample.designed, std::max(bead.start.z(), bead.end.z()) - plate_z_);
      sample.layer = std::max(sample.layer, bead.layer);
    }
  // Each footprint cell's highest material, by the cell a particle falls in.
  auto key = [&](double x, double y) {
    return (std::int64_t(std::floor(x / cell_)) << 32) ^ (std::int64_t(std::floor(y / cell_)) & 0xffffffff);
  };
  std::unordered_map<std::int64_t, double> tops;
  tops.reserve(footprint_.size());
  for (const Eigen::Vector2d& centre : footprint_) tops.emplace(key(centre.x(), centre.y()), plate_z_);
  const double radius = cell_ / 4;  // a particle's radius
  for (const Vec3& p : positions) {
    const auto found = tops.find(key(p.x(), p.y()));
    if (found != tops.end()) found->second = std::max(found->second, double(p.z()) + radius);
  }
  std::vector<double> heights;
  heights.reserve(tops.size());
  for (const auto& [cell, top] : tops) heights.push_back(top - plate_z_);
  if (!heights.empty()) {
    std::nth_element(heights.begin(), heights.begin() + std::ptrdiff_t(heights.size() / 2), heights.end());
    sample.printed = heights[heights.size() / 2];
  }
  history_.push_back(sample);
  if (!shortfall_ && sample.designed > 0 && sample.printed < (1 - tolerance_) * sample.designed)
    shortfall_ = Shortfall{time, sample.layer, sample.designed, sample.printed};
}

}  // namespace m3dp::quality
