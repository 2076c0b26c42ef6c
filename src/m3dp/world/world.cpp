// The only translation unit that includes DART: the world's bodies, robots and contacts, and RobotIo,
// through which the controllers (controllers/) read and command the robots.
#include "m3dp/world/world.hpp"

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

namespace {

using dart::dynamics::BodyNode;
using dart::dynamics::ShapeNode;
using dart::dynamics::SkeletonPtr;

Pose pose_of(const Eigen::Isometry3d& transform) {
  Pose pose;
  pose.position = transform.translation().cast<Real>();
  pose.orientation = Quat(transform.linear().cast<Real>()).normalized();
  return pose;
}

Eigen::Isometry3d isometry_of(const Pose& pose) {
  Eigen::Isometry3d transform = Eigen::Isometry3d::Identity();
  transform.translation() = pose.position.cast<double>();
  transform.linear() = pose.orientation.cast<double>().toRotationMatrix();
  return transform;
}

/// DART reads meshes as Assimp scenes; build one from our triangles. MeshShape releases it with
/// aiReleaseImport, which deletes a scene that no importer owns.
const aiScene* assimp_scene_of(const TriangleMesh& mesh) {
  auto* scene = new aiScene;
  auto* assimp_mesh = new aiMesh;
  assimp_mesh->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  assimp_mesh->mNumVertices = static_cast<unsigned>(mesh.vertices.size());
  assimp_mesh->mVertices = new aiVector3D[mesh.vertices.size()];
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
    assimp_mesh->mVertices[v] = aiVector3D(mesh.vertices[v].x(), mesh.vertices[v].y(), mesh.vertices[v].z());
  assimp_mesh->mNumFaces = static_cast<unsigned>(mesh.triangles.size());
  assimp_mesh->mFaces = new aiFace[mesh.triangles.size()];
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    aiFace& face = assimp_mesh->mFaces[t];
    face.mNumIndices = 3;
    face.mIndices = new unsigned[3]{mesh.triangles[t][0], mesh.triangles[t][1], mesh.triangles[t][2]};
  }
  scene->mNumMeshes = 1;
  scene->mMeshes = new aiMesh*[1]{assimp_mesh};
  scene->mNumMaterials = 1;
  scene->mMaterials = new aiMaterial*[1]{new aiMaterial};
  scene->mRootNode = new aiNode;
  scene->mRootNode->mNumMeshes = 1;
  scene->mRootNode->mMeshes = new unsigned[1]{0};
  return scene;
}

dart::dynamics::ShapePtr dart_shape_of(const Shape& shape) {
  using namespace dart::dynamics;
  return std::visit(
      [](const auto& value) -> ShapePtr {
        using T = std::decay_t<decltype(value)>;
        if constexpr (std::is_same_v<T, BoxShape>) {
          return std::make_shared<dart::dynamics::BoxShape>(value.size.template cast<double>());
        } else if constexpr (std::is_same_v<T, SphereShape>) {
          return std::make_shared<dart::dynamics::SphereShape>(value.radius);
        } else if constexpr (std::is_same_v<T, CylinderShape>) {
          return std::make_shared<dart::dynamics::CylinderShape>(value.radius, value.length);
        } else if constexpr (std::is_same_v<T, PlaneShape>) {
          // A finite patch: DART's PlaneShape is infinite, so a thin box under the plane stands in.
          return std::make_shared<dart::dynamics::BoxShape>(Eigen::Vector3d(value.size_x, value.size_y, 0.01));
        } else {
          return std::make_shared<dart::dynamics::MeshShape>(Eigen::Vector3d::Ones(), assimp_scene_of(value.mesh));
        }
      },
      shape);
}

/// A plane patch's thin box sits below the plane, its normal along the local z.
Pose plane_pose(const Shape& shape, const Pose& pose) {
  const auto* plane = std::get_if<PlaneShape>(&shape);
  if (!plane) return pose;
  const Quat tilt = Quat::FromTwoVectors(Vec3::UnitZ(), plane->normal.normalized());
  Pose adjusted = pose;
  adjusted.orientation = pose.orientation * tilt;
  adjusted.position = pose.apply(tilt * Vec3(0, 0, Real(-0.005)));
  return adjusted;
}

}  // namespace


