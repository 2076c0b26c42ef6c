// The world: static shapes and free bodies, the links the fluid sees, stepping and its controllers'
// chunks, contacts and checkpoints (robots: world_robots.cpp; clearance queries: world_clearance.cpp).
#include "m3dp/world/world_impl.hpp"

namespace m3dp::world {

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

namespace {



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
