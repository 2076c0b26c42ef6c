#pragma once
// G-code → timed nozzle moves with the material they lay down. Reads what slicers write
// (PrusaSlicer/Slic3r, Cura): G0/G1 with X Y Z E F, G2/G3 arcs (centre offsets or R, helical),
// G90/G91, M82/M83, G92, G4 dwell, G20/G21 units, ';' and '(…)' comments, N line numbers and '*'
// checksums, and the slicers' layer (;LAYER_CHANGE, ;LAYER:n) and feature (;TYPE:…) comments.
// Other commands (temperatures, fans, homing, …) do not move the nozzle: they are skipped with a
// warning naming file:line. A line that cannot be read is an InputError naming file:line.
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/core/types.hpp"
#include "m3dp/toolpath/parametric.hpp"

namespace m3dp::toolpath {

struct GcodeSettings {
  // How E counts material. Unset: as the slicer's settings in the file say (PrusaSlicer's and Slic3r's
  // "; filament_diameter = …", "; use_volumetric_e = …", Cura's ";FLAVOR:UltiGCode" and its
  // material_diameter setting, Simplify3D's filamentDiameters, KISSlicer's fiber_dia_mm, M404 N…),
  // else 1.75 mm filament with a warning at the first extruding move. Set and contradicted by the
  // file: an InputError, since one of them is wrong.
  std::optional<Real> filament_diameter;    // m; in filament mode E counts millimetres of this filament
  std::optional<bool> volumetric_extrusion; // true: E counts mm³ of material (slicers' "volumetric E")
  Pose placement;                          // the G-code frame (scaled to m) → world: where the build plate is
  Real length_scale = Real(1e-3);          // G-code millimetres → m (G20 switches to inches)
  Real geometry_scale = 1;                 // enlarges the part: lengths and speeds × s, volumes × s³
                                           // (a desktop slicer's G-code printed at construction scale)
  Real default_feed_rate = Real(0.025);    // m/s until the first F word (1500 mm/min)
  Real speed_scale = 1;                    // every feed rate × this (a printer's M220 override): moves take 1/s the time
  Real flow_scale = 1;                     // material laid × this (a printer's M221 override)
  Real arc_segment_length = Real(0.5e-3);  // m, longest chord when arcs are split into lines
  // Moves (lines, arc pieces, dwells) a file may make, about 100 bytes each: more is refused at the
  // line that passes it, before it is allocated (a construction print is 10⁵–10⁶ moves).
  std::size_t max_moves = 20'000'000;
};

struct GcodeMove {
  Vec3 start = Vec3::Zero();      // m, world
  Vec3 end = Vec3::Zero();        // m, world
  double duration = 0;            // s at the feed rate (no acceleration)
  double extrusion = 0;           // E units this move adds (negative: retraction)
  double material_volume = 0;     // m³ of material laid down (0 for travel and retraction)
  bool dwell = false;             // G4, or an E-only move (retract/unretract) that takes time in place
  int layer = -1;                 // from the layer comments; -1 before the first
  int line = 0;                   // 1-based line in the file
  std::string feature;            // the last ;TYPE: comment, e.g. "Perimeter", "WALL-OUTER"
  [[nodiscard]] bool extruding() const { return material_volume > 0; }
};

struct GcodeProgram {
  std::vector<GcodeMove> moves;
  std::vector<Diagnostic> warnings;  // skipped commands, one per command per file (first line, count)
  double net_extrusion = 0;          // Σ E over the file (retractions net out): the slicer's "filament used"
  double material_volume = 0;        // m³ laid down
  double duration = 0;               // s
  int layers = 0;

  /// Nozzle path for a print head: one line per move (arcs already split), dwells as pauses,
  /// extrude on where the move lays material, at the volume rate E and F ask for.
  [[nodiscard]] std::vector<PathSegment> path_segments() const;
};

GcodeProgram parse_gcode(std::string_view text, const std::filesystem::path& file, const GcodeSettings& settings);
GcodeProgram read_gcode(const std::filesystem::path& file, const GcodeSettings& settings);

}  // namespace m3dp::toolpath
