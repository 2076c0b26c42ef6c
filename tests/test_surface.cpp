// Surface reconstruction: closed, outward meshes of the right size and shape for every method.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/surface/mesh_tools.hpp"
#include "m3dp/surface/surface.hpp"

using namespace m3dp;
using namespace m3dp::surface;

namespace {

constexpr Real kRadius = Real(0.005);  // particle radius r (m); spacing 2r
constexpr Real kSpacing = 2 * kRadius;

/// Cubic-lattice particles (spacing 2r) whose centres lie inside a ball of radius R. The lattice
/// is offset by half a spacing, as a block of particles fills space from its faces.
std::vector<Vec3> ball(const Vec3& centre, Real ball_radius) {
  std::vector<Vec3> points;
  const int reach = static_cast<int>(std::ceil(ball_radius / kSpacing)) + 1;
  for (int i = -reach; i <= reach; ++i)
    for (int j = -reach; j <= reach; ++j)
      for (int k = -reach; k <= reach; ++k) {
        const Vec3 offset((i + Real(0.5)) * kSpacing, (j + Real(0.5)) * kSpacing, (k + Real(0.5)) * kSpacing);
        if (offset.norm() < ball_radius) points.push_back(centre + offset);
      }
  return points;
}

/// A block of nx × ny × nz particles filling [0, n·2r] on each axis.
std::vector<Vec3> block(int nx, int ny, int nz, const Vec3& corner = Vec3::Zero()) {
  std::vector<Vec3> points;
  for (int i = 0; i < nx; ++i)
    for (int j = 0; j < ny; ++j)
      for (int k = 0; k < nz; ++k)
        points.push_back(corner + Vec3((i + Real(0.5)) * kSpacing, (j + Real(0.5)) * kSpacing, (k + Real(0.5)) * kSpacing));
  return points;
}

SurfaceSettings settings_for(Method method) {
  SurfaceSettings settings;
  settings.method = method;
  settings.particle_radius = kRadius;
  return settings;
}

class EveryMethod : public ::testing::TestWithParam<Method> {};

std::string name_of(const ::testing::TestParamInfo<Method>& info) { return std::string(method_name(info.param)); }

}  // namespace

TEST_P(EveryMethod, BallIsClosedOutwardAndOfTheRightSize) {
  const Real ball_radius = 16 * kRadius;
  const Vec3 centre(Real(0.3), Real(-0.2), Real(0.1));
  const auto particles = ball(centre, ball_radius);
  SurfaceStats stats;
  const TriangleMesh mesh = reconstruct_surface(particles, settings_for(GetParam()), &stats);
  ASSERT_FALSE(mesh.triangles.empty());

  const double volume = signed_volume(mesh);
  const double reference_volume = 4.0 / 3.0 * kPi * std::pow(ball_radius, 3);
  const double area = surface_area(mesh);
  const double reference_area = 4 * kPi * ball_radius * ball_radius;
  const double volume_error = volume / reference_volume - 1;
  const double area_error = area / reference_area - 1;
  const EdgeReport edges = check_edges(mesh);
  std::size_t inward = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3 a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], c = mesh.vertices[t[2]];
    if ((b - a).cross(c - a).dot((a + b + c) / 3 - centre) < 0) ++inward;
  }
  std::printf("%s: %zu particles, %zu triangles, volume %+.2f %%, area %+.2f %%, %zu boundary / %zu non-manifold edges, "
              "%zu inward triangles, %zu active voxels, %.3f s + %.3f s\n",
              std::string(method_name(GetParam())).c_str(), particles.size(), mesh.triangles.size(), 100 * volume_error,
              100 * area_error, edges.boundary_edges, edges.non_manifold_edges, inward, stats.active_voxels,
              stats.field_seconds, stats.mesh_seconds);

  EXPECT_TRUE(edges.watertight());
  EXPECT_EQ(edges.inconsistent_edges, 0u);
  EXPECT_EQ(connected_components(mesh), 1u);
  // Sections through the centre are the disc of the mesh's own ball (R from its volume), along
  // every axis; a plane past the ball cuts nothing.
  const double mesh_ball_radius = std::cbrt(3 * volume / (4 * kPi));
  for (int axis = 0; axis < 3; ++axis) {
    const double section = cross_section_area(mesh, axis, centre[axis]);
    const double error = section / (kPi * mesh_ball_radius * mesh_ball_radius) - 1;
    std::printf("  section through the centre across axis %d: %+.2f %% of pi R^2 (tolerance 3 %%)\n", axis, 100 * error);
    EXPECT_LT(std::abs(error), 0.03) << "axis " << axis;
  }
  EXPECT_EQ(cross_section_area(mesh, 2, centre.z() + 1.5 * ball_radius), 0.0);
  if (GetParam() == Method::spherical) {
    // A union of spheres is bumpy by design: its area is no measure of the ball's, and dimples
    // between spheres face sideways. Its volume overshoots by the spheres' overlap past the face.
    EXPECT_GT(volume_error, 0.0);
    EXPECT_LT(volume_error, 0.10);
    return;
  }
  EXPECT_EQ(inward, 0u);
  // Issue 4: volume within 3 % and area within 5 % (asked of anisotropic and Zhu–Bridson; the blobby
  // field meets it too).
  EXPECT_LT(std::abs(volume_error), 0.03);
  EXPECT_LT(std::abs(area_error), 0.05);
}

