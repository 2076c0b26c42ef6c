// A print head driven by slicer G-code lays the material the G-code asks for, where it asks.
#include <gtest/gtest.h>

#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/toolpath/gcode.hpp"

using namespace m3dp;

TEST(GcodePrint, EmittedMaterialFollowsTheGcodeFlow) {
  const std::filesystem::path scene_file = std::filesystem::path(M3DP_SCENES) / "gcode_print.sdf";
  scene::Scene scene = scene::load_scene(scene_file);
  scene.output.write_particles = false;
  sim::Simulation simulation(scene);
  // The same program the scene reads: volume asked for up to time t.
  toolpath::GcodeSettings settings;
  settings.placement = Pose::from_xyz_rpy(-1, -1, 0, 0, 0, 0);
  settings.geometry_scale = 10;
  const auto program = toolpath::read_gcode(std::filesystem::path(M3DP_SCENES) / "gcode" / "cylinder_shell.gcode", settings);
  auto volume_asked_until = [&](double time) {
    double elapsed = 0, volume = 0;
    for (const auto& move : program.moves) {
      if (elapsed >= time) break;
      const double fraction = std::min(1.0, (time - elapsed) / move.duration);
      volume += fraction * move.material_volume;
      elapsed += move.duration;
    }
    return volume;
  };
  const double density = scene.materials.front().material.density;
  const double end = 8.0;
  while (simulation.time() < end) simulation.step();
  const double asked = volume_asked_until(simulation.time());
  const double emitted = simulation.solver().state().mass_emitted_total / density;
  std::printf("G-code asked %.4g m³ by t = %.2f s; the nozzle emitted %.4g m³ (%+.2f %%)\n", asked, simulation.time(), emitted,
              100 * (emitted / asked - 1));
  ASSERT_GT(asked, 0);
  EXPECT_NEAR(emitted / asked, 1.0, 0.03);
  // Where it went: every particle lies within a strand width of an extruding move's line.
  const Real tolerance = Real(0.0045) + 2 * scene.solver.particle_radius;
  std::size_t off_path = 0;
  for (const Vec3& p : simulation.solver().fluid().position) {
    Real nearest = 1e9f;
    for (const auto& move : program.moves) {
      if (!move.extruding()) continue;
      const Vec3 direction = move.end - move.start;
      const Real t = std::clamp<Real>((p - move.start).dot(direction) / std::max(direction.squaredNorm(), Real(1e-12)), 0, 1);
      nearest = std::min(nearest, (p - (move.start + t * direction)).head<2>().norm());
    }
    off_path += nearest > tolerance ? 1 : 0;
  }
  std::printf("%zu of %zu particles farther than %.1f mm (sideways) from the extruding path\n", off_path,
              simulation.solver().fluid().size(), 1e3 * tolerance);
  EXPECT_EQ(off_path, 0u);
}
