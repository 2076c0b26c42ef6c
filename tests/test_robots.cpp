// Robots in the world: the UR10 model's kinematics against Universal Robots' published DH
// parameters, and the nozzle following a printing path through inverse kinematics.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>

#include "m3dp/toolpath/parametric.hpp"
#include "m3dp/world/controllers/controller.hpp"
#include "m3dp/world/world.hpp"

using namespace m3dp;

namespace {
const std::filesystem::path kUr10 = std::filesystem::path(M3DP_MODELS) / "ur10" / "ur10.urdf";

/// Flange position of a UR10 from the standard DH table Universal Robots publishes
/// (d1 = 0.1273, a2 = −0.612, a3 = −0.5723, d4 = 0.163941, d5 = 0.1157, d6 = 0.0922 m), in the DH
/// base frame, turned by π about z into the ROS base_link frame the URDF uses.
Eigen::Vector3d dh_flange_position(const std::vector<double>& q) {
  const double d[6] = {0.1273, 0, 0, 0.163941, 0.1157, 0.0922};
  const double a[6] = {0, -0.612, -0.5723, 0, 0, 0};
  const double alpha[6] = {kPi / 2, 0, 0, kPi / 2, -kPi / 2, 0};
  Eigen::Isometry3d transform = Eigen::Isometry3d(Eigen::AngleAxisd(kPi, Eigen::Vector3d::UnitZ()));
  for (int i = 0; i < 6; ++i) {
    Eigen::Isometry3d link = Eigen::Isometry3d::Identity();
    link.rotate(Eigen::AngleAxisd(q[i], Eigen::Vector3d::UnitZ()));
    link.translate(Eigen::Vector3d(a[i], 0, d[i]).cwiseProduct(Eigen::Vector3d(1, 1, 1)));
    // Standard DH: Rz(θ) · Tz(d) · Tx(a) · Rx(α).
    link = Eigen::Isometry3d(Eigen::AngleAxisd(q[i], Eigen::Vector3d::UnitZ())) *
           Eigen::Translation3d(0, 0, d[i]) * Eigen::Translation3d(a[i], 0, 0) * Eigen::AngleAxisd(alpha[i], Eigen::Vector3d::UnitX());
    transform = transform * link;
  }
  return transform.translation();
}
}  // namespace

TEST(Robots, Ur10KinematicsMatchThePublishedDhParameters) {
  const std::vector<std::vector<double>> configurations = {
      {0, 0, 0, 0, 0, 0}, {0.3, -1.2, 1.8, -2.1, -1.57, 0.4}, {-1.1, -0.4, -1.9, 0.7, 2.2, -3.0}};
  for (const auto& q : configurations) {
    world::World world;
    world::RobotDescription description;
    description.name = "ur10";
    description.urdf_file = kUr10;
    description.initial_joint_positions = q;
    const auto robot = world.add_robot(description);
    ASSERT_EQ(world.joint_names(robot).size(), 6u);
    const auto tool = world.add_tool(robot, world::ToolDescription{"flange", "tool0", Pose{}});
    const Vec3 position = world.tool_pose(tool).position;
    const Eigen::Vector3d expected = dh_flange_position(q);
    std::printf("q = (%.2f %.2f %.2f %.2f %.2f %.2f): flange (%.4f %.4f %.4f), DH (%.4f %.4f %.4f)\n", q[0], q[1], q[2], q[3],
                q[4], q[5], position.x(), position.y(), position.z(), expected.x(), expected.y(), expected.z());
    EXPECT_LT((position.cast<double>() - expected).norm(), 1e-4);
  }
}

