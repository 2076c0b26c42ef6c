// Two-way coupling of rigid bodies and robots with the fluid (Akinci et al. 2012): buoyancy,
// action and reaction, and a robot link that meets the fluid.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "m3dp/sim/presets.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/simulation.hpp"

using namespace m3dp;

namespace {
/// The water level (m) from the particles at least `clearance` from the box's axis: the mean height
/// of the highest particle in each column of the lattice, plus a particle radius.
Real water_level(const sph::Solver& solver, const Vec3& box_centre, Real clearance) {
  const Real diameter = solver.particle_diameter();
  std::map<std::pair<int, int>, Real> column_top;
  for (const Vec3& p : solver.fluid().position) {
    if (std::max(std::abs(p.x() - box_centre.x()), std::abs(p.y() - box_centre.y())) < clearance) continue;
    const auto key = std::make_pair(int(std::floor(p.x() / diameter)), int(std::floor(p.y() / diameter)));
    auto [it, inserted] = column_top.emplace(key, p.z());
    if (!inserted) it->second = std::max(it->second, p.z());
  }
  double sum = 0;
  for (const auto& [key, top] : column_top) sum += top;
  return Real(sum / double(column_top.size())) + solver.parameters().settings.particle_radius;
}
}  // namespace

TEST(Coupling, FloatingBoxSettlesAtTheArchimedesDepth) {
  // A 0.2 × 0.2 × 0.1 m box of density 600 kg/m³ dropped onto water floats with 60 % of its height
  // under the water line (Archimedes: depth = ρ_box/ρ_water · h = 0.06 m). Flat, so it floats
  // upright (metacentric height 36 mm; a cube of this density would tip onto an edge).
  sim::HydrostaticSetup setup;
  setup.width = Real(0.36);
  setup.height = Real(0.1);
  setup.particle_radius = Real(0.006);
  setup.end_time = 2.0;
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.output.write_particles = false;
  const Real edge = Real(0.1), width = Real(0.2), box_density = 600;
  scene::DynamicBody box;
  box.name = "box";
  box.collisions.push_back(scene::CollisionShape{"box/link/box", BoxShape{Vec3(width, width, edge)}, Pose{}, {}});
  box.pose.position = Vec3(0.18f, 0.18f, setup.height + edge / 2 + 0.01f);
  box.mass = box_density * width * width * edge;
  scene.dynamic_bodies.push_back(box);
  sim::Simulation simulation(scene);
  ASSERT_EQ(simulation.coupling().coupled_links(), 1u);
  const auto body = simulation.dynamic_bodies().front();

  // The box bobs with a period of about 2π √(depth/g) ≈ 0.5 s and little damping: average its height
  // over the last second.
  double height_sum = 0, level_sum = 0;
  int samples = 0;
  while (simulation.time() < setup.end_time) {
    simulation.step();
    if (simulation.time() > setup.end_time - 1.0) {
      const Vec3 centre = simulation.world().pose(body).position;
      height_sum += centre.z();
      level_sum += water_level(simulation.solver(), centre, Real(0.12));
      ++samples;
    }
  }
  const double centre_z = height_sum / samples, level = level_sum / samples;
  const double depth = level - (centre_z - edge / 2);
  const double expected = box_density / 1000.0 * edge;
  std::printf("floating box: water level %.4f m, box bottom %.4f m, depth %.4f m vs Archimedes %.4f m (%+.1f %%, "
              "tolerance 5 %%); upright: %.4f\n",
              level, centre_z - edge / 2, depth, expected, 100 * (depth / expected - 1),
              simulation.world().pose(body).rotate(Vec3::UnitZ()).z());
  EXPECT_NEAR(depth, expected, 0.05 * expected);
  EXPECT_GT(simulation.world().pose(body).rotate(Vec3::UnitZ()).z(), 0.99);
  // The drop may throw a droplet over the tank's edge (the splash differs from run to run with the
  // order in which threads add up the body forces); the water itself stays.
  EXPECT_LE(simulation.solver().state().particles_removed_total, simulation.solver().fluid().size() / 1000);
}

