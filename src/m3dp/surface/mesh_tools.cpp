#include "m3dp/surface/mesh_tools.hpp"

#include <algorithm>
#include <array>
#include <cstdint>
#include <numeric>
#include <vector>

namespace m3dp::surface {

namespace {
/// Directed edge key: (from, to) packed in 64 bits.
std::uint64_t edge_key(Index from, Index to) { return (std::uint64_t(from) << 32) | std::uint64_t(to); }

Eigen::Vector3d as_double(const Vec3& v) { return v.cast<double>(); }
}  // namespace

double signed_volume(const TriangleMesh& mesh) {
  double six_volume = 0;
  for (const auto& t : mesh.triangles)
    six_volume += as_double(mesh.vertices[t[0]]).dot(as_double(mesh.vertices[t[1]]).cross(as_double(mesh.vertices[t[2]])));
  return six_volume / 6;
}

double cross_section_area(const TriangleMesh& mesh, int axis, double coordinate) {
  const int u = (axis + 1) % 3, v = (axis + 2) % 3;  // the plane's axes, u × v along the normal
  const Eigen::Vector3d normal = Eigen::Vector3d::Unit(axis);
  double twice_area = 0;
  for (const auto& t : mesh.triangles) {
    const std::array<Eigen::Vector3d, 3> corner = {as_double(mesh.vertices[t[0]]), as_double(mesh.vertices[t[1]]),
                                                   as_double(mesh.vertices[t[2]])};
    std::array<double, 3> height{};
    for (int k = 0; k < 3; ++k) height[k] = corner[k][axis] - coordinate;
    // A corner on the plane counts as below it, so that each cut edge is cut once.
    std::array<Eigen::Vector3d, 2> cut;
    int cuts = 0;
    for (int k = 0; k < 3; ++k) {
      const int next = (k + 1) % 3;
      if ((height[k] > 0) == (height[next] > 0)) continue;
      const double fraction = height[k] / (height[k] - height[next]);
      if (cuts < 2) cut[cuts] = corner[k] + fraction * (corner[next] - corner[k]);
      ++cuts;
    }
    if (cuts != 2) continue;
    // The section's boundary runs along normal × (the face's outward normal): anticlockwise around it.
    const Eigen::Vector3d face_normal = (corner[1] - corner[0]).cross(corner[2] - corner[0]);
    if ((cut[1] - cut[0]).dot(normal.cross(face_normal)) < 0) std::swap(cut[0], cut[1]);
    twice_area += cut[0][u] * cut[1][v] - cut[0][v] * cut[1][u];
  }
  return twice_area / 2;
}

double surface_area(const TriangleMesh& mesh) {
  double area = 0;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = as_double(mesh.vertices[t[0]]);
    area += 0.5 * (as_double(mesh.vertices[t[1]]) - a).cross(as_double(mesh.vertices[t[2]]) - a).norm();
  }
  return area;
}

EdgeReport check_edges(const TriangleMesh& mesh) {
  // Directed half-edges, sorted: an undirected edge is the pair {a→b, b→a}.
  std::vector<std::uint64_t> half_edges;
  half_edges.reserve(mesh.triangles.size() * 3);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) half_edges.push_back(edge_key(t[k], t[(k + 1) % 3]));
  std::vector<std::uint64_t> undirected(half_edges.size());
  std::transform(half_edges.begin(), half_edges.end(), undirected.begin(), [](std::uint64_t key) {
    const auto from = Index(key >> 32), to = Index(key & 0xffffffffu);
    return edge_key(std::min(from, to), std::max(from, to));
  });
  std::sort(half_edges.begin(), half_edges.end());
  std::sort(undirected.begin(), undirected.end());
  EdgeReport report;
  for (std::size_t i = 0; i < undirected.size();) {
    std::size_t j = i;
    while (j < undirected.size() && undirected[j] == undirected[i]) ++j;
    ++report.edges;
    const std::size_t uses = j - i;
    if (uses == 1) ++report.boundary_edges;
    if (uses > 2) ++report.non_manifold_edges;
    i = j;
  }
  for (std::size_t i = 1; i < half_edges.size(); ++i)
    if (half_edges[i] == half_edges[i - 1]) ++report.inconsistent_edges;
  return report;
}