namespace {

/// Our shape for a DART shape (what the fluid samples into boundary particles); none for shapes
/// the fluid cannot see yet (capsules, cones, soft shapes).
std::optional<Shape> m3dp_shape_of(const dart::dynamics::Shape& shape) {
  if (const auto* box = dynamic_cast<const dart::dynamics::BoxShape*>(&shape)) return BoxShape{box->getSize().cast<Real>()};
  if (const auto* sphere = dynamic_cast<const dart::dynamics::SphereShape*>(&shape))
    return SphereShape{static_cast<Real>(sphere->getRadius())};
  if (const auto* cylinder = dynamic_cast<const dart::dynamics::CylinderShape*>(&shape))
    return CylinderShape{static_cast<Real>(cylinder->getRadius()), static_cast<Real>(cylinder->getHeight())};
  if (const auto* mesh_shape = dynamic_cast<const dart::dynamics::MeshShape*>(&shape)) {
    const aiScene* scene = mesh_shape->getMesh();
    if (!scene) return std::nullopt;
    MeshShape result;
    result.file = mesh_shape->getMeshPath();
    const Eigen::Vector3d scale = mesh_shape->getScale();
    for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
      const aiMesh* mesh = scene->mMeshes[m];
      const auto first = static_cast<Index>(result.mesh.vertices.size());
      for (unsigned v = 0; v < mesh->mNumVertices; ++v)
        result.mesh.vertices.emplace_back(Real(mesh->mVertices[v].x * scale.x()), Real(mesh->mVertices[v].y * scale.y()),
                                          Real(mesh->mVertices[v].z * scale.z()));
      for (unsigned f = 0; f < mesh->mNumFaces; ++f)
        if (mesh->mFaces[f].mNumIndices == 3)
          result.mesh.triangles.push_back({first + mesh->mFaces[f].mIndices[0], first + mesh->mFaces[f].mIndices[1],
                                           first + mesh->mFaces[f].mIndices[2]});
    }
    return result;
  }
  return std::nullopt;
}

/// A body node that cannot move: its skeleton is immobile or only welds lead from it to the world
/// (an arm's base).
bool is_immobile(const BodyNode* node) {
  return !node->getSkeleton()->isMobile() || node->getNumDependentGenCoords() == 0;
}

const BodyNode* body_node_of(const dart::collision::CollisionObject* object) {
  const auto* shape_node = dynamic_cast<const ShapeNode*>(object->getShapeFrame());
  return shape_node ? shape_node->getBodyNodePtr().get() : nullptr;
}

/// Pairs the world never needs contacts for:
/// - what DART's own body-node filter skips (a robot's links against each other, unless its
///   self-collision check is on);
/// - two bodies that cannot move (a printed mesh lying on the floor, an arm's base on its table);
/// - a print nozzle and the printed material: the nozzle sits in the strand it is laying.
class WorldCollisionFilter : public dart::collision::CollisionFilter {
 public:
  WorldCollisionFilter(const std::set<const BodyNode*>* nozzles, const std::set<const dart::dynamics::Skeleton*>* printed,
                       const std::set<const BodyNode*>* wheels)
      : nozzles_(nozzles), printed_(printed), wheels_(wheels) {}

  bool ignoresCollision(const dart::collision::CollisionObject* object1,
                        const dart::collision::CollisionObject* object2) const override {
    if (body_node_filter_.ignoresCollision(object1, object2)) return true;
    const BodyNode* node1 = body_node_of(object1);
    const BodyNode* node2 = body_node_of(object2);
    if (!node1 || !node2) return false;
    if (is_immobile(node1) && is_immobile(node2)) return true;
    auto nozzle_in_print = [&](const BodyNode* nozzle, const BodyNode* other) {
      return nozzles_->count(nozzle) > 0 && printed_->count(other->getSkeleton().get()) > 0;
    };
    if (nozzle_in_print(node1, node2) || nozzle_in_print(node2, node1)) return true;
    // A diff-drive wheel on the floor: the planar joint carries the base (printed material still counts).
    auto wheel_on_floor = [&](const BodyNode* wheel, const BodyNode* other) {
      return wheels_->count(wheel) > 0 && is_immobile(other) && printed_->count(other->getSkeleton().get()) == 0;
    };
    return wheel_on_floor(node1, node2) || wheel_on_floor(node2, node1);
  }

