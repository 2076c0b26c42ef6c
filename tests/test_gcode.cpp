// G-code: a real slicer's file read back to the slicer's own totals; arcs, modes, comments; errors
// with file:line.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include "m3dp/toolpath/gcode.hpp"

using namespace m3dp;
using namespace m3dp::toolpath;

namespace {
const std::filesystem::path kSlicerFile = std::filesystem::path(M3DP_SCENES) / "gcode" / "cylinder_shell.gcode";

std::string read_text(const std::filesystem::path& file) {
  std::ifstream stream(file);
  std::stringstream buffer;
  buffer << stream.rdbuf();
  return buffer.str();
}

/// A number the slicer wrote in a "; key = value" comment.
double slicer_total(const std::string& text, const std::string& key) {
  const std::regex pattern("; " + std::regex_replace(key, std::regex(R"([\[\]])"), R"(\$&)") + R"( = ([0-9.]+))");
  std::smatch match;
  if (!std::regex_search(text, match, pattern)) ADD_FAILURE() << "no '" << key << "' in the slicer file";
  return std::stod(match[1]);
}

constexpr double kPiDouble = 3.14159265358979323846;

GcodeProgram parse(const std::string& text, GcodeSettings settings = {}) { return parse_gcode(text, "test.gcode", settings); }

std::string error_of(const std::string& text) {
  try {
    (void)parse(text);
  } catch (const InputError& error) {
    return error.what();
  }
  return "no error";
}
}  // namespace

TEST(Gcode, PrusaSlicerFileMatchesTheSlicersTotals) {
  const std::string text = read_text(kSlicerFile);
  const GcodeProgram program = read_gcode(kSlicerFile, GcodeSettings{});
  const double filament_mm = slicer_total(text, "filament used [mm]");
  const double filament_cm3 = slicer_total(text, "filament used [cm3]");
  std::size_t layer_changes = 0;
  for (std::size_t at = text.find(";LAYER_CHANGE"); at != std::string::npos; at = text.find(";LAYER_CHANGE", at + 1)) ++layer_changes;
  std::printf("filament: parsed %.2f mm, PrusaSlicer %.2f mm (%+.3f %%); volume %.4f cm³ vs %.2f cm³; %d layers; %zu moves; "
              "%.0f s\n",
              program.net_extrusion, filament_mm, 100 * (program.net_extrusion / filament_mm - 1), program.material_volume * 1e6,
              filament_cm3, program.layers, program.moves.size(), program.duration);
  EXPECT_NEAR(program.net_extrusion / filament_mm, 1.0, 0.01);
  EXPECT_NEAR(program.material_volume * 1e6 / filament_cm3, 1.0, 0.01);
  EXPECT_EQ(program.layers, static_cast<int>(layer_changes));

  // The part: a shell of 15 mm outer radius centred at (100, 100) mm, 17 layers of 0.3 mm.
  double max_radius = 0, max_z = 0;
  std::set<std::string> features;
  for (const GcodeMove& move : program.moves) {
    if (!move.extruding()) continue;
    features.insert(move.feature);
    const Vec3 offset = move.end - Vec3(Real(0.1), Real(0.1), 0);
    if (move.feature != "Skirt/Brim") max_radius = std::max<double>(max_radius, offset.head<2>().norm());
    max_z = std::max<double>(max_z, move.end.z());
  }
  EXPECT_NEAR(max_radius, 0.015, 0.0005);  // metres: mm scaled
  EXPECT_NEAR(max_z, 17 * 0.0003, 1e-6);
  EXPECT_TRUE(features.count("External perimeter")) << "features seen: " << features.size();
  EXPECT_TRUE(features.count("Skirt/Brim"));
  // Temperatures, fans, homing are skipped with a warning at their first line.
  bool temperature_warning = false;
  for (const auto& warning : program.warnings)
    if (warning.message.rfind("M104 is not simulated", 0) == 0) temperature_warning = warning.location.line > 0;
  EXPECT_TRUE(temperature_warning);

  // The nozzle path follows the moves in time.
  const Trajectory trajectory(program.path_segments(), 0.0);
  EXPECT_NEAR(trajectory.end_time(), program.duration, 1e-6 * program.duration);
  const GcodeMove& middle = program.moves[program.moves.size() / 2];
  double begin = 0;
  for (const GcodeMove& move : program.moves) {
    if (&move == &middle) break;
    begin += move.duration;
  }
  const auto sample = trajectory.sample(begin + middle.duration / 2);
  EXPECT_LT((sample.position - (middle.start + middle.end) / 2).norm(), 1e-6);
}

