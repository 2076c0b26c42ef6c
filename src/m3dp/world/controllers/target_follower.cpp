#include "m3dp/world/controllers/target_follower.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "m3dp/core/error.hpp"

namespace m3dp::world {

void TargetFollower::reset(const Eigen::Vector3d& position, double time) {
  position_ = target_ = position;
  velocity_.setZero();
  target_velocity_.setZero();
  time_ = time;
}

void TargetFollower::set_target(const Eigen::Vector3d& target, const MotionLimits& limits, const Eigen::Vector3d& target_velocity) {
  if (!(limits.max_speed > 0) || !std::isfinite(limits.max_speed) || !(limits.max_acceleration > 0) ||
      !std::isfinite(limits.max_acceleration))
    throw Error(fmt::format("a target's max_speed ({} m/s) and max_acceleration ({} m/s²) must be numbers > 0",
                            limits.max_speed, limits.max_acceleration));
  if (!target.allFinite() || !target_velocity.allFinite()) throw Error("a target's position must be numbers (m)");
  target_ = target;
  target_velocity_ = target_velocity;
  limits_ = limits;
}

const Eigen::Vector3d& TargetFollower::advance(double time) {
  // Sub-steps of at most 1 ms: the braking rule is exact enough there and the same whatever the
  // caller's step, so a run does not depend on how often it is asked.
  constexpr double kSubStep = 1e-3;
  while (time > time_ + 1e-12) {
    const double step = std::min(kSubStep, time - time_);
    time_ += step;
    target_ += target_velocity_ * step;
    const Eigen::Vector3d to_target = target_ - position_;
    const double distance = to_target.norm();
    const double step_reach = limits_.max_acceleration * step * step;
    if (distance <= step_reach && (velocity_ - target_velocity_).norm() <= limits_.max_acceleration * step) {
      position_ = target_;  // there: within what one sub-step of braking moves
      velocity_ = target_velocity_;
      continue;
    }
    // The velocity it should have: the target's, and towards it as fast as it may and can still stop
    // there (relative to the target), no faster than the limit in all.
    const double speed = std::min(limits_.max_speed, std::sqrt(2 * limits_.max_acceleration * distance));
    Eigen::Vector3d wanted = target_velocity_;
    if (distance > 0) wanted += to_target * (speed / distance);
    if (wanted.norm() > limits_.max_speed) wanted *= limits_.max_speed / wanted.norm();
    Eigen::Vector3d change = wanted - velocity_;
    const double most = limits_.max_acceleration * step;
    if (change.norm() > most) change *= most / change.norm();
    velocity_ += change;
    position_ += velocity_ * step;
  }
  return position_;
}

void TargetFollower::save(StateWriter& out) const {
  out.put(position_);
  out.put(velocity_);
  out.put(target_);
  out.put(target_velocity_);
  out.put(limits_.max_speed);
  out.put(limits_.max_acceleration);
  out.put(time_);
}

void TargetFollower::load(StateReader& in) {
  in.get(position_);
  in.get(velocity_);
  in.get(target_);
  in.get(target_velocity_);
  in.get(limits_.max_speed);
  in.get(limits_.max_acceleration);
  in.get(time_);
}

}  // namespace m3dp::world
