// Forces on the material's surface. Surface tension: a liquid pulls itself towards the least surface
// (both models); adhesion (Akinci et al. 2013) holds a liquid to a wall against its weight (each
// compared with the same set-up without the force); the continuum surface force (Brackbill et al.
// 1992) oscillates Rayleigh's droplet at its period and keeps a sessile drop whole on a floor. Air drag (Gissler et al. 2017): a lone drop falls
// at the terminal speed of a sphere, and the inside of a body of material is shielded.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/sph/boundary_sampling.hpp"
#include "m3dp/sph/solver.hpp"

using namespace m3dp;

namespace {

/// A cube of water (side `side`, 12 particles across) floating without gravity for `seconds`; returns
/// the largest distance of a particle from the centre of mass, over the side.
double cube_corner_distance_after(double surface_tension, double seconds,
                                  sph::SurfaceTensionModel model = sph::SurfaceTensionModel::akinci2013) {
  const Real side = Real(0.006);
  const Real d = side / 12;
  sph::Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.gravity = Vec3::Zero();
  parameters.settings.max_time_step = Real(1e-3);
  parameters.settings.surface_tension_model = model;
  parameters.settings.bounds.min = Vec3::Constant(-side * 5);
  parameters.settings.bounds.max = Vec3::Constant(side * 5);
  material::Material water = material::newtonian("water", 1000, Real(1e-3));
  water.surface_tension = Real(surface_tension);
  parameters.phases.push_back(water);
  sph::Solver solver(parameters);
  solver.add_particles(sph::lattice_in_box(Aabb{Vec3::Constant(-side / 2), Vec3::Constant(side / 2)}, d), Vec3::Zero(), 0);
  while (solver.time() < seconds) solver.step();
  const auto& fluid = solver.fluid();
  Vec3 centre = Vec3::Zero();
  for (const Vec3& p : fluid.position) centre += p;
  centre /= Real(fluid.size());
  double farthest = 0;
  for (const Vec3& p : fluid.position) farthest = std::max(farthest, double((p - centre).norm()));
  return (farthest + d / 2) / side;
}

/// A flat drop of water (8 × 8 × 3 particles, d = 0.4 mm) hanging under a ceiling; returns how far (m)
/// its centre of mass has fallen after `seconds`.
double hanging_drop_fall(double adhesion, double seconds) {
  const Real d = Real(4e-4);
  sph::Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.max_time_step = Real(1e-3);
  parameters.settings.bounds.min = Vec3(-0.05f, -0.05f, -0.5f);
  parameters.settings.bounds.max = Vec3(0.05f, 0.05f, 0.05f);
  material::Material water = material::newtonian("water", 1000, Real(1e-3));
  water.surface_tension = Real(0.0728);
  water.adhesion = Real(adhesion);
  parameters.phases.push_back(water);
  sph::Solver solver(parameters);
  const BoxShape plate{Vec3(0.01f, 0.01f, 4 * d)};
  // The ceiling's lower surface at z = 0.
  solver.add_body("ceiling", sph::sample_box_surface(plate, d, -d / 2).points, Pose{Vec3(0, 0, 2 * d), Quat::Identity()}, true);
  solver.add_particles(sph::lattice_in_box(Aabb{Vec3(-4 * d, -4 * d, -3 * d), Vec3(4 * d, 4 * d, 0)}, d), Vec3::Zero(), 0);
  auto centre_height = [&] {
    double sum = 0;
    for (const Vec3& p : solver.fluid().position) sum += p.z();
    return sum / double(solver.fluid().size());
  };
  const double start = centre_height();
  while (solver.time() < seconds) solver.step();
  return start - centre_height();
}

}  // namespace

TEST(SurfaceTension, AFloatingCubeOfWaterPullsItselfRound) {
  // A cube's corners lie 0.87 sides from its centre; the ball of the same volume has radius 0.62.
  // The capillary time √(ρL³/σ) is 34 ms: after 0.15 s the corners must have been drawn in.
  const double with_tension = cube_corner_distance_after(0.0728, 0.15);
  const double without = cube_corner_distance_after(0.0, 0.15);
  std::printf("farthest particle from the centre, in sides: %.3f with sigma = 0.0728 N/m, %.3f without (cube 0.866, "
              "ball 0.620)\n",
              with_tension, without);
  EXPECT_LT(with_tension, 0.75);
  EXPECT_GT(without, 0.82);
}

TEST(SurfaceTension, TheContinuumForcePullsAFloatingCubeRoundToo) {
  const double with_tension = cube_corner_distance_after(0.0728, 0.15, sph::SurfaceTensionModel::csf_brackbill1992);
  std::printf("brackbill1992: farthest particle from the centre, in sides: %.3f (cube 0.866, ball 0.620)\n", with_tension);
  EXPECT_LT(with_tension, 0.70);
}

