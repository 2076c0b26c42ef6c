// The quality module on synthetic prints with known answers (issue 39): the design of a path, and
// beads of particles on a lattice measured against it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "m3dp/quality/buildability.hpp"
#include "m3dp/quality/design.hpp"
#include "m3dp/quality/deviation.hpp"
#include "m3dp/quality/sections.hpp"
#include "m3dp/toolpath/gcode.hpp"

using namespace m3dp;

namespace {
// A 10 mm nozzle at U = 50 mm/s laying a rounded box 16 mm wide and 5 mm high: A = 11·5 + π·5²/4 mm².
constexpr double kBore = 0.01, kExitSpeed = 0.05, kWidth = 0.016, kHeight = 0.005;
const double kArea = (kWidth - kHeight) * kHeight + kPi * kHeight * kHeight / 4;
const double kTravelSpeed = kPi * kBore * kBore / 4 * kExitSpeed / kArea;  // V = Q/A
constexpr double kLength = 0.1;  // m, the bead along x from the origin

quality::Design line_design(double length = kLength) {
  toolpath::PathSegment line;
  line.curve = toolpath::LineCurve{Vec3(0, 0, Real(kHeight)), Vec3(Real(length), 0, Real(kHeight))};
  line.speed = Real(kTravelSpeed);
  return quality::design_of(toolpath::Trajectory({line}, 0), quality::Nozzle{kBore, kExitSpeed, 0});
}

/// Two layers of the line, there and back, the second one layer height higher.
quality::Design two_layer_design() {
  toolpath::PathSegment first, second;
  first.curve = toolpath::LineCurve{Vec3(0, 0, Real(kHeight)), Vec3(Real(kLength), 0, Real(kHeight))};
  second.curve = toolpath::LineCurve{Vec3(Real(kLength), 0, Real(2 * kHeight)), Vec3(0, 0, Real(2 * kHeight))};
  first.speed = second.speed = Real(kTravelSpeed);
  return quality::design_of(toolpath::Trajectory({first, second}, 0), quality::Nozzle{kBore, kExitSpeed, 0});
}

/// Particles on a lattice of spacing `d` filling `bead` (its rounded box widened to `width`,
/// moved `shift` across) over [from, to] of its length.
std::vector<Vec3> lattice_bead(quality::Bead bead, double d, double width, double shift, double from, double to) {
  bead.width = width;
  std::vector<Vec3> points;
  for (double x = from + d / 2; x < to; x += d)
    for (double y = -width / 2 + d / 2; y < width / 2; y += d)
      for (double z = bead.start.z() - bead.height + d / 2; z < bead.start.z(); z += d)
        if (quality::inside(bead, Vec3d(x, y, z))) points.emplace_back(Real(x), Real(y + shift), Real(z));
  return points;
}
}  // namespace

TEST(Quality, ALineIsABeadOfTheFlowOverTheSpeed) {
  const quality::Design design = line_design();
  ASSERT_EQ(design.beads.size(), 1u);
  const quality::Bead& bead = design.beads[0];
  EXPECT_NEAR(bead.area, kArea, 1e-9);
  EXPECT_NEAR(bead.height, kHeight, 1e-9);
  EXPECT_NEAR(bead.width, kWidth, 1e-9);
  EXPECT_EQ(bead.layer, 0);
  EXPECT_TRUE(quality::inside(bead, Vec3d(0.05, kWidth / 2 - 1e-4, kHeight / 2)));
  EXPECT_FALSE(quality::inside(bead, Vec3d(0.05, kWidth / 2 - 1e-4, kHeight - 1e-4)));  // the rounded corner
  EXPECT_FALSE(quality::inside(bead, Vec3d(0.05, 0, kHeight + 1e-4)));
}

