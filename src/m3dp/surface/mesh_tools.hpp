#pragma once
// Measures and clean-up of triangle meshes: volume, area, watertightness, connected parts,
// orientation and Taubin smoothing. Used by surface reconstruction and its tests.
#include <cstddef>
#include <vector>

#include "m3dp/core/geometry.hpp"

namespace m3dp::surface {

/// Signed volume (m³) by the divergence theorem: positive when the triangles face outwards.
[[nodiscard]] double signed_volume(const TriangleMesh& mesh);
/// Area (m²) of a closed, outward-facing mesh's section by the plane where coordinate `axis` (0, 1, 2:
/// x, y, z) equals `coordinate` (m): the shoelace sum over the segments the triangles cut from it.
[[nodiscard]] double cross_section_area(const TriangleMesh& mesh, int axis, double coordinate);
/// Total area (m²).
[[nodiscard]] double surface_area(const TriangleMesh& mesh);

struct EdgeReport {
  std::size_t edges = 0;
  std::size_t boundary_edges = 0;      // used by one triangle: a hole
  std::size_t non_manifold_edges = 0;  // used by three or more triangles
  std::size_t inconsistent_edges = 0;  // two triangles walk it in the same direction (flipped faces)
  [[nodiscard]] bool watertight() const { return boundary_edges == 0 && non_manifold_edges == 0; }
};
/// Every edge of a closed, consistently oriented mesh is used by exactly two triangles, once each way.
[[nodiscard]] EdgeReport check_edges(const TriangleMesh& mesh);

/// Number of pieces: triangles that share a vertex belong to the same piece.
[[nodiscard]] std::size_t connected_components(const TriangleMesh& mesh);

/// Reverses every triangle's winding.
void flip_orientation(TriangleMesh& mesh);

/// Taubin 1995 λ|μ smoothing: alternating shrink (λ > 0) and inflate (μ < −λ) steps with the
/// umbrella operator. Keeps the volume far better than plain Laplacian smoothing.
void taubin_smooth(TriangleMesh& mesh, int iterations, Real lambda, Real mu);

/// Union–find over vertices joined by triangles: each vertex's piece, named by one of its vertices.
std::vector<Index> component_roots(const TriangleMesh& mesh);

/// Removes every closed piece that bounds a cavity (negative signed volume) smaller than
/// `max_volume` (m³). Returns how many were removed.
std::size_t remove_small_cavities(TriangleMesh& mesh, double max_volume);

/// Drops vertices no triangle uses and renumbers the rest.
void remove_unused_vertices(TriangleMesh& mesh);

}  // namespace m3dp::surface
