#pragma once
// A robot's tools (print nozzles) follow their trajectories by inverse kinematics: at each chunk's
// start the joint targets that put every tool on its target at the chunk's end are solved for
// (DART's IK, through RobotIo), and in between they are interpolated in joint space.
#include <vector>

#include "m3dp/world/controllers/controller.hpp"
#include "m3dp/world/world.hpp"

namespace m3dp::world {

/// The frame a tool should reach for `target`, from where it is now (`tool_now`, world): the
/// target's position, and the tool's own rotation turned by the least rotation onto the target axis.
Eigen::Isometry3d tool_target_transform(const Eigen::Isometry3d& tool_now, const ToolTarget& target);

class ToolIk final : public Controller {
 public:
  /// From now on `tool` (one of this robot's) follows `trajectory`.
  void follow(ToolIndex tool, ToolTrajectory trajectory);

  void plan(RobotIo& robot, double end_time) override;
  void command(RobotIo& robot, double step, double next_time, double chunk_fraction) override;
  /// The distance of each tool from its target, where the IK aimed it (the chunk's end).
  void end_chunk(RobotIo& robot) override;
  void save(StateWriter& out) const override;
  void load(StateReader& in) override;

 private:
  struct FollowedTool {
    ToolIndex tool;
    ToolTrajectory trajectory;
    Eigen::Vector3d target = Eigen::Vector3d::Zero();  // m, world: this chunk's target position
  };
  std::vector<FollowedTool> tools_;
  Eigen::VectorXd chunk_start_, chunk_end_;  // joint targets at the chunk's ends
};

}  // namespace m3dp::world