TEST(Coupling, MomentumOfFluidAndBodyIsConserved) {
  // No gravity, no walls: a 0.5 kg box at 0.5 m/s runs into a 1 kg cube of water at rest. Whatever
  // the fluid takes, the box loses: the pressure forces on its boundary particles act back on it.
  scene::Scene scene;
  scene.file = "momentum (built in)";
  scene.end_time = 0.5;
  scene.solver.particle_radius = Real(0.005);
  scene.solver.gravity = Vec3::Zero();
  scene.solver.bounds.min = Vec3::Constant(-1);
  scene.solver.bounds.max = Vec3::Constant(1);
  scene.materials.push_back(scene::MaterialEntry{material::newtonian("water", 1000, Real(1e-3)), {}});
  scene::FluidBlock block;
  block.name = "water";
  block.material = "water";
  block.box.min = Vec3::Constant(-0.05f);
  block.box.max = Vec3::Constant(0.05f);
  scene.fluid_blocks.push_back(block);
  scene.output.write_particles = false;
  scene::DynamicBody box;
  box.name = "box";
  box.collisions.push_back(scene::CollisionShape{"box/link/box", BoxShape{Vec3::Constant(0.06f)}, Pose{}, {}});
  box.pose.position = Vec3(-0.1f, 0, 0);
  box.mass = 0.5;
  scene.dynamic_bodies.push_back(box);
  sim::Simulation simulation(scene);
  const auto body = simulation.dynamic_bodies().front();
  simulation.world().set_linear_velocity(body, Vec3(0.5f, 0, 0));

  auto momentum = [&] {
    Eigen::Vector3d fluid = Eigen::Vector3d::Zero();
    const auto& particles = simulation.solver().fluid();
    for (std::size_t i = 0; i < particles.size(); ++i) fluid += particles.mass[i] * particles.velocity[i].cast<double>();
    const Eigen::Vector3d body_momentum = 0.5 * simulation.world().linear_velocity(body).cast<double>();
    return std::make_pair(fluid, body_momentum);
  };
  const auto [fluid_before, body_before] = momentum();
  while (simulation.time() < scene.end_time) simulation.step();
  const auto [fluid_after, body_after] = momentum();
  const double before = (fluid_before + body_before).x(), after = (fluid_after + body_after).x();
  std::printf("momentum x (kg m/s): before %.4f (box %.4f), after %.4f (box %.4f, fluid %.4f): %+.2f %%; |p_y|+|p_z| %.2e\n",
              before, body_before.x(), after, body_after.x(), fluid_after.x(), 100 * (after / before - 1),
              std::abs((fluid_after + body_after).y()) + std::abs((fluid_after + body_after).z()));
  EXPECT_GT(fluid_after.x(), 0.2 * before);  // the box really pushed the water
  EXPECT_NEAR(after, before, 0.03 * before);
}

TEST(Coupling, RobotNozzleDippedIntoWaterFeelsItAndHoldsItsPath) {
  // A UR10 lowers a 20 mm-radius nozzle barrel at 0.4 m/s into a tank of water and holds
  // it there. The fluid pushes back up on the barrel (buoyancy of the part under water, plus drag
  // on the way down); the arm's joint servos keep the nozzle on its path regardless.
  sim::HydrostaticSetup setup;
  setup.width = Real(0.2);
  setup.height = Real(0.1);
  setup.particle_radius = Real(0.005);
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.end_time = 1.6;
  scene.output.write_particles = false;
  // The tank's corner is at the origin: put the robot so that its nozzle starts above the tank centre.
  scene::RobotInclude robot;
  robot.name = "ur10";
  robot.urdf_file = std::filesystem::path(M3DP_MODELS) / "ur10" / "ur10.urdf";
  robot.pose.position = Vec3(0.1f - 0.775f, 0.1f - 0.164f, 0.25f);
  robot.initial_joint_positions = {{"shoulder_lift_joint", -1.2}, {"elbow_joint", 1.9}, {"wrist_1_joint", -2.27},
                                   {"wrist_2_joint", -1.5708}};
  scene.robots.push_back(robot);
  scene::PrintHead head;
  head.name = "nozzle";
  head.material = "water";
  head.inner_diameter = Real(0.012);
  scene::NozzleMount mount;
  mount.robot = "ur10";
  mount.link = "tool0";
  mount.offset.position = Vec3(0, 0, 0.15f);
  mount.barrel_radius = Real(0.02);
  head.mount = mount;
  const Vec3 start(0.1f, 0.1f, 0.25f + 0.0867f), bottom(0.1f, 0.1f, 0.04f);
  head.trajectory = toolpath::Trajectory({toolpath::PathSegment{toolpath::PolylineCurve{{start, start}}, Real(0.1), false, Real(0.2)},
                                          toolpath::PathSegment{toolpath::PolylineCurve{{start, bottom}}, Real(0.4), false},
                                          toolpath::PathSegment{toolpath::PolylineCurve{{bottom, bottom}}, Real(0.1), false, Real(1)}},
                                         0.0);
  scene.print_heads.push_back(head);
  sim::Simulation simulation(scene);
  const auto tool = *simulation.print_head_tool(0);
  std::printf("nozzle starts at (%.3f %.3f %.3f)\n", simulation.world().tool_pose(tool).position.x(),
              simulation.world().tool_pose(tool).position.y(), simulation.world().tool_pose(tool).position.z());

  // The barrel: the last link the coupling sampled.
  const Index barrel = Index(simulation.solver().bodies().size() - 1);
  ASSERT_EQ(simulation.solver().bodies()[barrel].name, "ur10/nozzle");
  double hold_force_sum = 0, descent_force_max = 0;
  int hold_samples = 0;
  while (simulation.time() < scene.end_time) {
    simulation.step();
    const double force_z = simulation.solver().bodies()[barrel].fluid_force.z();
    if (simulation.time() < 1.4) descent_force_max = std::max(descent_force_max, force_z);
    if (simulation.time() > 1.2) {
      hold_force_sum += force_z;
      ++hold_samples;
    }
  }
  const double hold_force = hold_force_sum / hold_samples;
  // Under water: from the barrel's end (one particle diameter above the exit at z = 0.04 m) to the
  // water line, which the barrel itself raises a little.
  const double level = setup.height / (1 - kPi * 0.02 * 0.02 / (0.2 * 0.2));
  const double immersed = level - (0.04 + 0.01);
  const double buoyancy = 1000 * 9.81 * kPi * 0.02 * 0.02 * immersed;
  const double tracking_rms = simulation.world().tool_tracking_rms(tool);
  std::printf("fluid force on the barrel: up to %.3f N on the way down, %.3f N held still vs buoyancy %.3f N "
              "(%+.0f %%); nozzle tracking %.3f mm rms\n",
              descent_force_max, hold_force, buoyancy, 100 * (hold_force / buoyancy - 1), 1e3 * tracking_rms);
  EXPECT_NEAR(hold_force, buoyancy, 0.25 * buoyancy);
  EXPECT_GT(descent_force_max, hold_force);  // drag while it moves
  EXPECT_LT(tracking_rms, 1e-3);
  EXPECT_EQ(simulation.solver().state().particles_removed_total, 0u);
}

