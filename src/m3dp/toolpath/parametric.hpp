#pragma once
// Parametric print paths → a timed nozzle trajectory: position, velocity and whether to extrude
// at any simulated time. Segments are walked in order at their speed; where a segment does not
// start where the previous one ended, the head travels there in a straight line without extruding.
#include <span>
#include <variant>
#include <vector>

#include "m3dp/core/state_io.hpp"
#include "m3dp/core/types.hpp"

namespace m3dp::toolpath {

struct LineCurve {
  Vec3 start = Vec3::Zero();
  Vec3 end = Vec3::Zero();
};
struct PolylineCurve {
  std::vector<Vec3> points;  // at least two
};
/// Circle in a horizontal plane (z = centre.z), counter-clockwise seen from above for turns > 0.
struct CircleCurve {
  Vec3 centre = Vec3::Zero();
  Real radius = 0;       // m
  Real start_angle = 0;  // rad from +x
  Real turns = 1;        // full turns (may be fractional or negative)
};
/// Helix around a vertical axis: like a circle but rising `rise_per_turn` metres each turn.
struct HelixCurve {
  Vec3 centre = Vec3::Zero();  // centre of the first turn
  Real radius = 0;
  Real start_angle = 0;
  Real turns = 1;
  Real rise_per_turn = 0;  // m
};
using Curve = std::variant<LineCurve, PolylineCurve, CircleCurve, HelixCurve>;

struct PathSegment {
  Curve curve;
  Real speed = Real(0.05);  // m/s along the curve
  bool extrude = true;
  Real dwell = 0;           // s; > 0: wait this long at the curve's first point instead of moving (G4)
  Real volume_rate = 0;     // m³/s of material while extruding; 0 = the nozzle's own π D²/4 · U (G-code sets it)
};

struct TrajectorySample {
  Vec3 position = Vec3::Zero();  // m
  Vec3 velocity = Vec3::Zero();  // m/s
  bool extruding = false;
  Real volume_rate = 0;          // m³/s asked of the nozzle; 0 = its nominal flow
};

/// A vertex of a path drawn as a polyline: where the head is at `time` and whether it extrudes on
/// the way from this vertex to the next.
struct PathVertex {
  Vec3 position = Vec3::Zero();  // m
  double time = 0;               // s
  bool extruding = false;
};

/// When a path drawn as `vertices` begins each print layer (s, on its clock): the first vertex that
/// extrudes more than `tolerance` (m) above or below the layer before.
[[nodiscard]] std::vector<double> layer_start_times(std::span<const PathVertex> vertices, Real tolerance);

/// Arc length of a curve (m) and the point at arc length s.
Real curve_length(const Curve& curve);
Vec3 curve_point(const Curve& curve, Real arc_length);

class Trajectory {
 public:
  Trajectory() = default;
  /// `start_time` (s): the head waits at the first point until then.
  Trajectory(std::vector<PathSegment> segments, double start_time);

  /// More segments after the last ones (with a travel to their first point where needed), from
  /// `not_before` (s) if that is later than the path's end: a path extended while it is followed.
  void append(std::vector<PathSegment> segments, double not_before);

  [[nodiscard]] TrajectorySample sample(double time) const;
  [[nodiscard]] double start_time() const { return start_time_; }
  [[nodiscard]] double end_time() const;
  [[nodiscard]] bool empty() const { return pieces_.empty(); }
  /// The whole path as a polyline: lines as their end points, arcs in chords no longer than
  /// `max_chord` (m); pauses leave no vertex. Viewers draw it, outputs write it.
  [[nodiscard]] std::vector<PathVertex> polyline(Real max_chord) const;

  /// A checkpoint of the path as it is (paths given at run time included), and back.
  void save(StateWriter& out) const;
  void load(StateReader& in);

 private:
  struct Piece {
    Curve curve;
    Real length;
    Real speed;
    bool extrude;
    double begin_time;
    double duration;
    Real volume_rate = 0;
  };
  std::vector<Piece> pieces_;
  double start_time_ = 0;
};

}  // namespace m3dp::toolpath