TEST(Gcode, ArcsRelativeModesAndUnits) {
  // Quarter circle of radius 10 mm counter-clockwise (I J), then back clockwise by radius (R).
  const auto arcs = parse("G21\nG90\nG1 X10 Y0 F600\nG3 X0 Y10 I-10 J0 E1\nG2 X10 Y0 R10\n");
  double arc_length = 0;
  for (const auto& move : arcs.moves)
    if (move.line == 4) arc_length += (move.end - move.start).norm();
  std::printf("G3 quarter circle: %.4f mm of polyline, exact %.4f mm\n", arc_length * 1e3, kPi * 10 / 2);
  EXPECT_NEAR(arc_length * 1e3, kPi * 10 / 2, 0.002 * kPi * 10 / 2);
  EXPECT_NEAR(arcs.moves.back().end.x(), 0.010, 1e-7);
  for (const auto& move : arcs.moves) {
    if (move.line == 4) {
      EXPECT_NEAR((move.end * 1e3).head<2>().norm(), 10.0, 1e-3);  // on the circle
    }
  }
  // The clockwise R arc passes through the same quadrant (its centre is the origin too).
  for (const auto& move : arcs.moves) {
    if (move.line == 5) {
      EXPECT_NEAR((move.end * 1e3).head<2>().norm(), 10.0, 1e-3);
    }
  }

  // G91 relative moves, M83 relative E, G92 resets, inches.
  const auto relative = parse("G91\nM83\nG1 X5 E1 F600\nG1 X5 E1\nG92 E0\nG90\nM82\nG1 X20 E2\nG20\nG1 X1\n");
  ASSERT_EQ(relative.moves.size(), 4u);
  EXPECT_NEAR(relative.moves[1].end.x(), 0.010, 1e-7);
  EXPECT_NEAR(relative.moves[2].end.x(), 0.020, 1e-7);
  EXPECT_NEAR(relative.moves[2].extrusion, 2.0, 1e-9);  // E from the G92 zero
  EXPECT_NEAR(relative.net_extrusion, 4.0, 1e-9);
  EXPECT_NEAR(relative.moves[3].end.x(), 0.0254, 1e-6);  // G20: X1 is one inch
  // Feed rate: 600 mm/min over 5 mm takes 0.5 s.
  EXPECT_NEAR(relative.moves[0].duration, 0.5, 1e-9);

  // Construction scale: ten times larger, a thousand times the material, the same timing.
  GcodeSettings enlarged;
  enlarged.geometry_scale = 10;
  const auto big = parse("G1 X10 F600\nG1 X20 E1\n", enlarged);
  const auto small = parse("G1 X10 F600\nG1 X20 E1\n");
  EXPECT_NEAR(big.moves[1].end.x(), 0.2, 1e-6);
  EXPECT_NEAR(big.material_volume / small.material_volume, 1000.0, 1e-6);
  EXPECT_NEAR(big.duration, small.duration, 1e-12);

  // A printer's overrides (M220 speed, M221 flow): the same path, moves 1.25x faster, 0.85x the material.
  GcodeSettings overridden;
  overridden.speed_scale = Real(1.25);
  overridden.flow_scale = Real(0.85);
  const auto scaled = parse("G1 X10 F600\nG1 X20 E1\n", overridden);
  EXPECT_NEAR(scaled.moves[1].end.x(), small.moves[1].end.x(), 1e-9);
  EXPECT_NEAR(scaled.duration, small.duration / 1.25, 1e-6);
  EXPECT_NEAR(scaled.material_volume / small.material_volume, 0.85, 1e-6);
  // The same overrides written in the file (Marlin's M220 and M221, percent), and with the scene's on top.
  const auto in_file = parse("M220 S125\nM221 S85\nG1 X10 F600\nG1 X20 E1\n");
  EXPECT_NEAR(in_file.duration, small.duration / 1.25, 1e-6);
  EXPECT_NEAR(in_file.material_volume / small.material_volume, 0.85, 1e-6);
  const auto both = parse("M221 S50\nG1 X10 F600\nG1 X20 E1\n", overridden);
  EXPECT_NEAR(both.material_volume / small.material_volume, 0.85 * 0.5, 1e-6);
  EXPECT_NE(error_of("M221 S0\nG1 X10 E1\n").find("test.gcode:1: error: M221 S0: the flow factor must be in (0, 1000] %"), std::string::npos)
      << error_of("M221 S0\nG1 X10 E1\n");
}