TEST(Surface, SphericalFieldIsTheOneOpenVdbRasterises) {
  // M3DP gathers the union of spheres per leaf node instead of calling ParticlesToLevelSet (four
  // times slower). The two grids must agree voxel for voxel and tile for tile, bit for bit: a lattice
  // ball straddling the origin (negative leaf coordinates), a random cloud with close pairs, a
  // cloud far from the origin (where index-space rounding shows), and spheres larger than the band.
  std::vector<Vec3> cloud = ball(Vec3(Real(0.01), Real(-0.02), Real(0.003)), 9 * kRadius);
  std::uint32_t state = 12345;
  auto uniform = [&] {
    state = state * 1664525u + 1013904223u;
    return static_cast<Real>(state >> 8) / static_cast<Real>(1 << 24);
  };
  for (int n = 0; n < 400; ++n)
    cloud.push_back(Vec3(Real(0.2) + 30 * kRadius * uniform(), -30 * kRadius * uniform(), 30 * kRadius * uniform()));
  for (int n = 0; n < 400; ++n)
    cloud.push_back(Vec3(Real(-7.3) + 30 * kRadius * uniform(), Real(5.1) - 30 * kRadius * uniform(), Real(3.7) + 30 * kRadius * uniform()));
  for (const Real sphere_in_voxels : {Real(1.5), Real(2.0), Real(3.3)}) {
    const Real voxel = kRadius * Real(0.8);
    const auto comparison = detail::compare_spherical_field_with_openvdb(cloud, sphere_in_voxels * voxel, voxel);
    std::printf("sphere %.1f voxels: %zu active voxels (ParticlesToLevelSet %zu), %zu differ in activity, "
                "largest value difference %.3g m\n",
                sphere_in_voxels, comparison.active_voxels, comparison.reference_active_voxels,
                comparison.activity_mismatches, comparison.max_difference);
    EXPECT_GT(comparison.active_voxels, 10000u);
    EXPECT_EQ(comparison.active_voxels, comparison.reference_active_voxels);
    EXPECT_EQ(comparison.activity_mismatches, 0u);
    EXPECT_EQ(comparison.max_difference, 0.0);
  }
}

