#include "m3dp/world/controllers/joint_servo.hpp"

#include <algorithm>

namespace m3dp::world {

void JointServo::command(RobotIo& robot, double step, double /*next_time*/, double /*chunk_fraction*/) {
  const Eigen::VectorXd& targets = robot.joint_targets();
  for (std::size_t k = 0; k < robot.joint_count(); ++k) {
    if (robot.is_wheel(k)) continue;  // the base's
    const auto [lower, upper] = robot.joint_velocity_limits(k);
    robot.command_joint_velocity(k, std::clamp((targets[static_cast<Eigen::Index>(k)] - robot.joint_position(k)) / step, lower, upper));
  }
}

}  // namespace m3dp::world