TEST(Robots, Ur10NozzleTracksAWallPathWithinAMillimetre) {
  // A 0.3 m square wall, three layers of 8 mm, 0.7 m in front of the base, printed at 0.1 m/s
  // with the nozzle pointing down: the path of the ur10_wall scene.
  world::World world;
  world.add_static_shape("floor", PlaneShape{Vec3::UnitZ(), 3, 3}, Pose{});
  world::RobotDescription description;
  description.name = "ur10";
  description.urdf_file = kUr10;
  description.initial_joint_positions = {0, -1.2, 1.9, -2.27, -1.5708, 0};
  const auto robot = world.add_robot(description);
  world::ToolDescription nozzle{"nozzle", "tool0", Pose::from_xyz_rpy(0, 0, 0.15f, 0, 0, 0), 0.02f, 0.004f, 0.5};
  const auto tool = world.add_tool(robot, nozzle);

  std::vector<toolpath::PathSegment> segments;
  // Approach from wherever the nozzle starts, then the layers.
  const Vec3 start = world.tool_pose(tool).position;
  const Real half = Real(0.15), layer = Real(0.008);
  const Vec3 centre(0.7f, 0, 0);
  std::vector<Vec3> points = {start, centre + Vec3(-half, -half, 0.005f)};
  segments.push_back(toolpath::PathSegment{toolpath::PolylineCurve{points}, Real(0.2), false});
  std::vector<Vec3> wall;
  for (int l = 0; l < 3; ++l) {
    const Real z = Real(0.005) + l * layer;
    for (const Vec3& corner : {Vec3(-half, -half, z), Vec3(half, -half, z), Vec3(half, half, z), Vec3(-half, half, z)})
      wall.push_back(centre + corner);
  }
  wall.push_back(centre + Vec3(-half, -half, 0.005f + 3 * layer));
  segments.push_back(toolpath::PathSegment{toolpath::PolylineCurve{wall}, Real(0.1), true});
  const double approach_end = toolpath::curve_length(segments.front().curve) / 0.2;
  const toolpath::Trajectory trajectory(std::move(segments), 0.0);
  world.set_tool_trajectory(tool, [&](double time) {
    return world::ToolTarget{trajectory.sample(time).position, Vec3(0, 0, -1)};
  });

  const auto started = std::chrono::steady_clock::now();
  // Skip the approach (a fast, unconstrained move) and measure along the wall only.
  world.step_to(approach_end);
  const double approach_rms = world.tool_tracking_rms(tool);
  std::vector<double> errors;
  for (double time = approach_end + 0.01; time < trajectory.end_time(); time += 0.01) {
    world.step_to(time);
    errors.push_back((world.tool_pose(tool).position - trajectory.sample(time).position).norm());
  }
  const double wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  double squared = 0, largest = 0;
  for (const double e : errors) {
    squared += e * e;
    largest = std::max(largest, e);
  }
  const double rms = std::sqrt(squared / static_cast<double>(errors.size()));
  std::printf("approach rms %.2f mm; along the wall (%.1f s, %zu samples): rms %.3f mm, max %.3f mm (goal rms <= 1 mm); "
              "%.2f s of wall clock for %.1f s simulated\n",
              approach_rms * 1e3, trajectory.end_time() - approach_end, errors.size(), rms * 1e3, largest * 1e3,
              wall_seconds, trajectory.end_time());
  EXPECT_LE(rms, 1e-3);
  // The nozzle points down all along.
  EXPECT_GT(world.tool_pose(tool).rotate(Vec3::UnitZ()).dot(Vec3(0, 0, -1)), 0.999);
  EXPECT_EQ(world.robot_contacts(robot).with_robots, 0u);
}

namespace {
const std::filesystem::path kTurtlebot = std::filesystem::path(M3DP_MODELS) / "turtlebot3_manipulator" / "turtlebot3_manipulator.urdf";

world::RobotIndex add_turtlebot(world::World& world, const Pose& pose) {
  world::RobotDescription description;
  description.name = "turtlebot";
  description.urdf_file = kTurtlebot;
  description.base_pose = pose;
  const auto robot = world.add_robot(description);
  world.make_diff_drive(robot, world::DiffDriveDescription{"wheel_left_joint", "wheel_right_joint", 0.033, 0.287, 0});
  return robot;
}
}  // namespace

TEST(Robots, TurtlebotFollowsACurveAndItsOdometryKnowsWhereItIs) {
  // A quarter circle of radius 0.4 m after a 0.2 m straight, at 0.1 m/s: the tracking controller
  // keeps the base on it, and the wheel odometry agrees with the truth (ideal wheels: no slip).
  world::World world;
  world.add_static_shape("floor", PlaneShape{Vec3::UnitZ(), 4, 4}, Pose{});
  const auto robot = add_turtlebot(world, Pose{});
  std::vector<toolpath::PathSegment> segments;
  segments.push_back(toolpath::PathSegment{toolpath::PolylineCurve{{Vec3(0, 0, 0), Vec3(0.2f, 0, 0)}}, Real(0.1), false});
  segments.push_back(toolpath::PathSegment{toolpath::CircleCurve{Vec3(0.2f, 0.4f, 0), Real(0.4), Real(-kPi / 2), Real(0.25)},
                                           Real(0.1), false});
  const toolpath::Trajectory path(std::move(segments), 0.0);
  world.set_base_trajectory(robot, [&](double time) { return path.sample(time).position; });
  world.step_to(path.end_time() + 0.5);
  const auto report = world.base_report(robot);
  const Pose pose = world.base_pose(robot);
  std::printf("base at (%.4f %.4f), path end (0.6000 0.4000); tracking rms %.2f mm, max %.2f mm; odometry off by %.3f mm "
              "after %.3f m; contacts %llu\n",
              pose.position.x(), pose.position.y(), 1e3 * report.tracking_rms, 1e3 * report.tracking_max,
              1e3 * report.odometry_error, report.distance, (unsigned long long)world.robot_contacts(robot).with_other);
  EXPECT_LT(report.tracking_rms, 0.005);
  EXPECT_LT((pose.position - Vec3(0.6f, 0.4f, pose.position.z())).norm(), 0.005);
  EXPECT_LT(report.odometry_error, 0.001);
  EXPECT_NEAR(report.distance, 0.2 + kPi * 0.4 / 2, 0.01);
  // It faces along the path's end: +y.
  EXPECT_GT(pose.rotate(Vec3::UnitX()).y(), 0.99);
}

