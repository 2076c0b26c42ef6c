#include "m3dp/world/controllers/base_tracking_kanayama1990.hpp"

#include <cmath>

namespace m3dp::world {

BaseTrackingKanayama1990::BaseTrackingKanayama1990(BaseTrajectory path, double initial_heading)
    : path_(std::move(path)), reference_heading_(initial_heading) {}

void BaseTrackingKanayama1990::command(RobotIo& robot, double /*step*/, double next_time, double /*chunk_fraction*/) {
  // Reference pose and velocities from the path (heading along its tangent; held while it stops).
  constexpr double kDelta = 0.01;  // s, for the path's derivatives
  const Vec3 target = path_(next_time);
  const Vec3 ahead = path_(next_time + kDelta), behind = path_(next_time - kDelta);
  const double dx = double(ahead.x() - behind.x()) / (2 * kDelta), dy = double(ahead.y() - behind.y()) / (2 * kDelta);
  const double reference_speed = std::hypot(dx, dy);
  double reference_turn = 0;
  if (reference_speed > 1e-4) {
    const double heading = std::atan2(dy, dx);
    const Vec3 further = path_(next_time + 2 * kDelta);
    const double heading_ahead = std::atan2(double(further.y() - target.y()), double(further.x() - target.x()));
    reference_turn = std::remainder(heading_ahead - heading, 2 * kPi) / (1.5 * kDelta);
    reference_heading_ = heading;
  }
  last_target_ = target.cast<double>();
  constexpr double kx = 4.0, ky = 400.0, ktheta = 20.0;  // 1/s, 1/m², 1/m
  const RobotIo::Odometry odometry = robot.base_odometry();
  const double cos_h = std::cos(odometry.heading), sin_h = std::sin(odometry.heading);
  const double ex = cos_h * (target.x() - odometry.x) + sin_h * (target.y() - odometry.y);
  const double ey = -sin_h * (target.x() - odometry.x) + cos_h * (target.y() - odometry.y);
  const double etheta = std::remainder(reference_heading_ - odometry.heading, 2 * kPi);
  robot.drive_base(reference_speed * std::cos(etheta) + kx * ex, reference_turn + reference_speed * (ky * ey + ktheta * std::sin(etheta)));
}

void BaseTrackingKanayama1990::after_step(RobotIo& robot) {
  const Eigen::Vector3d truth = robot.base_position();
  robot.base_tracking().add(std::hypot(truth.x() - last_target_.x(), truth.y() - last_target_.y()));
}

}  // namespace m3dp::world

namespace m3dp::world {

void BaseTrackingKanayama1990::save(StateWriter& out) const {
  out.put(reference_heading_);
  out.put(last_target_);
}

void BaseTrackingKanayama1990::load(StateReader& in) {
  in.get(reference_heading_);
  in.get(last_target_);
}

}  // namespace m3dp::world