TEST(Coupling, Ur10DepositsAlongItsPath) {
  // The ur10_wall scene, shortened to two layers of a 0.16 m square: per layer, the deposited
  // strand's centreline (centroid of the material laid along each side, corners excluded) stays
  // within one particle diameter of the commanded path.
  scene::Scene scene = scene::load_scene(std::filesystem::path(M3DP_SCENES) / "ur10_wall.sdf");
  scene.output.write_particles = false;
  scene.meshing.enabled = false;
  auto& head = scene.print_heads.at(0);
  const Real half = Real(0.08), layer_height = Real(0.008), speed = Real(0.1), z0 = Real(0.008);
  const Vec3 centre(0.7f, 0, 0);
  const Vec3 start(0.775f, 0.164f, 0.0867f);
  std::vector<Vec3> wall;
  for (int l = 0; l < 2; ++l)
    for (const Vec3& corner : {Vec3(-half, -half, 0), Vec3(half, -half, 0), Vec3(half, half, 0), Vec3(-half, half, 0), Vec3(-half, -half, 0)})
      wall.push_back(centre + corner + Vec3(0, 0, z0 + l * layer_height));
  const Real approach_speed = Real(0.2);
  const double approach = double((wall.front() - start).norm() / approach_speed);
  head.trajectory = toolpath::Trajectory({toolpath::PathSegment{toolpath::PolylineCurve{{start, wall.front()}}, approach_speed, false},
                                          toolpath::PathSegment{toolpath::PolylineCurve{wall}, speed, true}},
                                         0.0);
  const double layer_time = double(8 * half / speed);
  scene.end_time = approach + 2 * layer_time + double(layer_height / speed) + 0.5;
  sim::Simulation simulation(scene);
  while (simulation.time() < scene.end_time) simulation.step();

  const auto& fluid = simulation.solver().fluid();
  const Real diameter = simulation.solver().particle_diameter();
  double worst = 0;
  for (int l = 0; l < 2; ++l) {
    const double begin = approach + l * (layer_time + double(layer_height / speed)), end = begin + layer_time;
    double layer_worst = 0;
    std::size_t bins = 0;
    for (int side = 0; side < 4; ++side) {
      const Vec3 from = wall[std::size_t(side)], to = wall[std::size_t(side + 1)];
      const Vec3 along = (to - from).normalized(), across = Vec3::UnitZ().cross(along);
      // 4 cm stretches along the side (a strand is one or two particles wide: shorter ones count too
      // few particles for a centroid), 2 cm clear of each corner.
      const Real stretch = Real(0.04);
      for (Real s = Real(0.02); s + stretch <= 2 * half - Real(0.02) + 1e-6f; s += stretch) {
        double offset_sum = 0;
        std::size_t count = 0;
        for (std::size_t i = 0; i < fluid.size(); ++i) {
          if (fluid.birth_time[i] < begin || fluid.birth_time[i] > end) continue;
          const Vec3 relative = fluid.position[i] - from;
          const Real a = relative.dot(along), c = relative.dot(across);
          if (a < s || a >= s + stretch || std::abs(c) > Real(0.03)) continue;
          offset_sum += c;
          ++count;
        }
        if (count < 10) continue;
        layer_worst = std::max(layer_worst, std::abs(offset_sum / double(count)));
        ++bins;
      }
    }
    std::printf("layer %d: %zu stretches along the sides, largest centreline offset %.2f mm (one particle diameter: %.1f mm)\n",
                l + 1, bins, 1e3 * layer_worst, 1e3 * diameter);
    EXPECT_EQ(bins, 12u);  // material really was laid along the whole path
    worst = std::max(worst, layer_worst);
  }
  EXPECT_LE(worst, diameter);
  // All the material the path asks for left the nozzle (π D²/4 · U while extruding).
  const double extruding_time = 2 * layer_time + double(layer_height / speed);
  const double asked = kPi * head.inner_diameter * head.inner_diameter / 4 * head.exit_speed * extruding_time;
  const double emitted = double(fluid.size()) * std::pow(double(diameter), 3);
  std::printf("emitted %.4g m^3 of the %.4g m^3 the path asks for (%+.2f %%)\n", emitted, asked, 100 * (emitted / asked - 1));
  EXPECT_NEAR(emitted, asked, 0.02 * asked);
  const auto tool = *simulation.print_head_tool(0);
  std::printf("nozzle tracking: %.3f mm rms, %.3f mm max\n", 1e3 * simulation.world().tool_tracking_rms(tool),
              1e3 * simulation.world().tool_tracking_max(tool));
}

