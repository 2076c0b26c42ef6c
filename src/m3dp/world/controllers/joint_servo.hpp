#pragma once
// Position control of a robot's joints: each motor (a DART servo) is commanded the velocity that
// reaches its target in one step, within the joint's speed limits (the URDF's).
#include "m3dp/world/controllers/controller.hpp"

namespace m3dp::world {

class JointServo final : public Controller {
 public:
  void command(RobotIo& robot, double step, double next_time, double chunk_fraction) override;
};

}  // namespace m3dp::world