 private:
  dart::collision::BodyNodeCollisionFilter body_node_filter_;
  const std::set<const BodyNode*>* nozzles_;
  const std::set<const dart::dynamics::Skeleton*>* printed_;
  const std::set<const BodyNode*>* wheels_;
};

constexpr std::size_t kNoRobot = std::numeric_limits<std::size_t>::max();

}  // namespace

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

World::World(const WorldSettings& settings) : impl_(std::make_unique<Impl>()) {
  impl_->world = dart::simulation::World::create("m3dp");
  impl_->world->setGravity(settings.gravity.cast<double>());
  impl_->world->setTimeStep(settings.time_step);
  impl_->max_time_step = settings.time_step;
  // Bullet handles mesh–primitive contacts more robustly than DART's default FCL.
  impl_->world->getConstraintSolver()->setCollisionDetector(dart::collision::BulletCollisionDetector::create());
  impl_->world->getConstraintSolver()->getCollisionOption().collisionFilter =
      std::make_shared<WorldCollisionFilter>(&impl_->nozzle_nodes, &impl_->printed_skeletons, &impl_->wheel_nodes);
}

World::~World() = default;

BodyIndex World::add_static_shape(const std::string& name, const Shape& shape, const Pose& pose) {
  using namespace dart::dynamics;
  auto skeleton = Skeleton::create(name);
  auto pair = skeleton->createJointAndBodyNodePair<WeldJoint>();
  pair.first->setTransformFromParentBodyNode(isometry_of(plane_pose(shape, pose)));
  pair.second->createShapeNodeWith<CollisionAspect, DynamicsAspect>(dart_shape_of(shape));
  skeleton->setMobile(false);
  impl_->world->addSkeleton(skeleton);
  impl_->bodies.push_back(skeleton);
  impl_->body_links.push_back(std::numeric_limits<LinkIndex>::max());
  return impl_->bodies.size() - 1;
}

BodyIndex World::add_rigid_body(const std::string& name, const std::vector<Shape>& shapes,
                                const std::vector<Pose>& shape_poses, double mass, const Pose& pose,
                                const std::optional<Mat3>& inertia_tensor) {
  using namespace dart::dynamics;
  if (!(mass > 0)) throw Error(fmt::format("world: rigid body '{}' needs a mass > 0 kg", name));
  if (shapes.empty() || shapes.size() != shape_poses.size())
    throw Error(fmt::format("world: rigid body '{}' needs at least one shape, each with a pose", name));
  auto skeleton = Skeleton::create(name);
  auto pair = skeleton->createJointAndBodyNodePair<FreeJoint>();
  std::vector<ShapePtr> dart_shapes;
  for (std::size_t s = 0; s < shapes.size(); ++s) {
    dart_shapes.push_back(dart_shape_of(shapes[s]));
    auto* shape_node = pair.second->createShapeNodeWith<CollisionAspect, DynamicsAspect>(dart_shapes.back());
    shape_node->setRelativeTransform(isometry_of(plane_pose(shapes[s], shape_poses[s])));
  }
  Inertia inertia;
  inertia.setMass(mass);
  inertia.setMoment(inertia_tensor ? Eigen::Matrix3d(inertia_tensor->cast<double>())
                                   : Eigen::Matrix3d(dart_shapes.front()->computeInertia(mass)));
  pair.second->setInertia(inertia);
  pair.first->setPositions(FreeJoint::convertToPositions(isometry_of(pose)));
  impl_->world->addSkeleton(skeleton);
  impl_->bodies.push_back(skeleton);
  impl_->links.push_back(Impl::Link{pair.second, name});
  impl_->body_links.push_back(impl_->links.size() - 1);
  ++impl_->rigid_bodies;
  return impl_->bodies.size() - 1;
}