TEST(Gcode, CuraCommentsDwellRetractionAndPlacement) {
  GcodeSettings settings;
  settings.placement = Pose::from_xyz_rpy(1, 2, Real(0.5), 0, 0, kPi / 2);  // build plate at (1, 2, 0.5), turned 90°
  const auto program = parse(
      ";FLAVOR:Marlin\n;LAYER:0\n;TYPE:WALL-OUTER\nG0 X10 Y0 Z0.2 F3000\nG1 X20 E1 F1200\nG1 E-0.8 F2400 ; retract\n"
      "G4 P500\nG1 E0.2\n;LAYER:1\n;TYPE:SKIN\nN12 G1 X30 E1.2*93\nM107\n",
      settings);
  EXPECT_EQ(program.layers, 2);
  ASSERT_GE(program.moves.size(), 5u);
  const GcodeMove& wall = program.moves[1];
  EXPECT_EQ(wall.feature, "WALL-OUTER");
  EXPECT_EQ(wall.layer, 0);
  EXPECT_TRUE(wall.extruding());
  // X along the G-code frame is +y in the world after the 90° turn; mm → m.
  EXPECT_NEAR(wall.end.x(), 1.0, 1e-6);
  EXPECT_NEAR(wall.end.y(), 2.020, 1e-6);
  EXPECT_NEAR(wall.end.z(), 0.5002, 1e-6);
  // Retraction and un-retraction take time in place and lay nothing; G4 P500 waits 0.5 s.
  EXPECT_TRUE(program.moves[2].dwell);
  EXPECT_FALSE(program.moves[2].extruding());
  EXPECT_NEAR(program.moves[3].duration, 0.5, 1e-12);
  EXPECT_EQ(program.moves.back().feature, "SKIN");
  EXPECT_EQ(program.moves.back().layer, 1);
  EXPECT_EQ(program.moves.back().line, 11);  // line numbers and checksums are read past
  // A 1.75 mm filament: 1 mm of E is π·0.875² mm³.
  EXPECT_NEAR(wall.material_volume, kPi * 0.875 * 0.875 * 1e-9, 1e-15);
  // The trajectory holds still through the dwell.
  const Trajectory trajectory(program.path_segments(), 0.0);
  double dwell_start = 0;
  for (std::size_t k = 0; k < 3; ++k) dwell_start += program.moves[k].duration;
  const Vec3 before = trajectory.sample(dwell_start + 0.01).position, after = trajectory.sample(dwell_start + 0.49).position;
  EXPECT_LT((before - after).norm(), 1e-9);
  EXPECT_FALSE(trajectory.sample(dwell_start + 0.2).extruding);
}

TEST(Gcode, APathTooLargeToHoldIsRefusedAtItsLine) {
  // A file's moves are counted as they are made: the line that passes GcodeSettings::max_moves is
  // refused, and an arc before a single piece of it is made.
  GcodeSettings settings;
  settings.max_moves = 100;
  std::string lines = "G1 X0 Y0 F600\n";
  for (int k = 1; k <= 101; ++k) lines += fmt::format("G1 X{} Y0 E{}\n", k, 0.1 * k);  // line 1 does not move
  try {
    (void)parse(lines, settings);
    ADD_FAILURE() << "101 moves were read with a limit of 100";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("test.gcode:102: error: the path would be more than 100 moves here (100 so far, 1 more"),
              std::string::npos)
        << error.what();
  }
  try {
    (void)parse("G1 X0 Y0 F600\nG1 X10 Y0 E1\nG2 X10 Y0 I-5 J0 E3\n", settings);  // 31.4 mm in 0.5 mm lines: 63
    (void)parse("G1 X0 Y0 F600\nG1 X10 Y0 E1\nG2 X10 Y0 I-50 J0 E30\n", settings);  // 314 mm: 629
    ADD_FAILURE() << "an arc of 629 lines was read with a limit of 100 moves";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("test.gcode:3: error: the path would be more than 100 moves here (1 so far, 629 more"),
              std::string::npos)
        << error.what();
  }
}

