#include "m3dp/sim/presets.hpp"

#include <algorithm>
#include <cmath>

#include "m3dp/core/error.hpp"
#include "m3dp/toolpath/waypoints.hpp"

namespace m3dp::sim {

namespace {
scene::CollisionShape box_between(const std::string& name, const Vec3& min, const Vec3& max) {
  scene::CollisionShape collision;
  collision.name = name;
  collision.shape = BoxShape{max - min};
  collision.pose.position = (min + max) / 2;
  collision.where = SourceLocation{"<built in code>", 0};
  return collision;
}

scene::MaterialEntry water(Real viscosity) {
  scene::MaterialEntry entry;
  entry.material = material::newtonian("water", 1000, viscosity);
  entry.where = SourceLocation{"<built in code>", 0};
  return entry;
}

/// Open-top tank [0, length] × [0, depth] × [0, height] made of walls of thickness one particle diameter.
/// Floor and walls are separate bodies so the force on the floor can be read alone.
void add_tank(scene::Scene& scene, Real length, Real depth, Real height, Real thickness) {
  const Real t = thickness;
  scene.bodies.push_back({"floor", {box_between("floor", Vec3(-t, -t, -t), Vec3(length + t, depth + t, 0))}, {}});
  scene.bodies.push_back({"walls",
                          {box_between("left", Vec3(-t, -t, 0), Vec3(0, depth + t, height)),
                           box_between("right", Vec3(length, -t, 0), Vec3(length + t, depth + t, height)),
                           box_between("front", Vec3(0, -t, 0), Vec3(length, 0, height)),
                           box_between("back", Vec3(0, depth, 0), Vec3(length, depth + t, height))},
                          {}});
}
}  // namespace

Real dam_break_radius_for_count(std::size_t particle_count, Real column_width, Real depth) {
  const double volume = 2.0 * column_width * column_width * depth;
  const double diameter = std::cbrt(volume / static_cast<double>(particle_count));
  return static_cast<Real>(diameter / 2);
}

scene::Scene dam_break_scene(const DamBreakSetup& setup) {
  scene::Scene scene;
  scene.file = "dam_break (built in)";
  scene.world_name = "dam_break";
  scene.end_time = setup.end_time;
  const Real a = setup.column_width;
  const Real length = setup.tank_length_factor * a;
  const Real height = 3 * a;
  const Real diameter = 2 * setup.particle_radius;
  scene.solver.particle_radius = setup.particle_radius;
  scene.solver.kernel = setup.kernel;
  scene.solver.bounds.min = Vec3(-a, -a, -a);
  scene.solver.bounds.max = Vec3(length + a, setup.depth + a, 2 * height);
  scene.materials.push_back(water(setup.viscosity));
  add_tank(scene, length, setup.depth, height, diameter);
  scene::FluidBlock column;
  column.name = "column";
  column.material = "water";
  column.box.min = Vec3(0, 0, 0);
  column.box.max = Vec3(a, setup.depth, 2 * a);
  scene.fluid_blocks.push_back(column);
  scene.output.particles_period = Real(0.02);
  return scene;
}

namespace {
/// The clay_paste preset with its effective viscosity capped at `max_viscosity` (Pa·s).
scene::MaterialEntry clay_paste(Real max_viscosity) {
  const auto presets = scene::load_material_presets();
  const auto clay = std::find_if(presets.begin(), presets.end(), [](const scene::MaterialEntry& entry) {
    return entry.material.name == "clay_paste";
  });
  if (clay == presets.end()) throw Error("the material presets have no clay_paste");
  scene::MaterialEntry material = *clay;
  material.material.rheology.max_viscosity = max_viscosity;
  return material;
}

/// A nozzle named "nozzle" that an ideal gantry moves along `segment` from t = 0.
scene::PrintHead gantry_head(const std::string& material, Real inner_diameter, Real exit_speed, const toolpath::PathSegment& segment) {
  scene::PrintHead head;
  head.name = "nozzle";
  head.material = material;
  head.inner_diameter = inner_diameter;
  head.exit_speed = exit_speed;
  head.trajectory = toolpath::Trajectory({segment}, 0);
  head.where = SourceLocation{"<built in code>", 0};
  return head;
}
}  // namespace

scene::Scene clay_print_scene(const ClayPrintSetup& setup) {
  scene::Scene scene;
  scene.file = "clay_print (built in)";
  scene.world_name = "clay_print";
  scene.end_time = setup.end_time;
  const Real diameter = 2 * setup.particle_radius;
  scene.solver.particle_radius = setup.particle_radius;
  scene.solver.max_time_step = setup.time_step;
  // The bench times the viscous solve over every particle: the settled slab must not rest.
  scene.solver.rest_detection = false;
  // A slab 8 particles thick and twice as long as wide, holding about slab_particles.
  const Real thickness = 8 * diameter;
  const Real width = std::sqrt(Real(setup.slab_particles) * diameter * diameter * diameter / thickness / 2);
  const Real length = 2 * width;
  scene.solver.bounds.min = Vec3(-0.1f, -0.1f, -0.05f) - Vec3(0, width / 2, 0);
  scene.solver.bounds.max = Vec3(length + 0.1f, width / 2 + 0.1f, 0.2f);
  const scene::MaterialEntry material = clay_paste(setup.max_viscosity);
  scene.materials.push_back(material);
  scene.bodies.push_back({"floor", {box_between("floor", Vec3(-0.05f, -width / 2 - 0.05f, -diameter), Vec3(length + 0.05f, width / 2 + 0.05f, 0))}, {}});
  scene::FluidBlock slab;
  slab.name = "printed";
  slab.material = material.material.name;
  slab.box.min = Vec3(0, -width / 2, 0);
  slab.box.max = Vec3(length, width / 2, thickness);
  scene.fluid_blocks.push_back(slab);
  // A 10 mm nozzle lays a new strand along the slab's centre line, 8 mm above it.
  toolpath::PathSegment line;
  line.curve = toolpath::LineCurve{Vec3(0, 0, thickness + Real(0.008)), Vec3(length, 0, thickness + Real(0.008))};
  line.speed = Real(0.05);
  scene.print_heads.push_back(gantry_head(material.material.name, Real(0.01), Real(0.05), line));
  scene.output.write_particles = false;
  return scene;
}

scene::Scene wall_print_scene(const WallPrintSetup& setup) {
  scene::Scene scene;
  scene.file = "wall_print (built in)";
  scene.world_name = "wall_print";
  scene.solver.particle_radius = setup.particle_radius;
  const Real height = Real(setup.layers + 2) * setup.layer_height;
  scene.solver.bounds.min = Vec3(-0.1f, -0.1f, -0.05f);
  scene.solver.bounds.max = Vec3(setup.side + 0.1f, setup.side + 0.1f, height + 0.1f);
  scene.materials.push_back(clay_paste(setup.max_viscosity));
  scene.bodies.push_back({"floor", {box_between("floor", Vec3(-0.05f, -0.05f, -0.01f), Vec3(setup.side + 0.05f, setup.side + 0.05f, 0))}, {}});
  // A bead as wide as the nozzle and one layer high: U = V · (D h) / (π D²/4).
  const Real exit_speed = setup.nozzle_speed * setup.nozzle_diameter * setup.layer_height /
                          (kPi * setup.nozzle_diameter * setup.nozzle_diameter / 4);
  toolpath::PathSegment wall;
  wall.curve = toolpath::rectangle_wall(Vec3(0, 0, setup.layer_height), setup.side, setup.side, setup.layers, setup.layer_height);
  wall.speed = setup.nozzle_speed;
  scene.print_heads.push_back(gantry_head(scene.materials.front().material.name, setup.nozzle_diameter, exit_speed, wall));
  scene.end_time = scene.print_heads.back().trajectory.end_time() + 0.5;
  scene.output.write_particles = false;
  return scene;
}

scene::Scene hydrostatic_scene(const HydrostaticSetup& setup) {
  scene::Scene scene;
  scene.file = "hydrostatic (built in)";
  scene.world_name = "hydrostatic";
  scene.end_time = setup.end_time;
  const Real diameter = 2 * setup.particle_radius;
  scene.solver.particle_radius = setup.particle_radius;
  scene.solver.bounds.min = Vec3::Constant(-setup.width);
  scene.solver.bounds.max = Vec3(2 * setup.width, 2 * setup.width, 3 * setup.height);
  scene.materials.push_back(water(Real(1e-3)));
  add_tank(scene, setup.width, setup.width, Real(1.5) * setup.height, diameter);
  scene::FluidBlock block;
  block.name = "water";
  block.material = "water";
  block.box.min = Vec3::Zero();
  block.box.max = Vec3(setup.width, setup.width, setup.height);
  scene.fluid_blocks.push_back(block);
  scene.output.particles_period = Real(0.05);
  return scene;
}

material::Material bingham_test_paste() {
  material::Material paste = material::newtonian("paste", 1500, 0);
  paste.rheology.model = material::RheologyModel::bingham;
  paste.rheology.yield_stress = 150;
  paste.rheology.viscosity = 5;
  paste.sticks_to_walls = true;
  return paste;
}

scene::Scene paste_slab_scene(const PasteSlabSetup& setup) {
  scene::Scene scene;
  scene.file = "paste slab (built in)";
  scene.world_name = "paste_slab";
  scene.end_time = setup.end_time;
  scene.solver.particle_radius = setup.particle_radius;
  scene.solver.max_time_step = Real(2e-3);
  scene.solver.bounds.min = Vec3(-0.3f, -0.3f, -0.1f);
  scene.solver.bounds.max = Vec3(0.3f, 0.3f, 0.6f);
  scene.materials.push_back(scene::MaterialEntry{bingham_test_paste(), {}});
  scene.bodies.push_back(scene::StaticBody{
      "floor", {scene::CollisionShape{"floor", BoxShape{Vec3(0.4f, 0.4f, 0.02f)}, Pose{Vec3(0, 0, -0.01f), Quat::Identity()}, {}}}, {}});
  scene::FluidBlock slab;
  slab.name = "slab";
  slab.material = "paste";
  slab.box.min = Vec3(-setup.half_width, -setup.half_width, 0);
  slab.box.max = Vec3(setup.half_width, setup.half_width, setup.height);
  scene.fluid_blocks.push_back(slab);
  scene.output.write_particles = false;
  return scene;
}

}  // namespace m3dp::sim
