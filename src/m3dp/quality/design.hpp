#pragma once
// The designed print (issue 39): what a print head's path asks for, as beads to compare a print
// against. Every extruding stretch of the path (an edge of its polyline) lays a bead whose section
// is a slicer's rounded box (Slic3r's "extrusion width" model: a rectangle with half-discs at its
// sides) of area A = Q/V (the commanded flow over the speed), the layer's height h (the path's
// height over the layer below, the first over the plate) and width w = A/h + h(1 − π/4); the bead's
// top is at the nozzle exit.
#include <cstdint>
#include <span>
#include <vector>

#include "m3dp/core/types.hpp"
#include "m3dp/toolpath/parametric.hpp"

namespace m3dp::quality {

/// What lays the path: the nozzle's bore and exit speed (its nominal flow π D²/4 · U, which a G-code
/// move's own flow replaces), and the plate the first layer lies on.
struct Nozzle {
  double inner_diameter = 0;  // m, D
  double exit_speed = 0;      // m/s, U
  double plate_z = 0;         // m, the surface under the first layer
};

/// One designed bead: a straight stretch of the path the nozzle extrudes along.
struct Bead {
  Vec3d start = Vec3d::Zero(), end = Vec3d::Zero();  // m, the nozzle exit's path
  double start_time = 0, end_time = 0;               // s, on the path's clock
  std::int32_t layer = 0;                            // the path's layer (0 first)
  double area = 0;                                   // m², Q/V
  double height = 0;                                 // m, the layer's
  double width = 0;                                  // m, the rounded box's
  [[nodiscard]] double length() const { return (end - start).norm(); }
  [[nodiscard]] double volume() const { return area * length(); }
};

struct Design {
  std::vector<Bead> beads;
  std::vector<double> layer_z;  // m, each layer's nozzle height (its top), layer order
};

/// The design of `path` laid by `nozzle`: its polyline's extruding edges (arcs in chords no longer
/// than a tenth of the bore), each with its layer, section and width.
[[nodiscard]] Design design_of(const toolpath::Trajectory& path, const Nozzle& nozzle);

/// What of `design` its nozzle had laid by `path_time` (s, on the path's clock): the beads begun by
/// then, the one under way cut where the nozzle was, the layers they are in. A run stopped before its
/// path ends (<end_time>, --until) is judged against this.
[[nodiscard]] Design laid_by(const Design& design, double path_time);

/// Whether `point` (m) lies inside the bead's rounded box swept along it (no caps at its ends).
[[nodiscard]] bool inside(const Bead& bead, const Vec3d& point);

/// What a path asks for, before anything runs (`m3dp validate`).
struct PathSummary {
  double duration = 0;           // s, from the path's start to its end
  double extruding_length = 0;   // m
  double travel_length = 0;      // m, moved without extruding
  std::size_t layers = 0;
  double commanded_volume = 0;   // m³: the flow asked for over the extruding time
  double width_min = 0, width_max = 0;    // m, the designed beads'
  double height_min = 0, height_max = 0;  // m
};
[[nodiscard]] PathSummary summarize(const toolpath::Trajectory& path, const Nozzle& nozzle);

}  // namespace m3dp::quality
