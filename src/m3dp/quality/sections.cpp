#include "m3dp/quality/sections.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace m3dp::quality {

namespace {
/// A bead's frame: along its path, across it (horizontal, to the left of travel), up.
struct BeadFrame {
  Vec3d tangent, across;
  bool valid = false;
};
BeadFrame frame_of(const Bead& bead) {
  BeadFrame frame;
  const Vec3d along = bead.end - bead.start;
  if (along.norm() <= 0) return frame;
  frame.tangent = along.normalized();
  frame.across = Vec3d::UnitZ().cross(frame.tangent);
  frame.valid = frame.across.norm() > 1e-9;
  if (frame.valid) frame.across.normalize();
  return frame;
}
}  // namespace

/// The printed particles in cells of a uniform grid, so that a bead visits only those near it.
class ParticleCells {
 public:
  ParticleCells(std::span<const Vec3> positions, double cell) : cell_(cell) {
    if (positions.empty()) return;
    Vec3d low = Vec3d::Constant(std::numeric_limits<double>::infinity()), high = -low;
    for (const Vec3& p : positions) {
      low = low.cwiseMin(p.cast<double>());
      high = high.cwiseMax(p.cast<double>());
    }
    origin_ = low;
    cells_ = (((high - low) / cell_).array().floor() + 1).cast<long>().max(1);
    starts_.assign(std::size_t(cells_.prod()) + 1, 0);
    std::vector<std::size_t> cell_of(positions.size());
    for (std::size_t i = 0; i < positions.size(); ++i) {
      cell_of[i] = index(((positions[i].cast<double>() - origin_) / cell_).array().floor().cast<long>().min(cells_ - 1));
      ++starts_[cell_of[i] + 1];
    }
    for (std::size_t c = 1; c < starts_.size(); ++c) starts_[c] += starts_[c - 1];
    order_.resize(positions.size());
    std::vector<std::size_t> next(starts_.begin(), starts_.end() - 1);
    for (std::size_t i = 0; i < positions.size(); ++i) order_[next[cell_of[i]]++] = i;
  }
  /// Calls `visit(i)` for every particle in the cells that meet the box [low, high].
  template <class Visit>
  void each_in(const Vec3d& low, const Vec3d& high, Visit&& visit) const {
    if (order_.empty()) return;
    const Eigen::Array<long, 3, 1> first = ((low - origin_) / cell_).array().floor().cast<long>().max(0);
    const Eigen::Array<long, 3, 1> last = ((high - origin_) / cell_).array().floor().cast<long>().min(cells_ - 1);
    for (long k = first.z(); k <= last.z(); ++k)
      for (long j = first.y(); j <= last.y(); ++j)
        for (long i = first.x(); i <= last.x(); ++i) {
          const std::size_t c = index({i, j, k});
          for (std::size_t n = starts_[c]; n < starts_[c + 1]; ++n) visit(order_[n]);
        }
  }

 private:
  [[nodiscard]] std::size_t index(const Eigen::Array<long, 3, 1>& at) const {
    return std::size_t((at.z() * cells_.y() + at.y()) * cells_.x() + at.x());
  }
  double cell_;
  Vec3d origin_ = Vec3d::Zero();
  Eigen::Array<long, 3, 1> cells_ = Eigen::Array<long, 3, 1>::Zero();
  std::vector<std::size_t> starts_, order_;
};

std::vector<Section> measure_sections(const Design& design, const Printed& printed, double spacing) {
  std::vector<Section> sections;
  const double d = printed.particle_diameter;
  double widest = d;
  for (const Bead& bead : design.beads) widest = std::max({widest, bead.width, 3 * bead.height});
  const ParticleCells cells(printed.positions, widest);
  for (std::size_t b = 0; b < design.beads.size(); ++b) {
    const Bead& bead = design.beads[b];
    const BeadFrame frame = frame_of(bead);
    const double length = bead.length();
    if (!frame.valid || length <= bead.width) continue;
    // The particles that may belong to this bead: its layer, within a bead width across and a layer
    // height above or below it.
    std::vector<Vec3d> local;  // (along, across, z)
    // And the earlier layers' particles under it (with layers known), whose top its rise is taken from.
    std::vector<Vec3d> below;
    const Vec3d reach(bead.width + d, bead.width + d, 3 * bead.height);
    cells.each_in(bead.start.cwiseMin(bead.end) - reach, bead.start.cwiseMax(bead.end) + reach, [&](std::size_t i) {
      const bool earlier = !printed.layers.empty() && printed.layers[i] >= 0 && printed.layers[i] < bead.layer;
      if (!printed.layers.empty() && printed.layers[i] != bead.layer && !earlier) return;
      const Vec3d p = printed.positions[i].cast<double>() - bead.start;
      const double s = p.dot(frame.tangent), y = p.dot(frame.across);
      if (s < -d || s > length + d || std::abs(y) > bead.width) return;
      const double z = printed.positions[i].z();
      const double top = bead.start.z() + s / length * (bead.end.z() - bead.start.z());
      if (earlier) {
        if (z >= top - 3 * bead.height && z <= top) below.emplace_back(s, y, z);
        return;
      }
      if (z < top - 2 * bead.height || z > top + bead.height) return;
      local.emplace_back(s, y, z);
    });
    for (double s = bead.width / 2; s <= length - bead.width / 2 + 1e-12; s += spacing) {
      Section section;
      section.bead = b;
      section.layer = bead.layer;
      section.at = bead.start + s * frame.tangent;
      double y_min = std::numeric_limits<double>::infinity(), y_max = -y_min, z_min = y_min, z_max = -y_min;
      for (const Vec3d& p : local) {
        if (std::abs(p.x() - s) >= d) continue;  // a slab two diameters thick
        ++section.particles;
        y_min = std::min(y_min, p.y());
        y_max = std::max(y_max, p.y());
        z_min = std::min(z_min, p.z());
        z_max = std::max(z_max, p.z());
      }
      if (section.particles > 0) {
        section.width = y_max - y_min + d;
        section.extent = z_max - z_min + d;
        // The rise over what is under it: the top of the earlier layers across this section's span
        // (the extent reaches into the layer below wherever the bead sags into it). On the bed, or
        // with nothing printed under it, the extent.
        double below_top = -std::numeric_limits<double>::infinity();
        for (const Vec3d& p : below)
          if (std::abs(p.x() - s) < d && p.y() >= y_min - d / 2 && p.y() <= y_max + d / 2) below_top = std::max(below_top, p.z());
        section.height = std::isfinite(below_top) ? z_max - below_top : section.extent;
        section.area = double(section.particles) * d * d * d / (2 * d);
        section.offset_across = (y_max + y_min) / 2;
        section.offset_up = z_max + d / 2 - section.at.z();
      }
      sections.push_back(section);
    }
  }
  return sections;
}

