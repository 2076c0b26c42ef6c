#pragma once
// The scene's robots in the world: the one place they are loaded, by the simulation and by
// `m3dp validate` (whose check then is what a run would do).
#include <optional>
#include <vector>

#include "m3dp/scene/scene.hpp"
#include "m3dp/world/world.hpp"

namespace m3dp::sim {

/// Loads every robot of the scene: its URDF (an error names the scene line that included it as
/// well as the URDF's), its mobile base as a differential drive following its base path, its initial
/// joint positions. Returns the world's robot for each, in scene order.
std::vector<world::RobotIndex> add_scene_robots(const scene::Scene& scene, world::World& world);

/// Every print head a robot carries, as a tool on its link that follows the head's path by IK (with
/// its barrel `particle_diameter` short of the exit, so the first layer is never blocked by it). One
/// entry per print head: none for a head on an ideal gantry.
std::vector<std::optional<world::ToolIndex>> add_print_head_tools(const scene::Scene& scene, world::World& world,
                                                                  const std::vector<world::RobotIndex>& robots,
                                                                  Real particle_diameter);

}  // namespace m3dp::sim