TEST(Surface, FlatSlabTopIsFlatAndInPlace) {
  // 30 × 30 × 8 particles: the top face is at z = 8 · 2r. Vertices of the top face away from the
  // edges should lie on it: rms deviation below 0.25 r (issue 4, anisotropic).
  const auto particles = block(30, 30, 8);
  const Real top = 8 * kSpacing;
  for (const Method method : {Method::anisotropic, Method::sph_blobby, Method::zhu_bridson}) {
    const TriangleMesh mesh = reconstruct_surface(particles, settings_for(method));
    double squared = 0;
    std::size_t count = 0;
    for (const Vec3& v : mesh.vertices) {
      if (v.x() < 8 * kSpacing || v.x() > 22 * kSpacing || v.y() < 8 * kSpacing || v.y() > 22 * kSpacing || v.z() < top / 2) continue;
      squared += (v.z() - top) * (v.z() - top);
      ++count;
    }
    ASSERT_GT(count, 100u);
    const double rms_in_radii = std::sqrt(squared / count) / kRadius;
    std::printf("%s: top face rms deviation %.3f r over %zu vertices (limit 0.25 r)\n", std::string(method_name(method)).c_str(),
                rms_in_radii, count);
    EXPECT_LT(rms_in_radii, 0.25) << method_name(method);
  }
}

TEST(Surface, SeparateBlobsGiveSeparatePiecesAndAStrandStaysWhole) {
  // Two blocks 6 spacings apart (beyond every kernel's reach) are two pieces...
  std::vector<Vec3> particles = block(6, 6, 6);
  const auto second = block(6, 6, 6, Vec3(12 * kSpacing, 0, 0));
  particles.insert(particles.end(), second.begin(), second.end());
  // ...and a printed strand, 2 × 2 particles across and 60 long, is one piece.
  const auto strand = block(60, 2, 2);
  for (const Method method : {Method::spherical, Method::sph_blobby, Method::zhu_bridson, Method::anisotropic}) {
    const auto blobs = reconstruct_surface(particles, settings_for(method));
    EXPECT_EQ(connected_components(blobs), 2u) << method_name(method);
    EXPECT_TRUE(check_edges(blobs).watertight()) << method_name(method);
    const auto strand_mesh = reconstruct_surface(strand, settings_for(method));
    EXPECT_EQ(connected_components(strand_mesh), 1u) << method_name(method);
    EXPECT_TRUE(check_edges(strand_mesh).watertight()) << method_name(method);
    // A section two particles across comes out rounded (a circle in the 2r × 2r square would be
    // −21 %), so only a collapse or a bloat is an error here.
    const double strand_volume = 60 * 2 * 2 * std::pow(kSpacing, 3);
    std::printf("%s: strand volume %+.1f %% of the particles'\n", std::string(method_name(method)).c_str(),
                100 * (signed_volume(strand_mesh) / strand_volume - 1));
    EXPECT_GT(signed_volume(strand_mesh) / strand_volume, 0.6) << method_name(method);
    EXPECT_LT(signed_volume(strand_mesh) / strand_volume, 1.25) << method_name(method);
  }
}

TEST(Surface, NoParticlesGiveAnEmptyMeshAndBadSettingsAnError) {
  EXPECT_TRUE(reconstruct_surface({}, settings_for(Method::anisotropic)).triangles.empty());
  SurfaceSettings bad = settings_for(Method::sph_blobby);
  bad.particle_radius = 0;
  const std::vector<Vec3> one{Vec3::Zero()};
  EXPECT_THROW((void)reconstruct_surface(one, bad), Error);
  bad.particle_radius = kRadius;
  bad.iso_level = Real(1.5);
  EXPECT_THROW((void)reconstruct_surface(one, bad), Error);
  // A blown-up frame: the error names the particle; so does a position beyond the grid's reach.
  for (const Method method : {Method::spherical, Method::sph_blobby, Method::zhu_bridson, Method::anisotropic}) {
    std::vector<Vec3> frame = ball(Vec3::Zero(), 4 * kRadius);
    frame.push_back(Vec3(0, std::nan(""), 0));
    try {
      (void)reconstruct_surface(frame, settings_for(method));
      ADD_FAILURE() << method_name(method) << ": no error for a NaN particle";
    } catch (const Error& error) {
      EXPECT_NE(std::string(error.what()).find("particle " + std::to_string(frame.size() - 1) + " of"), std::string::npos)
          << error.what();
    }
  }
  const std::vector<Vec3> far{Vec3(Real(1e6), 0, 0)};
  try {
    (void)reconstruct_surface(far, settings_for(Method::spherical));
    ADD_FAILURE() << "no error for a particle 1000 km away";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("beyond the grid's reach"), std::string::npos) << error.what();
  }
}

