#include <gtest/gtest.h>

#include <cmath>

#include "m3dp/toolpath/parametric.hpp"

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
