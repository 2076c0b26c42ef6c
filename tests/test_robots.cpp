// Robots in the world: the UR10 model's kinematics against Universal Robots' published DH
// parameters, and the nozzle following a printing path through inverse kinematics.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>

#include "m3dp/toolpath/parametric.hpp"
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
