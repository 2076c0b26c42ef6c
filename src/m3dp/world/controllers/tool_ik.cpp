#include "m3dp/world/controllers/tool_ik.hpp"

namespace m3dp::world {

Eigen::Isometry3d tool_target_transform(const Eigen::Isometry3d& tool_now, const ToolTarget& target) {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  transform.translation() = target.position.cast<double>();
  // The target's rotation about its axis is free; take the tool's own, turned by the least
  // rotation that brings its axis onto the target axis. (An arbitrary choice can leave the two
  // frames near half a turn apart about the axis, where the IK's rotation error is ill-conditioned.)
  const Eigen::Matrix3d current = tool_now.linear();
  transform.linear() =
      Eigen::Quaterniond::FromTwoVectors(current.col(2), target.axis.cast<double>().normalized()).toRotationMatrix() * current;
  return transform;
}

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
    const Eigen::Isometry3d transform = tool_target_transform(robot.tool_transform(followed.tool), followed.trajectory(end_time));
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

namespace m3dp::world {

void ToolIk::save(StateWriter& out) const {
  out.put(static_cast<std::uint64_t>(tools_.size()));
  for (const FollowedTool& tool : tools_) out.put(tool.target);
  auto put_vector = [&](const Eigen::VectorXd& vector) {
    out.put(std::vector<double>(vector.data(), vector.data() + vector.size()));
  };
  put_vector(chunk_start_);
  put_vector(chunk_end_);
}

void ToolIk::load(StateReader& in) {
  if (in.get<std::uint64_t>() != tools_.size()) in.fail("a robot with a different number of tools");
  for (FollowedTool& tool : tools_) in.get(tool.target);
  auto get_vector = [&](Eigen::VectorXd& vector) {
    std::vector<double> values;
    in.get(values);
    vector = Eigen::Map<const Eigen::VectorXd>(values.data(), static_cast<Eigen::Index>(values.size()));
  };
  get_vector(chunk_start_);
  get_vector(chunk_end_);
}

}  // namespace m3dp::world