namespace {

struct DropletOscillation {
  double rayleigh_period = 0;   // s
  double measured_period = 0;   // s, twice the mean time between zero crossings of the quadrupole moment
  int crossings = 0;
  double first_extreme = 0;     // largest |quadrupole| over R² in the first period
  double last_extreme = 0;      // and in the last
};

/// Rayleigh's l = 2 oscillation of a free water droplet (R = 10 mm, 16 particles across, no gravity),
/// started in its velocity mode v = A (x, y, −2z) with A = 0.05 ω; the quadrupole moment
/// Σ (z² − (x² + y²)/2) / (N R²) is sampled every 2 ms.
DropletOscillation oscillate_droplet(double seconds) {
  const Real radius = Real(0.01), sigma = Real(0.0728), density = 1000;
  const Real d = 2 * radius / 16;
  sph::Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.gravity = Vec3::Zero();
  parameters.settings.max_time_step = Real(5e-4);
  parameters.settings.surface_tension_model = sph::SurfaceTensionModel::csf_brackbill1992;
  parameters.settings.bounds.min = Vec3::Constant(-5 * radius);
  parameters.settings.bounds.max = Vec3::Constant(5 * radius);
  material::Material water = material::newtonian("water", density, Real(1e-3));
  water.surface_tension = sigma;
  parameters.phases.push_back(water);
  sph::Solver solver(parameters);
  std::vector<Vec3> points;
  for (const Vec3& p : sph::lattice_in_box(Aabb{Vec3::Constant(-radius), Vec3::Constant(radius)}, d))
    if (p.norm() < radius) points.push_back(p);
  solver.add_particles(points, Vec3::Zero(), 0);
  // ω² = 8σ/(ρR³) with R the radius of the particles' volume.
  const double volume_radius = std::cbrt(3.0 * double(points.size()) / (4 * kPi)) * d;
  const double omega = std::sqrt(8 * sigma / (density * volume_radius * volume_radius * volume_radius));
  auto& fluid = const_cast<sph::FluidParticles&>(solver.fluid());
  for (std::size_t i = 0; i < fluid.size(); ++i) {
    const Vec3 p = fluid.position[i];
    fluid.velocity[i] = Real(0.05 * omega) * Vec3(p.x(), p.y(), -2 * p.z());
  }
  DropletOscillation result;
  result.rayleigh_period = 2 * kPi / omega;
  std::vector<double> times, moments;
  double next_sample = 0;
  while (solver.time() < seconds) {
    solver.step();
    if (solver.time() < next_sample) continue;
    next_sample += 0.002;
    Vec3 centre = Vec3::Zero();
    for (const Vec3& p : fluid.position) centre += p;
    centre /= Real(fluid.size());
    double moment = 0;
    for (const Vec3& p : fluid.position) {
      const Vec3 r = p - centre;
      moment += r.z() * r.z() - 0.5 * (r.x() * r.x() + r.y() * r.y());
    }
    times.push_back(solver.time());
    moments.push_back(moment / (double(fluid.size()) * volume_radius * volume_radius));
  }
  std::vector<double> crossings;
  for (std::size_t k = 1; k < times.size(); ++k)
    if ((moments[k - 1] < 0) != (moments[k] < 0))
      crossings.push_back(times[k - 1] + (times[k] - times[k - 1]) * moments[k - 1] / (moments[k - 1] - moments[k]));
  result.crossings = int(crossings.size());
  if (crossings.size() >= 2)
    result.measured_period = 2 * (crossings.back() - crossings.front()) / double(crossings.size() - 1);
  for (std::size_t k = 0; k < times.size(); ++k) {
    if (times[k] < result.rayleigh_period) result.first_extreme = std::max(result.first_extreme, std::abs(moments[k]));
    if (times[k] > seconds - result.rayleigh_period) result.last_extreme = std::max(result.last_extreme, std::abs(moments[k]));
  }
  return result;
}

}  // namespace

TEST(SurfaceTension, RayleighsDropletOscillatesAtItsPeriod) {
  // VALIDATION.md: ω² = 8σ/(ρR³) for mode l = 2; water's viscous damping time R²/(5ν) = 20 s is far
  // longer than the run.
  const DropletOscillation droplet = oscillate_droplet(0.56);
  std::printf("Rayleigh droplet (R = 10 mm, 16 particles across, brackbill1992): period %.4f s over %d zero "
              "crossings, Rayleigh %.4f s: error %+.1f %% (tolerance 10 %%); amplitude %.4f in the first period, %.4f "
              "in the last\n",
              droplet.measured_period, droplet.crossings, droplet.rayleigh_period,
              100 * (droplet.measured_period / droplet.rayleigh_period - 1), droplet.first_extreme, droplet.last_extreme);
  ASSERT_GE(droplet.crossings, 4);
  EXPECT_NEAR(droplet.measured_period / droplet.rayleigh_period, 1.0, 0.10);
  // Nearly undamped, as water is at this size, and not gaining energy either.
  EXPECT_GT(droplet.last_extreme, 0.6 * droplet.first_extreme);
  EXPECT_LT(droplet.last_extreme, 1.2 * droplet.first_extreme);
}

