#include <gtest/gtest.h>

#include <cmath>

#include <algorithm>
#include <array>
#include <map>

#include "m3dp/core/state_io.hpp"
#include "m3dp/material/material.hpp"
#include "m3dp/sph/boundary_sampling.hpp"
#include "m3dp/sph/kernels.hpp"
#include "m3dp/sph/solver.hpp"
#include "m3dp/sph/neighbors/neighbor_search.hpp"

using namespace m3dp;
using namespace m3dp::sph;

namespace {
Real nearest_neighbor_distance(const std::vector<Vec3>& points, std::size_t i) {
  Real best = 1e9f;
  for (std::size_t j = 0; j < points.size(); ++j)
    if (j != i) best = std::min(best, (points[i] - points[j]).norm());
  return best;
}
}  // namespace

TEST(BoundarySampling, BoxPointsLieOnTheSurfaceAtAboutTheSpacing) {
  const Real spacing = Real(0.01);
  const BoxShape box{Vec3(0.1f, 0.06f, 0.04f)};
  const auto samples = sample_box_surface(box, spacing);
  const auto& points = samples.points;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Vec3 distance_to_face = (box.size / 2 - points[i].cwiseAbs());
    EXPECT_NEAR(distance_to_face.minCoeff(), 0, 1e-6) << "point " << i << " is not on a face";
    // The normal is the outward normal of a face the point lies on.
    const Vec3& normal = samples.normals[i];
    EXPECT_NEAR(normal.norm(), 1, 1e-6);
    EXPECT_NEAR(points[i].dot(normal), (box.size / 2).cwiseProduct(normal.cwiseAbs()).sum(), 1e-6);
    EXPECT_LE(nearest_neighbor_distance(points, i), spacing * Real(1.001));
    EXPECT_GE(nearest_neighbor_distance(points, i), spacing * Real(0.25));
  }
  const double area = 2 * (0.1 * 0.06 + 0.1 * 0.04 + 0.06 * 0.04);
  EXPECT_NEAR(points.size(), area / (spacing * spacing), 0.4 * area / (spacing * spacing));
}

TEST(BoundarySampling, EachPointOfABoxSurfaceOnceWhereItsFacesMeet) {
  // Each face a lattice with its border; faces share edges, corners are on three: the surface holds
  // sum(faces) - 4 (a + b + c) + 8 points (a, b, c the points along x, y, z). Boxes whose sides all
  // exceed the spacing compare only the faces' borders; a thinner one (its two faces nearly one over
  // the other) compares every point, and keeps one of each close pair.
  const Real spacing = Real(0.01);
  for (const Vec3& size : {Vec3(0.1f, 0.06f, 0.04f), Vec3(0.537f, 0.3f, 0.0134f), Vec3(2.0f, 1.5f, 0.05f)}) {
    const auto samples = sample_box_surface(BoxShape{size}, spacing);
    const auto along = [&](Real length) { return std::max(1, int(std::ceil(length / spacing - Real(1e-4)))) + 1; };
    const long a = along(size.x()), b = along(size.y()), c = along(size.z());
    EXPECT_EQ(long(samples.points.size()), 2 * (a * b + b * c + a * c) - 4 * (a + b + c) + 8) << size.transpose();
    // No two points closer than a quarter spacing (the grid finds every close pair).
    SpatialHashGrid grid;
    grid.build(samples.points, spacing / 4);
    std::size_t close = 0;
    for (std::size_t i = 0; i < samples.points.size(); ++i)
      grid.for_each_candidate(samples.points[i], [&](Index j, const Vec3& other) {
        close += j != i && (samples.points[i] - other).norm() < spacing / 4;
      });
    EXPECT_EQ(close, 0u) << size.transpose();
  }
  const auto thin = sample_box_surface(BoxShape{Vec3(0.1f, 0.1f, 0.002f)}, spacing);
  // A plate 0.2 spacings thick: one layer of 11 x 11, its bottom and sides within a quarter spacing of it.
  EXPECT_EQ(thin.points.size(), 11u * 11u);
}

