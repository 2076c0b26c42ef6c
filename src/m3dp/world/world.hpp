#pragma once
// The rigid-body world (DART): static geometry, free rigid bodies, robots loaded from URDF with
// their controllers, and printed-material meshes added at run time as static collision bodies.
// DART stays inside world.cpp (pimpl), so the rest of M3DP never includes its headers; the fluid
// coupling (coupling module) sees the world only through links: poses, velocities, shapes, wrenches.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "m3dp/core/geometry.hpp"
#include "m3dp/core/types.hpp"
#include "m3dp/world/controllers/target_follower.hpp"
#include "m3dp/world/statistics.hpp"

namespace m3dp {
class StateWriter;
class StateReader;
}  // namespace m3dp

namespace m3dp::world {

struct WorldSettings {
  Vec3 gravity = Vec3(0, 0, Real(-9.81));  // m/s²
  double time_step = 1e-3;                 // s, longest step; the world sub-steps to the fluid's clock
};

/// A handle to a body of the world: its index in the order bodies were added.
using BodyIndex = std::size_t;
using RobotIndex = std::size_t;
using ToolIndex = std::size_t;
/// A handle to a movable link: a free rigid body or one link of a robot (see link_count()).
using LinkIndex = std::size_t;

/// A robot from a URDF file. A URDF whose root link is called "world" is fixed to the world (an arm
/// on a table); otherwise the base floats freely.
struct RobotDescription {
  std::string name;
  std::filesystem::path urdf_file;
  Pose base_pose;                               // pose of the URDF's root frame in the world (m)
  std::vector<double> initial_joint_positions;  // rad (or m), in the order of joint_names(); empty = zeros
};

/// A tool rigidly attached to a robot link, e.g. a print nozzle: a frame (its z axis is the tool's
/// axis, pointing out of the tool) and optionally a cylinder body from the link to just short of
/// the frame's origin, which collides and is seen by the fluid.
struct ToolDescription {
  std::string name;
  std::string link;                  // link of the robot it is fixed to
  Pose offset;                       // tool frame in the link frame (m)
  Real body_radius = 0;              // m; 0 = no body
  Real body_clearance = 0;           // m between the body's end and the tool frame's origin
  double body_mass = 0.5;            // kg
};

/// Where a tool should be at a time: position, and the direction its z axis should point.
/// Rotation about that axis is left free (a round nozzle does not care).
struct ToolTarget {
  Vec3 position = Vec3::Zero();      // m, world
  Vec3 axis = Vec3(0, 0, -1);        // unit, world
};
using ToolTrajectory = std::function<ToolTarget(double time)>;

/// A differential-drive mobile base (a TurtleBot): the robot's floating root becomes a planar joint
/// (x, y, heading) driven by its two wheel speeds without slip. Wheels do not touch the floor in
/// the collision world (the planar joint carries the base), so rolling adds no contact noise.
struct DiffDriveDescription {
  std::string left_wheel_joint;
  std::string right_wheel_joint;
  double wheel_radius = 0.033;      // m
  double wheel_separation = 0.287;  // m between the wheels' contact points
  double max_wheel_speed = 0;       // rad/s; 0 = the wheel joints' URDF velocity limit
};
/// Where the base's reference point (the root frame's origin) should be at a time (z is ignored).
using BaseTrajectory = std::function<Vec3(double time)>;

/// How a mobile base did: its path following (truth against the reference) and its odometry
/// (wheel encoders integrated, against the truth), over the world steps so far.
struct BaseReport {
  double tracking_rms = 0, tracking_max = 0;  // m
  double odometry_error = 0;                  // m, now
  double distance = 0;                        // m driven
};

/// What the fluid needs to know of a movable link: its collision shapes in the link frame.
struct LinkShapes {
  std::string name;                  // "robot/link" or the body's name
  std::vector<Shape> shapes;
  std::vector<Pose> poses;           // of each shape, in the link frame
};

class Controller;  // controllers/controller.hpp

class World {
 public:
  explicit World(const WorldSettings& settings = {});
  ~World();
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  /// A body fixed in the world with one collision shape at `pose` (m, world frame).
  BodyIndex add_static_shape(const std::string& name, const Shape& shape, const Pose& pose);
  /// A free rigid body with one or more collision shapes (poses in the body frame). Mass in kg;
  /// inertia about the body origin from the first shape at uniform density unless given (kg·m²).
  /// Every body feels the fluid (see link_feels_fluid) unless switched off with set_feels_fluid.
  BodyIndex add_rigid_body(const std::string& name, const std::vector<Shape>& shapes, const std::vector<Pose>& shape_poses,
                           double mass, const Pose& pose, const std::optional<Mat3>& inertia = std::nullopt);
  BodyIndex add_rigid_body(const std::string& name, const Shape& shape, double mass, const Pose& pose) {
    return add_rigid_body(name, {shape}, {Pose{}}, mass, pose);
  }
  /// Sets (first call) or replaces (later calls) the static collision mesh called `name`, e.g. the
  /// newest surface of the printed material. An empty mesh removes it.
  void set_static_mesh(const std::string& name, const TriangleMesh& mesh);