TEST(Quality, APathSummarySaysWhatWasAsked) {
  // Two layers of a 0.1 m line, there and back 5 mm higher, with a travel up between them.
  toolpath::PathSegment first, second;
  first.curve = toolpath::LineCurve{Vec3(0, 0, Real(kHeight)), Vec3(Real(kLength), 0, Real(kHeight))};
  second.curve = toolpath::LineCurve{Vec3(Real(kLength), 0, Real(2 * kHeight)), Vec3(0, 0, Real(2 * kHeight))};
  first.speed = second.speed = Real(kTravelSpeed);
  const toolpath::Trajectory path({first, second}, 0);
  const quality::PathSummary summary = quality::summarize(path, quality::Nozzle{kBore, kExitSpeed, 0});
  EXPECT_EQ(summary.layers, 2u);
  EXPECT_NEAR(summary.extruding_length, 2 * kLength, 1e-6);
  EXPECT_NEAR(summary.travel_length, kHeight, 1e-6);
  EXPECT_NEAR(summary.commanded_volume, 2 * kArea * kLength, 1e-9);
  EXPECT_NEAR(summary.duration, 2 * kLength / kTravelSpeed + kHeight / kTravelSpeed, 1e-6);
  EXPECT_NEAR(summary.height_min, kHeight, 1e-6);
  EXPECT_NEAR(summary.height_max, kHeight, 1e-6);
  EXPECT_NEAR(summary.width_max, kWidth, 1e-6);
}

TEST(Quality, APerfectBeadMeasuresAsDesigned) {
  const quality::Design design = line_design();
  const double d = 0.0005;
  const std::vector<Vec3> points = lattice_bead(design.beads[0], d, kWidth, 0, 0, kLength);
  const quality::Printed printed{points, {}, d};
  const auto sections = quality::measure_sections(design, printed, 0.01);
  ASSERT_GE(sections.size(), 8u);
  for (const auto& section : sections) {
    EXPECT_NEAR(section.width, kWidth, 0.02 * kWidth);
    EXPECT_NEAR(section.height, kHeight, 0.02 * kHeight);
    EXPECT_NEAR(section.area, kArea, 0.02 * kArea);
    EXPECT_NEAR(section.offset_across, 0, 1e-6);
    EXPECT_NEAR(section.offset_up, 0, 1e-6);
  }
  const quality::Fill fill = quality::measure_fill(design, printed);
  const double volume = kArea * kLength;
  EXPECT_NEAR(fill.designed, volume, 0.02 * volume);
  EXPECT_NEAR(fill.printed, volume, 0.02 * volume);
  EXPECT_LT(fill.over, 0.02 * volume);
  EXPECT_LT(fill.under, 0.02 * volume);
}

TEST(Quality, ABeadShiftedThreeMillimetresSitsThreeMillimetresOff) {
  const quality::Design design = line_design();
  const double d = 0.0005;
  const std::vector<Vec3> points = lattice_bead(design.beads[0], d, kWidth, 0.003, 0, kLength);
  const auto sections = quality::measure_sections(design, quality::Printed{points, {}, d}, 0.01);
  ASSERT_FALSE(sections.empty());
  for (const auto& section : sections) EXPECT_NEAR(section.offset_across, 0.003, 1e-6);
  // Left of travel (+y for a path along +x) is positive.
  const std::vector<Vec3> right = lattice_bead(design.beads[0], d, kWidth, -0.003, 0, kLength);
  EXPECT_NEAR(quality::measure_sections(design, quality::Printed{right, {}, d}, 0.01)[0].offset_across, -0.003, 1e-6);
}

TEST(Quality, AMissingSegmentIsUnderFillOfItsVolume) {
  const quality::Design design = line_design();
  const double d = 0.0005;
  const std::vector<Vec3> half = lattice_bead(design.beads[0], d, kWidth, 0, 0, kLength / 2);
  const quality::Printed printed{half, {}, d};
  const quality::Fill fill = quality::measure_fill(design, printed);
  const double missing = kArea * kLength / 2;
  EXPECT_NEAR(fill.under, missing, 0.03 * missing);
  EXPECT_LT(fill.over, 0.02 * missing);
  // Its sections say where: nothing printed past the middle.
  for (const auto& section : quality::measure_sections(design, printed, 0.01))
    EXPECT_EQ(section.particles == 0, section.at.x() > kLength / 2 + d) << section.at.x();
}

