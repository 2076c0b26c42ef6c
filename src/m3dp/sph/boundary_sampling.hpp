#pragma once
// Samples collision shapes into boundary particles (one layer, spacing ≈ `spacing`), as Akinci et al.
// 2012 boundaries need. Points are in the shape's own frame.
//
// `offset` moves the layer along the outward normal; the solver passes minus one particle radius,
// putting the layer a radius *inside* the solid. Fluid particles then rest with their centres a radius
// in front of the surface, one full spacing from the layer — the spacing at which the SPH density sums
// to the rest density. A layer on the surface itself starts every fluid particle at a wall ~50 %
// over-dense. Sizes shrink to zero at most (a wall thinner than 2 radii becomes one mid-plane layer).
#include <vector>

#include "m3dp/core/geometry.hpp"

namespace m3dp::sph {

/// Points on a surface and the outward unit normal of the surface at each.
struct SurfaceSamples {
  std::vector<Vec3> points;
  std::vector<Vec3> normals;
  void add(const Vec3& point, const Vec3& normal) {
    points.push_back(point);
    normals.push_back(normal);
  }
};

SurfaceSamples sample_shape_surface(const Shape& shape, Real spacing, Real offset = 0);

/// A flat face's lattice of points, as the samplers lay them: point(i, j) for i in 0..count_a and j in
/// 0..count_b spans a size_a × size_b rectangle, rotated and offset into the shape's frame. The points
/// in [first_a, last_a] × [first_b, last_b] are the ones a TiledSurface leaves to be made later.
struct RectangleLattice {
  Mat3 rotation = Mat3::Identity();
  Vec3 offset = Vec3::Zero();
  Real size_a = 0, size_b = 0;
  int count_a = 1, count_b = 1;
  int first_a = 0, last_a = 0, first_b = 0, last_b = 0;

  [[nodiscard]] Vec3 point(int i, int j) const {
    const Vec3 local(size_a * (Real(i) / Real(count_a) - Real(0.5)), size_b * (Real(j) / Real(count_b) - Real(0.5)), 0);
    return rotation * local + offset;
  }
};

/// A shape's samples with the points of its wide flat faces left to be made where material comes
/// (Solver::add_static_surface): `now` and every `later` lattice's range together are exactly
/// sample_shape_surface's points (in another order). Boxes leave their faces' inner points, planes
/// all theirs, when a face has at least `min_points_later` of them; other shapes are sampled now.
struct TiledSurface {
  SurfaceSamples now;
  std::vector<RectangleLattice> later;
};
TiledSurface sample_shape_surface_tiled(const Shape& shape, Real spacing, Real offset, std::size_t min_points_later);
/// The shape's surface area (m², in double: a scene's sizes are checked before anything is sampled).
double shape_surface_area(const Shape& shape);
SurfaceSamples sample_box_surface(const BoxShape& box, Real spacing, Real offset = 0);
SurfaceSamples sample_sphere_surface(const SphereShape& sphere, Real spacing, Real offset = 0);
SurfaceSamples sample_cylinder_surface(const CylinderShape& cylinder, Real spacing, Real offset = 0);
/// The plane's solid side is behind its normal: a negative offset moves the layer behind the plane.
SurfaceSamples sample_plane(const PlaneShape& plane, Real spacing, Real offset = 0);
/// Offsets along area-weighted vertex normals (outward for a closed, counter-clockwise wound mesh).
SurfaceSamples sample_mesh_surface(const TriangleMesh& mesh, Real spacing, Real offset = 0);

/// Fluid particles on a cubic lattice of spacing `spacing` filling `box`, centres half a spacing in from
/// its faces. Whole particles only: a block never reaches past its box (into a wall at its edge).
std::vector<Vec3> lattice_in_box(const Aabb& box, Real spacing);

/// Removes points closer than `min_distance` to an earlier point (edges shared by faces, mesh seams).
void remove_close_points(SurfaceSamples& samples, Real min_distance);

}  // namespace m3dp::sph
