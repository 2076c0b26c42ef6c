#include "m3dp/sim/world_view.hpp"

#include <algorithm>
#include <set>

#include "m3dp/core/tessellation.hpp"

namespace m3dp::sim {

const char* body_kind_name(BodyKind kind) {
  switch (kind) {
    case BodyKind::static_body: return "static";
    case BodyKind::free_body: return "body";
    case BodyKind::robot_link: return "link";
  }
  return "static";
}

namespace {

TriangleMesh shapes_triangles(const std::vector<Shape>& shapes, const std::vector<Pose>& poses) {
  TriangleMesh triangles;
  for (std::size_t s = 0; s < shapes.size(); ++s) append_transformed(tessellate(shapes[s]), poses.at(s), triangles);
  return triangles;
}

}  // namespace

WorldLayout world_layout(const Simulation& simulation, Real max_chord) {
  const auto& scene = simulation.scene();
  const auto& world = simulation.world();
  WorldLayout layout;
  for (const auto& body : scene.bodies)
    for (const auto& collision : body.collisions)
      layout.bodies.push_back({collision.name, BodyKind::static_body, std::nullopt, "",
                               shapes_triangles({collision.shape}, {collision.pose}), Pose{}});
  std::set<world::LinkIndex> free_links;
  for (const world::BodyIndex body : simulation.dynamic_bodies()) free_links.insert(world.link_of_body(body));
  for (world::LinkIndex link = 0; link < world.link_count(); ++link) {
    const world::LinkShapes shapes = world.link_shapes(link);
    BodyView view{shapes.name, free_links.contains(link) ? BodyKind::free_body : BodyKind::robot_link, link, "",
                  shapes_triangles(shapes.shapes, shapes.poses), Pose{}};
    if (view.kind == BodyKind::robot_link) view.robot = shapes.name.substr(0, shapes.name.find('/'));
    layout.bodies.push_back(std::move(view));
  }
  for (auto& [shapes, pose] : world.fixed_robot_links()) {
    BodyView view{shapes.name, BodyKind::robot_link, std::nullopt, shapes.name.substr(0, shapes.name.find('/')),
                  shapes_triangles(shapes.shapes, shapes.poses), pose};
    layout.bodies.push_back(std::move(view));
  }
  for (const auto& head : scene.print_heads) {
    NozzleView nozzle{head.name, "world", head.inner_diameter, {}};
    if (head.mount) {
      const std::string link_name = head.mount->robot + "/" + head.mount->link;
      if (std::any_of(layout.bodies.begin(), layout.bodies.end(), [&](const BodyView& body) { return body.name == link_name; }))
        nozzle.parent_frame = link_name;
    }
    // A tube of 1.5 inner diameters outside, 4 long, ending at the exit (material leaves along −z).
    const Real length = 4 * head.inner_diameter;
    Pose tube;
    tube.position = Vec3(0, 0, length / 2);
    nozzle.triangles = shapes_triangles({CylinderShape{Real(0.75) * head.inner_diameter, length}}, {tube});
    layout.nozzles.push_back(std::move(nozzle));
    layout.paths.push_back({head.name, false, head.trajectory.polyline(max_chord), layout.nozzles.size() - 1});
  }
  for (std::size_t r = 0; r < scene.robots.size(); ++r) {
    const auto& robot = scene.robots[r];
    if (robot.mobile_base && robot.mobile_base->path)
      layout.paths.push_back({robot.name, true, robot.mobile_base->path->polyline(max_chord), r});
  }
  return layout;
}

WorldPoses world_poses(const Simulation& simulation, const WorldLayout& layout) {
  WorldPoses poses;
  poses.time = simulation.time();
  poses.bodies.reserve(layout.bodies.size());
  for (const auto& body : layout.bodies) poses.bodies.push_back(body.link ? simulation.world().link_pose(*body.link) : body.fixed_pose);
  for (std::size_t head = 0; head < layout.nozzles.size(); ++head) poses.nozzles.push_back(simulation.nozzle_state(head));
  for (const auto& path : layout.paths)
    poses.path_times.push_back(path.base_path ? simulation.plan_clock(path.index).at(poses.time) : simulation.path_time(path.index));
  return poses;
}

std::vector<std::vector<Vec3>> printed_runs(const PathView& path, double time) {
  std::vector<std::vector<Vec3>> runs;
  bool in_run = false;
  const auto& vertices = path.vertices;
  for (std::size_t v = 0; v < vertices.size() && vertices[v].time <= time; ++v) {
    if (in_run) runs.back().push_back(vertices[v].position);  // the run's last move ends here
    if (vertices[v].extruding && !in_run) runs.emplace_back(1, vertices[v].position);
    in_run = vertices[v].extruding;
    // Part way along an extruding move: the run ends where the head is on it now.
    if (in_run && v + 1 < vertices.size() && vertices[v + 1].time > time) {
      const double span = vertices[v + 1].time - vertices[v].time;
      const Real along = span > 0 ? static_cast<Real>((time - vertices[v].time) / span) : Real(0);
      runs.back().push_back(vertices[v].position + along * (vertices[v + 1].position - vertices[v].position));
    }
  }
  std::erase_if(runs, [](const std::vector<Vec3>& run) { return run.size() < 2; });
  return runs;
}

}  // namespace m3dp::sim
