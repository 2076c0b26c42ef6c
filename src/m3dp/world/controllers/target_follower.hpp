#pragma once
// A commanded point (a nozzle's target from outside) that goes to its target along a straight line
// within a speed and an acceleration limit, braking in time to stop there (|v| ≤ √(2 a d)). A new
// target is taken from where the point is and how fast it moves, so targets given every control
// period move it smoothly instead of stepping the robot (a 32 mm step once drove a nozzle 3 mm into
// the plate and rang for 0.4 s).
#include <Eigen/Core>

#include "m3dp/core/state_io.hpp"

namespace m3dp::world {

struct MotionLimits {
  double max_speed = 0.25;        // m/s
  double max_acceleration = 2.5;  // m/s²
};

class TargetFollower {
 public:
  /// At rest at `position` (m) at `time` (s), with that as its target.
  void reset(const Eigen::Vector3d& position, double time);
  /// Goes to `target` (m) from where it is now, within `limits` (each > 0: Error otherwise). A target
  /// that moves on at `target_velocity` (m/s; a path it returns to) is caught up with, not trailed.
  void set_target(const Eigen::Vector3d& target, const MotionLimits& limits,
                  const Eigen::Vector3d& target_velocity = Eigen::Vector3d::Zero());
  /// Moves on to `time` (s; earlier times leave it where it is) and returns where it is.
  const Eigen::Vector3d& advance(double time);

  [[nodiscard]] const Eigen::Vector3d& position() const { return position_; }
  [[nodiscard]] const Eigen::Vector3d& velocity() const { return velocity_; }
  [[nodiscard]] const Eigen::Vector3d& target() const { return target_; }
  [[nodiscard]] bool arrived() const { return position_ == target_ && velocity_ == target_velocity_; }

  void save(StateWriter& out) const;
  void load(StateReader& in);

 private:
  Eigen::Vector3d position_ = Eigen::Vector3d::Zero(), velocity_ = Eigen::Vector3d::Zero(), target_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d target_velocity_ = Eigen::Vector3d::Zero();
  MotionLimits limits_;
  double time_ = 0;
};

}  // namespace m3dp::world