TEST(Robots, MobileManipulatorKeepsTheNozzleOnItsPathWhileDriving) {
  // The TurtleBot drives 0.3 m along x at 0.05 m/s while its arm holds a nozzle 0.15 m to its right
  // on a line 6 mm above the floor, pointing down: base and arm together.
  world::World world;
  world.add_static_shape("floor", PlaneShape{Vec3::UnitZ(), 4, 4}, Pose{});
  const auto robot = add_turtlebot(world, Pose{});
  world.set_joint_positions(robot, [&] {
    std::vector<double> q = world.joint_positions(robot);
    const auto names = world.joint_names(robot);
    for (std::size_t k = 0; k < names.size(); ++k) {
      // Some way from the line: the nozzle first travels there (and must settle, not sag).
      if (names[k] == "joint1") q[k] = -1.2;
      if (names[k] == "joint2") q[k] = 0.3;
      if (names[k] == "joint3") q[k] = 0.2;
      if (names[k] == "joint4") q[k] = 1.0;
    }
    return q;
  }());
  // The nozzle: 40 mm beyond the fingertips, its axis along the gripper.
  const auto tool = world.add_tool(robot, world::ToolDescription{"nozzle", "end_effector_link",
                                                                 Pose::from_xyz_rpy(0.04f, 0, 0, 0, Real(kPi / 2), 0), 0.008f,
                                                                 0.004f, 0.05});
  // The line runs beside the arm's base (0.08 m behind the axle), 0.15 m to the right, 6 mm up;
  // nozzle and base set off together once the nozzle has reached the line's start.
  const Vec3 start = world.tool_pose(tool).position;
  const Vec3 line_from(-0.08f, -0.15f, 0.006f), line_to(0.22f, -0.15f, 0.006f);
  const double line_start = double((line_from - start).norm() / 0.05) + 0.5;
  const toolpath::Trajectory base_path(
      {toolpath::PathSegment{toolpath::PolylineCurve{{Vec3(0, 0, 0), Vec3(0.3f, 0, 0)}}, Real(0.05), false}}, line_start);
  const toolpath::Trajectory nozzle_path(
      {toolpath::PathSegment{toolpath::PolylineCurve{{start, line_from}}, Real(0.05), false},
       toolpath::PathSegment{toolpath::PolylineCurve{{line_from, line_from}}, Real(0.05), false, Real(0.5)},
       toolpath::PathSegment{toolpath::PolylineCurve{{line_from, line_to}}, Real(0.05), true}},
      0.0);
  std::printf("nozzle starts at (%.3f %.3f %.3f); the line starts at t = %.2f s\n", start.x(), start.y(), start.z(), line_start);
  world.set_base_trajectory(robot, [&](double time) { return base_path.sample(time).position; });
  world.set_tool_trajectory(tool, [&](double time) { return world::ToolTarget{nozzle_path.sample(time).position, Vec3(0, 0, -1)}; });
  world.step_to(line_start);
  std::vector<double> errors;
  for (double time = line_start; time < nozzle_path.end_time(); time += 0.01) {
    world.step_to(time);
    errors.push_back((world.tool_pose(tool).position - nozzle_path.sample(time).position).norm());
  }
  double squared = 0, largest = 0;
  for (const double e : errors) {
    squared += e * e;
    largest = std::max(largest, e);
  }
  const double rms = std::sqrt(squared / double(errors.size()));
  std::printf("while driving: nozzle %.3f mm rms, %.3f mm max from its line; base %.2f mm rms from its path; axis·down %.4f\n",
              1e3 * rms, 1e3 * largest, 1e3 * world.base_report(robot).tracking_rms,
              world.tool_pose(tool).rotate(Vec3::UnitZ()).dot(Vec3(0, 0, -1)));
  EXPECT_LE(rms, 1e-3);
  EXPECT_GT(world.tool_pose(tool).rotate(Vec3::UnitZ()).dot(Vec3(0, 0, -1)), 0.99);
  EXPECT_GT(world.base_pose(robot).position.x(), 0.29);
}

