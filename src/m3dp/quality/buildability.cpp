#include "m3dp/quality/buildability.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <unordered_map>

namespace m3dp::quality {

namespace {
/// When the design has laid `bead` over (x, y) (s; its nozzle two bead widths past it: the material
/// under and just behind the nozzle is still being shaped, and a print's first strand is thin), if it lies
/// over the bead's footprint (its width about its straight stretch).
std::optional<double> laid_over(const Bead& bead, const Eigen::Vector2d& point) {
  const Eigen::Vector2d start = bead.start.head<2>(), end = bead.end.head<2>();
  const Eigen::Vector2d along = end - start;
  const double length = along.norm();
  if (length <= 0) return std::nullopt;
  const double s = (point - start).dot(along / length);
  if (s < 0 || s > length) return std::nullopt;
  const Eigen::Vector2d across(-along.y() / length, along.x() / length);
  if (std::abs((point - start).dot(across)) > bead.width / 2) return std::nullopt;
  const double speed = length / std::max(bead.end_time - bead.start_time, 1e-9);
  return bead.start_time + (s + 2 * bead.width) / speed;
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
      Cell cell{Eigen::Vector2d(x, y), {}};
      for (const Bead& bead : design_.beads)
        if (const auto laid = laid_over(bead, cell.centre)) cell.laid.emplace_back(*laid, std::max(bead.start.z(), bead.end.z()));
      if (!cell.laid.empty()) footprint_.push_back(std::move(cell));
    }
}

void Buildability::observe(double time, std::span<const Vec3> positions) {
  HeightSample sample;
  sample.time = time;
  for (const Bead& bead : design_.beads)
    if (bead.start_time <= time) sample.layer = std::max(sample.layer, bead.layer);
  // The cells laid by now, with the design's top there; then each one's highest material.
  auto key = [&](double x, double y) {
    return (std::int64_t(std::floor(x / cell_)) << 32) ^ (std::int64_t(std::floor(y / cell_)) & 0xffffffff);
  };
  struct Column {
    double designed = 0, printed = 0;  // m above the plate: the design's top laid by now, the highest material
  };
  std::unordered_map<std::int64_t, Column> columns;  // per laid cell
  std::vector<double> designed;
  for (const Cell& cell : footprint_) {
    double top = -std::numeric_limits<double>::infinity();
    for (const auto& [laid, z] : cell.laid)
      if (laid <= time) top = std::max(top, z);
    if (!std::isfinite(top)) continue;
    designed.push_back(top - plate_z_);
    columns.emplace(key(cell.centre.x(), cell.centre.y()), Column{top - plate_z_, 0.0});
  }
  const double radius = cell_ / 4;  // a particle's radius
  for (const Vec3& p : positions) {
    const auto found = columns.find(key(p.x(), p.y()));
    if (found != columns.end()) found->second.printed = std::max(found->second.printed, double(p.z()) + radius - plate_z_);
  }
  // Each cell against its own design: while a layer is being laid, half the footprint is a layer
  // higher than the rest, and the medians of the two heights apart flipped between them (a wall of
  // 10 mm layers "fell short" at 12 of 20 mm halfway round its second layer).
  std::vector<double> ratios;
  ratios.reserve(columns.size());
  for (const auto& [cell, column] : columns)
    if (column.designed > 0) ratios.push_back(column.printed / column.designed);
  auto median = [](std::vector<double>& values) {
    if (values.empty()) return 0.0;
    std::nth_element(values.begin(), values.begin() + std::ptrdiff_t(values.size() / 2), values.end());
    return values[values.size() / 2];
  };
  sample.designed = median(designed);
  sample.printed = median(ratios) * sample.designed;
  history_.push_back(sample);
  // Judged over enough of the footprint (a few bead widths of wall), not its first cells alone.
  constexpr std::size_t kLeastCells = 25;
  if (!shortfall_ && designed.size() >= kLeastCells && sample.designed > 0 && sample.printed < (1 - tolerance_) * sample.designed)
    shortfall_ = Shortfall{time, sample.layer, sample.designed, sample.printed};
}

void Buildability::save(StateWriter& out) const {
  out.put(history_);
  out.put(shortfall_.has_value());
  if (shortfall_) out.put(*shortfall_);
}

void Buildability::load(StateReader& in) {
  in.get(history_);
  shortfall_.reset();
  if (in.get<bool>()) shortfall_ = in.get<Shortfall>();
}

}  // namespace m3dp::quality