TEST(Gcode, BadLinesNameFileAndLine) {
  EXPECT_NE(error_of("G1 X10\nG1 Xabc Y2\n").find("test.gcode:2: error: 'Xabc' in 'G1 Xabc Y2' is not a number"),
            std::string::npos)
      << error_of("G1 X10\nG1 Xabc Y2\n");
  EXPECT_NE(error_of("G1 X10\nG2 X0 Y10\n").find("test.gcode:2: error: G2 needs a centre (I and J) or a radius (R)"),
            std::string::npos);
  EXPECT_NE(error_of("G1 X10\n\nX5 Y5\n").find("test.gcode:3: error: 'X5 Y5' has parameters but no G or M command"),
            std::string::npos);
  EXPECT_NE(error_of("G1 X10 F0\n").find("test.gcode:1: error:"), std::string::npos);
  // A centre a kilometre off: ~10⁷ lines, refused before they are made.
  EXPECT_NE(error_of("G1 X0 Y0\nG2 X0 Y0 I1000000 J0\n").find("test.gcode:2: error: G2: an arc of 6.283e+06 mm (radius 1e+06 mm) would be"),
            std::string::npos)
      << error_of("G1 X0 Y0\nG2 X0 Y0 I1000000 J0\n");
  EXPECT_NE(error_of("G1 X10 Y0\nG3 X0 Y30 I-10 J0\n").find("test.gcode:2: error: G3: start and end are not on one circle"),
            std::string::npos);
  // A number with an exponent: strtod firmwares read 1000, the grammar X1 then E3. Refused, never guessed.
  const std::string exponent = error_of("G1 X10\nG1 X1e3 Y2\n");
  EXPECT_NE(exponent.find("test.gcode:2: error: 'X1e3' in 'G1 X1e3 Y2' is ambiguous: 1 with an exponent, or X1 then e3 (E is the "
                          "extruder's axis)"),
            std::string::npos)
      << exponent;
  EXPECT_NE(error_of("G1 X10E-5\n").find("test.gcode:1: error: 'X10E-5'"), std::string::npos) << error_of("G1 X10E-5\n");
}

TEST(Gcode, RealPrinterProfilesLoadWithTheSlicersMaterial) {
  // Files that PrusaSlicer and Slic3r sliced with their printer profiles (tests/e2e/
  // slice_printer_profiles.py, run by ctest before this test): start and end G-code of real printers
  // (firmware checks, messages, macros, tool changes), every flavour, volumetric E, 2.85 mm filament,
  // extrusion on A. Each loads with the scene saying nothing about E, and lays the material the slicer
  // counted (its own moves: the printers' custom start G-code, ;TYPE:Custom, is not in its total).
  const char* directory = std::getenv("M3DP_SLICED_GCODE");
  ASSERT_NE(directory, nullptr) << "M3DP_SLICED_GCODE is not set: run this test through ctest";
  std::ifstream index(std::filesystem::path(directory) / "index.tsv");
  std::string row;
  int files = 0;
  std::set<std::string> macros;
  while (std::getline(index, row)) {
    // name \t printer and options \t what it must be refused for (empty: it loads)
    const std::size_t tab = row.find('\t'), second_tab = row.find('\t', tab + 1);
    const std::string name = row.substr(0, tab), printer = row.substr(tab + 1, second_tab - tab - 1);
    const std::string refusal = row.substr(second_tab + 1);
    const auto file = std::filesystem::path(directory) / (name + ".gcode");
    const std::string text = read_text(file);
    SCOPED_TRACE(row);
    ++files;
    GcodeProgram program;
    try {
      program = read_gcode(file, GcodeSettings{});
    } catch (const InputError& error) {
      std::printf("%-16s %-80s refused: %s\n", name.c_str(), printer.c_str(), error.what());
      EXPECT_FALSE(refusal.empty()) << error.what();
      EXPECT_NE(std::string(error.what()).find(refusal), std::string::npos) << error.what();
      continue;
    }
    EXPECT_TRUE(refusal.empty()) << "loaded, but should be refused: " << refusal;
    // The slicer's total: "; filament used [mm] = 178.32" (PrusaSlicer), "; filament used = 64.6mm (0.5cm3)" (Slic3r).
    std::smatch match;
    ASSERT_TRUE(std::regex_search(text, match, std::regex(R"(; filament used(?: \[mm\])? = ([0-9.]+))")));
    const double filament_mm = std::stod(match[1]);
    ASSERT_TRUE(std::regex_search(text, match, std::regex(R"(; filament_diameter = ([0-9.]+))")));
    const double diameter_mm = std::stod(match[1]);
    // What the printer lays of it: Prusa's MK3 profiles start with M221 S95 (flow at 95 %), which the
    // reader follows as the printer does; the slicer's total counts E alone.
    // The factor in effect where the printed features begin (the first ;TYPE: that is not the start's Custom).
    double flow_factor = 1;
    std::size_t features = text.find(";TYPE:");
    while (features != std::string::npos && text.compare(features, 12, ";TYPE:Custom") == 0) features = text.find(";TYPE:", features + 1);
    const std::string before_features = text.substr(0, features);
    const std::regex flow_override(R"((?:^|\n)M221 S([0-9.]+))");
    for (auto found = std::sregex_iterator(before_features.begin(), before_features.end(), flow_override); found != std::sregex_iterator(); ++found)
      flow_factor = std::stod((*found)[1]) / 100;
    const double expected = flow_factor * filament_mm * kPi * diameter_mm * diameter_mm / 4 * 1e-9;  // m³
    double laid = 0;
    for (const GcodeMove& move : program.moves)
      if (move.feature != "Custom") laid += move.material_volume;
    std::printf("%-16s %-80s %6.1f mm³ laid, the slicer's %6.1f (%+.2f %%), %zu warnings\n", name.c_str(), printer.c_str(), laid * 1e9, expected * 1e9, 100 * (laid / expected - 1),
                program.warnings.size());
    EXPECT_NEAR(laid / expected, 1.0, 0.01);
    for (const auto& warning : program.warnings)
      if (warning.message.find("firmware macro") != std::string::npos) macros.insert(warning.message.substr(0, warning.message.find(' ')));
  }
  EXPECT_GE(files, 30);
  // Klipper printers' start G-code calls their macros (Voron's print_start, RatRig's START_PRINT).
  EXPECT_TRUE(macros.count("PRINT_START") && macros.count("START_PRINT")) << macros.size() << " macros";
}

