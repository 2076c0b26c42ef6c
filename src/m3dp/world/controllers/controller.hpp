#pragma once
// A robot's controllers turn goals (a tool path, a base path, joint targets, or commands from outside
// the process) into the commands of each world step. They see the robot only through RobotIo, which
// the world implements over DART, so a new controller is a new file here and no DART.
#include <Eigen/Geometry>

#include <cstddef>
#include <utility>

#include "m3dp/core/state_io.hpp"
#include "m3dp/world/statistics.hpp"

namespace m3dp::world {

using ToolIndex = std::size_t;

/// A robot as its controllers read and command it, for one world step.
class RobotIo {
 public:
  virtual ~RobotIo() = default;
  // ---- joints: the actuated ones, in World::joint_names() order (rad or m) ----
  [[nodiscard]] virtual std::size_t joint_count() const = 0;
  [[nodiscard]] virtual double joint_position(std::size_t joint) const = 0;
  [[nodiscard]] virtual std::pair<double, double> joint_velocity_limits(std::size_t joint) const = 0;  // lower, upper
  /// A wheel of the mobile base: driven through drive_base, not by position.
  [[nodiscard]] virtual bool is_wheel(std::size_t joint) const = 0;
  /// The joints' position targets, which the servo tracks.
  [[nodiscard]] virtual Eigen::VectorXd& joint_targets() = 0;
  /// The velocity the joint's motor should reach in this step.
  virtual void command_joint_velocity(std::size_t joint, double velocity) = 0;
  // ---- tools (World::add_tool) ----
  [[nodiscard]] virtual Eigen::Isometry3d tool_transform(ToolIndex tool) const = 0;  // world
  /// Inverse kinematics: the joint positions that put the tool frame at `target` (world), from the
  /// current ones, written into `joints` for the joints the IK moves (the others are left).
  virtual void solve_tool_ik(ToolIndex tool, const Eigen::Isometry3d& target, Eigen::VectorXd& joints) = 0;
  [[nodiscard]] virtual TrackingError& tool_tracking(ToolIndex tool) = 0;
  // ---- a differential-drive base (World::make_diff_drive) ----
  struct Odometry {
    double x = 0, y = 0, heading = 0;  // m, m, rad: the base's pose from its wheel encoders
  };
  [[nodiscard]] virtual Odometry base_odometry() const = 0;
  [[nodiscard]] virtual Eigen::Vector3d base_position() const = 0;  // m, the true one
  /// Asks the base for a forward speed (m/s) and turn rate (rad/s) in this step; the wheels get them
  /// within their speed limit. Without a request the base stands still.
  virtual void drive_base(double speed, double turn_rate) = 0;
  [[nodiscard]] virtual TrackingError& base_tracking() = 0;
};

/// One controller of one robot. The world steps in chunks of a few milliseconds (the IK's period);
/// each chunk calls plan once, then command and after_step for each of its steps, then end_chunk.
class Controller {
 public:
  virtual ~Controller() = default;
  /// At a chunk's start: the chunk ends at `end_time` (s).
  virtual void plan(RobotIo& /*robot*/, double /*end_time*/) {}
  /// Commands for the step that ends at `next_time`, `step` s long; `chunk_fraction` (0, 1] is how far
  /// into the chunk its end is.
  virtual void command(RobotIo& robot, double step, double next_time, double chunk_fraction) = 0;
  /// After each world step.
  virtual void after_step(RobotIo& /*robot*/) {}
  /// At a chunk's end.
  virtual void end_chunk(RobotIo& /*robot*/) {}
  /// A checkpoint: what it carries from one world step to the next (between chunks), and back.
  virtual void save(StateWriter& /*out*/) const {}
  virtual void load(StateReader& /*in*/) {}
};

}  // namespace m3dp::world
