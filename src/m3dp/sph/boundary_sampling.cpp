#include "m3dp/sph/boundary_sampling.hpp"

#include <algorithm>
#include <cmath>

#include "m3dp/sph/neighbors/neighbor_search.hpp"

namespace m3dp::sph {

namespace {
int segments_for(Real length, Real spacing) { return std::max(1, static_cast<int>(std::ceil(length / spacing - Real(1e-4)))); }

RectangleLattice rectangle_lattice(Real size_a, Real size_b, Real spacing, const Mat3& rotation, const Vec3& offset) {
  RectangleLattice lattice;
  lattice.rotation = rotation, lattice.offset = offset, lattice.size_a = size_a, lattice.size_b = size_b;
  lattice.count_a = segments_for(size_a, spacing);
  lattice.count_b = segments_for(size_b, spacing);
  lattice.first_a = 0, lattice.last_a = lattice.count_a, lattice.first_b = 0, lattice.last_b = lattice.count_b;
  return lattice;
}

// Points on a rectangle [−a/2, a/2] × [−b/2, b/2] (z = 0), including its edges. `on_edge`, when
// given, gets for each point whether it lies on the rectangle's border. With `only_border`, the inner
// points are left out.
void add_rectangle(SurfaceSamples& samples, const RectangleLattice& lattice, const Vec3& normal, std::vector<char>* on_edge = nullptr,
                   bool only_border = false) {
  for (int i = 0; i <= lattice.count_a; ++i) {
    const bool border_a = i == 0 || i == lattice.count_a;
    for (int j = 0; j <= lattice.count_b; ++j) {
      const bool border = border_a || j == 0 || j == lattice.count_b;
      if (only_border && !border) {
        j = lattice.count_b - 1;  // on to the far border
        continue;
      }
      samples.add(lattice.point(i, j), normal);
      if (on_edge) on_edge->push_back(border);
    }
  }
}

// Which of `points` remove_close_points keeps: each one no earlier kept point is within `min_distance`
// of, among those marked in `candidates` (all when null); unmarked points are kept and never compared.
std::vector<char> kept_points(const std::vector<Vec3>& points, Real min_distance, const std::vector<char>* candidates = nullptr) {
  std::vector<Vec3> compared;
  std::vector<std::size_t> index_of;
  for (std::size_t i = 0; i < points.size(); ++i)
    if (!candidates || (*candidates)[i]) {
      compared.push_back(points[i]);
      index_of.push_back(i);
    }
  std::vector<char> keep(points.size(), 1);
  if (compared.empty()) return keep;
  SpatialHashGrid grid;
  grid.build(compared, min_distance);
  std::vector<char> kept(compared.size(), 1);
  const Real min_distance_squared = min_distance * min_distance;
  // Sequential on purpose: whether a point stays depends on the earlier points kept.
  for (std::size_t i = 0; i < compared.size(); ++i) {
    grid.for_each_candidate(compared[i], [&](Index j, const Vec3& position_j) {
      if (j < i && kept[j] && (compared[i] - position_j).squaredNorm() < min_distance_squared) kept[i] = 0;
    });
    keep[index_of[i]] = kept[i];
  }
  return keep;
}

void keep_only(SurfaceSamples& samples, const std::vector<char>& keep) {
  std::size_t kept = 0;
  for (std::size_t i = 0; i < samples.points.size(); ++i)
    if (keep[i]) {
      samples.points[kept] = samples.points[i];
      samples.normals[kept] = samples.normals[i];
      ++kept;
    }
  samples.points.resize(kept);
  samples.normals.resize(kept);
}

// Concentric rings on a disc of radius r in the z = 0 plane.
void add_disc(SurfaceSamples& samples, Real radius, Real spacing, Real z) {
  const Vec3 normal(0, 0, z >= 0 ? 1 : -1);
  samples.add(Vec3(0, 0, z), normal);
  const int rings = segments_for(radius, spacing);
  for (int ring = 1; ring <= rings; ++ring) {
    const Real ring_radius = radius * ring / rings;
    const int around = std::max(3, static_cast<int>(std::ceil(2 * kPi * ring_radius / spacing)));
    for (int k = 0; k < around; ++k) {
      const Real angle = 2 * kPi * k / around;
      samples.add(Vec3(ring_radius * std::cos(angle), ring_radius * std::sin(angle), z), normal);
    }
  }
}
}  // namespace

namespace {
/// A box's samples; with `later` given, the inner points of faces with at least `min_points_later`
/// of them are left out and their lattices go there instead.
SurfaceSamples sample_box(const BoxShape& inner_box, Real spacing, Real offset, std::vector<RectangleLattice>* later,
                          std::size_t min_points_later) {
  SurfaceSamples samples;
  const BoxShape box{(inner_box.size + Vec3::Constant(2 * offset)).cwiseMax(Real(0))};
  const Vec3 half = box.size / 2;
  const Mat3 identity = Mat3::Identity();
  Mat3 to_x;  // maps local (a, b, 0) to (0, a, b): faces normal to x
  to_x << 0, 0, 1, 1, 0, 0, 0, 1, 0;
  Mat3 to_y;  // maps (a, b, 0) to (a, 0, b): faces normal to y
  to_y << 1, 0, 0, 0, 0, 1, 0, 1, 0;
  // Faces meet only along the box's edges: with every side at least a spacing long, a face's inner
  // points are at least half a spacing from any other point, so only the faces' borders can repeat
  // (a 10 x 10 m floor at 5 mm: 8 million points, 32,000 on borders). A flatter box (a wall thinner
  // than the spacing, its two faces one over the other) takes the whole pass, and nothing is left.
  const bool only_borders_meet = (box.size.array() >= spacing).all();
  std::vector<char> on_edge;
  const auto face = [&](Real size_a, Real size_b, const Mat3& rotation, const Vec3& centre, const Vec3& normal) {
    RectangleLattice lattice = rectangle_lattice(size_a, size_b, spacing, rotation, centre);
    const std::size_t inner = std::size_t(std::max(0, lattice.count_a - 1)) * std::size_t(std::max(0, lattice.count_b - 1));
    const bool leave_inner = later && only_borders_meet && inner > 0 && inner >= min_points_later;
    add_rectangle(samples, lattice, normal, &on_edge, leave_inner);
    if (leave_inner) {
      lattice.first_a = 1, lattice.last_a = lattice.count_a - 1, lattice.first_b = 1, lattice.last_b = lattice.count_b - 1;
      later->push_back(lattice);
    }
  };
  for (int sign = -1; sign <= 1; sign += 2) {
    face(box.size.x(), box.size.y(), identity, Vec3(0, 0, sign * half.z()), Vec3(0, 0, sign));
    face(box.size.y(), box.size.z(), to_x, Vec3(sign * half.x(), 0, 0), Vec3(sign, 0, 0));
    face(box.size.x(), box.size.z(), to_y, Vec3(0, sign * half.y(), 0), Vec3(0, sign, 0));
  }
  if (only_borders_meet)
    keep_only(samples, kept_points(samples.points, spacing * Real(0.25), &on_edge));
  else
    remove_close_points(samples, spacing * Real(0.25));
  return samples;
}
}  // namespace

SurfaceSamples sample_box_surface(const BoxShape& inner_box, Real spacing, Real offset) {
  return sample_box(inner_box, spacing, offset, nullptr, 0);
}

SurfaceSamples sample_sphere_surface(const SphereShape& inner_sphere, Real spacing, Real offset) {
  const SphereShape sphere{std::max(Real(0), inner_sphere.radius + offset)};
  if (sphere.radius < spacing / 4) return SurfaceSamples{{Vec3::Zero()}, {Vec3::UnitZ()}};
  // Fibonacci lattice: near-uniform points, count from the area each should cover.
  const Real area = 4 * kPi * sphere.radius * sphere.radius;
  const int count = std::max(12, static_cast<int>(std::ceil(area / (spacing * spacing))));
  SurfaceSamples samples;
  const Real golden_angle = kPi * (Real(3) - std::sqrt(Real(5)));
  for (int i = 0; i < count; ++i) {
    const Real z = Real(1) - Real(2) * (Real(i) + Real(0.5)) / count;
    const Real ring = std::sqrt(std::max(Real(0), Real(1) - z * z));
    const Real angle = golden_angle * i;
    const Vec3 direction(ring * std::cos(angle), ring * std::sin(angle), z);
    samples.add(sphere.radius * direction, direction);
  }
  return samples;
}

SurfaceSamples sample_cylinder_surface(const CylinderShape& inner_cylinder, Real spacing, Real offset) {
  const CylinderShape cylinder{std::max(Real(0), inner_cylinder.radius + offset),
                               std::max(Real(0), inner_cylinder.length + 2 * offset)};
  SurfaceSamples samples;
  const int around = std::max(6, static_cast<int>(std::ceil(2 * kPi * cylinder.radius / spacing)));
  const int along = segments_for(cylinder.length, spacing);
  for (int i = 0; i <= along; ++i) {
    const Real z = cylinder.length * (Real(i) / along - Real(0.5));
    for (int k = 0; k < around; ++k) {
      const Real angle = 2 * kPi * k / around;
      const Vec3 direction(std::cos(angle), std::sin(angle), 0);
      samples.add(cylinder.radius * direction + Vec3(0, 0, z), direction);
    }
  }
  add_disc(samples, cylinder.radius, spacing, -cylinder.length / 2);
  add_disc(samples, cylinder.radius, spacing, cylinder.length / 2);
  remove_close_points(samples, spacing * Real(0.25));
  return samples;
}

namespace {
RectangleLattice plane_lattice(const PlaneShape& plane, Real spacing, Real offset) {
  const Vec3 normal = plane.normal.normalized();
  const Mat3 rotation = Quat::FromTwoVectors(Vec3::UnitZ(), normal).toRotationMatrix();
  return rectangle_lattice(plane.size_x, plane.size_y, spacing, rotation, offset * normal);
}
}  // namespace

SurfaceSamples sample_plane(const PlaneShape& plane, Real spacing, Real offset) {
  SurfaceSamples samples;
  add_rectangle(samples, plane_lattice(plane, spacing, offset), plane.normal.normalized());
  return samples;
}

TiledSurface sample_shape_surface_tiled(const Shape& shape, Real spacing, Real offset, std::size_t min_points_later) {
  TiledSurface surface;
  if (const auto* box = std::get_if<BoxShape>(&shape)) {
    surface.now = sample_box(*box, spacing, offset, &surface.later, min_points_later);
  } else if (const auto* plane = std::get_if<PlaneShape>(&shape)) {
    const RectangleLattice lattice = plane_lattice(*plane, spacing, offset);
    if (std::size_t(lattice.count_a + 1) * std::size_t(lattice.count_b + 1) >= min_points_later)
      surface.later.push_back(lattice);
    else
      surface.now = sample_plane(*plane, spacing, offset);
  } else {
    surface.now = sample_shape_surface(shape, spacing, offset);
  }
  return surface;
}

SurfaceSamples sample_mesh_surface(const TriangleMesh& input_mesh, Real spacing, Real offset) {
  TriangleMesh mesh = input_mesh;
  if (offset != 0) {
    std::vector<Vec3> normals(mesh.vertices.size(), Vec3::Zero());
    for (const auto& triangle : mesh.triangles) {
      const Vec3 area_normal = (input_mesh.vertices[triangle[1]] - input_mesh.vertices[triangle[0]])
                                   .cross(input_mesh.vertices[triangle[2]] - input_mesh.vertices[triangle[0]]);
      for (const Index vertex : triangle) normals[vertex] += area_normal;
    }
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
      if (normals[v].squaredNorm() > 0) mesh.vertices[v] += offset * normals[v].normalized();
  }
  SurfaceSamples samples;
  std::vector<Vec3> vertex_normals(mesh.vertices.size(), Vec3::Zero());
  for (const auto& triangle : mesh.triangles) {
    const Vec3 area_normal = (mesh.vertices[triangle[1]] - mesh.vertices[triangle[0]]).cross(mesh.vertices[triangle[2]] - mesh.vertices[triangle[0]]);
    for (const Index vertex : triangle) vertex_normals[vertex] += area_normal;
  }
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v) samples.add(mesh.vertices[v], vertex_normals[v].normalized());
  for (const auto& triangle : mesh.triangles) {
    const Vec3& a = mesh.vertices[triangle[0]];
    const Vec3& b = mesh.vertices[triangle[1]];
    const Vec3& c = mesh.vertices[triangle[2]];
    // A barycentric grid fine enough for the longest edge; duplicates on shared edges are removed below.
    const Real longest = std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
    const Vec3 face_normal = (b - a).cross(c - a).normalized();
    const int divisions = segments_for(longest, spacing);
    for (int i = 0; i <= divisions; ++i)
      for (int j = 0; j <= divisions - i; ++j) {
        const Real u = Real(i) / divisions;
        const Real v = Real(j) / divisions;
        samples.add(a + u * (b - a) + v * (c - a), face_normal);
      }
  }
  remove_close_points(samples, spacing * Real(0.6));
  return samples;
}