void World::set_static_mesh(const std::string& name, const TriangleMesh& mesh) {
  using namespace dart::dynamics;
  if (const auto old = impl_->meshes.find(name); old != impl_->meshes.end()) {
    impl_->printed_skeletons.erase(old->second.get());
    impl_->world->removeSkeleton(old->second);
    impl_->meshes.erase(old);
    ++impl_->replacements;
  }
  if (mesh.triangles.empty()) return;
  auto skeleton = Skeleton::create(name);
  auto pair = skeleton->createJointAndBodyNodePair<WeldJoint>();
  pair.second->createShapeNodeWith<CollisionAspect, DynamicsAspect>(
      std::make_shared<dart::dynamics::MeshShape>(Eigen::Vector3d::Ones(), assimp_scene_of(mesh)));
  skeleton->setMobile(false);
  impl_->world->addSkeleton(skeleton);
  impl_->meshes[name] = skeleton;
  impl_->printed_skeletons.insert(skeleton.get());
}

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

std::size_t World::link_count() const { return impl_->links.size(); }

namespace {
LinkShapes shapes_of(const BodyNode& node, std::string name) {
  LinkShapes result;
  result.name = std::move(name);
  for (const ShapeNode* shape_node : node.getShapeNodesWith<dart::dynamics::CollisionAspect>()) {
    if (auto shape = m3dp_shape_of(*shape_node->getShape())) {
      result.shapes.push_back(std::move(*shape));
      result.poses.push_back(pose_of(shape_node->getRelativeTransform()));
    }
  }
  return result;
}
}  // namespace

LinkShapes World::link_shapes(LinkIndex link) const {
  const auto& record = impl_->links.at(link);
  return shapes_of(*record.node, record.name);
}

std::optional<Pose> World::robot_link_pose(RobotIndex robot, const std::string& link) const {
  const BodyNode* node = impl_->robots.at(robot).skeleton->getBodyNode(link);
  if (!node) return std::nullopt;
  return pose_of(node->getWorldTransform());
}

std::vector<std::pair<LinkShapes, Pose>> World::fixed_robot_links() const {
  std::vector<std::pair<LinkShapes, Pose>> links;
  for (const auto& robot : impl_->robots)
    for (std::size_t b = 0; b < robot.skeleton->getNumBodyNodes(); ++b) {
      const BodyNode* node = robot.skeleton->getBodyNode(b);
      if (node->getNumDependentGenCoords() != 0 || node->getShapeNodesWith<dart::dynamics::CollisionAspect>().empty()) continue;
      links.emplace_back(shapes_of(*node, robot.name + "/" + node->getName()), pose_of(node->getWorldTransform()));
    }
  return links;
}

Pose World::link_pose(LinkIndex link) const { return pose_of(impl_->links.at(link).node->getWorldTransform()); }

Vec3 World::link_linear_velocity(LinkIndex link) const {
  return impl_->links.at(link).node->getLinearVelocity().cast<Real>();
}

Vec3 World::link_angular_velocity(LinkIndex link) const {
  return impl_->links.at(link).node->getAngularVelocity().cast<Real>();
}

void World::set_link_wrench(LinkIndex link, const Vec3& force, const Vec3& torque) {
  auto& record = impl_->links.at(link);
  record.force = force;
  record.torque = torque;
}

bool World::link_feels_fluid(LinkIndex link) const { return impl_->links.at(link).feels_fluid; }

void World::set_feels_fluid(LinkIndex link, bool feels_fluid) { impl_->links.at(link).feels_fluid = feels_fluid; }

LinkIndex World::link_of_body(BodyIndex body) const {
  const LinkIndex link = impl_->body_links.at(body);
  if (link == std::numeric_limits<LinkIndex>::max()) throw Error("world: a static body has no link");
  return link;
}

void World::Impl::plan_chunk(double end_time) {
  for (Robot& robot : robots) {
    DartRobotIo io(*this, robot);
    robot.each_controller([&](Controller& controller) { controller.plan(io, end_time); });
  }
}