TEST(Quality, ABeadTenPercentTooWideIsOverFillOfThatMuch) {
  const quality::Design design = line_design();
  const double d = 0.0005;
  const std::vector<Vec3> wide = lattice_bead(design.beads[0], d, 1.1 * kWidth, 0, 0, kLength);
  const quality::Fill fill = quality::measure_fill(design, quality::Printed{wide, {}, d});
  const double extra = 0.1 * kWidth * kHeight * kLength;  // the rounded box 1.6 mm wider, as high
  EXPECT_NEAR(fill.over, extra, 0.05 * extra);
  EXPECT_LT(fill.under, 0.02 * kArea * kLength);
  for (const auto& section : quality::measure_sections(design, quality::Printed{wide, {}, d}, 0.01))
    EXPECT_NEAR(section.width, 1.1 * kWidth, 0.02 * kWidth);
}

TEST(Quality, SectionsTakeTheirOwnLayer) {
  // Two layers of the same line; a section of the first sees only the first's particles.
  const quality::Design design = two_layer_design();
  ASSERT_EQ(design.beads.size(), 2u);
  ASSERT_EQ(design.layer_z.size(), 2u);
  EXPECT_EQ(design.beads[1].layer, 1);
  EXPECT_NEAR(design.beads[1].height, kHeight, 1e-6);
  const double d = 0.0005;
  std::vector<Vec3> points = lattice_bead(design.beads[0], d, kWidth, 0, 0, kLength);
  std::vector<std::int32_t> layers(points.size(), 0);
  // The second layer 20 % too thin: its particles up to 4 mm above the first's top.
  quality::Bead thin = design.beads[1];
  thin.height = 0.8 * kHeight;
  thin.start.z() = thin.end.z() = kHeight + thin.height;
  std::swap(thin.start, thin.end);
  thin.area = (kWidth - thin.height) * thin.height + kPi * thin.height * thin.height / 4;
  for (const Vec3& p : lattice_bead(thin, d, kWidth, 0, 0, kLength)) {
    points.push_back(p);
    layers.push_back(1);
  }
  const auto sections = quality::measure_sections(design, quality::Printed{points, layers, d}, 0.01);
  for (const auto& section : sections) {
    const double expected = section.layer == 0 ? kHeight : 0.8 * kHeight;
    EXPECT_NEAR(section.height, expected, 0.02 * kHeight) << "layer " << section.layer;
    EXPECT_NEAR(section.offset_up, section.layer == 0 ? 0 : -0.2 * kHeight, 1e-6);
  }
}

TEST(Quality, AJitteredPackingKeepsItsVolume) {
  // Particles a fifth of a diameter off a lattice, as material at rest sits: the fill's printed
  // volume is still the particles' (d³ each), and the sections' widths and heights within 5 %.
  const quality::Design design = line_design();
  const double d = 0.0005;
  std::vector<Vec3> points = lattice_bead(design.beads[0], d, kWidth, 0, 0, kLength);
  std::uint64_t state = 12345;
  auto jitter = [&] {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    return (double(state >> 11) / double(1ULL << 53) - 0.5) * 0.4 * d;
  };
  for (Vec3& p : points) p += Vec3(Real(jitter()), Real(jitter()), Real(jitter()));
  const quality::Printed printed{points, {}, d};
  const quality::Fill fill = quality::measure_fill(design, printed);
  const double volume = double(points.size()) * d * d * d;
  EXPECT_NEAR(fill.printed, volume, 0.03 * volume);
  for (const auto& section : quality::measure_sections(design, printed, 0.01)) {
    EXPECT_NEAR(section.width, kWidth, 0.05 * kWidth);
    EXPECT_NEAR(section.height, kHeight, 0.05 * kHeight);
  }
}

