#pragma once
// The world's private parts, for its translation units only (world.cpp: bodies, links, stepping and
// checkpoints; world_robots.cpp: robots, tools, drives and commands; world_clearance.cpp: the
// coordinator's distance queries). DART is slow to compile against: only these include it.

#include <assimp/scene.h>
#include <dart/collision/bullet/BulletCollisionDetector.hpp>
#include <dart/collision/fcl/FCLCollisionDetector.hpp>
#include <dart/dart.hpp>
#include <dart/utils/urdf/DartLoader.hpp>

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <iostream>
#include <limits>
#include <map>
#include <set>
#include <variant>

#include "m3dp/core/error.hpp"
#include "m3dp/core/state_io.hpp"
#include "m3dp/world/controllers/base_tracking_kanayama1990.hpp"
#include "m3dp/world/controllers/external_command.hpp"
#include "m3dp/world/controllers/joint_servo.hpp"
#include "m3dp/world/controllers/tool_ik.hpp"


namespace m3dp::world {

using dart::dynamics::BodyNode;
using dart::dynamics::ShapeNode;
using dart::dynamics::SkeletonPtr;

/// A DART transform as our pose, and back.
Pose pose_of(const Eigen::Isometry3d& transform);
Eigen::Isometry3d isometry_of(const Pose& pose);

struct World::Impl {
  struct Link {
    BodyNode* node = nullptr;
    std::string name;
    Vec3 force = Vec3::Zero();   // N, world, at the link origin
    Vec3 torque = Vec3::Zero();  // N·m, world
    bool feels_fluid = true;
  };
  struct Tool {
    std::string name;
    RobotIndex robot = 0;
    dart::dynamics::EndEffector* end_effector = nullptr;
    std::shared_ptr<dart::dynamics::SimpleFrame> target;
    std::vector<Eigen::Index> target_slot;  // per IK DoF: its slot in the robot's position targets, or −1
    Eigen::VectorXd solution;
    TrackingError tracking;                 // from its target, at the ends of the IK's chunks
  };
  struct Robot {
    std::string name;
    SkeletonPtr skeleton;
    std::vector<dart::dynamics::DegreeOfFreedom*> joint_dofs;  // the actuated joints, in joint_names() order
    Eigen::VectorXd position_targets;
    std::vector<ToolIndex> tools;
    RobotContacts contacts;
    // Run in order each world step; the joint servo is always last.
    std::vector<std::unique_ptr<Controller>> controllers;
    ToolIk* tool_ik = nullptr;  // among the controllers, once a tool follows a trajectory
    /// Commands from outside; while `external`, it runs instead of the controllers but the servo.
    std::unique_ptr<ExternalCommand> external_command;
    bool external = false;
    /// Calls `call` with each controller that runs this step, in order.
    template <class Call>
    void each_controller(Call&& call) {
      if (!external) {
        for (const auto& controller : controllers) call(*controller);
        return;
      }
      call(*external_command);
      call(*controllers.back());  // the joint servo
    }
    struct DiffDrive {
      DiffDriveDescription description;
      dart::dynamics::DegreeOfFreedom* left = nullptr;
      dart::dynamics::DegreeOfFreedom* right = nullptr;
      dart::dynamics::Joint* planar = nullptr;  // x, y, heading of the base in the floor plane
      double max_wheel_speed = 0;
      double odometry_x = 0, odometry_y = 0, odometry_heading = 0;
      double last_left = 0, last_right = 0;  // wheel angles at the last odometry update (rad)
      double requested_speed = 0, requested_turn = 0;  // this step's drive_base (m/s, rad/s)
      double distance = 0;                   // m driven
      TrackingError tracking;                // from its path (a base tracking controller)
    };
    std::optional<DiffDrive> drive;
    /// The joints the robot's own position loop drives (not the wheels).
    [[nodiscard]] bool is_wheel(const dart::dynamics::DegreeOfFreedom* dof) const {
      return drive && (dof == drive->left || dof == drive->right);
    }
  };

  dart::simulation::WorldPtr world;
  std::vector<SkeletonPtr> bodies;
  std::vector<LinkIndex> body_links;  // per body: its link, or npos for static ones
  std::map<std::string, SkeletonPtr> meshes;
  std::vector<Link> links;
  std::vector<Robot> robots;
  std::vector<Tool> tools;
  std::map<const dart::dynamics::Skeleton*, RobotIndex> robot_of_skeleton;
  std::set<const BodyNode*> nozzle_nodes;
  std::set<const BodyNode*> wheel_nodes;
  std::set<const dart::dynamics::Skeleton*> printed_skeletons;
  std::size_t replacements = 0;
  std::size_t rigid_bodies = 0;
  double max_time_step = 1e-3;  // s
  double ik_period = 4e-3;      // s of world time between IK solutions (joint targets are interpolated between)
  std::vector<char> touched;    // per robot, scratch of count_contacts

