#pragma once
// The scene's robots in the world: the one place they are loaded, by the simulation and by
// `m3dp validate` (whose check then is what a run would do).
#include <optional>
#include <vector>

#include "m3dp/scene/scene.hpp"
#include "m3dp/world/world.hpp"

namespace m3dp::sim {

/// A robot's clock for its paths: the time its base and tool paths are sampled at ("plan time"),
/// which runs at `rate` times the world's clock: 1 unless the coordinator slows (0 < rate < 1) or
/// stops (0) the robot. Piecewise linear in world time, so the world's sub-steps sample it exactly.
struct PlanClock {
  double world_time0 = 0, plan_time0 = 0;  // s: a point of the clock
  double rate = 1;
  [[nodiscard]] double at(double world_time) const { return plan_time0 + rate * (world_time - world_time0); }
  /// From `world_time` on, the clock runs at `new_rate`.
  void set_rate(double world_time, double new_rate) {
    plan_time0 = at(world_time);
    world_time0 = world_time;
    rate = new_rate;
  }
};

/// The scene's plans as a run starts them: each print head's path, and each robot's base path (none
/// without a mobile base or a path).
std::vector<toolpath::Trajectory> scene_head_paths(const scene::Scene& scene);
std::vector<std::optional<toolpath::Trajectory>> scene_base_paths(const scene::Scene& scene);

/// Loads every robot of the scene: its URDF (an error names the scene line that included it as
/// well as the URDF's), its mobile base as a differential drive following its base path, its initial
/// joint positions. Returns the world's robot for each, in scene order. Bases follow `base_paths`
/// (one per scene robot), sampled at `clocks[robot]`; both must outlive the world's use of them.
std::vector<world::RobotIndex> add_scene_robots(const scene::Scene& scene, world::World& world,
                                                const std::vector<PlanClock>& clocks,
                                                const std::vector<std::optional<toolpath::Trajectory>>& base_paths);

/// Every print head a robot carries, as a tool on its link that follows the head's path by IK (with
/// its barrel `particle_diameter` short of the exit, so the first layer is never blocked by it). One
/// entry per print head: none for a head on an ideal gantry. `head_paths` (one per head) must outlive
/// the world's use of them.
std::vector<std::optional<world::ToolIndex>> add_print_head_tools(const scene::Scene& scene, world::World& world,
                                                                  const std::vector<world::RobotIndex>& robots,
                                                                  Real particle_diameter, const std::vector<PlanClock>& clocks,
                                                                  const std::vector<toolpath::Trajectory>& head_paths);
/// A base path as the world follows it: sampled at the robot's plan clock (both must outlive it).
world::BaseTrajectory clocked_base_path(const toolpath::Trajectory& path, const PlanClock& clock);
/// The scene robot (scene order) that carries a print head; none for a head on an ideal gantry.
std::optional<std::size_t> robot_of_print_head(const scene::Scene& scene, std::size_t head);

}  // namespace m3dp::sim
