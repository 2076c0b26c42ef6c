// Granular mode (discrete spheres, Cundall & Strack 1979 contacts): a bounce keeps e² of the drop
// height, a heap at rest weighs on the floor with its weight, and friction is what lets a heap stand.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/sph/boundary_sampling.hpp"
#include "m3dp/sph/solver.hpp"

using namespace m3dp;

namespace {

constexpr Real kDiameter = Real(0.002);  // m

sph::Solver make_granular_solver(Real restitution, Real friction) {
  sph::Parameters parameters;
  parameters.settings.particle_radius = kDiameter / 2;
  parameters.settings.bounds.min = Vec3(-0.2f, -0.2f, -0.05f);
  parameters.settings.bounds.max = Vec3(0.2f, 0.2f, 0.3f);
  material::Material pellets = material::newtonian("clay_pellets", 1800, 0);
  pellets.granular.enabled = true;
  pellets.granular.restitution = restitution;
  pellets.granular.friction = friction;
  parameters.phases.push_back(pellets);
  sph::Solver solver(parameters);
  // A floor whose surface is z = 0; its boundary particles lie a radius below it.
  const BoxShape floor{Vec3(0.1f, 0.1f, 4 * kDiameter)};
  solver.add_body("floor", sph::sample_box_surface(floor, kDiameter, -kDiameter / 2).points,
                  Pose{Vec3(0, 0, -2 * kDiameter), Quat::Identity()}, true);
  return solver;
}

/// Highest point of a lone sphere after its first bounce, dropped from `height` (m, centre above its
/// resting height).
double rebound_height(Real restitution, Real height) {
  sph::Solver solver = make_granular_solver(restitution, 0.5f);
  // Right above one boundary particle (the floor's lie at (±d/2, ±d/2, −d/2)): a single contact, and the
  // sphere rests with its centre at z = d/2. (Between four of them it would sink into the pocket and
  // lose more: contacts at 45° also slide.)
  const Real rest = kDiameter / 2;
  const Vec3 start(kDiameter / 2, kDiameter / 2, rest + height);
  solver.add_particles(std::span<const Vec3>(&start, 1), Vec3::Zero(), 0);
  bool bounced = false;
  double highest = 0;
  Real last_speed = 0;
  while (solver.time() < 1.0) {
    solver.step();
    const Real z = solver.fluid().position[0].z(), vz = solver.fluid().velocity[0].z();
    if (!bounced && vz > 0) bounced = true;
    if (bounced) highest = std::max(highest, double(z - rest));
    if (bounced && vz < 0 && last_speed > 0) break;  // the top of the rebound
    last_speed = vz;
  }
  return highest;
}

struct Heap {
  double height = 0;   // m, top of the highest particle above the floor
  double radius = 0;   // m, radius holding 95 % of the particles
  double floor_force = 0, weight = 0;  // N
  std::size_t particles = 0;
};

/// Pours particles from a nozzle 40 mm above the floor for 0.6 s, lets them settle for 0.6 s, and
/// averages the floor's load over the last 0.2 s.
Heap pour_heap(Real friction) {
  sph::Solver solver = make_granular_solver(0.3f, friction);
  sph::Parameters parameters = solver.parameters();
  parameters.nozzles.push_back(sph::NozzleSettings{"spout", Real(0.006), Real(0.2), 0});
  sph::Solver poured(parameters);
  const BoxShape floor{Vec3(0.1f, 0.1f, 4 * kDiameter)};
  poured.add_body("floor", sph::sample_box_surface(floor, kDiameter, -kDiameter / 2).points,
                  Pose{Vec3(0, 0, -2 * kDiameter), Quat::Identity()}, true);
  poured.set_nozzle(0, Pose{Vec3(0, 0, 0.04f), Quat::Identity()}, Vec3::Zero(), true);
  while (poured.time() < 0.6) poured.step();
  poured.set_nozzle(0, Pose{Vec3(0, 0, 0.04f), Quat::Identity()}, Vec3::Zero(), false);
  Heap heap;
  double load_time = 0;
  while (poured.time() < 1.2) {
    const double step = poured.step().time_step;
    if (poured.time() < 1.0) continue;
    heap.floor_force += -poured.bodies()[0].fluid_force.z() * step;  // the particles' push on the floor, downwards
    load_time += step;
  }
  heap.floor_force /= load_time;
  const auto& fluid = poured.fluid();
  heap.particles = fluid.size();
  std::vector<double> radii;
  for (std::size_t i = 0; i < fluid.size(); ++i) {
    heap.height = std::max(heap.height, double(fluid.position[i].z() + kDiameter / 2));
    radii.push_back(fluid.position[i].head<2>().norm());
  }
  std::sort(radii.begin(), radii.end());
  heap.radius = radii.empty() ? 0 : radii[std::size_t(0.95 * double(radii.size() - 1))];
  heap.weight = poured.total_fluid_mass() * 9.81;
  return heap;
}

}  // namespace

TEST(Granular, ABounceKeepsTheSquareOfTheRestitution) {
  // A binary collision of the linear spring–dashpot keeps e of the speed, so e² of the height.
  for (const Real restitution : {Real(0.5), Real(0.8)}) {
    const double height = 0.02;
    const double rebound = rebound_height(restitution, Real(height));
    const double expected = restitution * restitution * height;
    std::printf("restitution %.1f: rebound %.2f mm, e^2 H = %.2f mm: error %+.1f %% (tolerance 5 %%)\n", restitution,
                rebound * 1e3, expected * 1e3, 100 * (rebound / expected - 1));
    EXPECT_NEAR(rebound / expected, 1.0, 0.05) << "restitution " << restitution;
  }
}

TEST(Granular, AHeapStandsWithFrictionAndWeighsOnTheFloor) {
  // Without friction the spheres still stack in each other's pockets (they cannot roll), so the smooth
  // heap is low but not flat.
  const Heap rough = pour_heap(0.6f);
  const Heap smooth = pour_heap(0.0f);
  std::printf("heap of %zu particles: with friction 0.6 %.1f mm high, %.1f mm radius; without friction %.1f mm high, "
              "%.1f mm radius\n",
              rough.particles, rough.height * 1e3, rough.radius * 1e3, smooth.height * 1e3, smooth.radius * 1e3);
  std::printf("floor force at rest %.4f N, weight %.4f N: error %+.2f %% (tolerance 2 %%)\n", rough.floor_force, rough.weight,
              100 * (rough.floor_force / rough.weight - 1));
  EXPECT_GT(rough.height, Real(1.5) * smooth.height);
  EXPECT_LT(rough.radius, smooth.radius);
  EXPECT_NEAR(rough.floor_force / rough.weight, 1.0, 0.02);
}

TEST(Granular, FluidAndGranularMaterialsInOneSceneAreAnError) {
  sph::Parameters parameters;
  parameters.phases.push_back(material::newtonian("water", 1000, Real(1e-3)));
  material::Material pellets = material::newtonian("pellets", 1000, 0);
  pellets.granular.enabled = true;
  parameters.phases.push_back(pellets);
  try {
    sph::Solver solver(parameters);
    FAIL() << "no error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("all fluids or all granular"), std::string::npos) << error.what();
  }
}