TEST(Gcode, FirmwareTextMacrosAndSignsAreSkippedOrReadNeverAnError) {
  const auto program = parse(
      "M117 Printing... 50% done; a message\nM862.3 P \"MK3S\" ; printer model check\nM115 U3.9.0\nM84 X Y E\n"
      "PRINT_START BED=60 EXTRUDER=210\nEXCLUDE_OBJECT_START NAME=cube_id_0\nexclude_object_end NAME=cube_id_0\n"
      "G1 X+30 Y-2 F600\nG1 X+40 E+1\nM118 E1 hello\n");
  ASSERT_EQ(program.moves.size(), 2u);
  EXPECT_NEAR(program.moves[1].end.x(), 0.040, 1e-7);  // "+40" is 40
  EXPECT_NEAR(program.moves[1].extrusion, 1.0, 1e-12);
  std::map<std::string, int> first_line;
  for (const auto& warning : program.warnings) first_line[warning.message.substr(0, warning.message.find(' '))] = warning.location.line;
  for (const auto& [command, line] : std::map<std::string, int>{{"M117", 1}, {"M862.3", 2}, {"M115", 3}, {"M84", 4}, {"PRINT_START", 5},
                                                                {"EXCLUDE_OBJECT_START", 6}, {"EXCLUDE_OBJECT_END", 7}, {"M118", 10}})
    EXPECT_EQ(first_line[command], line) << command;
  bool macro_named = false;
  for (const auto& warning : program.warnings)
    macro_named |= warning.message.rfind("PRINT_START is a firmware macro", 0) == 0;
  EXPECT_TRUE(macro_named);
}

