// The world's robots: URDF loading, tools and their IK, differential-drive bases, controllers and
// commands from outside, and what the robots report.
#include "m3dp/world/world_impl.hpp"

namespace m3dp::world {

RobotIndex World::add_robot(const RobotDescription& description) {
  using namespace dart::dynamics;
  const std::string file = description.urdf_file.string();
  if (!std::filesystem::exists(description.urdf_file))
    throw InputError(SourceLocation{file, 0}, "URDF file not found");
  // A URDF link without <inertial> is a frame (tool0, an end-effector point), not a body: DART's
  // default would give it 1 kg, which hung a phantom kilogram on the UR10's flange and on the
  // OpenManipulator's fingertips (enough to make its 4.1 N m servos sag).
  Inertia frame_inertia;
  frame_inertia.setMass(1e-6);
  frame_inertia.setMoment(Eigen::Matrix3d::Identity() * 1e-12);
  dart::utils::DartLoader loader(dart::utils::DartLoader::Options(nullptr, dart::utils::DartLoader::RootJointType::FLOATING, frame_inertia));
  SkeletonPtr skeleton = loader.parseSkeleton(dart::common::Uri::createFromPath(std::filesystem::absolute(description.urdf_file).string()));
  if (!skeleton)
    throw InputError(SourceLocation{file, 0},
                     "DART's URDF loader rejected the robot (its reason is printed above); check the <link>, <joint> "
                     "and <inertial> elements");
  // A URDF of nothing but a "world" link loads as a skeleton of no bodies (DART asserts on its root).
  if (skeleton->getNumBodyNodes() == 0)
    throw InputError(SourceLocation{file, 0}, "the robot has no link besides \"world\" (the world frame): nothing to simulate");
  skeleton->setName(description.name);
  // Place the base: a welded root (URDF root link "world") moves its weld, a floating base its free joint.
  Joint* root = skeleton->getRootJoint();
  if (auto* free_joint = dynamic_cast<FreeJoint*>(root)) {
    free_joint->setPositions(FreeJoint::convertToPositions(isometry_of(description.base_pose) * free_joint->getRelativeTransform()));
  } else {
    root->setTransformFromParentBodyNode(isometry_of(description.base_pose) * root->getTransformFromParentBodyNode());
  }
  // The actuated joints: every one-DoF joint below the root, tracked by servo motors.
  std::vector<DegreeOfFreedom*> joint_dofs;
  for (std::size_t j = 0; j < skeleton->getNumJoints(); ++j) {
    Joint* joint = skeleton->getJoint(j);
    if (joint == root || joint->getNumDofs() != 1) continue;
    joint->setActuatorType(Joint::SERVO);
    joint_dofs.push_back(joint->getDof(0));
  }
  if (!description.initial_joint_positions.empty()) {
    if (description.initial_joint_positions.size() != joint_dofs.size())
      throw InputError(SourceLocation{file, 0},
                       fmt::format("robot '{}' has {} joints but {} initial joint positions were given", description.name,
                                   joint_dofs.size(), description.initial_joint_positions.size()));
    for (std::size_t k = 0; k < joint_dofs.size(); ++k) joint_dofs[k]->setPosition(description.initial_joint_positions[k]);
  }
  Impl::Robot robot;
  robot.name = description.name;
  robot.skeleton = skeleton;
  robot.joint_dofs = joint_dofs;
  robot.position_targets.resize(static_cast<Eigen::Index>(joint_dofs.size()));
  for (std::size_t k = 0; k < joint_dofs.size(); ++k) robot.position_targets[static_cast<Eigen::Index>(k)] = joint_dofs[k]->getPosition();
  robot.controllers.push_back(std::make_unique<JointServo>());
  impl_->world->addSkeleton(skeleton);
  const RobotIndex index = impl_->robots.size();
  impl_->robot_of_skeleton[skeleton.get()] = index;
  for (std::size_t b = 0; b < skeleton->getNumBodyNodes(); ++b) {
    BodyNode* node = skeleton->getBodyNode(b);
    if (node->getNumDependentGenCoords() == 0 || node->getShapeNodesWith<CollisionAspect>().empty()) continue;
    impl_->links.push_back(Impl::Link{node, description.name + "/" + node->getName()});
  }
  impl_->robots.push_back(std::move(robot));
  return index;
}

ToolIndex World::add_tool(RobotIndex robot_index, const ToolDescription& description) {
  using namespace dart::dynamics;
  Impl::Robot& robot = impl_->robots.at(robot_index);
  BodyNode* link = robot.skeleton->getBodyNode(description.link);
  if (!link)
    throw Error(fmt::format("robot '{}' has no link '{}'; its links: {}", robot.name, description.link,
                            fmt::join(link_names(robot_index), ", ")));
  Impl::Tool tool;
  tool.name = description.name;
  tool.robot = robot_index;
  tool.end_effector = link->createEndEffector(description.name);
  tool.end_effector->setDefaultRelativeTransform(isometry_of(description.offset), true);
  tool.target = std::make_shared<SimpleFrame>(Frame::World(), description.name + "_target");
  tool.target->setTransform(tool.end_effector->getWorldTransform());

  // The tool's inverse kinematics: position exact, the tool axis along the target's z, rotation
  // about that axis free (the error is measured in the target's frame; its z rotation is unbounded).
  auto ik = tool.end_effector->getIK(true);
  ik->setTarget(tool.target);
  // The arm's joints only: a floating or driven base moves by its own controller.
  std::vector<std::size_t> arm_dofs;
  for (const auto* dof : robot.joint_dofs)
    if (!robot.is_wheel(dof)) arm_dofs.push_back(dof->getIndexInSkeleton());
  ik->setDofs(arm_dofs);
  auto& error_method = ik->getErrorMethod();
  if (auto* region = dynamic_cast<InverseKinematics::TaskSpaceRegion*>(&error_method)) {
    region->setReferenceFrame(tool.target);
    // Errors from the region's edge, not its centre: from the centre, the free rotation would still
    // be pulled to zero, which an arm with fewer than six joints (OpenManipulator-X) cannot do
    // while it reaches the point, and the solver would trade position for it.
    region->setComputeFromCenter(false);
  }
  error_method.setLinearBounds(Eigen::Vector3d::Constant(-1e-6), Eigen::Vector3d::Constant(1e-6));
  error_method.setAngularBounds(Eigen::Vector3d(-1e-5, -1e-5, -kPi), Eigen::Vector3d(1e-5, 1e-5, kPi));
  // Few iterations: each world step starts from the last solution, a millisecond away. (An arm
  // with fewer than six joints rarely meets the tight bounds exactly; its best is within 0.1 mm.)
  ik->getSolver()->setNumMaxIterations(10);
  for (const std::size_t dof : ik->getDofs()) {
    const auto found = std::find(robot.joint_dofs.begin(), robot.joint_dofs.end(), robot.skeleton->getDof(dof));
    tool.target_slot.push_back(found == robot.joint_dofs.end() ? -1 : static_cast<Eigen::Index>(found - robot.joint_dofs.begin()));
  }

  // A body for the tool (the nozzle's barrel): a cylinder along the tool axis from the link to
  // `body_clearance` before the tool frame's origin. Its own body node, so it is a link the fluid
  // sees and the world can exclude from contacts with the printed material.
  if (description.body_radius > 0) {
    const Vec3 tip = description.offset.position - description.body_clearance * description.offset.rotate(Vec3::UnitZ());
    const Real length = tip.norm();
    if (length > Real(1e-4)) {
      auto pair = link->createChildJointAndBodyNodePair<WeldJoint>(
          WeldJoint::Properties(), BodyNode::AspectProperties(description.name));
      Pose barrel;
      barrel.position = tip / 2;
      barrel.orientation = Quat::FromTwoVectors(Vec3::UnitZ(), tip / length);
      pair.first->setTransformFromParentBodyNode(isometry_of(barrel));
      pair.second->createShapeNodeWith<CollisionAspect, DynamicsAspect>(
          std::make_shared<dart::dynamics::CylinderShape>(description.body_radius, length));
      Inertia inertia;
      inertia.setMass(description.body_mass);
      inertia.setMoment(dart::dynamics::CylinderShape::computeInertia(description.body_radius, length, description.body_mass));
      pair.second->setInertia(inertia);
      impl_->nozzle_nodes.insert(pair.second);
      impl_->links.push_back(Impl::Link{pair.second, robot.name + "/" + description.name});
    }
  }
  impl_->tools.push_back(std::move(tool));
  robot.tools.push_back(impl_->tools.size() - 1);
  return impl_->tools.size() - 1;
}

void World::make_diff_drive(RobotIndex robot_index, const DiffDriveDescription& description) {
  using namespace dart::dynamics;
  Impl::Robot& robot = impl_->robots.at(robot_index);
  auto* free_joint = dynamic_cast<FreeJoint*>(robot.skeleton->getRootJoint());
  if (!free_joint)
    throw Error(fmt::format("robot '{}': a differential drive needs a floating base (its URDF root is fixed)", robot.name));
  auto wheel = [&](const std::string& name) {
    Joint* joint = robot.skeleton->getJoint(name);
    if (!joint || joint->getNumDofs() != 1)
      throw Error(fmt::format("robot '{}' has no one-axis joint '{}' for a wheel; its joints: {}", robot.name, name,
                              fmt::join(joint_names(robot_index), ", ")));
    return joint->getDof(0);
  };
  Impl::Robot::DiffDrive drive;
  drive.description = description;
  drive.left = wheel(description.left_wheel_joint);
  drive.right = wheel(description.right_wheel_joint);
  drive.max_wheel_speed = description.max_wheel_speed > 0
                              ? description.max_wheel_speed
                              : std::min(drive.left->getVelocityUpperLimit(), drive.right->getVelocityUpperLimit());
  // The base's pose now: keep its height and tilt in the planar joint's parent transform.
  const Eigen::Isometry3d base = robot.skeleton->getRootBodyNode()->getWorldTransform();
  const double heading = std::atan2(base.linear()(1, 0), base.linear()(0, 0));
  BodyNode* root = robot.skeleton->getRootBodyNode();
  auto* planar = root->changeParentJointType<PlanarJoint>();
  planar->setName(robot.name + "_planar_base");
  Eigen::Isometry3d lift = Eigen::Isometry3d::Identity();
  lift.translation().z() = base.translation().z();
  planar->setTransformFromParentBodyNode(lift);
  planar->setXYPlane();
  planar->setPositions(Eigen::Vector3d(base.translation().x(), base.translation().y(), heading));
  planar->setActuatorType(Joint::SERVO);
  for (std::size_t k = 0; k < 3; ++k) {
    planar->setForceLowerLimit(k, -1e3);
    planar->setForceUpperLimit(k, 1e3);
  }
  drive.planar = planar;
  drive.odometry_x = base.translation().x();
  drive.odometry_y = base.translation().y();
  drive.odometry_heading = heading;
  drive.last_left = drive.left->getPosition();
  drive.last_right = drive.right->getPosition();
  impl_->wheel_nodes.insert(drive.left->getChildBodyNode());
  impl_->wheel_nodes.insert(drive.right->getChildBodyNode());
  robot.drive = drive;
}

void World::set_base_trajectory(RobotIndex robot, BaseTrajectory trajectory) {
  auto& drive = impl_->robots.at(robot).drive;
  if (!drive) throw Error(fmt::format("robot '{}' has no mobile base", impl_->robots.at(robot).name));
  add_controller(robot, std::make_unique<BaseTrackingKanayama1990>(std::move(trajectory), drive->odometry_heading));
}

void World::add_controller(RobotIndex robot_index, std::unique_ptr<Controller> controller) {
  auto& controllers = impl_->robots.at(robot_index).controllers;
  controllers.insert(controllers.end() - 1, std::move(controller));  // before the joint servo
}

bool World::has_diff_drive(RobotIndex robot) const { return impl_->robots.at(robot).drive.has_value(); }

Pose World::base_pose(RobotIndex robot) const {
  return pose_of(impl_->robots.at(robot).skeleton->getRootBodyNode()->getWorldTransform());
}

Pose World::base_odometry(RobotIndex robot) const {
  const auto& drive = impl_->robots.at(robot).drive;
  if (!drive) return base_pose(robot);
  Pose pose;
  pose.position = Vec3(Real(drive->odometry_x), Real(drive->odometry_y), base_pose(robot).position.z());
  pose.orientation = Quat(Eigen::AngleAxis<Real>(Real(drive->odometry_heading), Vec3::UnitZ()));
  return pose;
}

BaseReport World::base_report(RobotIndex robot) const {
  BaseReport report;
  const auto& drive = impl_->robots.at(robot).drive;
  if (!drive) return report;
  report.tracking_rms = drive->tracking.rms();
  report.tracking_max = drive->tracking.max;
  const Vec3 truth = base_pose(robot).position;
  report.odometry_error = std::hypot(truth.x() - drive->odometry_x, truth.y() - drive->odometry_y);
  report.distance = drive->distance;
  return report;
}

void World::Impl::drive_base(Robot& robot, double step) {
  auto& drive = *robot.drive;
  const auto& description = drive.description;
  const double v = drive.requested_speed, w = drive.requested_turn;  // m/s, rad/s asked of the base
  // Wheel speeds, both scaled down together when one would exceed its limit.
  const double radius = description.wheel_radius, half_track = description.wheel_separation / 2;
  double right = (v + w * half_track) / radius, left = (v - w * half_track) / radius;
  const double fastest = std::max(std::abs(left), std::abs(right));
  if (fastest > drive.max_wheel_speed) {
    left *= drive.max_wheel_speed / fastest;
    right *= drive.max_wheel_speed / fastest;
  }
  drive.left->setCommand(left);
  drive.right->setCommand(right);
  // The base rolls as the wheels turn (no slip).
  const double speed = radius * (right + left) / 2, turn = radius * (right - left) / description.wheel_separation;
  const double heading = drive.planar->getPosition(2);
  drive.planar->setCommand(0, speed * std::cos(heading + turn * step / 2));
  drive.planar->setCommand(1, speed * std::sin(heading + turn * step / 2));
  drive.planar->setCommand(2, turn);
}

void World::Impl::update_odometry(Robot& robot) {
  auto& drive = *robot.drive;
  const double left = drive.left->getPosition(), right = drive.right->getPosition();
  const double left_step = left - drive.last_left, right_step = right - drive.last_right;
  drive.last_left = left;
  drive.last_right = right;
  const double radius = drive.description.wheel_radius;
  const double distance = radius * (left_step + right_step) / 2;
  const double turn = radius * (right_step - left_step) / drive.description.wheel_separation;
  drive.odometry_x += distance * std::cos(drive.odometry_heading + turn / 2);
  drive.odometry_y += distance * std::sin(drive.odometry_heading + turn / 2);
  drive.odometry_heading += turn;
  drive.distance += std::abs(distance);
}

void World::set_tool_trajectory(ToolIndex tool, ToolTrajectory trajectory) {
  Impl::Robot& robot = impl_->robots.at(impl_->tools.at(tool).robot);
  if (!robot.tool_ik) {
    auto controller = std::make_unique<ToolIk>();
    robot.tool_ik = controller.get();
    add_controller(impl_->tools.at(tool).robot, std::move(controller));
  }
  robot.tool_ik->follow(tool, std::move(trajectory));
}

void World::set_external_control(RobotIndex robot_index, bool external) {
  Impl::Robot& robot = impl_->robots.at(robot_index);
  if (!robot.external_command) robot.external_command = std::make_unique<ExternalCommand>();
  if (external && !robot.external) robot.external_command->clear();  // hold where it is
  robot.external = external;
}

bool World::external_control(RobotIndex robot) const { return impl_->robots.at(robot).external; }

namespace {
/// Throws Error unless `positions` has a value for each of the robot's joints.
void check_joint_count(const std::string& robot, const Eigen::VectorXd& targets, const std::vector<double>& positions) {
  if (positions.size() != static_cast<std::size_t>(targets.size()))
    throw Error(fmt::format("robot '{}': {} joint targets for {} joints", robot, positions.size(), targets.size()));
}
}  // namespace

void World::command_joint_targets(RobotIndex robot_index, const std::vector<double>& positions) {
  Impl::Robot& robot = impl_->robots.at(robot_index);
  check_joint_count(robot.name, robot.position_targets, positions);
  for (const double position : positions)
    if (!std::isfinite(position)) throw Error(fmt::format("robot '{}': a joint target that is not a number", robot.name));
  set_external_control(robot_index, true);
  robot.external_command->set_joint_targets(Eigen::Map<const Eigen::VectorXd>(positions.data(), static_cast<Eigen::Index>(positions.size())));
}

void World::command_tool_target(ToolIndex tool, const ToolTarget& target, const MotionLimits& limits) {
  const RobotIndex robot_index = impl_->tools.at(tool).robot;
  if (!target.position.allFinite() || !target.axis.allFinite() || target.axis.norm() < Real(1e-6))
    throw Error(fmt::format("robot '{}': a tool target needs a finite position and a non-zero axis", impl_->robots.at(robot_index).name));
  set_external_control(robot_index, true);
  impl_->robots.at(robot_index).external_command->set_tool_target(tool, target, limits, tool_pose(tool).position.cast<double>(),
                                                                   impl_->world->getTime());
}

const TargetFollower* World::tool_target_follower(ToolIndex tool) const {
  const Impl::Robot& robot = impl_->robots.at(impl_->tools.at(tool).robot);
  return robot.external && robot.external_command ? robot.external_command->tool_follower(tool) : nullptr;
}

double World::tool_target_miss(ToolIndex tool_index, const ToolTarget& target) {
  Impl::Tool& tool = impl_->tools.at(tool_index);
  const auto saved = impl_->robots.at(tool.robot).skeleton->getPositions();
  auto ik = tool.end_effector->getIK();
  double miss = 0;
  // Rounds of the run's (10-iteration) IK until it stops getting closer: a target across the
  // workspace takes a few, one out of reach stops short.
  for (int round = 0; round < 40; ++round) {
    tool.target->setTransform(tool_target_transform(tool.end_effector->getWorldTransform(), target));
    ik->findSolution(tool.solution);
    ik->setPositions(tool.solution);
    const double now = (tool.end_effector->getWorldTransform().translation() - target.position.cast<double>()).norm();
    if (now < 1e-4 || (round > 4 && now > 0.99 * miss)) {
      miss = now;
      break;
    }
    miss = now;
  }
  impl_->robots.at(tool.robot).skeleton->setPositions(saved);
  return miss;
}

void World::command_base_velocity(RobotIndex robot_index, double speed, double turn_rate) {
  Impl::Robot& robot = impl_->robots.at(robot_index);
  if (!robot.drive) throw Error(fmt::format("robot '{}' has no mobile base", robot.name));
  if (!std::isfinite(speed) || !std::isfinite(turn_rate)) throw Error(fmt::format("robot '{}': a base velocity that is not a number", robot.name));
  set_external_control(robot_index, true);
  robot.external_command->set_base_velocity(speed, turn_rate);
}

void World::set_joint_targets(RobotIndex robot_index, const std::vector<double>& positions) {
  Impl::Robot& robot = impl_->robots.at(robot_index);
  check_joint_count(robot.name, robot.position_targets, positions);
  for (std::size_t k = 0; k < positions.size(); ++k) robot.position_targets[static_cast<Eigen::Index>(k)] = positions[k];
}

void World::set_joint_positions(RobotIndex robot_index, const std::vector<double>& positions) {
  set_joint_targets(robot_index, positions);
  Impl::Robot& robot = impl_->robots.at(robot_index);
  for (std::size_t k = 0; k < positions.size(); ++k) {
    robot.joint_dofs[k]->setPosition(positions[k]);
    robot.joint_dofs[k]->setVelocity(0);
  }
}

std::size_t World::robot_count() const { return impl_->robots.size(); }
const std::string& World::robot_name(RobotIndex robot) const { return impl_->robots.at(robot).name; }

std::vector<std::string> World::joint_names(RobotIndex robot) const {
  std::vector<std::string> names;
  for (const auto* dof : impl_->robots.at(robot).joint_dofs) names.push_back(dof->getJoint()->getName());
  return names;
}

std::vector<std::string> World::link_names(RobotIndex robot) const {
  std::vector<std::string> names;
  const auto& skeleton = *impl_->robots.at(robot).skeleton;
  for (std::size_t b = 0; b < skeleton.getNumBodyNodes(); ++b) names.push_back(skeleton.getBodyNode(b)->getName());
  return names;
}

std::vector<double> World::joint_positions(RobotIndex robot) const {
  std::vector<double> positions;
  for (const auto* dof : impl_->robots.at(robot).joint_dofs) positions.push_back(dof->getPosition());
  return positions;
}

std::vector<double> World::joint_velocities(RobotIndex robot) const {
  std::vector<double> velocities;
  for (const auto* dof : impl_->robots.at(robot).joint_dofs) velocities.push_back(dof->getVelocity());
  return velocities;
}

std::vector<double> World::joint_efforts(RobotIndex robot) const {
  std::vector<double> efforts;
  const double step = impl_->world->getTimeStep();
  for (const auto* dof : impl_->robots.at(robot).joint_dofs) efforts.push_back(dof->getForce() + dof->getConstraintImpulse() / step);
  return efforts;
}

Pose World::tool_pose(ToolIndex tool) const { return pose_of(impl_->tools.at(tool).end_effector->getWorldTransform()); }

Vec3 World::tool_linear_velocity(ToolIndex tool) const {
  return impl_->tools.at(tool).end_effector->getLinearVelocity().cast<Real>();
}

const RobotContacts& World::robot_contacts(RobotIndex robot) const { return impl_->robots.at(robot).contacts; }

double World::tool_tracking_rms(ToolIndex tool) const { return impl_->tools.at(tool).tracking.rms(); }

double World::tool_tracking_max(ToolIndex tool) const { return impl_->tools.at(tool).tracking.max; }

}  // namespace m3dp::world
