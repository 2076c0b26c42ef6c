#include "m3dp/toolpath/parametric.hpp"

#include <algorithm>
#include <cmath>

namespace m3dp::toolpath {

namespace {
Vec3 first_point(const Curve& curve) { return curve_point(curve, 0); }
Vec3 last_point(const Curve& curve) { return curve_point(curve, curve_length(curve)); }
}  // namespace

Real curve_length(const Curve& curve) {
  return std::visit(
      [](const auto& c) -> Real {
        using T = std::decay_t<decltype(c)>;
        if constexpr (std::is_same_v<T, LineCurve>) {
          return (c.end - c.start).norm();
        } else if constexpr (std::is_same_v<T, PolylineCurve>) {
          Real length = 0;
          for (std::size_t i = 1; i < c.points.size(); ++i) length += (c.points[i] - c.points[i - 1]).norm();
          return length;
        } else if constexpr (std::is_same_v<T, CircleCurve>) {
          return 2 * kPi * c.radius * std::abs(c.turns);
        } else {
          const Real per_turn = std::hypot(2 * kPi * c.radius, c.rise_per_turn);
          return per_turn * std::abs(c.turns);
        }
      },
      curve);
}

Vec3 curve_point(const Curve& curve, Real arc_length) {
  const Real length = curve_length(curve);
  const Real s = std::clamp(arc_length, Real(0), length);
  return std::visit(
      [&](const auto& c) -> Vec3 {
        using T = std::decay_t<decltype(c)>;
        if constexpr (std::is_same_v<T, LineCurve>) {
          return length > 0 ? Vec3(c.start + (c.end - c.start) * (s / length)) : c.start;
        } else if constexpr (std::is_same_v<T, PolylineCurve>) {
          Real remaining = s;
          for (std::size_t i = 1; i < c.points.size(); ++i) {
            const Real piece = (c.points[i] - c.points[i - 1]).norm();
            if (remaining <= piece && piece > 0) return c.points[i - 1] + (c.points[i] - c.points[i - 1]) * (remaining / piece);
            remaining -= piece;
          }
          return c.points.back();
        } else if constexpr (std::is_same_v<T, CircleCurve>) {
          const Real fraction = length > 0 ? s / length : 0;
          const Real angle = c.start_angle + 2 * kPi * c.turns * fraction;
          return c.centre + c.radius * Vec3(std::cos(angle), std::sin(angle), 0);
        } else {
          const Real fraction = length > 0 ? s / length : 0;
          const Real angle = c.start_angle + 2 * kPi * c.turns * fraction;
          return c.centre + Vec3(c.radius * std::cos(angle), c.radius * std::sin(angle), c.rise_per_turn * std::abs(c.turns) * fraction);
        }
      },
      curve);
}

Trajectory::Trajectory(std::vector<PathSegment> segments, double start_time) : start_time_(start_time) {
  append(std::move(segments), start_time);
}

void Trajectory::append(std::vector<PathSegment> segments, double not_before) {
  const double end = end_time();
  double time = std::max(end, not_before);
  bool have_previous = !pieces_.empty();
  Vec3 previous_end = have_previous ? last_point(pieces_.back().curve) : Vec3::Zero();
  Real previous_speed = have_previous ? pieces_.back().speed : Real(0);
  // A path added later than this one ends: the head waits where it stopped.
  if (have_previous && time > end) pieces_.push_back(Piece{LineCurve{previous_end, previous_end}, 0, 0, false, end, time - end});
  for (auto& segment : segments) {
    const Vec3 start = first_point(segment.curve);
    if (segment.dwell > 0) {
      // A pause where the head is (G4): no travel to it, no motion.
      const Vec3 where = have_previous ? previous_end : start;
      pieces_.push_back(Piece{LineCurve{where, where}, 0, 0, false, time, segment.dwell});
      time += segment.dwell;
      previous_end = where;
      have_previous = true;
      continue;
    }
    // Travel (no extrusion) where a segment does not start where the last one ended.
    if (have_previous && (start - previous_end).norm() > Real(1e-9)) {
      const Real length = (start - previous_end).norm();
      const Real speed = std::max(previous_speed, segment.speed);
      pieces_.push_back(Piece{LineCurve{previous_end, start}, length, speed, false, time, length / speed});
      time += length / speed;
    }
    const Real length = curve_length(segment.curve);
    const double duration = segment.speed > 0 ? length / segment.speed : 0.0;
    previous_end = last_point(segment.curve);
    previous_speed = segment.speed;
    have_previous = true;
    pieces_.push_back(Piece{std::move(segment.curve), length, segment.speed, segment.extrude, time, duration, segment.volume_rate});
    time += duration;
  }
}

double Trajectory::end_time() const { return pieces_.empty() ? start_time_ : pieces_.back().begin_time + pieces_.back().duration; }

std::vector<PathVertex> Trajectory::polyline(Real max_chord) const {
  std::vector<PathVertex> vertices;
  for (const Piece& piece : pieces_) {
    if (piece.length <= 0) continue;
    const bool straight = std::holds_alternative<LineCurve>(piece.curve);
    const bool polyline = std::holds_alternative<PolylineCurve>(piece.curve);
    std::vector<Real> arcs;
    if (polyline) {
      // Its own corners, so that no corner is cut.
      const auto& points = std::get<PolylineCurve>(piece.curve).points;
      Real arc = 0;
      arcs.push_back(0);
      for (std::size_t p = 1; p < points.size(); ++p) arcs.push_back(arc += (points[p] - points[p - 1]).norm());
    } else {
      const auto chords = straight ? 1 : std::max<std::size_t>(1, static_cast<std::size_t>(std::ceil(piece.length / max_chord)));
      for (std::size_t c = 0; c <= chords; ++c) arcs.push_back(piece.length * static_cast<Real>(c) / static_cast<Real>(chords));
    }
    for (std::size_t a = 0; a < arcs.size(); ++a) {
      const Vec3 position = curve_point(piece.curve, arcs[a]);
      const double time = piece.begin_time + arcs[a] / piece.speed;
      // A piece's first vertex is the previous piece's last one: it takes over its extrusion flag.
      if (a == 0 && !vertices.empty() && (vertices.back().position - position).norm() < Real(1e-9)) {
        vertices.back().extruding = piece.extrude;
        continue;
      }
      vertices.push_back({position, time, a + 1 < arcs.size() && piece.extrude});
    }
  }
  return vertices;
}

TrajectorySample Trajectory::sample(double time) const {
  TrajectorySample sample;
  if (pieces_.empty()) return sample;
  if (time < start_time_) {
    sample.position = first_point(pieces_.front().curve);
    return sample;
  }
  // Binary search: G-code paths have tens of thousands of pieces, sampled every step.
  const auto found = std::lower_bound(pieces_.begin(), pieces_.end(), time,
                                      [](const Piece& piece, double t) { return piece.begin_time + piece.duration < t; });
  if (found != pieces_.end()) {
    const Piece& piece = *found;
    const Real arc = static_cast<Real>((time - piece.begin_time) * piece.speed);
    sample.position = curve_point(piece.curve, arc);
    // Velocity by a central difference along the curve: exact for lines, O(ds²) for arcs.
    const Real ds = std::max(piece.length * Real(1e-4), Real(1e-7));
    const Real a = std::max(Real(0), arc - ds), b = std::min(piece.length, arc + ds);
    if (b > a) sample.velocity = (curve_point(piece.curve, b) - curve_point(piece.curve, a)) / (b - a) * piece.speed;
    sample.extruding = piece.extrude;
    sample.volume_rate = piece.volume_rate;
    return sample;
  }
  sample.position = last_point(pieces_.back().curve);
  return sample;
}

std::vector<double> layer_start_times(std::span<const PathVertex> vertices, Real tolerance) {
  std::vector<double> starts;
  Real layer_height = 0;
  for (const PathVertex& vertex : vertices) {
    if (!vertex.extruding) continue;
    if (starts.empty() || std::abs(vertex.position.z() - layer_height) > tolerance) {
      starts.push_back(vertex.time);
      layer_height = vertex.position.z();
    }
  }
  return starts;
}

void Trajectory::save(StateWriter& out) const {
  out.put(start_time_);
  out.put(static_cast<std::uint64_t>(pieces_.size()));
  for (const Piece& piece : pieces_) {
    out.put(static_cast<std::uint8_t>(piece.curve.index()));
    std::visit(
        [&](const auto& curve) {
          using C = std::decay_t<decltype(curve)>;
          if constexpr (std::is_same_v<C, PolylineCurve>) out.put(curve.points);
          else out.put(curve);
        },
        piece.curve);
    out.put(piece.length);
    out.put(piece.speed);
    out.put(piece.extrude);
    out.put(piece.begin_time);
    out.put(piece.duration);
    out.put(piece.volume_rate);
  }
}

void Trajectory::load(StateReader& in) {
  in.get(start_time_);
  const auto count = in.get<std::uint64_t>();
  if (count > in.remaining()) in.fail("a path with more pieces than the file holds");
  pieces_.clear();
  for (std::uint64_t p = 0; p < count; ++p) {
    Piece piece{LineCurve{}, 0, 0, false, 0, 0};
    switch (in.get<std::uint8_t>()) {
      case 0: piece.curve = in.get<LineCurve>(); break;
      case 1: {
        PolylineCurve polyline;
        in.get(polyline.points);
        piece.curve = std::move(polyline);
        break;
      }
      case 2: piece.curve = in.get<CircleCurve>(); break;
      case 3: piece.curve = in.get<HelixCurve>(); break;
      default: in.fail("a path piece of a kind that does not exist");
    }
    in.get(piece.length);
    in.get(piece.speed);
    in.get(piece.extrude);
    in.get(piece.begin_time);
    in.get(piece.duration);
    in.get(piece.volume_rate);
    pieces_.push_back(std::move(piece));
  }
}

}  // namespace m3dp::toolpath