namespace {
/// A controller of the kind a user's code adds (world/controllers/controller.hpp): it swings the
/// shoulder to an angle that changes with time, through the joint targets the servo tracks.
class ShoulderSwing final : public world::Controller {
 public:
  void command(world::RobotIo& robot, double /*step*/, double next_time, double /*chunk_fraction*/) override {
    robot.joint_targets()[0] = 0.5 * std::sin(next_time);
    ++commands;
  }
  int commands = 0;
};
}  // namespace

/// The UR10 with its elbow bent, the flange pointing down in front of it.
static world::RobotIndex add_ur10_bent(world::World& world) {
  world::RobotDescription description;
  description.name = "ur10";
  description.urdf_file = kUr10;
  description.initial_joint_positions = {0, -1.2, 1.8, -2.1, -1.57, 0};
  return world.add_robot(description);
}

TEST(Robots, AnAddedControllerDrivesTheJointsThroughTheServo) {
  world::World world;
  const auto robot = add_ur10_bent(world);
  auto controller = std::make_unique<ShoulderSwing>();
  const ShoulderSwing& swing = *controller;
  world.add_controller(robot, std::move(controller));
  world.step_to(1.0);
  const double shoulder = world.joint_positions(robot)[0];
  std::printf("shoulder at t = 1 s: %.4f rad (target 0.5 sin 1 = %.4f rad), %d commands\n", shoulder, 0.5 * std::sin(1.0),
              swing.commands);
  EXPECT_EQ(swing.commands, 1000);  // one per 1 ms world step
  EXPECT_NEAR(shoulder, 0.5 * std::sin(1.0), 2e-3);
  // The other joints hold their initial positions.
  EXPECT_NEAR(world.joint_positions(robot)[2], 1.8, 2e-3);
}

TEST(Robots, ClearanceQueriesMeasureDistancesBetweenRobotsAndToThePrint) {
  // Two TurtleBots one behind the other, 0.3 m between their reference points: their base boxes
  // (0.266 m long, centred 0.064 m behind the reference) are 0.3 − 0.266 = 0.034 m apart. FCL's own
  // manager-to-manager distance said 0.35 m here (it missed the bases); shape by shape it is right.
  world::World world;
  const auto front = add_turtlebot(world, Pose{Vec3(0.3, 0, 0), Quat::Identity()});
  const auto back = add_turtlebot(world, Pose{Vec3(0, 0, 0), Quat::Identity()});
  EXPECT_NEAR(world.robot_distance(front, back, 0), 0.034, 1e-4);
  // With a bound the search stops there and returns the bound.
  EXPECT_EQ(world.robot_distance(front, back, 0.05), 0.05);
  // A box of print 5 cm in front of the front robot's base (its base box ends 0.069 m ahead of it).
  EXPECT_TRUE(std::isinf(world.print_distance(front, 0)));
  world.set_print_boxes({Aabb{Vec3(0.3 + 0.069 + 0.05, -0.05, 0), Vec3(0.6, 0.05, 0.02)}});
  EXPECT_NEAR(world.print_distance(front, 0), 0.05, 1e-4);
  // Placed 4 cm further on, the front robot is 1 cm from the print and 7.4 cm from the other; put
  // back, exactly as it was.
  const auto joints = world.joint_positions(front);
  world.place_robot(front, Vec3(0.34, 0, 0), {});
  EXPECT_NEAR(world.print_distance(front, 0), 0.01, 1e-4);
  EXPECT_NEAR(world.robot_distance(front, back, 0), 0.074, 1e-4);
  world.restore_robots();
  EXPECT_NEAR(world.print_distance(front, 0), 0.05, 1e-4);
  EXPECT_EQ(world.base_x_y_heading(front), Vec3(0.3, 0, 0));
  EXPECT_EQ(world.joint_positions(front), joints);
}

TEST(Robots, APlacedToolReachesItsTargetByIk) {
  // The UR10 with a tool on its flange, placed so that the tool is 10 cm lower: the IK puts it there,
  // and restoring brings back every joint.
  world::World world;
  const auto robot = add_ur10_bent(world);
  world::ToolDescription tool_description;
  tool_description.name = "nozzle";
  tool_description.link = "tool0";
  const auto tool = world.add_tool(robot, tool_description);
  const Pose before = world.tool_pose(tool);
  const auto joints = world.joint_positions(robot);
  const Vec3 target = before.position - Vec3(0, 0, 0.1);
  world.place_robot(robot, std::nullopt, {{tool, world::ToolTarget{target, before.rotate(Vec3::UnitZ())}}});
  EXPECT_LT((world.tool_pose(tool).position - target).norm(), 1e-3);
  world.restore_robots();
  EXPECT_EQ(world.joint_positions(robot), joints);
  EXPECT_LT((world.tool_pose(tool).position - before.position).norm(), 1e-9);
}