void World::Impl::control(double step, double chunk_fraction) {
  const double next_time = world->getTime() + step;
  for (Robot& robot : robots) {
    if (robot.drive) robot.drive->requested_speed = robot.drive->requested_turn = 0;  // stands, unless asked
    DartRobotIo io(*this, robot);
    robot.each_controller([&](Controller& controller) { controller.command(io, step, next_time, chunk_fraction); });
    if (robot.drive) drive_base(robot, step);
  }
  for (const Link& link : links) {
    if (link.force.isZero() && link.torque.isZero()) continue;
    link.node->addExtForce(link.force.cast<double>(), Eigen::Vector3d::Zero(), false, true);
    link.node->addExtTorque(link.torque.cast<double>(), false);
  }
}

void World::Impl::after_step() {
  count_contacts();
  for (Robot& robot : robots) {
    if (robot.drive) update_odometry(robot);
    DartRobotIo io(*this, robot);
    robot.each_controller([&](Controller& controller) { controller.after_step(io); });
  }
}

void World::Impl::end_chunk() {
  for (Robot& robot : robots) {
    DartRobotIo io(*this, robot);
    robot.each_controller([&](Controller& controller) { controller.end_chunk(io); });
  }
}

void World::Impl::count_contacts() {
  if (robots.empty()) return;
  touched.assign(robots.size(), 0);  // sized once: no allocation per step
  for (const auto& contact : world->getLastCollisionResult().getContacts()) {
    const BodyNode* nodes[2] = {body_node_of(contact.collisionObject1), body_node_of(contact.collisionObject2)};
    for (int side = 0; side < 2; ++side) {
      if (!nodes[side]) continue;
      const auto robot = robot_of_skeleton.find(nodes[side]->getSkeleton().get());
      if (robot == robot_of_skeleton.end()) continue;
      const BodyNode* other = nodes[1 - side];
      const bool other_robot =
          other && robot_of_skeleton.count(other->getSkeleton().get()) && other->getSkeleton() != nodes[side]->getSkeleton();
      const bool printed = other && printed_skeletons.count(other->getSkeleton().get());
      robots[robot->second].contacts.add(other_robot ? ContactWith::robot : printed ? ContactWith::printed_material : ContactWith::other);
      touched[robot->second] = true;
    }
  }
  for (std::size_t r = 0; r < robots.size(); ++r)
    if (touched[r]) ++robots[r].contacts.steps_in_contact;
}

World::Impl::Clearance::Proxy World::Impl::Clearance::proxy(std::shared_ptr<dart::dynamics::SimpleFrame> frame) const {
  Proxy proxy;
  proxy.group = detector->createCollisionGroupAsSharedPtr();
  proxy.group->addShapeFrame(frame.get());
  const auto& box = frame->getShape()->getBoundingBox();
  proxy.radius = std::max(box.getMin().norm(), box.getMax().norm());
  proxy.frame = std::move(frame);
  return proxy;
}

double World::Impl::Clearance::distance(const std::vector<Proxy>& first, const std::vector<Proxy>& second, bool with_tools,
                                        double enough) const {
  double best = std::numeric_limits<double>::infinity();
  const dart::collision::DistanceOption option(false, enough, nullptr);
  for (const Proxy& a : first) {
    if (a.tool && !with_tools) continue;
    const Eigen::Vector3d centre = a.frame->getWorldTransform().translation();
    for (const Proxy& b : second) {
      // Spheres about both that are already farther apart than the best: the shapes are too.
      if ((centre - b.frame->getWorldTransform().translation()).norm() - a.radius - b.radius >= best) continue;
      best = std::min(best, detector->distance(a.group.get(), b.group.get(), option));
      if (best <= enough) return best;
    }
  }
  return best;
}