  // ---- robots ----
  /// Loads a URDF robot. Its joints track position targets (the initial positions until a tool
  /// target or set_joint_targets says otherwise) through DART servo motors within the URDF's
  /// velocity and effort limits. Throws InputError naming the file if the URDF cannot be loaded.
  RobotIndex add_robot(const RobotDescription& description);
  /// Fixes a tool to a robot link. Throws Error if the link does not exist.
  ToolIndex add_tool(RobotIndex robot, const ToolDescription& tool);
  /// From now on the robot's joints follow inverse kinematics (DART's IK, joint limits respected)
  /// so that the tool follows `trajectory` (controllers/tool_ik.hpp).
  void set_tool_trajectory(ToolIndex tool, ToolTrajectory trajectory);
  /// Adds a controller to the robot (controllers/controller.hpp): it runs each world step after the
  /// ones added before it and before the joint servo, which tracks the joint targets.
  void add_controller(RobotIndex robot, std::unique_ptr<Controller> controller);
  /// Makes the robot's floating base a differential drive (see DiffDriveDescription). Throws Error
  /// if a wheel joint does not exist or the base is not floating.
  void make_diff_drive(RobotIndex robot, const DiffDriveDescription& drive);
  /// The base follows `trajectory` (controllers/base_tracking_kanayama1990.hpp, on odometry).
  void set_base_trajectory(RobotIndex robot, BaseTrajectory trajectory);
  [[nodiscard]] Pose base_pose(RobotIndex robot) const;
  [[nodiscard]] Pose base_odometry(RobotIndex robot) const;
  [[nodiscard]] BaseReport base_report(RobotIndex robot) const;
  [[nodiscard]] bool has_diff_drive(RobotIndex robot) const;
  /// Position targets (rad or m) for every joint in joint_names() order.
  void set_joint_targets(RobotIndex robot, const std::vector<double>& positions);
  /// Puts the joints at these positions (rad or m, joint_names() order) at rest, and makes them the targets.
  void set_joint_positions(RobotIndex robot, const std::vector<double>& positions);
  // ---- commands from outside the process (controllers/external_command.hpp) ----
  /// Switches the robot between its scene controllers (false: its tool and base paths) and commands
  /// from outside (true: the joints hold their targets and the base stands until commanded). The
  /// commands below switch it to external control themselves.
  void set_external_control(RobotIndex robot, bool external);
  [[nodiscard]] bool external_control(RobotIndex robot) const;
  /// Joint position targets (rad or m, joint_names() order), held until the next command.
  void command_joint_targets(RobotIndex robot, const std::vector<double>& positions);
  /// Where a tool should be, reached by the same IK as a tool path; held until the next command. The
  /// tool goes there along a straight line within `limits` (controllers/target_follower.hpp).
  void command_tool_target(ToolIndex tool, const ToolTarget& target, const MotionLimits& limits = {});
  /// Where a commanded tool is asked to be on its way to its target now; null unless under a tool target.
  [[nodiscard]] const TargetFollower* tool_target_follower(ToolIndex tool) const;
  /// How far (m) the robot's IK gets the tool from `target` (position only), from the configuration
  /// it is in, the robot left as it was: about 0 for a target in reach.
  [[nodiscard]] double tool_target_miss(ToolIndex tool, const ToolTarget& target);
  /// A mobile base's forward speed (m/s) and turn rate (rad/s), held until the next command. Throws
  /// Error if the robot has no mobile base.
  void command_base_velocity(RobotIndex robot, double speed, double turn_rate);
  [[nodiscard]] std::size_t robot_count() const;
  [[nodiscard]] const std::string& robot_name(RobotIndex robot) const;
  [[nodiscard]] std::vector<std::string> joint_names(RobotIndex robot) const;
  [[nodiscard]] std::vector<std::string> link_names(RobotIndex robot) const;
  [[nodiscard]] std::vector<double> joint_positions(RobotIndex robot) const;
  [[nodiscard]] std::vector<double> joint_velocities(RobotIndex robot) const;  // rad/s (or m/s)
  /// What each joint's servo exerted over the last world step (N·m or N): its constraint impulse over the step.
  [[nodiscard]] std::vector<double> joint_efforts(RobotIndex robot) const;
  [[nodiscard]] Pose tool_pose(ToolIndex tool) const;
  [[nodiscard]] Vec3 tool_linear_velocity(ToolIndex tool) const;
  [[nodiscard]] const RobotContacts& robot_contacts(RobotIndex robot) const;
  /// Root-mean-square and largest distance (m) between tool and its target over the steps so far.
  [[nodiscard]] double tool_tracking_rms(ToolIndex tool) const;
  [[nodiscard]] double tool_tracking_max(ToolIndex tool) const;

