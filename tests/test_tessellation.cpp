// Collision shapes as triangles (what world.pvd, run.mcap and the live stream draw): closed,
// outward-facing surfaces whose enclosed volume is the shape's, where the pose puts them.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <utility>

#include "m3dp/core/tessellation.hpp"
#include "m3dp/surface/mesh_tools.hpp"

namespace {

using namespace m3dp;
using surface::signed_volume;

/// Every edge shared by exactly two triangles that run it in opposite directions: a closed, consistently oriented surface.
void expect_closed(const TriangleMesh& mesh) {
  std::map<std::pair<Index, Index>, int> directed;
  for (const auto& triangle : mesh.triangles)
    for (int e = 0; e < 3; ++e) ++directed[{triangle[e], triangle[(e + 1) % 3]}];
  for (const auto& [edge, count] : directed) {
    EXPECT_EQ(count, 1) << "edge " << edge.first << "-" << edge.second << " run " << count << " times the same way";
    EXPECT_EQ(directed.count({edge.second, edge.first}), 1u) << "edge " << edge.first << "-" << edge.second << " is open";
  }
}

TEST(Tessellation, BoxIsClosedWithItsVolume) {
  const TriangleMesh box = tessellate(BoxShape{Vec3(0.2f, 0.3f, 0.5f)});
  expect_closed(box);
  EXPECT_NEAR(signed_volume(box), 0.2 * 0.3 * 0.5, 1e-7);  // positive: faces point outward
}

TEST(Tessellation, SphereAndCylinderConvergeToTheirVolumes) {
  const double pi = std::acos(-1.0);
  for (const int segments : {12, 24, 48}) {
    const TriangleMesh sphere = tessellate(SphereShape{0.1f}, segments);
    const TriangleMesh cylinder = tessellate(CylinderShape{0.05f, 0.4f}, segments);
    expect_closed(sphere);
    expect_closed(cylinder);
    // Inscribed polyhedra: a little smaller, by the chords' sagitta, O(1/segments²).
    const double sphere_error = signed_volume(sphere) / (4.0 / 3.0 * pi * 1e-3) - 1;
    const double cylinder_error = signed_volume(cylinder) / (pi * 0.05 * 0.05 * 0.4) - 1;
    const double bound = 4 * pi * pi / (segments * segments);
    EXPECT_LT(sphere_error, 0) << segments;
    EXPECT_GT(sphere_error, -bound) << segments;
    EXPECT_LT(cylinder_error, 0) << segments;
    EXPECT_GT(cylinder_error, -bound) << segments;
  }
}

TEST(Tessellation, PlaneFacesAlongItsNormal) {
  const TriangleMesh plane = tessellate(PlaneShape{Vec3(1, 0, 0), 2, 4});
  ASSERT_EQ(plane.triangles.size(), 2u);
  for (const auto& t : plane.triangles) {
    const Vec3 normal = (plane.vertices[t[1]] - plane.vertices[t[0]]).cross(plane.vertices[t[2]] - plane.vertices[t[0]]);
    EXPECT_GT(normal.normalized().x(), 0.999f);
    EXPECT_NEAR(normal.norm() / 2, 4, 1e-5);  // half the 2 × 4 patch
  }
}

TEST(Tessellation, AppendedShapesMoveByTheirPose) {
  TriangleMesh out = tessellate(BoxShape{Vec3(1, 1, 1)});
  const Pose pose = Pose::from_xyz_rpy(1, 2, 3, 0, 0, 0.5f);
  append_transformed(tessellate(SphereShape{0.5f}), pose, out);
  expect_closed(out);
  Vec3 centre = Vec3::Zero();
  for (std::size_t v = 8; v < out.vertices.size(); ++v) {
    EXPECT_NEAR((out.vertices[v] - pose.position).norm(), 0.5, 1e-5);
    centre += out.vertices[v];
  }
  EXPECT_LT((centre / static_cast<Real>(out.vertices.size() - 8) - pose.position).norm(), 1e-5);
}

}  // namespace