TEST(Gcode, ArcsInEachPlane) {
  // A half circle of radius 5 mm in each plane, from the origin: G17 XY (I J), G18 ZX (K I), G19 YZ (J K).
  const auto xy = parse("G17\nG1 X0 Y0 Z0 F600\nG3 X10 Y0 I5 J0\n");
  const auto zx = parse("G18\nG1 X0 Y0 Z0 F600\nG2 X10 Z0 I5 K0\n");
  const auto yz = parse("G19\nG1 X0 Y0 Z0 F600\nG2 Y10 Z0 J5 K0\n");
  for (const auto* program : {&xy, &zx, &yz}) {
    double length = 0;
    for (const auto& move : program->moves) length += (move.end - move.start).norm();
    EXPECT_NEAR(length * 1e3, kPi * 5, 0.01);
  }
  // Counter-clockwise seen from +Z (G3) from (0,0) to (10,0) around (5,0) passes y = −5; clockwise
  // seen from +Y (G2 in ZX: +X turns to +Z) passes z = −5; clockwise seen from +X (G2 in YZ: +Y
  // turns to −Z) passes z = +5.
  auto extreme = [](const GcodeProgram& program, int axis) {
    double lowest = 0, highest = 0;
    for (const auto& move : program.moves) {
      lowest = std::min<double>(lowest, move.end[axis]);
      highest = std::max<double>(highest, move.end[axis]);
    }
    return std::abs(lowest) > highest ? lowest : highest;
  };
  EXPECT_NEAR(extreme(xy, 1) * 1e3, -5, 1e-3);
  EXPECT_NEAR(extreme(zx, 2) * 1e3, -5, 1e-3);
  EXPECT_NEAR(extreme(yz, 2) * 1e3, 5, 1e-3);
  EXPECT_NE(error_of("G18\nG2 X10 J5\n").find("G2 needs a centre (K and I) or a radius (R)"), std::string::npos);
}