World::Impl::Clearance& World::Impl::clearance_groups() const {
  if (clearance.detector) return clearance;
  auto detector = dart::collision::FCLCollisionDetector::create();
  // FCL's own boxes rather than DART's default 12-triangle meshes of them: the run with the
  // coordinator 9.2 s against 7.7 s (multi_robot_shared). DART warns on stderr that FCL's primitives
  // are incomplete for contact dynamics, which these queries are not: the warning is kept quiet.
  std::streambuf* standard_error = std::cerr.rdbuf(nullptr);
  detector->setPrimitiveShapeType(dart::collision::FCLCollisionDetector::PRIMITIVE);
  std::cerr.rdbuf(standard_error);  // and clears the stream's state
  clearance.detector = detector;
  // Each link's shapes as frames that move with it: boxes and spheres as they are, other shapes as
  // their bounding boxes (a cylinder's corners, a mesh's hull, a little larger than the shape): a
  // URDF's meshes and DART's tessellated cylinders cost FCL a hundred times more.
  for (const Robot& robot : robots) {
    std::vector<Clearance::Proxy> proxies;
    for (std::size_t b = 0; b < robot.skeleton->getNumBodyNodes(); ++b) {
      BodyNode* node = robot.skeleton->getBodyNode(b);
      for (auto* shape_node : node->getShapeNodesWith<dart::dynamics::CollisionAspect>()) {
        dart::dynamics::ShapePtr shape = shape_node->getShape();
        Eigen::Isometry3d placement = shape_node->getRelativeTransform();
        if (!shape->is<dart::dynamics::BoxShape>() && !shape->is<dart::dynamics::SphereShape>()) {
          const auto& box = shape->getBoundingBox();
          placement = placement * Eigen::Translation3d(box.computeCenter());
          shape = std::make_shared<dart::dynamics::BoxShape>(box.computeFullExtents().cwiseMax(1e-4));
        }
        auto frame = std::make_shared<dart::dynamics::SimpleFrame>(node, shape_node->getName() + "_clearance", placement);
        frame->setShape(shape);
        proxies.push_back(clearance.proxy(std::move(frame)));
        proxies.back().tool = nozzle_nodes.count(node) > 0;
      }
    }
    clearance.robots.push_back(std::move(proxies));
  }
  return clearance;
}

void World::place_robot(RobotIndex robot_index, const std::optional<Vec3>& base_x_y_heading,
                        const std::vector<std::pair<ToolIndex, ToolTarget>>& tool_targets) {
  auto& saved = impl_->clearance.saved_positions;
  if (saved.empty())
    for (const auto& robot : impl_->robots) saved.push_back(robot.skeleton->getPositions());
  Impl::Robot& robot = impl_->robots.at(robot_index);
  if (base_x_y_heading) {
    if (!robot.drive) throw Error(fmt::format("robot '{}' has no mobile base to place", robot.name));
    robot.drive->planar->setPositions(base_x_y_heading->cast<double>());
  }
  for (const auto& [tool_index, target] : tool_targets) {
    Impl::Tool& tool = impl_->tools.at(tool_index);
    auto ik = tool.end_effector->getIK();
    // A few rounds of the run's (10-iteration) IK: a placement may be centimetres from the last one.
    for (int round = 0; round < 3; ++round) {
      tool.target->setTransform(tool_target_transform(tool.end_effector->getWorldTransform(), target));
      ik->findSolution(tool.solution);
      ik->setPositions(tool.solution);
    }
  }
}

void World::restore_robots() {
  auto& saved = impl_->clearance.saved_positions;
  if (saved.empty()) return;
  for (std::size_t r = 0; r < impl_->robots.size(); ++r) impl_->robots[r].skeleton->setPositions(saved[r]);
  saved.clear();
}

Vec3 World::base_x_y_heading(RobotIndex robot) const {
  const auto& drive = impl_->robots.at(robot).drive;
  if (!drive) throw Error(fmt::format("robot '{}' has no mobile base", impl_->robots.at(robot).name));
  return drive->planar->getPositions().cast<Real>();
}

double World::robot_distance(RobotIndex first, RobotIndex second, double enough) const {
  const auto& groups = impl_->clearance_groups();
  return groups.distance(groups.robots.at(first), groups.robots.at(second), true, enough);
}

