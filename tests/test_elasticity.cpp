// Elastic materials (Peer et al. 2018 stress, implicit in the velocity solve): a stretched block
// springs back to its reference length, and a soft column on a floor sags under its own weight by
// the amount of linear elasticity, δ = ρgH²/(2E), E = 2G(1 + ν). The column is 40 mm wide and 50 mm
// high: a 10 mm wide one buckles under its own weight (Greenhill's height 1.99 (EI/(ρgA))^(1/3) is 34 mm;
// the model does buckle), and a 20 mm one is close enough to it to sag more.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "m3dp/sph/boundary_sampling.hpp"
#include "m3dp/sph/solver.hpp"

using namespace m3dp;

namespace {

/// nx × ny × nz particles of spacing d, centred on the z axis, standing on z = 0.
std::vector<Vec3> lattice_block(int nx, int ny, int nz, Real d) {
  return sph::lattice_in_box(Aabb{Vec3(-nx * d / 2, -ny * d / 2, 0), Vec3(nx * d / 2, ny * d / 2, nz * d)}, d);
}

double height_of(const sph::Solver& solver) {
  Real low = 1e9, high = -1e9;
  for (const Vec3& p : solver.fluid().position) {
    low = std::min(low, p.z());
    high = std::max(high, p.z());
  }
  return double(high - low) + 2 * solver.parameters().settings.particle_radius;
}

/// A 8 × 8 × 16 block (d = 2.5 mm) released stretched by 20 % along z (volume kept) without gravity;
/// returns its length after `seconds` over its reference length.
double stretched_block_length_after(bool elastic, double seconds, Real relaxation_time = 0) {
  const Real d = Real(0.0025);
  sph::Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.gravity = Vec3::Zero();
  parameters.settings.max_time_step = Real(2e-3);
  parameters.settings.bounds.min = Vec3::Constant(-1);
  parameters.settings.bounds.max = Vec3::Constant(1);
  material::Material gel = material::newtonian("gel", 1000, 2);  // Pa·s: damps the spring-back
  gel.elasticity.enabled = elastic;
  gel.elasticity.shear_modulus = Real(1e4);
  gel.elasticity.relaxation_time = relaxation_time;
  parameters.phases.push_back(gel);
  sph::Solver solver(parameters);
  const auto points = lattice_block(8, 8, 16, d);
  solver.add_particles(points, Vec3::Zero(), 0);
  const double reference_length = height_of(solver);
  sph::State state = solver.state();
  const Real stretch = Real(1.2), squeeze = 1 / std::sqrt(stretch);
  for (Vec3& p : state.fluid.position) p = Vec3(p.x() * squeeze, p.y() * squeeze, p.z() * stretch);
  solver.restore(state);
  while (solver.time() < seconds) solver.step();
  return height_of(solver) / reference_length;
}

}  // namespace

TEST(Elasticity, AStretchedBlockSpringsBack) {
  const double elastic = stretched_block_length_after(true, 0.3);
  const double viscous = stretched_block_length_after(false, 0.3);
  // With a stress relaxation time of 5 ms the stretch is forgotten before it has sprung back far
  // (the spring-back takes about 10 ms).
  const double relaxing = stretched_block_length_after(true, 0.3, Real(0.005));
  std::printf("block stretched to 1.20 of its length, after 0.3 s: %.3f with G = 10 kPa, %.3f with G = 10 kPa relaxing "
              "in 5 ms, %.3f without elasticity\n",
              elastic, relaxing, viscous);
  EXPECT_NEAR(elastic, 1.0, 0.03);
  EXPECT_GT(viscous, 1.1);
  EXPECT_GT(relaxing, elastic + 0.03);
  EXPECT_LT(relaxing, viscous);
}

TEST(Elasticity, ASoftColumnSagsByItsWeightLikeLinearElasticity) {
  const Real d = Real(0.0025);
  const int high = 20;
  const double density = 1000, shear_modulus = 2000, g = 9.81, height = high * d;
  sph::Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.max_time_step = Real(2e-3);
  parameters.settings.bounds.min = Vec3(-1, -1, -0.1f);
  parameters.settings.bounds.max = Vec3(1, 1, 1);
  material::Material gel = material::newtonian("gel", Real(density), 20);  // Pa·s: damps the oscillation
  gel.elasticity.enabled = true;
  gel.elasticity.shear_modulus = Real(shear_modulus);
  parameters.phases.push_back(gel);
  sph::Solver solver(parameters);
  const BoxShape floor{Vec3(0.2f, 0.2f, 4 * d)};
  solver.add_body("floor", sph::sample_box_surface(floor, d, -d / 2).points, Pose{Vec3(0, 0, -2 * d), Quat::Identity()}, true);
    solver.add_particles(lattice_block(16, 16, high, d), Vec3::Zero(), 0);
  // The top layer's particles, followed by id (the solver reorders them).
  std::vector<std::uint64_t> top_layer;
  for (std::size_t i = 0; i < solver.fluid().size(); ++i)
    if (solver.fluid().position[i].z() > height - d) top_layer.push_back(solver.fluid().id[i]);
  auto top = [&] {
    double sum = 0;
    const auto& fluid = solver.fluid();
    for (std::size_t i = 0; i < fluid.size(); ++i)
      if (std::find(top_layer.begin(), top_layer.end(), fluid.id[i]) != top_layer.end()) sum += fluid.position[i].z();
    return sum / double(top_layer.size());
  };
  const double start = top();
  while (solver.time() < 0.5) solver.step();  // settled by 0.15 s (damped by the viscosity)
  const double sag = start - top();
  // Uniaxial stress, free to bulge (a smooth floor): strain ρg(H − z)/E integrated over the height.
  const double expected = density * g * height * height / (2 * gel.elasticity.youngs_modulus());
  std::printf("column %.0f mm high, G = %.0f Pa: top sank %.2f mm, linear elasticity %.2f mm: error %+.1f %% "
              "(tolerance 15 %%)\n",
              height * 1e3, shear_modulus, sag * 1e3, expected * 1e3, 100 * (sag / expected - 1));
  EXPECT_NEAR(sag / expected, 1.0, 0.15);
}