TEST(Coupling, ThreeMobileRobotsPrintOneStrandWithoutTouching) {
  // scenes/multi_robot.sdf: three TurtleBots drive in a row, each printing a third of one strand, the
  // middle one in a mortar of another density than the others' clay paste.
  scene::Scene scene = scene::load_scene(std::filesystem::path(M3DP_SCENES) / "multi_robot.sdf");
  scene.output.write_particles = false;
  scene.meshing.enabled = false;
  sim::Simulation simulation(scene);
  while (simulation.time() < scene.end_time) simulation.step();
  const auto& world = simulation.world();
  ASSERT_EQ(simulation.robots().size(), 3u);
  for (std::size_t r = 0; r < 3; ++r) {
    const auto robot = simulation.robots()[r];
    const auto tool = *simulation.print_head_tool(r);
    const auto base = world.base_report(robot);
    std::printf("%s: robot contacts %llu, nozzle %.3f mm rms, base %.3f mm rms over %.3f m\n", world.robot_name(robot).c_str(),
                (unsigned long long)world.robot_contacts(robot).with_robots, 1e3 * world.tool_tracking_rms(tool),
                1e3 * base.tracking_rms, base.distance);
    EXPECT_EQ(world.robot_contacts(robot).with_robots, 0u);
    EXPECT_LE(world.tool_tracking_rms(tool), 1e-3);
    EXPECT_NEAR(base.distance, 0.35, 0.005);
  }
  // One strand from x = -0.08 to 0.97 m along y = -0.2: material in every 3 cm of it.
  const auto& fluid = simulation.solver().fluid();
  int empty = 0;
  // 35 stretches, counted in integers: a float sum of 0.03s overshoots and adds one past the end.
  for (int stretch = 0; stretch < 35; ++stretch) {
    const Real x = Real(-0.08) + Real(0.03) * Real(stretch);
    int count = 0;
    for (std::size_t i = 0; i < fluid.size(); ++i)
      if (fluid.position[i].x() >= x && fluid.position[i].x() < x + Real(0.03) && std::abs(fluid.position[i].y() + Real(0.2)) < Real(0.02))
        ++count;
    if (count == 0) {
      ++empty;
      std::printf("no material in x = [%.2f, %.2f) m\n", x, x + Real(0.03));
    }
  }
  std::size_t mortar = 0;
  for (std::size_t i = 0; i < fluid.size(); ++i) mortar += simulation.solver().parameters().phases[fluid.phase[i]].name == "mortar";
  std::printf("strand: %zu particles (%zu of them mortar), %d empty 3 cm stretches along 1.05 m\n", fluid.size(), mortar, empty);
  EXPECT_EQ(empty, 0);
  EXPECT_GT(mortar, fluid.size() / 5);
  EXPECT_LT(mortar, fluid.size() / 2);
}
