// The only translation unit that includes DART.
#include "m3dp/world/world.hpp"

#include <assimp/scene.h>
#include <dart/collision/bullet/BulletCollisionDetector.hpp>
#include <dart/dart.hpp>

#include <fmt/format.h>

#include <cmath>
#include <map>
#include <variant>

#include "m3dp/core/error.hpp"

namespace m3dp::world {

namespace {

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

/// Bodies that cannot move never need contacts between themselves: skipping them keeps a printed
/// mesh lying on the floor from costing a mesh–box contact query every step.
class SkipImmobilePairs : public dart::collision::CollisionFilter {
 public:
  bool ignoresCollision(const dart::collision::CollisionObject* object1,
                        const dart::collision::CollisionObject* object2) const override {
    auto immobile = [](const dart::collision::CollisionObject* object) {
      const auto* shape_node = dynamic_cast<const dart::dynamics::ShapeNode*>(object->getShapeFrame());
      return shape_node != nullptr && !shape_node->getSkeleton()->isMobile();
    };
    return immobile(object1) && immobile(object2);
  }
};

}  // namespace

struct World::Impl {
  dart::simulation::WorldPtr world;
  std::vector<dart::dynamics::SkeletonPtr> bodies;
  std::map<std::string, dart::dynamics::SkeletonPtr> meshes;
  std::size_t replacements = 0;
  std::size_t rigid_bodies = 0;
};

World::World(const WorldSettings& settings) : impl_(std::make_unique<Impl>()) {
  impl_->world = dart::simulation::World::create("m3dp");
  impl_->world->setGravity(settings.gravity.cast<double>());
  impl_->world->setTimeStep(settings.time_step);
  // Bullet handles mesh–primitive contacts more robustly than DART's default FCL.
  impl_->world->getConstraintSolver()->setCollisionDetector(dart::collision::BulletCollisionDetector::create());
  impl_->world->getConstraintSolver()->getCollisionOption().collisionFilter = std::make_shared<SkipImmobilePairs>();
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
  return impl_->bodies.size() - 1;
}

BodyIndex World::add_rigid_body(const std::string& name, const Shape& shape, double mass, const Pose& pose) {
  using namespace dart::dynamics;
  if (!(mass > 0)) throw Error(fmt::format("world: rigid body '{}' needs a mass > 0 kg", name));
  auto skeleton = Skeleton::create(name);
  auto pair = skeleton->createJointAndBodyNodePair<FreeJoint>();
  const ShapePtr dart_shape = dart_shape_of(shape);
  pair.second->createShapeNodeWith<CollisionAspect, DynamicsAspect>(dart_shape);
  Inertia inertia;
  inertia.setMass(mass);
  inertia.setMoment(dart_shape->computeInertia(mass));
  pair.second->setInertia(inertia);
  pair.first->setPositions(FreeJoint::convertToPositions(isometry_of(pose)));
  impl_->world->addSkeleton(skeleton);
  impl_->bodies.push_back(skeleton);
  ++impl_->rigid_bodies;
  return impl_->bodies.size() - 1;
}

void World::set_static_mesh(const std::string& name, const TriangleMesh& mesh) {
  using namespace dart::dynamics;
  if (const auto old = impl_->meshes.find(name); old != impl_->meshes.end()) {
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
}

void World::step_to(double time) {
  const double step = impl_->world->getTimeStep();
  if (impl_->rigid_bodies == 0) {
    // Nothing can move: keep the clock, skip collision detection against static meshes.
    while (impl_->world->getTime() + 0.5 * step <= time) impl_->world->setTime(impl_->world->getTime() + step);
    return;
  }
  while (impl_->world->getTime() + 0.5 * step <= time) impl_->world->step();
}

double World::time() const { return impl_->world->getTime(); }

Pose World::pose(BodyIndex body) const {
  const Eigen::Isometry3d transform = impl_->bodies.at(body)->getRootBodyNode()->getWorldTransform();
  Pose pose;
  pose.position = transform.translation().cast<Real>();
  pose.orientation = Quat(transform.linear().cast<Real>());
  return pose;
}

Vec3 World::linear_velocity(BodyIndex body) const {
  return impl_->bodies.at(body)->getRootBodyNode()->getLinearVelocity().cast<Real>();
}

std::size_t World::contact_count() const { return impl_->world->getLastCollisionResult().getNumContacts(); }

std::size_t World::mesh_replacements() const { return impl_->replacements; }

}  // namespace m3dp::world
