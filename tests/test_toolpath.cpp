#include <gtest/gtest.h>

#include <cmath>

#include "m3dp/core/error.hpp"
#include "m3dp/toolpath/parametric.hpp"
#include "m3dp/toolpath/waypoints.hpp"

using namespace m3dp;
using namespace m3dp::toolpath;

TEST(Toolpath, CurveLengths) {
  EXPECT_NEAR(curve_length(LineCurve{Vec3(0, 0, 0), Vec3(3, 4, 0)}), 5, 1e-6);
  EXPECT_NEAR(curve_length(PolylineCurve{{Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(1, 1, 0)}}), 2, 1e-6);
  EXPECT_NEAR(curve_length(CircleCurve{Vec3::Zero(), 0.5f, 0, 2}), 2 * kPi, 1e-5);
  EXPECT_NEAR(curve_length(HelixCurve{Vec3::Zero(), 1, 0, 1, 0.1f}), std::hypot(2 * kPi, 0.1), 1e-5);
}

TEST(Toolpath, CircleIsWalkedAtSpeedWithTangentVelocity) {
  const Real radius = 0.05f, speed = 0.02f;
  Trajectory trajectory({PathSegment{CircleCurve{Vec3(0, 0, 0.01f), radius, 0, 1}, speed, true}}, 0.5);
  EXPECT_NEAR(trajectory.end_time(), 0.5 + 2 * kPi * radius / speed, 1e-4);
  const auto before = trajectory.sample(0.2);
  EXPECT_FALSE(before.extruding);
  EXPECT_NEAR((before.position - Vec3(radius, 0, 0.01f)).norm(), 0, 1e-6);
  const double quarter = 0.5 + 0.25 * 2 * kPi * radius / speed;
  const auto sample = trajectory.sample(quarter);
  EXPECT_TRUE(sample.extruding);
  EXPECT_NEAR((sample.position - Vec3(0, radius, 0.01f)).norm(), 0, 1e-5);
  EXPECT_NEAR(sample.velocity.norm(), speed, 1e-4);
  EXPECT_NEAR(sample.velocity.x(), -speed, 1e-4);
  EXPECT_FALSE(trajectory.sample(trajectory.end_time() + 1).extruding);
}

TEST(Toolpath, GapsBetweenSegmentsAreTravelledWithoutExtrusion) {
  Trajectory trajectory({PathSegment{LineCurve{Vec3(0, 0, 0), Vec3(1, 0, 0)}, 1, true},
                         PathSegment{LineCurve{Vec3(1, 1, 0), Vec3(2, 1, 0)}, 1, true}},
                        0);
  EXPECT_NEAR(trajectory.end_time(), 3, 1e-6);
  EXPECT_TRUE(trajectory.sample(0.5).extruding);
  const auto travel = trajectory.sample(1.5);
  EXPECT_FALSE(travel.extruding);
  EXPECT_NEAR((travel.position - Vec3(1, 0.5f, 0)).norm(), 0, 1e-6);
  EXPECT_TRUE(trajectory.sample(2.5).extruding);
}

TEST(Toolpath, RectangleWallLaysClosedLoopsLayerAboveLayer) {
  const auto wall = m3dp::toolpath::rectangle_wall(Vec3(1, 2, 0.01f), Real(0.3), Real(0.2), 3, Real(0.008));
  ASSERT_EQ(wall.points.size(), 15u);
  // Three loops of perimeter 1 m plus two rises of 8 mm.
  EXPECT_NEAR(m3dp::toolpath::curve_length(wall), 3 * 1.0 + 2 * 0.008, 1e-5);
  EXPECT_TRUE(wall.points[2].isApprox(Vec3(1.3f, 2.2f, 0.01f)));
  EXPECT_TRUE(wall.points.back().isApprox(Vec3(1, 2, 0.026f)));
  EXPECT_THROW(m3dp::toolpath::rectangle_wall(Vec3::Zero(), 1, 1, 0, Real(0.01)), m3dp::Error);
}