  // ---- clearance queries (the multi-robot coordinator's: DART's FCL distance) ----
  /// Puts a robot where it would be for the queries below: its mobile base at (x, y, heading in
  /// rad) and each listed tool on its target by IK, from the configuration it is in (so a series of
  /// nearby placements converges as the run's own IK does). restore_robots() puts every robot back
  /// exactly as it was; the world must not step in between.
  void place_robot(RobotIndex robot, const std::optional<Vec3>& base_x_y_heading,
                   const std::vector<std::pair<ToolIndex, ToolTarget>>& tool_targets);
  void restore_robots();
  /// The base's (x, y, heading) now (m, m, rad); throws Error without a mobile base.
  [[nodiscard]] Vec3 base_x_y_heading(RobotIndex robot) const;
  /// The least distance (m) between two robots' collision shapes as they are placed (0 where they
  /// overlap). The search stops once it finds one below `enough` (m) and returns `enough` itself.
  [[nodiscard]] double robot_distance(RobotIndex first, RobotIndex second, double enough) const;
  /// The same between a robot, its tools' bodies left out (a nozzle sits in the strand it lays), and
  /// the printed material as set_print_boxes gave it. Infinity when there is none.
  [[nodiscard]] double print_distance(RobotIndex robot, double enough) const;
  /// The printed material for print_distance: boxes (m, world) around it, fresh and meshed alike.
  void set_print_boxes(const std::vector<Aabb>& boxes);

  // ---- movable links (what the fluid couples to) ----
  /// Free rigid bodies and robot links that can move and have collision shapes.
  [[nodiscard]] std::size_t link_count() const;
  [[nodiscard]] LinkShapes link_shapes(LinkIndex link) const;
  [[nodiscard]] Pose link_pose(LinkIndex link) const;
  /// Robot links welded to the world (a fixed base) with collision shapes: not movable, so not
  /// among the links above, but drawn by the outputs. Each with its pose in the world.
  [[nodiscard]] std::vector<std::pair<LinkShapes, Pose>> fixed_robot_links() const;
  /// Any link of a robot by its URDF name (with collision shapes or a bare frame like tool0): its
  /// pose in the world now; none if the robot has no such link.
  [[nodiscard]] std::optional<Pose> robot_link_pose(RobotIndex robot, const std::string& link) const;
  [[nodiscard]] Vec3 link_linear_velocity(LinkIndex link) const;   // m/s of the link frame's origin, world
  [[nodiscard]] Vec3 link_angular_velocity(LinkIndex link) const;  // rad/s, world
  /// A force (N, world) at the link origin and a torque (N·m, world) applied in every world step
  /// until the next call: how the fluid pushes on bodies and robots.
  void set_link_wrench(LinkIndex link, const Vec3& force, const Vec3& torque);
  /// The link of a free rigid body.
  [[nodiscard]] LinkIndex link_of_body(BodyIndex body) const;
  /// Whether the fluid coupling turns the link into boundary particles (default true). False: the
  /// link only collides in the world (e.g. a test that wants the printed mesh alone to hold a body).
  [[nodiscard]] bool link_feels_fluid(LinkIndex link) const;
  void set_feels_fluid(LinkIndex link, bool feels_fluid);

  /// Steps until the world's clock reaches `time` (s) exactly, in equal steps no longer than the set time step.
  void step_to(double time);

  [[nodiscard]] double time() const;
  /// A checkpoint of what moves and what the controllers carry (joints, bodies, targets, odometry,
  /// contacts and tracking so far), and back into a world the same scene made. Printed meshes are
  /// the caller's (set_static_mesh).
  void save_state(StateWriter& out) const;
  void load_state(StateReader& in);
  [[nodiscard]] Pose pose(BodyIndex body) const;
  [[nodiscard]] Vec3 linear_velocity(BodyIndex body) const;  // m/s of the body's origin, world frame
  /// Sets a free body's velocity (m/s of its origin, world frame), e.g. a thrown body's initial state.
  void set_linear_velocity(BodyIndex body, const Vec3& velocity);
  [[nodiscard]] double mass(BodyIndex body) const;  // kg
  /// Contacts found by the last world step.
  [[nodiscard]] std::size_t contact_count() const;
  /// How many times set_static_mesh replaced a mesh (0 after the first insertion).
  [[nodiscard]] std::size_t mesh_replacements() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace m3dp::world
