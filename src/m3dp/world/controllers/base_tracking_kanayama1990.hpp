#pragma once
// A differential-drive base follows a path with the tracking law of Y. Kanayama, Y. Kimura,
// F. Miyazaki, T. Noguchi, "A stable tracking control method for an autonomous mobile robot",
// IEEE ICRA 1990, 384–389, on its wheel odometry: v = v_r cos e_θ + k_x e_x,
// ω = ω_r + v_r (k_y e_y + k_θ sin e_θ), with the error (e_x, e_y, e_θ) in the base's frame.
#include "m3dp/world/controllers/controller.hpp"
#include "m3dp/world/world.hpp"

namespace m3dp::world {

class BaseTrackingKanayama1990 final : public Controller {
 public:
  /// `initial_heading` (rad): the reference heading until the path first moves.
  BaseTrackingKanayama1990(BaseTrajectory path, double initial_heading);

  void command(RobotIo& robot, double step, double next_time, double chunk_fraction) override;
  /// The true base's distance from the path's point of this step.
  void after_step(RobotIo& robot) override;
  void save(StateWriter& out) const override;
  void load(StateReader& in) override;

 private:
  BaseTrajectory path_;
  double reference_heading_;
  Eigen::Vector3d last_target_ = Eigen::Vector3d::Zero();
};

}  // namespace m3dp::world