TEST(Toolpath, WaypointFileBecomesStraightMoves) {
  const std::string text =
      "# made by hand\n"
      "x,y,z,speed,extrude\n"
      "0, 0, 0.01, 0.1, 0\n"
      "0.1 0 0.01 0.05 1   # first strand\n"
      "0.1,0.1,0.01,0.05,true\n";
  const Pose placement = Pose::from_xyz_rpy(1, 0, 0, 0, 0, 0);
  const auto segments = m3dp::toolpath::parse_waypoints(text, "path.csv", placement);
  ASSERT_EQ(segments.size(), 2u);
  EXPECT_TRUE(segments[0].extrude);
  EXPECT_NEAR(segments[0].speed, 0.05, 1e-7);
  const m3dp::toolpath::Trajectory trajectory(segments, 0.0);
  EXPECT_NEAR(trajectory.end_time(), 4.0, 1e-6);  // 0.2 m at 0.05 m/s
  EXPECT_TRUE(trajectory.sample(0).position.isApprox(Vec3(1, 0, 0.01f)));
  EXPECT_TRUE(trajectory.sample(3).position.isApprox(Vec3(1.1f, 0.05f, 0.01f)));

  try {
    m3dp::toolpath::parse_waypoints("0 0 0 0.1 0\n0 0 oops 0.1 1\n0 0 0 -1 1\n1 2 3\n", "bad.csv");
    FAIL() << "no error";
  } catch (const m3dp::InputError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("bad.csv:2: error: field 3 ('oops') is not a number"), std::string::npos) << message;
    EXPECT_NE(message.find("bad.csv:3: error: the speed must be > 0 m/s and at most 100 m/s, got -1"), std::string::npos) << message;
    EXPECT_NE(message.find("bad.csv:4: error: expected 5 fields"), std::string::npos) << message;
  }
  // nan, inf and a float's overflow are no places or speeds; a first waypoint with a typo is no header.
  try {
    m3dp::toolpath::parse_waypoints("x y z speed extrude\nO.1 0 0 0.1 1\n0 nan 0 0.1 1\n0 0 inf 0.1 1\n1e308 0 0 0.1 1\n"
                                    "0 0 0 nan 1\n0 0 0 1e300 1\n",
                                    "odd.csv");
    FAIL() << "no error";
  } catch (const m3dp::InputError& error) {
    const std::string message = error.what();
    EXPECT_NE(message.find("odd.csv:2: error: field 1 ('O.1') is not a number"), std::string::npos) << message;
    EXPECT_NE(message.find("odd.csv:3: error: field 2 ('nan') must be a finite coordinate within ±10000 m"), std::string::npos) << message;
    EXPECT_NE(message.find("odd.csv:4: error: field 3 ('inf') must be a finite coordinate"), std::string::npos) << message;
    EXPECT_NE(message.find("odd.csv:5: error: field 1 ('1e308') must be a finite coordinate"), std::string::npos) << message;
    EXPECT_NE(message.find("odd.csv:6: error: the speed must be > 0 m/s and at most 100 m/s, got nan"), std::string::npos) << message;
    EXPECT_NE(message.find("odd.csv:7: error: the speed must be > 0 m/s and at most 100 m/s, got 1e300"), std::string::npos) << message;
  }
}

TEST(Toolpath, AppendedSegmentsFollowAfterAPauseAndATravel) {
  // A path extended while it is followed (the Python API's append): 1 s along x, then at 1.5 s (a
  // 0.5 s pause at the end) a travel of 0.1 m up to the new segment at its 0.1 m/s, then it.
  Trajectory path({PathSegment{LineCurve{Vec3(0, 0, 0), Vec3(0.1, 0, 0)}, 0.1f, true}}, 0);
  path.append({PathSegment{LineCurve{Vec3(0.1, 0, 0.1), Vec3(0.1, 0.1, 0.1)}, 0.1f, true}}, 1.5);
  EXPECT_NEAR(path.end_time(), 3.5, 1e-6);
  const auto paused = path.sample(1.25);
  EXPECT_NEAR(paused.position.x(), 0.1, 1e-6);
  EXPECT_FALSE(paused.extruding);
  const auto travelling = path.sample(2.0);
  EXPECT_NEAR(travelling.position.z(), 0.05, 1e-6);
  EXPECT_FALSE(travelling.extruding);
  const auto printing = path.sample(3.0);
  EXPECT_NEAR(printing.position.y(), 0.05, 1e-6);
  EXPECT_TRUE(printing.extruding);
  // Appended before the end: straight after it, no pause.
  Trajectory busy({PathSegment{LineCurve{Vec3(0, 0, 0), Vec3(0.1, 0, 0)}, 0.1f, true}}, 0);
  busy.append({PathSegment{LineCurve{Vec3(0.1, 0, 0), Vec3(0.2, 0, 0)}, 0.1f, true}}, 0.5);
  EXPECT_NEAR(busy.end_time(), 2.0, 1e-6);
  EXPECT_TRUE(busy.sample(1.5).extruding);
}