  /// The coordinator's distance queries: FCL (Bullet, the contacts' detector, has no distances),
  /// shape against shape. (FCL 0.7's distance between two broad-phase managers misses pairs: two
  /// TurtleBot bases 3.4 cm apart came out 35 cm apart.) Made on first use, when every robot and
  /// tool has been added.
  struct Clearance {
    struct Proxy {
      std::shared_ptr<dart::dynamics::SimpleFrame> frame;  // moves with its link
      std::shared_ptr<dart::collision::CollisionGroup> group;  // of this shape alone
      double radius = 0;    // m, of a sphere about the frame's origin that holds the shape
      bool tool = false;    // a tool's body (a nozzle's barrel)
    };
    std::shared_ptr<dart::collision::CollisionDetector> detector;
    std::vector<std::vector<Proxy>> robots;   // per robot, its links' shapes
    std::vector<Proxy> print_boxes;           // around the printed material
    std::vector<Eigen::VectorXd> saved_positions;  // per robot while placed; empty otherwise
    [[nodiscard]] Proxy proxy(std::shared_ptr<dart::dynamics::SimpleFrame> frame) const;
    /// The least distance (m) between two sets of shapes (infinity if one is empty); stops once
    /// below `enough` and returns it.
    [[nodiscard]] double distance(const std::vector<Proxy>& first, const std::vector<Proxy>& second, bool with_tools,
                                  double enough) const;
  };
  mutable Clearance clearance;
  Clearance& clearance_groups() const;

  class DartRobotIo;
  /// Every robot's controllers at the start of a chunk of world steps that ends at `end_time`.
  void plan_chunk(double end_time);
  /// The controllers' commands for one world step; `chunk_fraction` (0, 1] says how far into the chunk its end is.
  void control(double step, double chunk_fraction);
  /// After one world step: contacts, odometry and the controllers' own bookkeeping.
  void after_step();
  void end_chunk();
  /// The wheel and planar-joint commands of this step's drive request.
  void drive_base(Robot& robot, double step);
  void update_odometry(Robot& robot);
  void count_contacts();
};

/// The robot as its controllers see it (controllers/controller.hpp), over its DART skeleton.
class World::Impl::DartRobotIo final : public RobotIo {
 public:
  DartRobotIo(Impl& impl, Robot& robot) : impl_(impl), robot_(robot) {}
  [[nodiscard]] std::size_t joint_count() const override { return robot_.joint_dofs.size(); }
  [[nodiscard]] double joint_position(std::size_t joint) const override { return robot_.joint_dofs[joint]->getPosition(); }
  [[nodiscard]] std::pair<double, double> joint_velocity_limits(std::size_t joint) const override {
    return {robot_.joint_dofs[joint]->getVelocityLowerLimit(), robot_.joint_dofs[joint]->getVelocityUpperLimit()};
  }
  [[nodiscard]] bool is_wheel(std::size_t joint) const override { return robot_.is_wheel(robot_.joint_dofs[joint]); }
  [[nodiscard]] Eigen::VectorXd& joint_targets() override { return robot_.position_targets; }
  void command_joint_velocity(std::size_t joint, double velocity) override { robot_.joint_dofs[joint]->setCommand(velocity); }
  [[nodiscard]] Eigen::Isometry3d tool_transform(ToolIndex tool) const override {
    return impl_.tools.at(tool).end_effector->getWorldTransform();
  }
  void solve_tool_ik(ToolIndex tool_index, const Eigen::Isometry3d& target, Eigen::VectorXd& joints) override {
    Tool& tool = impl_.tools.at(tool_index);
    tool.target->setTransform(target);
    // The best solution found is used even when it misses the (tight) bounds: it is close.
    tool.end_effector->getIK()->findSolution(tool.solution);
    for (std::size_t k = 0; k < tool.target_slot.size(); ++k)
      if (tool.target_slot[k] >= 0) joints[tool.target_slot[k]] = tool.solution[static_cast<Eigen::Index>(k)];
  }
  [[nodiscard]] TrackingError& tool_tracking(ToolIndex tool) override { return impl_.tools.at(tool).tracking; }
  [[nodiscard]] Odometry base_odometry() const override {
    const auto& drive = drive_of();
    return {drive.odometry_x, drive.odometry_y, drive.odometry_heading};
  }
  [[nodiscard]] Eigen::Vector3d base_position() const override {
    return robot_.skeleton->getRootBodyNode()->getWorldTransform().translation();
  }
  void drive_base(double speed, double turn_rate) override {
    drive_of().requested_speed = speed;
    drive_of().requested_turn = turn_rate;
  }
  [[nodiscard]] TrackingError& base_tracking() override { return drive_of().tracking; }

 private:
  [[nodiscard]] Robot::DiffDrive& drive_of() const {
    if (!robot_.drive) throw Error(fmt::format("robot '{}' has no mobile base", robot_.name));
    return *robot_.drive;
  }
  Impl& impl_;
  Robot& robot_;
};

}  // namespace m3dp::world