double World::print_distance(RobotIndex robot, double enough) const {
  const auto& groups = impl_->clearance_groups();
  return groups.distance(groups.robots.at(robot), groups.print_boxes, false, enough);
}

void World::set_print_boxes(const std::vector<Aabb>& boxes) {
  auto& groups = impl_->clearance_groups();
  groups.print_boxes.clear();
  for (const Aabb& box : boxes) {
    Eigen::Isometry3d centre = Eigen::Isometry3d::Identity();
    centre.translation() = ((box.min + box.max) / 2).cast<double>();
    auto frame = std::make_shared<dart::dynamics::SimpleFrame>(dart::dynamics::Frame::World(), "printed_material_box", centre);
    frame->setShape(std::make_shared<dart::dynamics::BoxShape>((box.max - box.min).cast<double>()));
    groups.print_boxes.push_back(groups.proxy(std::move(frame)));
  }
}

void World::step_to(double time) {
  const double remaining = time - impl_->world->getTime();
  if (remaining <= 1e-12) return;
  // Equal sub-steps no longer than the set time step that land exactly on `time`: the world and
  // the fluid keep one clock, and a fluid step's force acts for exactly that step's duration.
  const double longest = impl_->max_time_step;
  const auto steps = static_cast<long>(std::ceil(remaining / longest - 1e-9));
  const double step = remaining / static_cast<double>(steps);
  if (impl_->rigid_bodies == 0 && impl_->robots.empty()) {
    // Nothing can move: keep the clock, skip collision detection against static meshes.
    impl_->world->setTime(time);
    return;
  }
  impl_->world->setTimeStep(step);
  // A driving base moves the arm's frame during a chunk, which the IK (solved where the base is at
  // the chunk's start) cannot know: mobile manipulators solve every step.
  bool mobile_arm = false;
  for (const auto& robot : impl_->robots) mobile_arm |= robot.drive.has_value() && !robot.tools.empty();
  const long steps_per_chunk =
      mobile_arm ? 1L : std::max(1L, static_cast<long>(std::floor(impl_->ik_period / step + 1e-9)));
  for (long chunk_begin = 0; chunk_begin < steps; chunk_begin += steps_per_chunk) {
    const long chunk_steps = std::min(steps_per_chunk, steps - chunk_begin);
    impl_->plan_chunk(impl_->world->getTime() + static_cast<double>(chunk_steps) * step);
    for (long k = 1; k <= chunk_steps; ++k) {
      impl_->control(step, static_cast<double>(k) / static_cast<double>(chunk_steps));
      impl_->world->step();  // clears the commands and external forces: control() sets them every step
      impl_->after_step();
    }
    impl_->end_chunk();  // at the chunk's end, where the IK target is
  }
  impl_->world->setTime(time);  // no rounding drift between the two clocks
}

double World::time() const { return impl_->world->getTime(); }

namespace {
void put_vector(StateWriter& out, const Eigen::VectorXd& vector) {
  out.put(std::vector<double>(vector.data(), vector.data() + vector.size()));
}
/// `expected_size` < 0: any.
void get_vector(StateReader& in, Eigen::VectorXd& vector, Eigen::Index expected_size) {
  std::vector<double> values;
  in.get(values);
  if (expected_size >= 0 && static_cast<Eigen::Index>(values.size()) != expected_size)
    in.fail("a robot or body with another number of joints than the scene's");
  vector = Eigen::Map<const Eigen::VectorXd>(values.data(), static_cast<Eigen::Index>(values.size()));
}
}  // namespace

