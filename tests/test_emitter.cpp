// Nozzle emitter: volume flux π D²/4 · U (mass flux within 2 %), particles never spawned
// inside a boundary or another particle, and a nozzle that cannot emit waits instead.
#include <gtest/gtest.h>

#include "m3dp/core/error.hpp"

#include <cmath>

#include "m3dp/sim/simulation.hpp"
#include "m3dp/sph/boundary_sampling.hpp"

using namespace m3dp;

namespace {
sph::Parameters nozzle_parameters(Real inner_diameter, Real exit_speed) {
  sph::Parameters parameters;
  parameters.settings.particle_radius = Real(0.002);
  parameters.settings.bounds.min = Vec3(-0.2f, -0.2f, -0.05f);
  parameters.settings.bounds.max = Vec3(0.2f, 0.2f, 0.3f);
  parameters.phases.push_back(material::newtonian("paste", 1500, Real(0.05)));
  parameters.nozzles.push_back(sph::NozzleSettings{"nozzle", inner_diameter, exit_speed, 0});
  return parameters;
}

void add_floor(sph::Solver& solver) {
  const auto& settings = solver.parameters().settings;
  const auto samples =
      sph::sample_box_surface(BoxShape{Vec3(0.3f, 0.3f, 0.01f)}, settings.boundary_spacing_factor * solver.particle_diameter(),
                              -settings.particle_radius)
          .points;
  Pose pose;
  pose.position = Vec3(0, 0, -0.005f);
  solver.add_body("floor", samples, pose, true);
}

Real min_distance_to(const std::vector<Vec3>& points, std::size_t skip_begin, std::size_t skip_end, const Vec3& query) {
  Real best = 1e9f;
  for (std::size_t j = 0; j < points.size(); ++j)
    if (j < skip_begin || j >= skip_end) best = std::min(best, (points[j] - query).norm());
  return best;
}
}  // namespace

TEST(Emitter, MassFluxMatchesNozzleFlow) {
  const Real diameter = Real(0.012), speed = Real(0.2);
  sph::Solver solver(nozzle_parameters(diameter, speed));
  add_floor(solver);
  solver.reserve(20000);
  Pose pose;
  pose.position = Vec3(0, 0, 0.1f);
  solver.set_nozzle(0, pose, Vec3::Zero(), true);
  // Long enough (80 layers) that the last, partly due layer is within the tolerance.
  while (solver.time() < 2.0) solver.step();
  const double expected = 1500.0 * kPi * diameter * diameter / 4 * speed * solver.time();
  const double emitted = solver.state().mass_emitted_total;
  const double error = (emitted - expected) / expected;
  std::printf("emitted %.6f kg in %.3f s, rho*pi*D^2/4*U*t = %.6f kg: error %+.2f %% (tolerance 2 %%); %zu particles per layer\n",
              emitted, solver.time(), expected, 100 * error, solver.nozzle_geometry(0).disc_offsets.size());
  EXPECT_LT(std::abs(error), 0.02);
  // Nothing created or lost on the way: what is in the scene plus what left its bounds is what was emitted.
  EXPECT_NEAR(solver.total_fluid_mass() + solver.state().mass_removed_total, emitted, 1e-6 * emitted);
}

TEST(Emitter, FlowScaleSetsTheFlux) {
  // A G-code move asking for 40 % of the nominal flow gets 40 % of the mass, leaving at 40 % of the speed.
  const Real diameter = Real(0.012), speed = Real(0.2), scale = Real(0.4);
  sph::Solver solver(nozzle_parameters(diameter, speed));
  add_floor(solver);
  solver.reserve(20000);
  Pose pose;
  pose.position = Vec3(0, 0, 0.1f);
  solver.set_nozzle(0, pose, Vec3::Zero(), true, scale);
  while (solver.time() < 2.0) solver.step();
  const double expected = scale * 1500.0 * kPi * diameter * diameter / 4 * speed * solver.time();
  const double error = (solver.state().mass_emitted_total - expected) / expected;
  std::printf("flow scale %.1f: emitted %.6f kg, expected %.6f kg: error %+.2f %% (tolerance 2 %%)\n", scale,
              solver.state().mass_emitted_total, expected, 100 * error);
  EXPECT_LT(std::abs(error), 0.02);
  EXPECT_THROW(solver.set_nozzle(0, pose, Vec3::Zero(), true, Real(-1)), Error);
}

TEST(Emitter, NeverSpawnsInsideParticlesOrBoundaries) {
  sph::Solver solver(nozzle_parameters(Real(0.01), Real(0.15)));
  add_floor(solver);
  // The nozzle moves down towards the floor and sideways, over material it laid itself.
  const Real clearance = Real(0.5) * solver.particle_diameter() * Real(0.999);
  std::size_t checked = 0;
  // It reaches 1 mm above the floor at 0.39 s and stays there: the layers due then must wait.
  while (solver.time() < 0.5) {
    const double t = solver.time();
    Pose pose;
    pose.position = Vec3(Real(0.05 * std::sin(6 * t)), 0, Real(std::max(0.001, 0.04 - 0.1 * t)));
    solver.set_nozzle(0, pose, Vec3::Zero(), true);
    const std::size_t before = solver.fluid().size();
    // Positions of the others as the emitter saw them (emission happens before the step moves anything).
    const std::vector<Vec3> previous = solver.fluid().position;
    solver.step();
    const auto& fluid = solver.fluid();
    for (std::size_t i = 0; i < fluid.size(); ++i) {
      if (fluid.id[i] < solver.state().next_particle_id - (fluid.size() - before)) continue;  // not new this step
      // Compare the spawn point (undo this step's motion) with every older particle and the floor.
      const Vec3 spawn = fluid.position[i] - static_cast<Real>(solver.state().last_step.time_step) * fluid.velocity[i];
      EXPECT_GE(min_distance_to(previous, previous.size(), previous.size(), spawn), clearance * Real(0.9));
      // Not inside the floor: the centre at least a radius above its top face (z = 0).
      EXPECT_GE(spawn.z(), solver.parameters().settings.particle_radius * Real(0.9));
      ++checked;
    }
  }
  EXPECT_GT(checked, 50u);
  EXPECT_GT(solver.state().nozzles[0].blocked_layers, 0u) << "the nozzle reached the floor: some layers must wait";
}

TEST(Emitter, StopsWhenExtrusionIsOff) {
  sph::Solver solver(nozzle_parameters(Real(0.01), Real(0.2)));
  Pose pose;
  pose.position = Vec3(0, 0, 0.1f);
  solver.set_nozzle(0, pose, Vec3::Zero(), true);
  while (solver.time() < 0.1) solver.step();
  const std::uint64_t after_on = solver.state().nozzles[0].particles_emitted;
  EXPECT_GT(after_on, 0u);
  solver.set_nozzle(0, pose, Vec3::Zero(), false);
  while (solver.time() < 0.2) solver.step();
  EXPECT_EQ(solver.state().nozzles[0].particles_emitted, after_on);
}
