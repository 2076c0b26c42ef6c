#include "m3dp/world/controllers/tool_ik.hpp"

namespace m3dp::world {

void ToolIk::follow(ToolIndex tool, ToolTrajectory trajectory) {
  for (FollowedTool& followed : tools_)
    if (followed.tool == tool) {
      followed.trajectory = std::move(trajectory);
      return;
    }
  tools_.push_back(FollowedTool{tool, std::move(trajectory)});
}

void ToolIk::plan(RobotIo& robot, double end_time) {
  chunk_start_ = robot.joint_targets();
  chunk_end_ = robot.joint_targets();
  for (FollowedTool& followed : tools_) {
    const ToolTarget target = followed.trajectory(end_time);
    Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
    transform.translation() = target.position.cast<double>();
    // The target's rotation about its axis is free; take the tool's own, turned by the least
    // rotation that brings its axis onto the target axis. (An arbitrary choice can leave the two
    // frames near half a turn apart about the axis, where the IK's rotation error is ill-conditioned.)
    const Eigen::Matrix3d current = robot.tool_transform(followed.tool).linear();
    transform.linear() =
        Eigen::Quaterniond::FromTwoVectors(current.col(2), target.axis.cast<double>().normalized()).toRotationMatrix() * current;
    followed.target = transform.translation();
    robot.solve_tool_ik(followed.tool, transform, chunk_end_);
  }
}

void ToolIk::command(RobotIo& robot, double /*step*/, double /*next_time*/, double chunk_fraction) {
  // Joint space is smooth over a few milliseconds: the targets between IK solutions are interpolated.
  robot.joint_targets() = chunk_start_ + chunk_fraction * (chunk_end_ - chunk_start_);
}

void ToolIk::end_chunk(RobotIo& robot) {
  for (const FollowedTool& followed : tools_)
    robot.tool_tracking(followed.tool).add((robot.tool_transform(followed.tool).translation() - followed.target).norm());
}

}  // namespace m3dp::world
