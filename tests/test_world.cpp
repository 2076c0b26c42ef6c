// The rigid world: printed-material meshes are real collision bodies, during a run too.
#include <gtest/gtest.h>

#include <unistd.h>

#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/run.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/surface/surface.hpp"
#include "m3dp/world/world.hpp"

using namespace m3dp;

namespace {
/// A 20 × 20 × 4 block of particles of radius 5 mm on z = 0: its surface tops out at z = 0.04 m.
TriangleMesh slab_surface() {
  std::vector<Vec3> particles;
  const Real spacing = Real(0.01);
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j)
      for (int k = 0; k < 4; ++k) particles.push_back(Vec3((i - 9.5f) * spacing, (j - 9.5f) * spacing, (k + 0.5f) * spacing));
  surface::SurfaceSettings settings;
  settings.method = surface::Method::sph_blobby;
  settings.particle_radius = spacing / 2;
  return surface::reconstruct_surface(particles, settings);
}
}  // namespace

TEST(World, PrintedMeshStopsAFallingBox) {
  world::World world;
  world.add_static_shape("ground", PlaneShape{Vec3::UnitZ(), 2, 2}, Pose{});
  const auto box = world.add_rigid_body("box", BoxShape{Vec3(0.05f, 0.05f, 0.05f)}, 0.5, Pose::from_xyz_rpy(0, 0, 0.2f, 0, 0, 0));
  world.set_static_mesh("printed_material", slab_surface());
  world.step_to(1.0);
  const Real resting = world.pose(box).position.z();
  std::printf("box centre rests at z = %.4f m (slab top 0.04 m + half box 0.025 m = 0.065 m)\n", resting);
  EXPECT_NEAR(resting, 0.065, 0.004);
  EXPECT_LT(world.linear_velocity(box).norm(), 0.01);
  EXPECT_GT(world.contact_count(), 0u);

  // Without the mesh the box drops to the ground: the mesh, not something else, held it.
  world.set_static_mesh("printed_material", TriangleMesh{});
  EXPECT_EQ(world.mesh_replacements(), 1u);
  world.step_to(2.0);
  std::printf("after removing the mesh: z = %.4f m (ground + half box = 0.025 m)\n", world.pose(box).position.z());
  EXPECT_NEAR(world.pose(box).position.z(), 0.025, 0.004);
}

TEST(World, MeshMadeDuringARunStopsAFallingBox) {
  // A tank of water at rest (top at z ≈ 0.1 m); a box is dropped from above while the run meshes
  // the water every 20 ms and hands each mesh to the world.
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.005);
  setup.end_time = 0.4;
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.output.write_particles = false;
  scene.meshing.enabled = true;
  scene.meshing.period = Real(0.02);
  scene.meshing.surface.method = surface::Method::sph_blobby;
  sim::Simulation simulation(scene);
  const auto box = simulation.world().add_rigid_body("box", BoxShape{Vec3(0.04f, 0.04f, 0.04f)}, 0.2,
                                                       Pose::from_xyz_rpy(0.05f, 0.05f, 0.2f, 0, 0, 0));
  // Only the mesh may hold it: the fluid would too (the coupling test checks that), so it is off here.
  simulation.world().set_feels_fluid(simulation.world().link_of_body(box), false);

  sim::RunOptions options;
  options.output_directory = std::filesystem::temp_directory_path() / ("m3dp_test_world_" + std::to_string(::getpid()));
  options.show_progress = false;
  // Each mesh joins the world at the step it was asked for, however busy the machine is (a slow
  // mesher would otherwise let the box pass the water level before the first mesh exists).
  options.wait_for_meshes = true;
  // Until 0.3 s, then on to the end (0.4 s): the box's height at both times says whether it is held.
  options.until = 0.3;
  const auto first_part = sim::run_simulation(simulation, options);
  ASSERT_EQ(first_part.status, sim::RunStatus::completed);
  const Real held_at = simulation.world().pose(box).position.z();
  options.until.reset();
  const auto summary = sim::run_simulation(simulation, options);
  std::filesystem::remove_all(options.output_directory);
  ASSERT_EQ(summary.status, sim::RunStatus::completed);
  EXPECT_EQ(first_part.meshes_skipped + summary.meshes_skipped, 0u);
  EXPECT_GE(first_part.meshes_inserted + summary.meshes_inserted, 19u);  // every 20 ms of 0.4 s
  // The box lands on the highest point of the water's surface under it (the same field as the run's).
  surface::SurfaceSettings settings = scene.meshing.surface;
  settings.particle_radius = setup.particle_radius;
  const TriangleMesh water = surface::reconstruct_surface(simulation.solver().fluid().position, settings);
  Real top = 0;
  for (const Vec3& v : water.vertices)
    if (std::abs(v.x() - Real(0.05)) < Real(0.02) && std::abs(v.y() - Real(0.05)) < Real(0.02)) top = std::max(top, v.z());
  const Real resting = simulation.world().pose(box).position.z();
  std::printf("water surface under the box at %.4f m; box centre at %.4f m (expected surface + 0.02 m), %.4f m at 0.3 s; "
              "%zu meshes inserted\n",
              top, resting, held_at, first_part.meshes_inserted + summary.meshes_inserted);
  EXPECT_GT(top, Real(0.08));  // the water, not the tank floor
  // Within a particle diameter: the surface is replaced every 20 ms under a resting box, and Bullet
  // lets it settle ~5 mm into a triangle soup (measured 5.3 mm; the tank floor would be 80 mm lower).
  EXPECT_NEAR(resting, top + Real(0.02), 2 * setup.particle_radius);
  // Held: it moved less than 5 mm in the last 0.1 s (still falling, it would move more than 0.1 m). Its
  // speed at one instant says less: each new mesh nudges it (up to 0.1 m/s measured, between meshes
  // under 0.01 m/s).
  EXPECT_LT(std::abs(resting - held_at), Real(0.005));
}
