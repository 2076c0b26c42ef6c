#pragma once
// Commands from outside the process (the Python API, a user's controller): a robot switched to
// external control runs this instead of its scene controllers (tool path, base path), before its
// joint servo. It holds the last command until the next: joint targets, a tool target reached by
// the same inverse kinematics as a path (tool_ik.hpp), and a base velocity.
#include <optional>

#include "m3dp/world/controllers/target_follower.hpp"
#include "m3dp/world/controllers/tool_ik.hpp"

namespace m3dp::world {

class ExternalCommand final : public Controller {
 public:
  /// The joints' position targets (rad or m, World::joint_names() order); ends a tool target.
  void set_joint_targets(Eigen::VectorXd targets);
  /// Where `tool` should be; ends joint targets. The tool goes there along a straight line within
  /// `limits` (target_follower.hpp), from `tool_now` (m, where it is) at `now` (s) unless it was
  /// already going to a target; its joints follow through IK over the world's IK period.
  void set_tool_target(ToolIndex tool, const ToolTarget& target, const MotionLimits& limits, const Eigen::Vector3d& tool_now, double now);
  /// Where the commanded tool is asked to be now on its way, and whether it got there; none without a tool target.
  [[nodiscard]] const TargetFollower* tool_follower(ToolIndex tool) const {
    return mode_ == Mode::tool && tool_ == tool ? &follower_ : nullptr;
  }
  /// A differential-drive base's forward speed (m/s) and turn rate (rad/s), held until changed.
  void set_base_velocity(double speed, double turn_rate);
  /// No command: the joints hold their last targets and the base stands.
  void clear();

  void plan(RobotIo& robot, double end_time) override;
  void command(RobotIo& robot, double step, double next_time, double chunk_fraction) override;
  void end_chunk(RobotIo& robot) override;

 private:
  enum class Mode { hold, joints, tool } mode_ = Mode::hold;
  Eigen::VectorXd joint_targets_;
  ToolTarget tool_target_;
  std::optional<ToolIndex> tool_;
  ToolIk tool_ik_;           // follows follower_ with tool_target_'s axis
  TargetFollower follower_;  // the tool's way to tool_target_
  double base_speed_ = 0, base_turn_rate_ = 0;
};

}  // namespace m3dp::world