TEST(Quality, TheDesignsSignedDistanceIsThatOfItsRoundedBoxes) {
  const quality::Design design = line_design();
  const quality::DesignDistance distance(design);
  const double middle = kHeight / 2;  // the section's centre height
  EXPECT_NEAR(distance(Vec3d(0.05, 0, kHeight)), 0, 1e-7);                       // on its top
  EXPECT_NEAR(distance(Vec3d(0.05, 0, middle)), -kHeight / 2, 1e-7);             // inside: half a height from top and bottom
  EXPECT_NEAR(distance(Vec3d(0.05, kWidth / 2 + 0.003, middle)), 0.003, 1e-7);   // 3 mm off its side
  EXPECT_NEAR(distance(Vec3d(0.05, -kWidth / 2 - 0.003, middle)), 0.003, 1e-7);
  EXPECT_NEAR(distance(Vec3d(0.05, 0.002, kHeight + 0.001)), 0.001, 1e-7);       // 1 mm above its flat top
  EXPECT_NEAR(distance(Vec3d(kLength + 0.004, 0, middle)), 0.004, 1e-7);         // past its end
  EXPECT_NEAR(distance(Vec3d(0.05, 1.0, middle)), 0.05, 1e-12);                 // beyond reach
  // The rounded side: from the half-disc's centre, its radius away.
  const double corner_centre = kWidth / 2 - kHeight / 2;
  EXPECT_NEAR(distance(Vec3d(0.05, corner_centre + 0.004, kHeight + 0.003)), std::hypot(0.004, 0.003 + kHeight / 2) - kHeight / 2, 1e-7);
  const std::vector<float> deviation{0.003f, -0.003f, 0.0f, 0.001f};
  const auto stats = quality::statistics(deviation);
  EXPECT_NEAR(stats.mean, 0.00025, 1e-7);
  EXPECT_NEAR(stats.max, 0.003, 1e-7);
}

TEST(Quality, ABeadThatStandsAndOneThatSlumped) {
  // The line laid in 0.1 m / V ≈ 1.9 s; observed after it: as designed it stood, flattened to 60 %
  // of its height (and wider) it fell short, at layer 0.
  const quality::Design design = line_design();
  const double d = 0.0005, done = design.beads[0].end_time + 0.5;
  const std::vector<Vec3> standing = lattice_bead(design.beads[0], d, kWidth, 0, 0, kLength);
  quality::Buildability stood(design, d);
  stood.observe(0.0, {});
  stood.observe(done, standing);
  EXPECT_FALSE(stood.shortfall().has_value());
  EXPECT_NEAR(stood.history().back().designed, kHeight, 1e-6);
  EXPECT_NEAR(stood.history().back().printed, kHeight, d);
  quality::Bead flat = design.beads[0];
  flat.height = 0.6 * kHeight;
  flat.start.z() = flat.end.z() = flat.height;
  const std::vector<Vec3> slumped = lattice_bead(flat, d, 1.5 * kWidth, 0, 0, kLength);
  quality::Buildability fell(design, d);
  fell.observe(done, slumped);
  ASSERT_TRUE(fell.shortfall().has_value());
  EXPECT_EQ(fell.shortfall()->layer, 0);
  EXPECT_NEAR(fell.shortfall()->printed, 0.6 * kHeight, d);
}

TEST(Quality, AGcodeDesignHasTheSlicersOwnWidths) {
  // PrusaSlicer writes the width it planned each extrusion with (";WIDTH:") and computes E from the
  // same rounded box (its Flow: A = (w − h)·h + π h²/4); the design recovered from E and the layer
  // heights must give those widths back (scenes/gcode/cylinder_shell.gcode, 0.3 mm layers).
  const std::filesystem::path file = std::filesystem::path(M3DP_SCENES) / "gcode" / "cylinder_shell.gcode";
  const toolpath::GcodeProgram program = toolpath::read_gcode(file, {});
  const quality::Design design =
      quality::design_of(toolpath::Trajectory(program.path_segments(), 0), quality::Nozzle{0.0004, 0.05, 0});
  // The slicer's width for each line of the file: the last ";WIDTH:" before it.
  std::ifstream stream(file);
  std::vector<double> width_at_line{0};
  double width = 0;
  for (std::string line; std::getline(stream, line);) {
    if (line.rfind(";WIDTH:", 0) == 0) width = std::stod(line.substr(7)) * 1e-3;
    width_at_line.push_back(width);
  }
  // Beads and extruding moves in the same order (a move is a straight line; vertical ones lay no bead).
  std::size_t bead = 0;
  double length = 0, matching = 0;
  for (const auto& move : program.moves) {
    if (!move.extruding() || (move.end - move.start).head<2>().norm() < 1e-6) continue;
    ASSERT_LT(bead, design.beads.size());
    const quality::Bead& designed = design.beads[bead++];
    ASSERT_NEAR((designed.end - move.end.cast<double>()).norm(), 0, 1e-6) << "line " << move.line;
    const double planned = width_at_line.at(std::size_t(move.line));
    length += designed.length();
    if (std::abs(designed.width / planned - 1) < 0.02) matching += designed.length();
  }
  EXPECT_EQ(bead, design.beads.size());
  std::printf("%.1f %% of %.2f m of extrusion within 2 %% of PrusaSlicer's planned width\n", 100 * matching / length, length);
  EXPECT_GT(matching, 0.95 * length);
}

