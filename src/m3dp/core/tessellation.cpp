#include "m3dp/core/tessellation.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace m3dp {

namespace {

Index add_vertex(TriangleMesh& mesh, const Vec3& vertex) {
  mesh.vertices.push_back(vertex);
  return static_cast<Index>(mesh.vertices.size() - 1);
}

TriangleMesh box_triangles(const Vec3& size) {
  TriangleMesh mesh;
  const Vec3 half = size / 2;
  for (int corner = 0; corner < 8; ++corner)
    add_vertex(mesh, Vec3((corner & 1) ? half.x() : -half.x(), (corner & 2) ? half.y() : -half.y(), (corner & 4) ? half.z() : -half.z()));
  // Two triangles per face, each face's corners counter-clockwise seen from outside.
  const std::array<std::array<Index, 4>, 6> faces{{{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}}};
  for (const auto& face : faces) {
    mesh.triangles.push_back({face[0], face[1], face[2]});
    mesh.triangles.push_back({face[0], face[2], face[3]});
  }
  return mesh;
}

TriangleMesh sphere_triangles(Real radius, int segments) {
  TriangleMesh mesh;
  const int rings = std::max(2, segments / 2);
  const Index north = add_vertex(mesh, Vec3(0, 0, radius));
  for (int ring = 1; ring < rings; ++ring) {
    const Real polar = std::numbers::pi_v<Real> * static_cast<Real>(ring) / static_cast<Real>(rings);
    for (int s = 0; s < segments; ++s) {
      const Real azimuth = 2 * std::numbers::pi_v<Real> * static_cast<Real>(s) / static_cast<Real>(segments);
      add_vertex(mesh, radius * Vec3(std::sin(polar) * std::cos(azimuth), std::sin(polar) * std::sin(azimuth), std::cos(polar)));
    }
  }
  const Index south = add_vertex(mesh, Vec3(0, 0, -radius));
  auto at = [&](int ring, int s) { return static_cast<Index>(1 + (ring - 1) * segments + (s % segments)); };
  for (int s = 0; s < segments; ++s) {
    mesh.triangles.push_back({north, at(1, s), at(1, s + 1)});
    for (int ring = 1; ring + 1 < rings; ++ring) {
      mesh.triangles.push_back({at(ring, s), at(ring + 1, s), at(ring + 1, s + 1)});
      mesh.triangles.push_back({at(ring, s), at(ring + 1, s + 1), at(ring, s + 1)});
    }
    mesh.triangles.push_back({south, at(rings - 1, s + 1), at(rings - 1, s)});
  }
  return mesh;
}

TriangleMesh cylinder_triangles(Real radius, Real length, int segments) {
  TriangleMesh mesh;
  const Real half = length / 2;
  const Index top = add_vertex(mesh, Vec3(0, 0, half));
  const Index bottom = add_vertex(mesh, Vec3(0, 0, -half));
  for (int s = 0; s < segments; ++s) {
    const Real azimuth = 2 * std::numbers::pi_v<Real> * static_cast<Real>(s) / static_cast<Real>(segments);
    const Vec3 rim(radius * std::cos(azimuth), radius * std::sin(azimuth), 0);
    add_vertex(mesh, rim + Vec3(0, 0, half));
    add_vertex(mesh, rim - Vec3(0, 0, half));
  }
  auto upper = [&](int s) { return static_cast<Index>(2 + 2 * (s % segments)); };
  auto lower = [&](int s) { return static_cast<Index>(3 + 2 * (s % segments)); };
  for (int s = 0; s < segments; ++s) {
    mesh.triangles.push_back({top, upper(s), upper(s + 1)});
    mesh.triangles.push_back({bottom, lower(s + 1), lower(s)});
    mesh.triangles.push_back({lower(s), lower(s + 1), upper(s + 1)});
    mesh.triangles.push_back({lower(s), upper(s + 1), upper(s)});
  }
  return mesh;
}

TriangleMesh plane_triangles(const PlaneShape& plane) {
  const Vec3 normal = plane.normal.normalized();
  // In-plane axes as SDF takes them: the patch's x and y are the world's, turned onto the normal.
  const Quat turn = Quat::FromTwoVectors(Vec3::UnitZ(), normal);
  const Vec3 u = turn * Vec3::UnitX() * (plane.size_x / 2), v = turn * Vec3::UnitY() * (plane.size_y / 2);
  TriangleMesh mesh;
  mesh.vertices = {-u - v, u - v, u + v, -u + v};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
  return mesh;
}

}  // namespace

TriangleMesh tessellate(const Shape& shape, int segments) {
  segments = std::max(3, segments);
  return std::visit(
      [&](const auto& s) -> TriangleMesh {
        using T = std::decay_t<decltype(s)>;
        if constexpr (std::is_same_v<T, BoxShape>) return box_triangles(s.size);
        else if constexpr (std::is_same_v<T, SphereShape>) return sphere_triangles(s.radius, segments);
        else if constexpr (std::is_same_v<T, CylinderShape>) return cylinder_triangles(s.radius, s.length, segments);
        else if constexpr (std::is_same_v<T, PlaneShape>) return plane_triangles(s);
        else return s.mesh;
      },
      shape);
}

void append_transformed(const TriangleMesh& mesh, const Pose& pose, TriangleMesh& out) {
  const auto first = static_cast<Index>(out.vertices.size());
  for (const Vec3& vertex : mesh.vertices) out.vertices.push_back(pose.apply(vertex));
  for (const auto& triangle : mesh.triangles) out.triangles.push_back({triangle[0] + first, triangle[1] + first, triangle[2] + first});
}

}  // namespace m3dp
