// The multi-robot coordinator's queries: robots placed where they would be, and FCL distances
// between their links' shapes and to the printed material's boxes.
#include "m3dp/world/world_impl.hpp"

namespace m3dp::world {

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


}  // namespace m3dp::world