SurfaceSamples sample_shape_surface(const Shape& shape, Real spacing, Real offset) {
  return std::visit(
      [&](const auto& concrete) -> SurfaceSamples {
        using T = std::decay_t<decltype(concrete)>;
        if constexpr (std::is_same_v<T, BoxShape>) return sample_box_surface(concrete, spacing, offset);
        if constexpr (std::is_same_v<T, SphereShape>) return sample_sphere_surface(concrete, spacing, offset);
        if constexpr (std::is_same_v<T, CylinderShape>) return sample_cylinder_surface(concrete, spacing, offset);
        if constexpr (std::is_same_v<T, PlaneShape>) return sample_plane(concrete, spacing, offset);
        if constexpr (std::is_same_v<T, MeshShape>) return sample_mesh_surface(concrete.mesh, spacing, offset);
      },
      shape);
}

void remove_close_points(SurfaceSamples& samples, Real min_distance) {
  if (samples.points.empty()) return;
  keep_only(samples, kept_points(samples.points, min_distance));
}

double shape_surface_area(const Shape& shape) {
  constexpr double pi = 3.14159265358979323846;
  return std::visit(
      [&](const auto& concrete) -> double {
        using T = std::decay_t<decltype(concrete)>;
        if constexpr (std::is_same_v<T, BoxShape>) {
          const double x = concrete.size.x(), y = concrete.size.y(), z = concrete.size.z();
          return 2 * (x * y + y * z + z * x);
        } else if constexpr (std::is_same_v<T, SphereShape>) {
          return 4 * pi * double(concrete.radius) * concrete.radius;
        } else if constexpr (std::is_same_v<T, CylinderShape>) {
          return 2 * pi * double(concrete.radius) * (concrete.radius + concrete.length);
        } else if constexpr (std::is_same_v<T, PlaneShape>) {
          return double(concrete.size_x) * concrete.size_y;
        } else {
          double area = 0;
          for (const auto& t : concrete.mesh.triangles)
            area += 0.5 * (concrete.mesh.vertices[t[1]] - concrete.mesh.vertices[t[0]]).template cast<double>()
                              .cross((concrete.mesh.vertices[t[2]] - concrete.mesh.vertices[t[0]]).template cast<double>())
                              .norm();
          return area;
        }
      },
      shape);
}

std::vector<Vec3> lattice_in_box(const Aabb& box, Real spacing) {
  std::vector<Vec3> points;
  const Vec3 size = box.size();
  auto count_along = [&](Real length) { return std::max(1, static_cast<int>(std::floor(length / spacing + Real(1e-3)))); };
  const int nx = count_along(size.x()), ny = count_along(size.y()), nz = count_along(size.z());
  points.reserve(static_cast<std::size_t>(nx) * ny * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) points.push_back(box.min + spacing * Vec3(i + Real(0.5), j + Real(0.5), k + Real(0.5)));
  return points;
}

}  // namespace m3dp::sph