TEST(Gcode, TheSlicersCountOfEIsFollowedOrTheContradictionRefused) {
  const std::string moves = "G1 X0 Y0 F600\nG1 X10 E2\n";
  const double filament_mm3 = 2 * kPiDouble * 1.75 * 1.75 / 4;
  // Volumetric E in the slicer's settings, the scene silent: E is mm³.
  EXPECT_NEAR(parse(moves + "; use_volumetric_e = 1\n").material_volume * 1e9, 2.0, 1e-9);
  EXPECT_NEAR(parse(";FLAVOR:UltiGCode\n" + moves).material_volume * 1e9, 2.0, 1e-9);  // Cura's UltiGCode
  EXPECT_NEAR(parse(moves + "; use_volumetric_e = 0\n").material_volume * 1e9, filament_mm3, 1e-6);
  // The file's filament diameter where the scene gives none.
  EXPECT_NEAR(parse(moves + "; filament_diameter = 2.85\n").material_volume * 1e9, 2 * kPiDouble * 2.85 * 2.85 / 4, 1e-6);
  // The scene and the file disagree: refused at the file's line, with the ratio.
  GcodeSettings filament;
  filament.volumetric_extrusion = false;
  auto error_with = [](const std::string& text, const GcodeSettings& settings) {
    try {
      (void)parse(text, settings);
    } catch (const InputError& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(error_with(moves + "; use_volumetric_e = 1\n", filament)
                .find("test.gcode:3: error: the slicer wrote E as mm³ of material (volumetric E) but the scene says mm of filament"),
            std::string::npos);
  GcodeSettings thin;
  thin.filament_diameter = Real(1.75e-3);
  const std::string diameter_error = error_with(moves + "; filament_diameter = 2.85\n", thin);
  EXPECT_NE(diameter_error.find("test.gcode:3: error: the slicer counted E in mm of 2.85 mm filament but the scene says 1.75 mm: "
                                "the material would be 0.377 times"),
            std::string::npos)
      << diameter_error;
  // Extrusion on A: followed where the slicer says so (mach3 and machinekit flavours), refused where not.
  EXPECT_NEAR(parse("G1 X0 Y0 F600\nG1 X10 A2\n; gcode_flavor = mach3\n").material_volume * 1e9, filament_mm3, 1e-6);
  EXPECT_NE(error_of("G1 X0 Y0 F600\nG1 X10 A2\n").find("test.gcode:2: error: G1 moves the A axis, which this reader does not follow"),
            std::string::npos);
  EXPECT_NE(error_of("G1 X10 E1\n; gcode_flavor = no-extrusion\n").find("test.gcode:2: error: the slicer wrote this file without extrusion"),
            std::string::npos);
}

TEST(Gcode, ARetractionIsPushedBackBeforeMaterialAndAPrimeComesOutWithTheNextMove) {
  // Retract 1, restart with 1.05 (0.05 extra), extrude 2: 2.05 laid; a wipe's retraction on a move lays nothing.
  const auto program = parse("M83\nG1 X0 F600\nG1 E-1\nG1 E1.05\nG1 X10 E2\nG1 X12 E-0.5\nG1 E0.5\nG1 X20 E1\n");
  const double per_mm = kPiDouble * 1.75 * 1.75 / 4 * 1e-9;
  EXPECT_NEAR(program.material_volume / per_mm, 3.05, 1e-6);
  EXPECT_NEAR(program.net_extrusion, 3.05, 1e-9);
}

TEST(Gcode, AFilamentDiameterNobodyStatedIsAssumedAloud) {
  const std::string moves = "G1 X0 Y0 F600\nG1 X5\nG1 X10 E2\n";
  const double area_175 = kPiDouble * 1.75 * 1.75 / 4, area_285 = kPiDouble * 2.85 * 2.85 / 4;  // mm²
  // Neither the file nor the scene says: 1.75 mm, and a warning at the first move that lays material.
  const GcodeProgram silent = parse(moves);
  EXPECT_NEAR(silent.material_volume * 1e9, 2 * area_175, 1e-6);
  ASSERT_EQ(silent.warnings.size(), 1u);
  EXPECT_EQ(silent.warnings[0].location.line, 3);
  EXPECT_NE(silent.warnings[0].message.find("neither the file nor the scene says how thick: read as 1.75 mm filament; sliced for "
                                            "2.85 mm filament, the print would need 2.65 times this material"),
            std::string::npos)
      << silent.warnings[0].message;
  // Every header that states it is read, and nothing is assumed.
  for (const std::string& header : {std::string("; filament_diameter = 2.85\n"),           // PrusaSlicer, Slic3r, Orca
                                    std::string(";   filamentDiameters,2.85|2.85|2.85\n"),  // Simplify3D
                                    std::string("; fiber_dia_mm = 2.85\n"),                 // KISSlicer
                                    std::string("M404 N2.85\n"),                           // RepRapFirmware
                                    // Cura: its changed settings, JSON cut into lines at the end of the file
                                    std::string(";SETTING_3 {\"extruder_quality\": [\"[general]\\\\nversion = 4\\\\n[values]\\\\nmaterial_di\n"
                                                ";SETTING_3 ameter = 2.85\\\\n\\\\n\"]}\n")}) {
    const GcodeProgram program = parse(header + moves);
    EXPECT_NEAR(program.material_volume * 1e9, 2 * area_285, 1e-6) << header;
    EXPECT_TRUE(program.warnings.empty()) << header << (program.warnings.empty() ? "" : program.warnings[0].message);
  }
  // The scene settles it, and volumetric E needs no diameter.
  GcodeSettings scene;
  scene.filament_diameter = Real(2.85e-3);
  EXPECT_TRUE(parse(moves, scene).warnings.empty());
  EXPECT_TRUE(parse("; use_volumetric_e = 1\n" + moves).warnings.empty());
  // A file that lays nothing has nothing to warn about.
  EXPECT_TRUE(parse("G1 X0 Y0 F600\nG1 X10\n").warnings.empty());
}

TEST(Gcode, AFeedRateBeyondAnyMachineIsRefusedAtItsLine) {
  // A feed of 10²⁶ mm/min would make its moves take no time; the fastest taken is 10 m/s at the
  // file's scale. (F1e26 itself is refused as ambiguous: F1 then e26.)
  const std::string huge = "G1 X0 Y0 F600\nG1 X10 E1 F100000000000000000000000000\n";
  EXPECT_NE(error_of(huge).find("test.gcode:2: error: F1e+26: a feed rate of 1.67e+21 m/s, beyond any printer; the fastest this reader "
                                "takes is F600000 (10 m/s at this file's scale)"),
            std::string::npos)
      << error_of(huge);
  EXPECT_EQ(error_of("G1 X0 Y0 F600000\nG1 X10 E1\n"), "no error");  // 10 m/s: a gantry's travel, taken
  // Printed five times larger, the same 10 m/s is F120000 of the file's millimetres.
  GcodeSettings larger;
  larger.geometry_scale = 5;
  try {
    (void)parse("G1 X10 F200000\n", larger);
    ADD_FAILURE() << "F200000 at × 5 (16.7 m/s) was taken";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("the fastest this reader takes is F120000 (10 m/s at this file's scale, × 5)"),
              std::string::npos)
        << error.what();
  }
}
