#include "m3dp/quality/deviation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <fmt/format.h>

#include "m3dp/core/error.hpp"

namespace m3dp::quality {

double signed_distance(const Bead& bead, const Vec3d& point) {
  const Vec3d along = bead.end - bead.start;
  const double length = along.norm();
  const Vec3d horizontal(along.x(), along.y(), 0);
  if (length <= 0 || horizontal.norm() < 1e-9) return std::numeric_limits<double>::infinity();
  const Vec3d tangent = along / length;
  const Vec3d across = Vec3d::UnitZ().cross(tangent).normalized();
  const double s = (point - bead.start).dot(tangent);
  const double clamped = std::clamp(s, 0.0, length);
  const Vec3d at = bead.start + clamped * tangent;
  // The section: a capsule between (±a, −h/2) below the path, radius h/2, a = w/2 − h/2.
  const double radius = bead.height / 2, half_flat = std::max(0.0, bead.width / 2 - radius);
  const double y = (point - at).dot(across), z = point.z() - (at.z() - radius);
  const double section = std::hypot(std::max(0.0, std::abs(y) - half_flat), z) - radius;
  // Swept along [0, length] with flat ends: the extrusion's distance.
  const double beyond = std::max(-s, s - length);
  return std::min(std::max(section, beyond), 0.0) + std::hypot(std::max(section, 0.0), std::max(beyond, 0.0));
}

DesignDistance::DesignDistance(const Design& design, double reach) : beads_(design.beads), reach_(reach) {
  std::erase_if(beads_, [](const Bead& bead) { return Vec3d(bead.end - bead.start).head<2>().norm() < 1e-9; });
  if (beads_.empty()) return;
  Vec3d low = Vec3d::Constant(std::numeric_limits<double>::infinity()), high = -low;
  double widest = 0;
  for (const Bead& bead : beads_) {
    low = low.cwiseMin(bead.start.cwiseMin(bead.end));
    high = high.cwiseMax(bead.start.cwiseMax(bead.end));
    widest = std::max(widest, bead.width);
  }
  cell_ = std::max(widest + 2 * reach_, 1e-3);
  origin_ = low - Vec3d::Constant(cell_);
  cells_ = (((high - origin_) / cell_).array().floor() + 2).cast<int>();
  buckets_.resize(std::size_t(cells_.x()) * std::size_t(cells_.y()) * std::size_t(cells_.z()));
  for (std::size_t b = 0; b < beads_.size(); ++b) {
    const Bead& bead = beads_[b];
    const Vec3d grow = Vec3d::Constant(bead.width + reach_);
    const Eigen::Array3i first = ((bead.start.cwiseMin(bead.end) - grow - origin_) / cell_).array().floor().cast<int>().max(0);
    const Eigen::Array3i last = ((bead.start.cwiseMax(bead.end) + grow - origin_) / cell_).array().floor().cast<int>().min(cells_ - 1);
    for (int k = first.z(); k <= last.z(); ++k)
      for (int j = first.y(); j <= last.y(); ++j)
        for (int i = first.x(); i <= last.x(); ++i)
          buckets_[(std::size_t(k) * std::size_t(cells_.y()) + std::size_t(j)) * std::size_t(cells_.x()) + std::size_t(i)].push_back(
              std::uint32_t(b));
  }
}

double DesignDistance::operator()(const Vec3d& point) const {
  if (beads_.empty()) return reach_;
  const Eigen::Array3i at = ((point - origin_) / cell_).array().floor().cast<int>();
  if ((at < 0).any() || (at >= cells_).any()) return reach_;
  double nearest = reach_;
  for (const std::uint32_t b : buckets_[(std::size_t(at.z()) * std::size_t(cells_.y()) + std::size_t(at.y())) * std::size_t(cells_.x()) +
                                        std::size_t(at.x())])
    nearest = std::min(nearest, signed_distance(beads_[b], point));
  return nearest;
}

std::vector<float> deviation_at(const DesignDistance& distance, std::span<const Vec3> points) {
  std::vector<float> deviation(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) deviation[i] = float(distance(points[i].cast<double>()));
  return deviation;
}

DeviationStatistics statistics(std::span<const float> deviation) {
  DeviationStatistics result;
  result.points = deviation.size();
  if (deviation.empty()) return result;
  std::vector<double> magnitude;
  magnitude.reserve(deviation.size());
  double sum = 0;
  for (const float value : deviation) {
    sum += value;
    magnitude.push_back(std::abs(double(value)));
  }
  result.mean = sum / double(deviation.size());
  std::sort(magnitude.begin(), magnitude.end());
  result.max = magnitude.back();
  result.p95 = magnitude[std::min(magnitude.size() - 1, static_cast<std::size_t>(0.95 * double(magnitude.size())))];
  return result;
}

Histogram histogram(std::span<const float> deviation, double range, std::size_t bins) {
  Histogram result;
  if (!(range > 0) || bins == 0) throw Error(fmt::format("a deviation histogram needs a range > 0 and bins (got {} m, {})", range, bins));
  for (std::size_t b = 0; b <= bins; ++b) result.edges.push_back(-range + 2 * range * double(b) / double(bins));
  result.counts.assign(bins, 0);
  for (const float value : deviation) {
    const double at = std::floor((double(value) + range) / (2 * range) * double(bins));
    ++result.counts[std::size_t(std::clamp(at, 0.0, double(bins - 1)))];
  }
  return result;
}

double deviation_range(const Design& design) {
  double thickest = 0;
  for (const Bead& bead : design.beads) thickest = std::max(thickest, bead.height);
  return thickest > 0 ? thickest : 0.01;
}

}  // namespace m3dp::quality
