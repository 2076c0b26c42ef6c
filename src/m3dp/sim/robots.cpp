#include "m3dp/sim/robots.hpp"

#include <fmt/format.h>

#include "m3dp/core/error.hpp"

namespace m3dp::sim {

std::vector<toolpath::Trajectory> scene_head_paths(const scene::Scene& scene) {
  std::vector<toolpath::Trajectory> paths;
  for (const auto& head : scene.print_heads) paths.push_back(head.trajectory);
  return paths;
}

std::vector<std::optional<toolpath::Trajectory>> scene_base_paths(const scene::Scene& scene) {
  std::vector<std::optional<toolpath::Trajectory>> paths;
  for (const auto& robot : scene.robots) paths.push_back(robot.mobile_base ? robot.mobile_base->path : std::nullopt);
  return paths;
}

std::vector<world::RobotIndex> add_scene_robots(const scene::Scene& scene, world::World& world,
                                                const std::vector<PlanClock>& clocks,
                                                const std::vector<std::optional<toolpath::Trajectory>>& base_paths) {
  std::vector<world::RobotIndex> robots;
  for (std::size_t r = 0; r < scene.robots.size(); ++r) {
    const auto& robot = scene.robots[r];
    world::RobotDescription description;
    description.name = robot.name;
    description.urdf_file = robot.urdf_file;
    description.base_pose = robot.pose;
    world::RobotIndex index = 0;
    try {
      index = world.add_robot(description);
    } catch (const InputError& error) {
      // Name the scene line that included the robot too.
      std::vector<Diagnostic> diagnostics = error.diagnostics();
      diagnostics.push_back(Diagnostic{robot.where, fmt::format("robot '{}' included here could not be loaded", robot.name)});
      throw InputError(std::move(diagnostics));
    }
    if (robot.mobile_base) {
      const auto& base = *robot.mobile_base;
      world.make_diff_drive(index, world::DiffDriveDescription{base.left_wheel_joint, base.right_wheel_joint,
                                                                base.wheel_radius, base.wheel_separation, 0});
      if (const auto& path = base_paths.at(r)) world.set_base_trajectory(index, clocked_base_path(*path, clocks.at(r)));
    }
    if (!robot.initial_joint_positions.empty()) {
      const auto names = world.joint_names(index);
      std::vector<double> positions = world.joint_positions(index);
      for (const auto& [joint, value] : robot.initial_joint_positions)
        for (std::size_t k = 0; k < names.size(); ++k)
          if (names[k] == joint) positions[k] = value;
      world.set_joint_positions(index, positions);
    }
    robots.push_back(index);
  }
  return robots;
}

std::vector<std::optional<world::ToolIndex>> add_print_head_tools(const scene::Scene& scene, world::World& world,
                                                                  const std::vector<world::RobotIndex>& robots,
                                                                  Real particle_diameter, const std::vector<PlanClock>& clocks,
                                                                  const std::vector<toolpath::Trajectory>& head_paths) {
  std::vector<std::optional<world::ToolIndex>> head_tools;
  for (std::size_t h = 0; h < scene.print_heads.size(); ++h) {
    const auto& head = scene.print_heads[h];
    if (!head.mount) {
      head_tools.emplace_back();
      continue;
    }
    const std::size_t robot = *robot_of_print_head(scene, h);
    world::ToolDescription tool;
    tool.name = head.name;
    tool.link = head.mount->link;
    tool.offset = head.mount->offset;
    tool.body_radius = head.mount->barrel_radius;
    // The barrel ends a particle diameter before the exit, so the first layer is never blocked by it,
    // or above a bore, whose walls the engine carries (sph::NozzleSettings::bore_length).
    tool.body_clearance = particle_diameter + head.bore_length;
    const world::ToolIndex index = world.add_tool(robots[robot], tool);
    const toolpath::Trajectory* trajectory = &head_paths.at(h);
    const Vec3 axis = head.direction.normalized();
    const PlanClock* clock = &clocks.at(robot);
    world.set_tool_trajectory(index, [trajectory, axis, clock](double time) {
      return world::ToolTarget{trajectory->sample(clock->at(time)).position, axis};
    });
    head_tools.emplace_back(index);
  }
  return head_tools;
}

world::BaseTrajectory clocked_base_path(const toolpath::Trajectory& path, const PlanClock& clock) {
  return [path = &path, clock = &clock](double time) { return path->sample(clock->at(time)).position; };
}

std::optional<std::size_t> robot_of_print_head(const scene::Scene& scene, std::size_t head) {
  const auto& mount = scene.print_heads.at(head).mount;
  if (!mount) return std::nullopt;
  for (std::size_t robot = 0; robot < scene.robots.size(); ++robot)
    if (scene.robots[robot].name == mount->robot) return robot;
  return std::nullopt;  // the scene loader checked that it exists
}

}  // namespace m3dp::sim