TEST(BoundarySampling, SphereAndCylinderPointsLieOnTheSurface) {
  const auto sphere = sample_sphere_surface(SphereShape{0.05f}, 0.005f);
  for (std::size_t i = 0; i < sphere.points.size(); ++i) {
    EXPECT_NEAR(sphere.points[i].norm(), 0.05f, 1e-6);
    EXPECT_NEAR((sphere.normals[i] - sphere.points[i] / 0.05f).norm(), 0, 1e-5);
  }
  EXPECT_NEAR(sphere.points.size(), 4 * kPi * 0.05 * 0.05 / (0.005 * 0.005), 2);
  // Sampled a radius inside: the layer a fluid particle rests a full spacing from.
  for (const auto& p : sample_sphere_surface(SphereShape{0.05f}, 0.005f, -0.0025f).points) EXPECT_NEAR(p.norm(), 0.0475f, 1e-6);
  const CylinderShape cylinder{0.02f, 0.1f};
  for (const auto& p : sample_cylinder_surface(cylinder, 0.004f).points) {
    const bool on_side = std::abs(p.head<2>().norm() - cylinder.radius) < 1e-6 && std::abs(p.z()) <= cylinder.length / 2 + 1e-6;
    const bool on_cap = std::abs(std::abs(p.z()) - cylinder.length / 2) < 1e-6 && p.head<2>().norm() <= cylinder.radius + 1e-6;
    EXPECT_TRUE(on_side || on_cap);
  }
}

TEST(BoundarySampling, MeshSamplesCoverTrianglesWithoutDuplicates) {
  TriangleMesh square;
  square.vertices = {Vec3(0, 0, 0), Vec3(0.1f, 0, 0), Vec3(0.1f, 0.1f, 0), Vec3(0, 0.1f, 0)};
  square.triangles = {{0, 1, 2}, {0, 2, 3}};
  const auto points = sample_mesh_surface(square, 0.01f).points;
  for (std::size_t i = 0; i < points.size(); ++i) {
    EXPECT_NEAR(points[i].z(), 0, 1e-7);
    EXPECT_GE(nearest_neighbor_distance(points, i), 0.006f);
  }
  // Every point of the square is within a spacing of a sample.
  for (int i = 0; i <= 10; ++i)
    for (int j = 0; j <= 10; ++j) {
      const Vec3 q(i * 0.01f, j * 0.01f, 0);
      Real best = 1;
      for (const auto& p : points) best = std::min(best, (p - q).norm());
      EXPECT_LT(best, 0.01f);
    }
}

TEST(BoundarySampling, PlaneFollowsItsNormal) {
  const auto points = sample_plane(PlaneShape{Vec3(1, 0, 0), 0.2f, 0.1f}, 0.01f).points;
  for (const auto& p : points) EXPECT_NEAR(p.x(), 0, 1e-6);
  EXPECT_EQ(points.size(), 21u * 11u);
  for (const auto& p : sample_plane(PlaneShape{Vec3(1, 0, 0), 0.2f, 0.1f}, 0.01f, -0.005f).points) EXPECT_NEAR(p.x(), -0.005f, 1e-6);
}

// A tank of overlapping static boxes added one at a time, and a moving body beside them: each static
// particle's Akinci volume is 1 / Σ_k W over every static particle (walls that meet are not counted
// twice), though add_body sums again only the particles near the body it adds; a moving body's over
// its own particles only.
TEST(BoundarySampling, StaticVolumesSummedOverEveryStaticParticleWhenBodiesAreAddedOneByOne) {
  const Real d = Real(0.01);
  Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.phases.push_back(material::newtonian("water", 1000, Real(1e-3)));
  Solver solver(parameters);
  const BoxShape wall{Vec3(0.3f, 0.02f, 0.2f)}, floor{Vec3(0.3f, 0.3f, 0.02f)};
  const auto place = [](Real x, Real y, Real z) { return Pose{Vec3(x, y, z), Quat::Identity()}; };
  solver.add_body("floor", sample_box_surface(floor, d).points, place(0, 0, 0), true);
  solver.add_body("far floor", sample_box_surface(floor, d).points, place(2, 0, 0), true);  // beyond every support
  solver.add_body("moving", sample_box_surface(BoxShape{Vec3(0.05f, 0.05f, 0.05f)}, d).points, place(0, 0, 0.05f), false);
  solver.add_body("wall 1", sample_box_surface(wall, d).points, place(0, 0.14f, 0.1f), true);
  solver.add_body("wall 2", sample_box_surface(wall, d).points, place(0, -0.14f, 0.1f), true);
  const auto& boundary = solver.state().boundary;
  const auto& bodies = solver.state().bodies;
  const Real support = solver.model().support_radius;
  const CubicSplineKernel kernel(support);
  std::size_t checked = 0;
  Real largest_error = 0;
  for (std::size_t k = 0; k < boundary.size(); k += 7) {  // every 7th: a brute-force sum each
    const bool is_static = bodies[boundary.body[k]].is_static;
    Real sum = 0;
    for (std::size_t j = 0; j < boundary.size(); ++j) {
      const bool together = is_static ? bodies[boundary.body[j]].is_static : boundary.body[j] == boundary.body[k];
      if (together) sum += kernel.W((boundary.position[k] - boundary.position[j]).norm());
    }
    largest_error = std::max(largest_error, std::abs(boundary.volume[k] * sum / solver.model().boundary_volume_scale - 1));
    ++checked;
  }
  EXPECT_GT(checked, 1000u);
  EXPECT_LT(largest_error, Real(1e-5));
}