TEST(Surface, MethodNamesRoundTrip) {
  for (const Method method : {Method::spherical, Method::sph_blobby, Method::zhu_bridson, Method::anisotropic})
    EXPECT_EQ(parse_method(method_name(method)), method);
  EXPECT_FALSE(parse_method("marching_squares").has_value());
}

INSTANTIATE_TEST_SUITE_P(Surface, EveryMethod,
                         ::testing::Values(Method::spherical, Method::sph_blobby, Method::zhu_bridson, Method::anisotropic),
                         name_of);

namespace {

/// One 20 × 4 layer of a printed wall, `layer` layers up, its particles shaken off the lattice by up
/// to 0.15 spacings (a fixed pseudo-random pattern) as deposited material is.
std::vector<Vec3> wall_layer(int layer) {
  std::vector<Vec3> points = block(20, 4, 1, Vec3(0, 0, layer * kSpacing));
  for (std::size_t n = 0; n < points.size(); ++n) {
    const Real phase = Real(n * 7 + layer * 13);
    points[n] += Real(0.15) * kSpacing * Vec3(std::sin(phase), std::cos(1.3f * phase), std::sin(2.1f * phase));
  }
  return points;
}

}  // namespace

TEST(IncrementalSurface, KeepsTheRestingFieldAndMeshesWhatTheWholeFrameGives) {
  // A wall printed layer by layer: in frame f the layers below f rest and layer f still moves. Each
  // frame adds only the layer that came to rest since the last one to the kept field.
  for (const Method method : {Method::spherical, Method::sph_blobby, Method::anisotropic}) {
    IncrementalSurface incremental(settings_for(method));
    std::vector<Vec3> resting;
    std::vector<std::uint64_t> ids;
    double worst_volume = 0, worst_triangles = 0;
    for (int frame = 0; frame < 6; ++frame) {
      if (frame > 0) {
        for (const Vec3& p : wall_layer(frame - 1)) {
          ids.push_back(resting.size());
          resting.push_back(p);
        }
      }
      const auto moving = wall_layer(frame);
      SurfaceStats stats;
      const TriangleMesh mesh = incremental.reconstruct(moving, resting, ids, &stats);
      std::vector<Vec3> all = moving;
      all.insert(all.end(), resting.begin(), resting.end());
      const TriangleMesh whole = reconstruct_surface(all, settings_for(method));
      EXPECT_EQ(stats.reused_particles, frame > 1 ? resting.size() - 80 : 0u) << method_name(method) << " frame " << frame;
      EXPECT_EQ(stats.added_particles, frame > 0 ? 80u : 0u) << method_name(method) << " frame " << frame;
      EXPECT_FALSE(stats.rebuilt);
      // Kernels under the new layer are remade (they were the flat kernels of a top face).
      if (method == Method::anisotropic && frame > 1) {
        EXPECT_GT(stats.refreshed_kernels, 0u) << "frame " << frame;
      }
      EXPECT_TRUE(check_edges(mesh).watertight()) << method_name(method) << " frame " << frame;
      EXPECT_EQ(connected_components(mesh), connected_components(whole)) << method_name(method) << " frame " << frame;
      worst_volume = std::max(worst_volume, std::abs(signed_volume(mesh) / signed_volume(whole) - 1));
      worst_triangles = std::max(worst_triangles, std::abs(double(mesh.triangles.size()) / double(whole.triangles.size()) - 1));
    }
    std::printf("%s: incremental against whole-frame meshes, largest difference: volume %.4f %%, triangles %.3f %%\n",
                std::string(method_name(method)).c_str(), 100 * worst_volume, 100 * worst_triangles);
    // A union and sums split into parts: the same field up to rounding.
    EXPECT_LT(worst_volume, 1e-4) << method_name(method);
    EXPECT_LT(worst_triangles, 1e-3) << method_name(method);
  }
}