TEST(SurfaceTension, TheContinuumForceKeepsASessileDropTogetherOnAFloor) {
  // A hemisphere of water (R = 4 mm, 10 particles per radius) on a floor under gravity, wetted at 90°
  // (brackbill1992 mirrors the surface at walls). It flattens and rocks (Bond number 2.2), but its rim
  // must not spray apart: before the mirror the rim's curvature fell short and the drop's own pressure
  // sprayed its rim apart within 0.05 s (over a third of the particles beyond 1.6 R).
  // What it does not yet do: keep every particle. A film squeezed out under the rim sheds a few particles
  // that slide off along the slip floor; how many depends on rounding (0–1.1 % of the particles over
  // time steps of 0.8–1 ms and 10–14 particles per radius, docs/architecture.md). So the bulk is asserted.
  const Real d = Real(4e-4), radius = Real(0.004);
  sph::Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.max_time_step = Real(1e-3);
  parameters.settings.surface_tension_model = sph::SurfaceTensionModel::csf_brackbill1992;
  parameters.settings.bounds.min = Vec3::Constant(-0.05f);
  parameters.settings.bounds.max = Vec3::Constant(0.05f);
  material::Material water = material::newtonian("water", 1000, Real(1e-3));
  water.surface_tension = Real(0.0728);
  parameters.phases.push_back(water);
  sph::Solver solver(parameters);
  const BoxShape plate{Vec3(0.02f, 0.02f, 4 * d)};
  solver.add_body("floor", sph::sample_box_surface(plate, d, -d / 2).points, Pose{Vec3(0, 0, -2 * d), Quat::Identity()}, true);
  std::vector<Vec3> points;
  for (const Vec3& p : sph::lattice_in_box(Aabb{Vec3(-radius, -radius, 0), Vec3(radius, radius, radius)}, d))
    if (p.norm() < radius) points.push_back(p);
  solver.add_particles(points, Vec3::Zero(), 0);
  while (solver.time() < 0.2) solver.step();
  // The 98th percentiles of the distance from the axis and of the height: the drop's bulk.
  std::vector<double> distances, heights;
  for (const Vec3& p : solver.fluid().position) {
    distances.push_back(std::hypot(p.x(), p.y()));
    heights.push_back(p.z());
  }
  std::sort(distances.begin(), distances.end());
  std::sort(heights.begin(), heights.end());
  const std::size_t percentile = distances.size() * 98 / 100;
  const double shed = double(std::count_if(distances.begin(), distances.end(), [&](double r) { return r > 1.6 * radius; }));
  std::printf("sessile drop after 0.2 s: %zu of %zu particles; 98 %% within %.2f mm of the axis and below %.2f mm "
              "(hemisphere %.1f mm); %.0f shed beyond 1.6 R, the farthest at %.2f mm\n",
              solver.fluid().size(), points.size(), distances[percentile] * 1e3, heights[percentile] * 1e3, radius * 1e3, shed,
              distances.back() * 1e3);
  EXPECT_GE(solver.fluid().size(), points.size() * 98 / 100);
  EXPECT_LT(distances[percentile], 1.6 * radius);
  EXPECT_LT(heights[percentile], 1.3 * radius);
}

TEST(SurfaceTension, TheContinuumForceRefusesAnAdhesion) {
  sph::Parameters parameters;
  parameters.settings.surface_tension_model = sph::SurfaceTensionModel::csf_brackbill1992;
  material::Material water = material::newtonian("water", 1000, Real(1e-3));
  water.surface_tension = Real(0.0728);
  water.adhesion = Real(0.1);
  parameters.phases.push_back(water);
  try {
    sph::Solver solver(parameters);
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("akinci2013"), std::string::npos) << error.what();
  }
}

TEST(SurfaceTension, AdhesionHoldsAWaterDropUnderACeiling) {
  // Water wets glass: work of adhesion σ(1 + cos θ) ≈ 2σ. Without adhesion nothing holds the drop
  // (g t²/2 = 49 mm after 0.1 s); it falls further, as its own Laplace pressure pushes it off the
  // ceiling as well (a non-wetting drop touches a wall in a point, not a face).
  const double stuck = hanging_drop_fall(2 * 0.0728, 0.1);
  const double free = hanging_drop_fall(0.0, 0.1);
  std::printf("centre of mass fell %.2f mm with adhesion 2 sigma, %.2f mm without (free fall alone 49 mm)\n", stuck * 1e3,
              free * 1e3);
  EXPECT_LT(stuck, 1e-3);
  EXPECT_GT(free, 0.03);
}