namespace {
/// Points as exact bit patterns, sorted: two samplings hold the same points when these are equal.
std::vector<std::array<Real, 3>> sorted_points(const std::vector<Vec3>& points) {
  std::vector<std::array<Real, 3>> sorted;
  for (const Vec3& p : points) sorted.push_back({p.x(), p.y(), p.z()});
  std::sort(sorted.begin(), sorted.end());
  return sorted;
}
}  // namespace

// A tiled sampling leaves the wide faces' lattices for later: its points now and the lattices' points
// together are the whole sampling's, bit for bit (a floor box: its top and bottom faces' inner points).
TEST(BoundarySampling, TiledSurfacesHoldTheWholeSamplingsPoints) {
  const Real d = Real(0.005);
  for (const Shape& shape : {Shape{BoxShape{Vec3(1.0f, 0.6f, 0.1f)}}, Shape{PlaneShape{Vec3(0, 0.6f, 0.8f), 0.9f, 0.7f}}}) {
    const SurfaceSamples whole = sample_shape_surface(shape, d, -d / 2);
    const TiledSurface tiled = sample_shape_surface_tiled(shape, d, -d / 2, 4096);
    ASSERT_FALSE(tiled.later.empty());
    std::vector<Vec3> points = tiled.now.points;
    for (const RectangleLattice& lattice : tiled.later)
      for (int i = lattice.first_a; i <= lattice.last_a; ++i)
        for (int j = lattice.first_b; j <= lattice.last_b; ++j) points.push_back(lattice.point(i, j));
    std::printf("%zu points, %zu of them now\n", whole.points.size(), tiled.now.points.size());
    EXPECT_LT(tiled.now.points.size(), whole.points.size() / 4);
    EXPECT_TRUE(sorted_points(points) == sorted_points(whole.points));
  }
}

namespace {
/// A paste block settling on a 2 × 2 m floor box, its walls sampled whole or made where the paste comes.
Solver paste_on_a_floor(bool lazy) {
  const Real d = Real(0.01);
  Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.bounds.min = Vec3(-1.5f, -1.5f, -0.5f);
  parameters.settings.bounds.max = Vec3(1.5f, 1.5f, 1.0f);
  parameters.phases.push_back(material::newtonian("paste", 1500, 50));
  Solver solver(parameters);
  const BoxShape floor{Vec3(2.0f, 2.0f, 0.1f)};
  const Pose pose{Vec3(0.3f, -0.2f, -0.05f), Quat(Eigen::AngleAxis<Real>(Real(0.3), Vec3::UnitZ()))};
  if (lazy)
    solver.add_static_surface("floor", sample_shape_surface_tiled(floor, d, -d / 2, 4096), pose);
  else
    solver.add_body("floor", sample_box_surface(floor, d, -d / 2).points, pose, true);
  std::vector<Vec3> block;
  for (int x = 0; x < 10; ++x)
    for (int y = 0; y < 10; ++y)
      for (int z = 0; z < 8; ++z) block.push_back(Vec3(x * d, y * d, d / 2 + z * d + Real(0.02)));
  solver.add_particles(block, Vec3::Zero(), 0);
  return solver;
}
}  // namespace

