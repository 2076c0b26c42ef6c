// Micropolar materials (Bender et al. 2017): the micro-rotation follows the flow's own rotation (in a
// rigid rotation at Ω it settles to Ω), exerts no force once it does, and leaves momentum unchanged.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <vector>

#include "m3dp/sph/solver.hpp"

using namespace m3dp;

TEST(Micropolar, MicroRotationSettlesToTheRotationOfASpinningBall) {
  const Real radius = Real(0.01), d = radius / 6;
  const Real spin = 2;  // rad/s about z; slow, so that the free ball barely widens (Ω²R t²/2 ≈ 0.1 spacing)
  sph::Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.gravity = Vec3::Zero();
  parameters.settings.max_time_step = Real(2e-3);
  parameters.settings.bounds.min = Vec3::Constant(-1);
  parameters.settings.bounds.max = Vec3::Constant(1);
  material::Material liquid = material::newtonian("liquid", 1000, Real(1e-3));
  liquid.micropolar.enabled = true;
  liquid.micropolar.vortex_viscosity = Real(1e-2);
  parameters.phases.push_back(liquid);
  sph::Solver solver(parameters);
  std::vector<Vec3> points;
  for (int i = -7; i <= 7; ++i)
    for (int j = -7; j <= 7; ++j)
      for (int k = -7; k <= 7; ++k) {
        const Vec3 p = d * Vec3(Real(i), Real(j), Real(k));
        if (p.norm() <= radius) points.push_back(p);
      }
  solver.add_particles(points, Vec3::Zero(), 0);
  {
    sph::State state = solver.state();
    for (std::size_t i = 0; i < state.fluid.size(); ++i)
      state.fluid.velocity[i] = Vec3(0, 0, spin).cross(state.fluid.position[i]);
    solver.restore(state);
  }
  // Relaxation time ρΘ/(2μ_t): with Θ = (2/5) R_p², R_p the radius of one particle's sphere.
  const double sphere_radius = d * std::cbrt(3 / (4 * kPi));
  const double relaxation = 1000 * 0.4 * sphere_radius * sphere_radius / (2 * 1e-2);
  while (solver.time() < 5 * relaxation) solver.step();
  const auto& fluid = solver.fluid();
  double inner_omega = 0, angular = 0, inertia = 0;
  int inner = 0;
  for (std::size_t i = 0; i < fluid.size(); ++i) {
    const Vec3& p = fluid.position[i];
    angular += fluid.mass[i] * p.cross(fluid.velocity[i]).z();
    inertia += fluid.mass[i] * p.head<2>().squaredNorm();
    if (p.norm() < radius / 2) {
      inner_omega += fluid.angular_velocity[i].z();
      ++inner;
    }
  }
  Vec3 linear = Vec3::Zero();
  for (std::size_t i = 0; i < fluid.size(); ++i) linear += fluid.mass[i] * fluid.velocity[i];
  inner_omega /= inner;
  const double ball_spin = angular / inertia;
  std::printf("after %.3f s (5 relaxation times): inner micro-rotation %.3f rad/s, the ball spins at %.3f rad/s "
              "(started at %.1f): error %+.1f %% (tolerance 5 %%); linear momentum %.2g kg m/s\n",
              solver.time(), inner_omega, ball_spin, double(spin), 100 * (inner_omega / ball_spin - 1), double(linear.norm()));
  EXPECT_NEAR(inner_omega / ball_spin, 1.0, 0.05);
  EXPECT_GT(ball_spin, 0.9 * spin);  // the coupling does not brake a rigid rotation
  EXPECT_LT(linear.norm(), 1e-6 * solver.total_fluid_mass() * spin * radius);
}