std::vector<Index> component_roots(const TriangleMesh& mesh) {
  std::vector<Index> parent(mesh.vertices.size());
  std::iota(parent.begin(), parent.end(), Index(0));
  auto find = [&](Index v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& t : mesh.triangles) {
    parent[find(t[1])] = find(t[0]);
    parent[find(t[2])] = find(t[0]);
  }
  for (Index v = 0; v < parent.size(); ++v) parent[v] = find(v);
  return parent;
}

std::size_t connected_components(const TriangleMesh& mesh) {
  const std::vector<Index> root = component_roots(mesh);
  std::vector<bool> is_root_used(mesh.vertices.size(), false);
  for (const auto& t : mesh.triangles) is_root_used[root[t[0]]] = true;
  return static_cast<std::size_t>(std::count(is_root_used.begin(), is_root_used.end(), true));
}

std::size_t remove_small_cavities(TriangleMesh& mesh, double max_volume) {
  const std::vector<Index> root = component_roots(mesh);
  std::vector<double> six_volume(mesh.vertices.size(), 0.0);
  for (const auto& t : mesh.triangles)
    six_volume[root[t[0]]] += as_double(mesh.vertices[t[0]]).dot(as_double(mesh.vertices[t[1]]).cross(as_double(mesh.vertices[t[2]])));
  std::vector<bool> drop(mesh.vertices.size(), false);
  std::size_t removed = 0;
  for (std::size_t v = 0; v < drop.size(); ++v)
    if (root[v] == v && six_volume[v] < 0 && -six_volume[v] / 6 < max_volume) {
      drop[v] = true;
      ++removed;
    }
  if (removed == 0) return 0;
  std::erase_if(mesh.triangles, [&](const std::array<Index, 3>& t) { return drop[root[t[0]]]; });
  remove_unused_vertices(mesh);
  return removed;
}

void flip_orientation(TriangleMesh& mesh) {
  for (auto& t : mesh.triangles) std::swap(t[1], t[2]);
}

void taubin_smooth(TriangleMesh& mesh, int iterations, Real lambda, Real mu) {
  if (iterations <= 0 || mesh.triangles.empty()) return;
  const std::size_t vertex_count = mesh.vertices.size();
  // Vertex neighbours as compressed rows (each undirected edge once per end).
  std::vector<std::uint64_t> edges;
  edges.reserve(mesh.triangles.size() * 6);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      edges.push_back(edge_key(t[k], t[(k + 1) % 3]));
      edges.push_back(edge_key(t[(k + 1) % 3], t[k]));
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<Index> row_start(vertex_count + 1, 0);
  std::vector<Index> neighbor(edges.size());
  for (const auto key : edges) ++row_start[(key >> 32) + 1];
  std::partial_sum(row_start.begin(), row_start.end(), row_start.begin());
  for (std::size_t e = 0; e < edges.size(); ++e) neighbor[e] = Index(edges[e] & 0xffffffffu);

  std::vector<Vec3> moved(vertex_count);
  auto umbrella_step = [&](Real factor) {
    for (std::size_t v = 0; v < vertex_count; ++v) {
      const Index begin = row_start[v], end = row_start[v + 1];
      if (begin == end) {
        moved[v] = mesh.vertices[v];
        continue;
      }
      Vec3 mean = Vec3::Zero();
      for (Index e = begin; e < end; ++e) mean += mesh.vertices[neighbor[e]];
      mean /= Real(end - begin);
      moved[v] = mesh.vertices[v] + factor * (mean - mesh.vertices[v]);
    }
    mesh.vertices.swap(moved);
  };
  for (int iteration = 0; iteration < iterations; ++iteration) {
    umbrella_step(lambda);
    umbrella_step(mu);
  }
}

void remove_unused_vertices(TriangleMesh& mesh) {
  constexpr Index kUnused = ~Index(0);
  std::vector<Index> new_index(mesh.vertices.size(), kUnused);
  for (const auto& t : mesh.triangles)
    for (const Index v : t) new_index[v] = 0;
  Index next = 0;
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
    if (new_index[v] != kUnused) {
      new_index[v] = next;
      mesh.vertices[next++] = mesh.vertices[v];
    }
  mesh.vertices.resize(next);
  for (auto& t : mesh.triangles)
    for (Index& v : t) v = new_index[v];
}

}  // namespace m3dp::surface