namespace {

sph::Parameters drag_parameters(Real diameter) {
  sph::Parameters parameters;
  parameters.settings.particle_radius = diameter / 2;
  parameters.settings.air_drag = true;
  parameters.settings.bounds.min = Vec3::Constant(-100);
  parameters.settings.bounds.max = Vec3::Constant(100);
  parameters.phases.push_back(material::newtonian("water", 1000, Real(1e-3)));
  return parameters;
}

}  // namespace

TEST(AirDrag, ALoneDropFallsAtTheTerminalSpeedOfItsSphere) {
  const Real diameter = Real(2e-4);
  sph::Solver solver(drag_parameters(diameter));
  const Vec3 start = Vec3::Zero();
  solver.add_particles(std::span<const Vec3>(&start, 1), Vec3::Zero(), 0);
  while (solver.time() < 0.8) solver.step();
  const double speed = -solver.fluid().velocity[0].z();
  // Terminal speed: m g = ½ ρ_air C_D(Re) A v² for the sphere of the particle's volume (bisection).
  const auto& settings = solver.parameters().settings;
  const double mass = solver.particle_mass(0), sphere = diameter * std::cbrt(6 / kPi), area = kPi * sphere * sphere / 4;
  double low = 0, high = 10;
  for (int iteration = 0; iteration < 60; ++iteration) {
    const double v = (low + high) / 2;
    const double reynolds = settings.air_density * v * sphere / settings.air_viscosity;
    const double drag = 0.5 * settings.air_density * sph::sphere_drag_coefficient(Real(reynolds)) * area * v * v;
    (drag < mass * 9.81 ? low : high) = v;
  }
  std::printf("lone drop of %.2f mm (sphere of its volume): falls at %.4f m/s, terminal speed %.4f m/s: error %+.2f %% "
              "(tolerance 1 %%)\n",
              sphere * 1e3, speed, low, 100 * (speed / low - 1));
  EXPECT_NEAR(speed / low, 1.0, 0.01);
  // Measured: R. Gunn, G. D. Kinzer, "The terminal velocity of fall for water droplets in stagnant
  // air", J. Meteorology 6, 243–248, 1949: 0.72 m/s at 0.2 mm, 1.17 m/s at 0.3 mm (20 °C, 1 atm).
  const double measured = 0.72 + (1.17 - 0.72) * (sphere - 2e-4) / 1e-4;
  std::printf("Gunn & Kinzer 1949, interpolated to %.3f mm: %.3f m/s: error %+.1f %% (tolerance 5 %%)\n", sphere * 1e3,
              measured, 100 * (speed / measured - 1));
  EXPECT_NEAR(speed / measured, 1.0, 0.05);
}

TEST(AirDrag, WindPushesTheSurfaceOfABlockNotItsInside) {
  const Real diameter = Real(1e-3);
  sph::Parameters parameters = drag_parameters(diameter);
  parameters.settings.gravity = Vec3::Zero();
  parameters.settings.air_velocity = Vec3(5, 0, 0);
  sph::Solver solver(parameters);
  solver.add_particles(sph::lattice_in_box(Aabb{Vec3::Constant(-5 * diameter), Vec3::Constant(5 * diameter)}, diameter), Vec3::Zero(), 0);
  solver.step();
  const auto& fluid = solver.fluid();
  const int full = sph::full_neighbourhood_count(solver.support_radius(), diameter);
  double block_push = 0, inside_push = 0;
  std::size_t inside = 0;
  for (std::size_t i = 0; i < fluid.size(); ++i) {
    block_push += fluid.mass[i] * fluid.acceleration[i].x();
    if (fluid.neighbor_count[i] >= full) {
      ++inside;
      inside_push += std::abs(fluid.mass[i] * fluid.acceleration[i].x());
    }
  }
  // The same particles each alone in the wind.
  const double sphere = diameter * std::cbrt(6 / kPi), area = kPi * sphere * sphere / 4;
  const double reynolds = parameters.settings.air_density * 5 * sphere / parameters.settings.air_viscosity;
  const double lone = 0.5 * parameters.settings.air_density * sph::sphere_drag_coefficient(Real(reynolds)) * area * 25;
  std::printf("wind 5 m/s on a block of %zu particles: drag %.3g N, %.1f %% of theirs if each were alone; %zu inside "
              "particles feel %.3g N\n",
              fluid.size(), block_push, 100 * block_push / (lone * double(fluid.size())), inside, inside_push);
  EXPECT_GT(inside, 100u);
  EXPECT_EQ(inside_push, 0.0);
  EXPECT_GT(block_push, 0.0);
  EXPECT_LT(block_push, 0.5 * lone * double(fluid.size()));
}