TEST(Quality, ALayerIsAsHighAsItRisesOverTheOneUnderIt) {
  // Two layers of the same line; the second sags 2 mm into the first (its particles from 1 mm below
  // the first's top), its top 5 mm over the first's: 5 mm high, 7 mm from bottom to top.
  const quality::Design design = two_layer_design();
  const double d = 0.0005;
  std::vector<Vec3> points;
  std::vector<std::int32_t> layers;
  for (double x = d / 2; x < kLength; x += d)
    for (double y = -0.004 + d / 2; y < 0.004; y += d) {
      for (double z = d / 2; z < 0.004; z += d) points.emplace_back(Real(x), Real(y), Real(z)), layers.push_back(0);  // top 4 mm
      for (double z = 0.004 - 0.002 + d / 2; z < 0.009; z += d) points.emplace_back(Real(x), Real(y), Real(z)), layers.push_back(1);
    }
  const auto sections = quality::measure_sections(design, quality::Printed{points, layers, d}, 0.01);
  std::size_t upper = 0;
  for (const auto& section : sections) {
    if (section.layer != 1 || section.particles == 0) continue;
    ++upper;
    EXPECT_NEAR(section.height, 0.005, 1e-6);  // 9 mm − 4 mm
    EXPECT_NEAR(section.extent, 0.007, 1e-6);  // 9 mm − 2 mm
  }
  EXPECT_GT(upper, 5u);
  for (const auto& section : sections) {
    if (section.layer == 0 && section.particles > 0) {
      EXPECT_NEAR(section.height, section.extent, 1e-12);  // on the bed
    }
  }
}

TEST(Quality, ARunStoppedEarlyIsJudgedOnWhatWasLaidByThen) {
  // Two layers there and back; stopped 30 % into the first, the design is 30 % of the first bead.
  const quality::Design design = two_layer_design();
  ASSERT_EQ(design.beads.size(), 2u);
  const double into = design.beads[0].start_time + 0.3 * (design.beads[0].end_time - design.beads[0].start_time);
  const quality::Design laid = quality::laid_by(design, into);
  ASSERT_EQ(laid.beads.size(), 1u);
  EXPECT_EQ(laid.layer_z.size(), 1u);
  EXPECT_NEAR(laid.beads[0].length(), 0.3 * kLength, 1e-9);
  EXPECT_NEAR(laid.beads[0].volume(), 0.3 * design.beads[0].volume(), 1e-12);
  // Past the end, the whole design.
  const quality::Design whole = quality::laid_by(design, design.beads[1].end_time + 1);
  EXPECT_EQ(whole.beads.size(), 2u);
  EXPECT_EQ(whole.layer_z.size(), 2u);
  // The fill of the laid part printed exactly: nothing under, as the whole design would say 70 % of
  // the first bead and all the second were.
  const std::vector<Vec3> printed = lattice_bead(design.beads[0], 0.0005, kWidth, 0, 0, 0.3 * kLength);
  const auto fill = quality::measure_fill(laid, quality::Printed{printed, {}, 0.0005});
  EXPECT_LT(fill.under, 0.05 * fill.designed);
}
