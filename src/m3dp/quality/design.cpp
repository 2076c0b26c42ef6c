#include "m3dp/quality/design.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace m3dp::quality {

namespace {
/// The rounded box's width for a section of `area` and `height`: (w − h)·h + π h²/4 = A.
double rounded_box_width(double area, double height) { return area / height + height * (1 - kPi / 4); }
}  // namespace

Design design_of(const toolpath::Trajectory& path, const Nozzle& nozzle) {
  Design design;
  const double bore = nozzle.inner_diameter;
  const std::vector<toolpath::PathVertex> vertices = path.polyline(Real(bore / 10));
  // Layers as the simulation counts them: a height more than a quarter of the bore from the last.
  const std::vector<double> starts = toolpath::layer_start_times(vertices, Real(0.25 * bore));
  for (const double start : starts) {
    for (const auto& vertex : vertices)
      if (vertex.extruding && vertex.time == start) {
        design.layer_z.push_back(double(vertex.position.z()));
        break;
      }
  }
  const double nominal_flow = kPi * bore * bore / 4 * nozzle.exit_speed;
  for (std::size_t v = 0; v + 1 < vertices.size(); ++v) {
    const auto& from = vertices[v];
    const auto& to = vertices[v + 1];
    const double duration = to.time - from.time;
    const Vec3d start = from.position.cast<double>(), end = to.position.cast<double>();
    const double length = (end - start).norm();
    // A vertical move (a step up between layers) lays no bead of this shape.
    if (!from.extruding || duration <= 0 || (end - start).head<2>().norm() < 1e-6) continue;
    Bead bead;
    bead.start = start;
    bead.end = end;
    bead.start_time = from.time;
    bead.end_time = to.time;
    bead.layer = static_cast<std::int32_t>(std::upper_bound(starts.begin(), starts.end(), from.time) - starts.begin()) - 1;
    const auto sample = path.sample((from.time + to.time) / 2);
    const double flow = sample.volume_rate > 0 ? double(sample.volume_rate) : nominal_flow;
    bead.area = flow / (length / duration);
    const std::size_t layer = static_cast<std::size_t>(std::max(0, bead.layer));
    const double below = layer == 0 ? nozzle.plate_z : design.layer_z[layer - 1];
    bead.height = std::max(design.layer_z.empty() ? 0.0 : design.layer_z[layer] - below, 1e-6);
    bead.width = rounded_box_width(bead.area, bead.height);
    design.beads.push_back(bead);
  }
  return design;
}

Design laid_by(const Design& design, double path_time) {
  Design laid;
  for (const Bead& bead : design.beads) {
    if (bead.start_time >= path_time) continue;
    Bead part = bead;
    if (bead.end_time > path_time) {
      // The nozzle moves along a bead at its constant speed: cut where it was at path_time.
      const double fraction = (path_time - bead.start_time) / (bead.end_time - bead.start_time);
      part.end = bead.start + fraction * (bead.end - bead.start);
      part.end_time = path_time;
    }
    laid.beads.push_back(part);
  }
  std::int32_t layers = 0;
  for (const Bead& bead : laid.beads) layers = std::max(layers, bead.layer + 1);
  laid.layer_z.assign(design.layer_z.begin(), design.layer_z.begin() + std::min<std::ptrdiff_t>(layers, std::ssize(design.layer_z)));
  return laid;
}

bool inside(const Bead& bead, const Vec3d& point) {
  const Vec3d along = bead.end - bead.start;
  const double length = along.norm();
  if (length <= 0) return false;
  const Vec3d tangent = along / length;
  const double s = (point - bead.start).dot(tangent);
  if (s < 0 || s > length) return false;
  // Across (horizontal, normal to the path) and up, in the section's plane.
  Vec3d across = Vec3d::UnitZ().cross(tangent);
  if (across.norm() < 1e-9) return false;  // a vertical move lays no bead of this shape
  across.normalize();
  const Vec3d at = bead.start + s * tangent;
  const double y = std::abs((point - at).dot(across));
  const double z = point.z() - (at.z() - bead.height);  // from the bead's bottom
  if (z < 0 || z > bead.height) return false;
  const double half_flat = bead.width / 2 - bead.height / 2;  // the rectangle's half width
  if (y <= half_flat) return true;
  const double radius = bead.height / 2;
  const double dy = y - half_flat, dz = z - radius;
  return dy * dy + dz * dz <= radius * radius;
}

PathSummary summarize(const toolpath::Trajectory& path, const Nozzle& nozzle) {
  PathSummary summary;
  summary.duration = path.end_time() - path.start_time();
  const std::vector<toolpath::PathVertex> vertices = path.polyline(Real(nozzle.inner_diameter / 10));
  const double nominal_flow = kPi * nozzle.inner_diameter * nozzle.inner_diameter / 4 * nozzle.exit_speed;
  for (std::size_t v = 0; v + 1 < vertices.size(); ++v) {
    const auto& from = vertices[v];
    const auto& to = vertices[v + 1];
    const double length = (to.position - from.position).norm();
    (from.extruding ? summary.extruding_length : summary.travel_length) += length;
    if (!from.extruding || to.time <= from.time) continue;
    const auto sample = path.sample((from.time + to.time) / 2);
    summary.commanded_volume += (sample.volume_rate > 0 ? double(sample.volume_rate) : nominal_flow) * (to.time - from.time);
  }
  const Design design = design_of(path, nozzle);
  summary.layers = design.layer_z.size();
  if (design.beads.empty()) return summary;
  summary.width_min = summary.height_min = std::numeric_limits<double>::infinity();
  for (const Bead& bead : design.beads) {
    summary.width_min = std::min(summary.width_min, bead.width);
    summary.width_max = std::max(summary.width_max, bead.width);
    summary.height_min = std::min(summary.height_min, bead.height);
    summary.height_max = std::max(summary.height_max, bead.height);
  }
  return summary;
}

}  // namespace m3dp::quality