// The lazy floor holds the tiles under the paste only, each wall particle near the paste has the
// volume it has in the whole floor, and the paste settles on it as on the whole floor (rounding apart:
// the particles' order differs, and a falling block amplifies it); a state saved mid-run and loaded
// into a fresh solver, which had made fewer tiles, goes on bit for bit.
TEST(BoundarySampling, LazyWallsAreMadeUnderTheMaterialAndActAsTheWholeWall) {
  Solver whole = paste_on_a_floor(false), lazy = paste_on_a_floor(true);
  for (int step = 0; step < 60; ++step) whole.step(), lazy.step();
  const auto& state = lazy.state();
  std::printf("boundary particles: whole %zu, lazy %zu (%zu tiles)\n", whole.state().boundary.size(), state.boundary.size(),
              state.made_tiles.size());
  EXPECT_LT(state.boundary.size(), whole.state().boundary.size() / 4);
  // Volumes: every lazy wall particle within reach of the paste against the whole floor's at its place.
  std::map<std::array<Real, 3>, Real> whole_volume;
  for (std::size_t k = 0; k < whole.state().boundary.size(); ++k) {
    const Vec3& p = whole.state().boundary.position[k];
    whole_volume[{p.x(), p.y(), p.z()}] = whole.state().boundary.volume[k];
  }
  Aabb paste;
  for (const Vec3& p : lazy.fluid().position) paste.extend(p);
  const Real reach = 2 * lazy.model().support_radius;
  std::size_t compared = 0;
  Real largest_volume_error = 0;
  for (std::size_t k = 0; k < state.boundary.size(); ++k) {
    const Vec3& p = state.boundary.position[k];
    if (((p.array() < paste.min.array() - reach).any() || (p.array() > paste.max.array() + reach).any())) continue;
    const auto found = whole_volume.find({p.x(), p.y(), p.z()});
    ASSERT_NE(found, whole_volume.end()) << "a wall particle the whole floor does not have";
    largest_volume_error = std::max(largest_volume_error, std::abs(state.boundary.volume[k] / found->second - 1));
    ++compared;
  }
  std::printf("%zu wall particles near the paste: largest volume difference %.3g\n", compared, largest_volume_error);
  EXPECT_GT(compared, 500u);
  EXPECT_LT(largest_volume_error, Real(1e-5));
  ASSERT_EQ(whole.fluid().size(), lazy.fluid().size());
  // The block as a whole: where it stands and how low it reaches (single particles part by rounding).
  Real lowest_whole = 1, lowest_lazy = 1;
  Vec3 centre_whole = Vec3::Zero(), centre_lazy = Vec3::Zero();
  for (const Vec3& p : lazy.fluid().position) lowest_lazy = std::min(lowest_lazy, p.z()), centre_lazy += p;
  for (const Vec3& p : whole.fluid().position) lowest_whole = std::min(lowest_whole, p.z()), centre_whole += p;
  centre_lazy /= Real(lazy.fluid().size()), centre_whole /= Real(whole.fluid().size());
  const Real d = lazy.particle_diameter();
  std::printf("lowest particle: whole %.5f m, lazy %.5f m; centres %.3g m apart\n", lowest_whole, lowest_lazy, (centre_lazy - centre_whole).norm());
  EXPECT_NEAR(lowest_lazy, lowest_whole, Real(0.05) * d);  // on the floor as on the whole one
  EXPECT_LT((centre_lazy - centre_whole).norm(), Real(0.02) * d);

  // Saved after 60 steps, loaded into a fresh solver (which made only the tiles its block needed).
  StateWriter out;
  save_state(state, out);
  Solver resumed = paste_on_a_floor(true);
  {
    State loaded = resumed.state();
    StateReader in(out.bytes(), "test");
    load_state(in, loaded);
    resumed.restore(loaded);
  }
  for (int step = 0; step < 40; ++step) lazy.step(), resumed.step();
  EXPECT_TRUE(lazy.fluid().position == resumed.fluid().position);
  EXPECT_TRUE(lazy.state().boundary.position == resumed.state().boundary.position);
}
