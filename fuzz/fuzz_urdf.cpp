// The URDF path a scene's robot takes: the scene reader's check of the URDF at its own lines, then,
// if it passes, DART's loader (urdfdom) through World::add_robot. What the check lets through, DART
// must load or refuse with an m3dp::Error naming the file: a crash or an abort inside DART is a
// finding against the check.
#include "fuzz/fuzz_input.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/world/world.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto urdf = m3dp::fuzz::as_file(data, size, "urdf");
  const std::string scene = R"(<?xml version="1.0"?>
<sdf version="1.9"><world name="fuzz">
  <include><uri>file://)" + urdf.string() + R"(</uri><name>robot</name></include>
  <plugin name="m3dp" filename="m3dp">
    <solver><particle_radius>0.01</particle_radius><end_time>0.1</end_time>
      <bounds><min>-2 -2 -1</min><max>2 2 2</max></bounds></solver>
    <material name="water"><density>1000</density><viscosity>0.001</viscosity></material>
    <fluid_block name="water" material="water"><min>1 1 0</min><max>1.05 1.05 0.05</max></fluid_block>
  </plugin>
</world></sdf>
)";
  m3dp::fuzz::expect_clear_error_or_success([&] {
    const m3dp::scene::Scene loaded = m3dp::scene::load_scene_from_string(scene, "fuzz.sdf");
    m3dp::world::World world;
    for (const auto& robot : loaded.robots) (void)world.add_robot({robot.name, robot.urdf_file, robot.pose, {}});
  });
  return 0;
}