namespace {
/// The mesh's triangles as corner coordinates, each started at its smallest corner (orientation
/// kept) and sorted: equal for two meshes with the same triangles in any order and numbering.
std::vector<std::array<Real, 9>> canonical_triangles(const TriangleMesh& mesh) {
  std::vector<std::array<Real, 9>> result;
  auto less = [](const Vec3& a, const Vec3& b) { return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3); };
  for (const auto& t : mesh.triangles) {
    int first = 0;
    for (int k = 1; k < 3; ++k)
      if (less(mesh.vertices[t[k]], mesh.vertices[t[first]])) first = k;
    std::array<Real, 9> corners;
    for (int k = 0; k < 3; ++k)
      for (int axis = 0; axis < 3; ++axis) corners[3 * k + axis] = mesh.vertices[t[(first + k) % 3]][axis];
    result.push_back(corners);
  }
  std::sort(result.begin(), result.end());
  return result;
}
}  // namespace

TEST(IncrementalSurface, MeshesOnlyTheTilesWhereTheFieldChanged) {
  // A long resting wall (8 tiles of 32 voxels long) and a blob moving along its top at one end:
  // each frame meshes again only the tiles around the blob, now and one frame before, and the mesh
  // has the whole frame's triangles.
  // The wall straddles the origin on every axis: tiles on both sides of zero (negative keys).
  const Vec3 corner(-60 * kSpacing, Real(-1.5) * kSpacing, -2 * kSpacing);
  std::vector<Vec3> resting = block(120, 3, 4, corner);
  std::vector<std::uint64_t> ids(resting.size());
  std::iota(ids.begin(), ids.end(), std::uint64_t(0));
  for (const Method method : {Method::spherical, Method::sph_blobby, Method::zhu_bridson, Method::anisotropic}) {
    IncrementalSurface incremental(settings_for(method));
    for (int frame = 0; frame < 3; ++frame) {
      const auto moving = block(3, 3, 2, corner + Vec3((4 + Real(0.3) * frame) * kSpacing, 0, 4 * kSpacing));
      SurfaceStats stats;
      const TriangleMesh mesh = incremental.reconstruct(moving, resting, ids, &stats);
      std::vector<Vec3> all = moving;
      all.insert(all.end(), resting.begin(), resting.end());
      const TriangleMesh whole = reconstruct_surface(all, settings_for(method));
      std::printf("%s frame %d: %zu of %zu tiles meshed, %zu triangles (whole frame %zu)\n",
                  std::string(method_name(method)).c_str(), frame, stats.remeshed_tiles, stats.mesh_tiles,
                  mesh.triangles.size(), whole.triangles.size());
      if (method == Method::spherical || method == Method::zhu_bridson) {
        // The same field bit for bit (a union; a field made whole): the same triangles exactly.
        EXPECT_TRUE(canonical_triangles(mesh) == canonical_triangles(whole)) << method_name(method) << " frame " << frame;
      } else {
        // Kept and moving parts summed apart differ from one sum in the last bits of the field.
        EXPECT_EQ(mesh.triangles.size(), whole.triangles.size()) << method_name(method) << " frame " << frame;
        EXPECT_NEAR(signed_volume(mesh) / signed_volume(whole), 1.0, 1e-5) << method_name(method) << " frame " << frame;
      }
      EXPECT_TRUE(check_edges(mesh).watertight()) << method_name(method) << " frame " << frame;
      EXPECT_GE(stats.mesh_tiles, 8u);
      if (frame == 0) {
        EXPECT_EQ(stats.remeshed_tiles, stats.mesh_tiles);
      } else {
        EXPECT_LE(stats.remeshed_tiles, stats.mesh_tiles / 3) << method_name(method) << " frame " << frame;
        EXPECT_GT(stats.remeshed_tiles, 0u);
      }
    }
  }
}