Fill measure_fill(const Design& design, const Printed& printed) {
  Fill fill;
  const double d = printed.particle_diameter;
  const double voxel = d / 2;
  // The grid spans the design's beads and the printed material.
  Vec3d low = Vec3d::Constant(std::numeric_limits<double>::infinity()), high = -low;
  for (const Bead& bead : design.beads) {
    const Vec3d reach(bead.width, bead.width, bead.height);
    for (const Vec3d& end : {bead.start, bead.end}) {
      low = low.cwiseMin(end - reach);
      high = high.cwiseMax(end + reach);
    }
  }
  for (const Vec3& p : printed.positions) {
    low = low.cwiseMin(p.cast<double>() - Vec3d::Constant(d));
    high = high.cwiseMax(p.cast<double>() + Vec3d::Constant(d));
  }
  if (!(low.array() < high.array()).all()) return fill;
  const Eigen::Array3d cells = ((high - low) / voxel).array().ceil();
  const auto nx = static_cast<std::size_t>(cells.x()), ny = static_cast<std::size_t>(cells.y()), nz = static_cast<std::size_t>(cells.z());
  auto index = [&](std::size_t i, std::size_t j, std::size_t k) { return (k * ny + j) * nx + i; };
  auto centre = [&](std::size_t i, std::size_t j, std::size_t k) {
    return Vec3d(low.x() + (double(i) + 0.5) * voxel, low.y() + (double(j) + 0.5) * voxel, low.z() + (double(k) + 0.5) * voxel);
  };
  std::vector<std::uint8_t> cell(nx * ny * nz, 0);  // bit 0: designed, bit 1: printed
  std::vector<float> occupancy(nx * ny * nz, 0.0f);
  for (const Bead& bead : design.beads) {
    const Vec3d reach(bead.width, bead.width, bead.height);
    const Vec3d box_low = bead.start.cwiseMin(bead.end) - reach, box_high = bead.start.cwiseMax(bead.end) + reach;
    const auto first = ((box_low - low) / voxel).array().floor().max(0).cast<std::size_t>();
    const Eigen::Array3d last_cell = ((box_high - low) / voxel).array().ceil();
    const std::size_t last_i = std::min(nx, std::size_t(last_cell.x())), last_j = std::min(ny, std::size_t(last_cell.y())),
                      last_k = std::min(nz, std::size_t(last_cell.z()));
    for (std::size_t k = first.z(); k < last_k; ++k)
      for (std::size_t j = first.y(); j < last_j; ++j)
        for (std::size_t i = first.x(); i < last_i; ++i)
          if (inside(bead, centre(i, j, k))) cell[index(i, j, k)] |= 1;
  }
  // Printed where the material's volume fraction is at least a half: each particle's volume d³
  // spread by a tent of half-width d per axis (the sum is 1 inside a lattice of spacing d and 0.5 on
  // its fair face, half a spacing past its outer particles; a random packing's is smooth).
  for (const Vec3& particle : printed.positions) {
    const Vec3d p = particle.cast<double>();
    const Eigen::Array3d first = ((p - low) / voxel - Vec3d::Constant(2.5)).array().ceil().max(0);
    for (auto k = std::size_t(first.z()); k < nz && k <= std::size_t(first.z()) + 4; ++k)
      for (auto j = std::size_t(first.y()); j < ny && j <= std::size_t(first.y()) + 4; ++j)
        for (auto i = std::size_t(first.x()); i < nx && i <= std::size_t(first.x()) + 4; ++i) {
          const Vec3d offset = (centre(i, j, k) - p).cwiseAbs() / d;
          if ((offset.array() >= 1).any()) continue;
          occupancy[index(i, j, k)] += float((1 - offset.x()) * (1 - offset.y()) * (1 - offset.z()));
        }
  }
  for (std::size_t c = 0; c < cell.size(); ++c)
    if (occupancy[c] >= 0.5f) cell[c] |= 2;
  const double voxel_volume = voxel * voxel * voxel;
  for (const std::uint8_t value : cell) {
    if (value & 1) fill.designed += voxel_volume;
    if (value & 2) fill.printed += voxel_volume;
    if (value == 2) fill.over += voxel_volume;
    if (value == 1) fill.under += voxel_volume;
  }
  return fill;
}

}  // namespace m3dp::quality
