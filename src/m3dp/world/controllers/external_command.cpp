#include "m3dp/world/controllers/external_command.hpp"

namespace m3dp::world {

void ExternalCommand::set_joint_targets(Eigen::VectorXd targets) {
  joint_targets_ = std::move(targets);
  mode_ = Mode::joints;
}

void ExternalCommand::set_tool_target(ToolIndex tool, const ToolTarget& target, const MotionLimits& limits,
                                      const Eigen::Vector3d& tool_now, double now) {
  // From where the tool is unless it was on its way to a target already (then on from there).
  if (mode_ != Mode::tool || tool_ != tool) follower_.reset(tool_now, now);
  follower_.set_target(target.position.cast<double>(), limits);
  tool_target_ = target;
  if (tool_ != tool) {
    tool_ik_ = ToolIk();  // one tool at a time: the IK aims the one last commanded
    tool_ik_.follow(tool, [this](double time) {
      ToolTarget on_the_way = tool_target_;
      on_the_way.position = follower_.advance(time).cast<Real>();
      return on_the_way;
    });
    tool_ = tool;
  }
  mode_ = Mode::tool;
}

void ExternalCommand::set_base_velocity(double speed, double turn_rate) {
  base_speed_ = speed;
  base_turn_rate_ = turn_rate;
}

void ExternalCommand::clear() {
  mode_ = Mode::hold;
  base_speed_ = base_turn_rate_ = 0;
}

void ExternalCommand::plan(RobotIo& robot, double end_time) {
  if (mode_ == Mode::tool) tool_ik_.plan(robot, end_time);
}

void ExternalCommand::command(RobotIo& robot, double step, double next_time, double chunk_fraction) {
  if (mode_ == Mode::joints) robot.joint_targets() = joint_targets_;
  if (mode_ == Mode::tool) tool_ik_.command(robot, step, next_time, chunk_fraction);
  if (base_speed_ != 0 || base_turn_rate_ != 0) robot.drive_base(base_speed_, base_turn_rate_);
}

void ExternalCommand::end_chunk(RobotIo& robot) {
  if (mode_ == Mode::tool) tool_ik_.end_chunk(robot);
}

}  // namespace m3dp::world