TEST(IncrementalSurface, RebuildsWhenARestingParticleWakesOrMoves) {
  IncrementalSurface incremental(settings_for(Method::sph_blobby));
  std::vector<Vec3> resting = block(10, 4, 3);
  std::vector<std::uint64_t> ids(resting.size());
  for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = i;
  SurfaceStats stats;
  (void)incremental.reconstruct({}, resting, ids, &stats);
  EXPECT_EQ(stats.added_particles, resting.size());
  (void)incremental.reconstruct({}, resting, ids, &stats);
  EXPECT_EQ(stats.reused_particles, resting.size());
  EXPECT_EQ(stats.added_particles, 0u);
  // Particle 7 woke up (it moves now), and particle 3 moved and rested again.
  const Vec3 woken = resting[7];
  resting[3].z() += kSpacing;
  std::vector<Vec3> still_resting;
  std::vector<std::uint64_t> still_ids;
  for (std::size_t i = 0; i < resting.size(); ++i)
    if (i != 7) {
      still_resting.push_back(resting[i]);
      still_ids.push_back(ids[i]);
    }
  const std::vector<Vec3> moving{woken + Vec3(0, 0, 4 * kSpacing)};
  const TriangleMesh mesh = incremental.reconstruct(moving, still_resting, still_ids, &stats);
  EXPECT_TRUE(stats.rebuilt);
  EXPECT_EQ(stats.reused_particles, 0u);
  std::vector<Vec3> all = moving;
  all.insert(all.end(), still_resting.begin(), still_resting.end());
  const TriangleMesh whole = reconstruct_surface(all, settings_for(Method::sph_blobby));
  EXPECT_NEAR(signed_volume(mesh), signed_volume(whole), 1e-4 * signed_volume(whole));
  const std::vector<std::uint64_t> too_few_ids(still_ids.begin(), still_ids.end() - 1);
  EXPECT_THROW((void)incremental.reconstruct(moving, still_resting, too_few_ids), Error);
}

TEST(IncrementalSurface, SavedFramesTreatUnmovedParticlesAsResting) {
  // Frames as m3dp run saves them: a block that stays put and a layer that moves on top of it.
  const std::vector<Vec3> still = block(10, 4, 3);
  IncrementalSurface incremental(settings_for(Method::spherical));
  for (int frame = 0; frame < 3; ++frame) {
    std::vector<Vec3> positions = still;
    std::vector<std::uint64_t> ids(still.size());
    for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = 1000 + i;
    for (const Vec3& p : block(10, 4, 1, Vec3(frame * kRadius, 0, 3 * kSpacing))) {
      ids.push_back(positions.size() + 1000);
      positions.push_back(p);
    }
    SurfaceStats stats;
    const TriangleMesh mesh = incremental.reconstruct_frame(positions, ids, &stats);
    EXPECT_EQ(stats.reused_particles, frame >= 2 ? still.size() : 0u) << "frame " << frame;
    EXPECT_EQ(stats.added_particles, frame >= 1 ? still.size() * (frame == 1) : 0u) << "frame " << frame;
    const TriangleMesh whole = reconstruct_surface(positions, settings_for(Method::spherical));
    EXPECT_EQ(mesh.triangles.size(), whole.triangles.size()) << "frame " << frame;
  }
}