void World::save_state(StateWriter& out) const {
  out.section("world");
  out.put(impl_->world->getTime());
  auto put_skeleton = [&](const dart::dynamics::Skeleton& skeleton) {
    put_vector(out, skeleton.getPositions());
    put_vector(out, skeleton.getVelocities());
  };
  out.put(static_cast<std::uint64_t>(impl_->bodies.size()));
  for (const auto& body : impl_->bodies) put_skeleton(*body);
  out.put(static_cast<std::uint64_t>(impl_->links.size()));
  for (const auto& link : impl_->links) {
    out.put(link.force);
    out.put(link.torque);
  }
  out.put(static_cast<std::uint64_t>(impl_->robots.size()));
  for (const auto& robot : impl_->robots) {
    put_skeleton(*robot.skeleton);
    put_vector(out, robot.position_targets);
    out.put(robot.contacts);
    out.put(robot.drive.has_value());
    if (robot.drive) {
      const auto& drive = *robot.drive;
      out.put(std::array<double, 8>{drive.odometry_x, drive.odometry_y, drive.odometry_heading, drive.last_left, drive.last_right,
                                    drive.requested_speed, drive.requested_turn, drive.distance});
      out.put(drive.tracking);
    }
    for (const auto& controller : robot.controllers) controller->save(out);
  }
  out.put(static_cast<std::uint64_t>(impl_->tools.size()));
  for (const auto& tool : impl_->tools) {
    put_vector(out, tool.solution);
    out.put(tool.tracking);
  }
}

void World::load_state(StateReader& in) {
  in.section("world");
  const auto time = in.get<double>();
  auto get_skeleton = [&](dart::dynamics::Skeleton& skeleton) {
    Eigen::VectorXd positions, velocities;
    get_vector(in, positions, static_cast<Eigen::Index>(skeleton.getNumDofs()));
    get_vector(in, velocities, static_cast<Eigen::Index>(skeleton.getNumDofs()));
    skeleton.setPositions(positions);
    skeleton.setVelocities(velocities);
  };
  if (in.get<std::uint64_t>() != impl_->bodies.size()) in.fail("another number of bodies than the scene makes");
  for (const auto& body : impl_->bodies) get_skeleton(*body);
  if (in.get<std::uint64_t>() != impl_->links.size()) in.fail("another number of links than the scene makes");
  for (auto& link : impl_->links) {
    in.get(link.force);
    in.get(link.torque);
  }
  if (in.get<std::uint64_t>() != impl_->robots.size()) in.fail("another number of robots than the scene makes");
  for (auto& robot : impl_->robots) {
    get_skeleton(*robot.skeleton);
    get_vector(in, robot.position_targets, robot.position_targets.size());
    in.get(robot.contacts);
    if (in.get<bool>() != robot.drive.has_value()) in.fail("a mobile base where the scene has none, or none where it has one");
    if (robot.drive) {
      auto& drive = *robot.drive;
      const auto values = in.get<std::array<double, 8>>();
      drive.odometry_x = values[0], drive.odometry_y = values[1], drive.odometry_heading = values[2];
      drive.last_left = values[3], drive.last_right = values[4];
      drive.requested_speed = values[5], drive.requested_turn = values[6], drive.distance = values[7];
      in.get(drive.tracking);
    }
    for (const auto& controller : robot.controllers) controller->load(in);
  }
  if (in.get<std::uint64_t>() != impl_->tools.size()) in.fail("another number of tools than the scene makes");
  for (auto& tool : impl_->tools) {
    get_vector(in, tool.solution, -1);  // empty until the IK first solves
    in.get(tool.tracking);
  }
  impl_->world->setTime(time);
}

Pose World::pose(BodyIndex body) const {
  return pose_of(impl_->bodies.at(body)->getRootBodyNode()->getWorldTransform());
}

Vec3 World::linear_velocity(BodyIndex body) const {
  return impl_->bodies.at(body)->getRootBodyNode()->getLinearVelocity().cast<Real>();
}

void World::set_linear_velocity(BodyIndex body, const Vec3& velocity) {
  auto* joint = dynamic_cast<dart::dynamics::FreeJoint*>(impl_->bodies.at(body)->getRootJoint());
  if (!joint) throw Error("world: only a free rigid body can be given a velocity");
  joint->setLinearVelocity(velocity.cast<double>());
}

double World::mass(BodyIndex body) const { return impl_->bodies.at(body)->getMass(); }

std::size_t World::contact_count() const { return impl_->world->getLastCollisionResult().getNumContacts(); }

std::size_t World::mesh_replacements() const { return impl_->replacements; }

}  // namespace m3dp::world
