// Particle fields to meshes on sparse OpenVDB grids: the table of methods (each filled by its file in
// methods/), the tiled mesher and the incremental cache of resting material. See surface.hpp.
#include <openvdb/openvdb.h>
#include <openvdb/tools/Composite.h>
#include <openvdb/tools/ParticlesToLevelSet.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <openvdb/tree/LeafManager.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <fmt/format.h>

#include <chrono>
#include <climits>
#include <cmath>
#include <map>
#include <mutex>
#include <set>
#include <bit>
#include <numeric>
#include <unordered_map>
#include <unordered_set>

#include "m3dp/core/error.hpp"
#include "m3dp/sph/kernels.hpp"
#include "m3dp/sph/neighbors/neighbor_search.hpp"
#include "m3dp/surface/methods/anisotropic_yu_turk2013.hpp"
#include "m3dp/surface/mesh_tools.hpp"
#include "m3dp/surface/field.hpp"
#include "m3dp/surface/surface.hpp"

namespace m3dp::surface {

/// The table of methods: each is its file's FieldMethod (one row per method).
extern const FieldMethod kSphericalMethod, kSphBlobbyMethod, kZhuBridsonMethod, kAnisotropicMethod;
constexpr const FieldMethod* kFieldMethods[] = {&kSphericalMethod, &kSphBlobbyMethod, &kZhuBridsonMethod, &kAnisotropicMethod};

namespace {

/// Throws for a particle that is not finite (a blown-up frame): every grid key below would be garbage.
void check_finite(std::span<const Vec3> positions) {
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!positions[i].allFinite())
      throw Error(fmt::format("surface reconstruction: particle {} of {} is not finite ({}, {}, {})", i, positions.size(),
                              positions[i].x(), positions[i].y(), positions[i].z()));
}

TriangleMesh extract_mesh(const openvdb::FloatGrid& grid, double isovalue) {
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(grid, points, triangles, quads, isovalue, /*adaptivity=*/0.0);
  TriangleMesh mesh;
  mesh.vertices.reserve(points.size());
  for (const auto& p : points) mesh.vertices.emplace_back(p.x(), p.y(), p.z());
  mesh.triangles.reserve(triangles.size() + 2 * quads.size());
  for (const auto& t : triangles) mesh.triangles.push_back({t[0], t[1], t[2]});
  for (const auto& q : quads) {
    mesh.triangles.push_back({q[0], q[1], q[2]});
    mesh.triangles.push_back({q[0], q[2], q[3]});
  }
  return mesh;
}

/// A field and the value of the surface in it.
struct Field {
  openvdb::FloatGrid::Ptr grid;
  double isovalue = 0;
};

/// Volume fractions are stored negated (see methods/sph_blobby.cpp); level sets have their surface at 0.
double isovalue_of(const SurfaceSettings& settings) {
  return field_method(settings.method).volume_fraction ? -static_cast<double>(settings.iso_level) : 0.0;
}

/// The field of `positions` by `settings.method` (resolved settings).
Field field_of(std::span<const Vec3> positions, const SurfaceSettings& settings, SurfaceStats& stats, const FieldInputs& inputs = {}) {
  const auto transform = openvdb::math::Transform::createLinearTransform(settings.voxel_size);
  return {field_method(settings.method).field(positions, settings, transform, stats, inputs), isovalue_of(settings)};
}

/// `into` becomes the field of both particle sets; `from` is emptied. Level sets combine by union
/// (min), volume fractions by sum: both are exactly the field of the union of the sets.
void merge_field(Method method, openvdb::FloatGrid& into, openvdb::FloatGrid& from) {
  if (field_method(method).volume_fraction)
    openvdb::tools::compSum(into, from);
  else
    openvdb::tools::csgUnion(into, from);
}

/// Marks inside every active voxel that is outside (≥ 0) while all 26 around it are inside: the
/// voxel-sized pockets a union of spheres leaves between a lattice's spheres (a cell's centre is
/// √3 r from its corners, farther than the spheres' 1.5 r). Meshed, each is a closed inside-out
/// shell of 12 triangles inside its 8 cubes, which remove_small_cavities drops again whenever
/// 8 voxels³ ≤ the particle volume; half the triangles of a near-lattice frame were such shells.
/// The value of the voxel does not matter once no cube around it has an outside corner.
std::size_t fill_voxel_pockets(openvdb::FloatGrid& grid) {
  std::vector<openvdb::Coord> pockets;
  std::mutex pockets_mutex;
  openvdb::tree::LeafManager<const openvdb::FloatTree> leaves(grid.constTree());
  leaves.foreach([&](const openvdb::FloatTree::LeafNodeType& leaf, std::size_t) {
    auto accessor = grid.getConstAccessor();
    std::vector<openvdb::Coord> found;
    for (auto voxel = leaf.cbeginValueOn(); voxel; ++voxel) {
      if (*voxel < 0) continue;
      const openvdb::Coord ijk = voxel.getCoord();
      bool enclosed = true;
      for (int dx = -1; dx <= 1 && enclosed; ++dx)
        for (int dy = -1; dy <= 1 && enclosed; ++dy)
          for (int dz = -1; dz <= 1 && enclosed; ++dz)
            if ((dx | dy | dz) != 0 && !(accessor.getValue(ijk.offsetBy(dx, dy, dz)) < 0)) enclosed = false;
      if (enclosed) found.push_back(ijk);
    }
    if (found.empty()) return;
    const std::lock_guard lock(pockets_mutex);
    pockets.insert(pockets.end(), found.begin(), found.end());
  });
  const float inside = -grid.background();
  auto accessor = grid.getAccessor();
  for (const openvdb::Coord& ijk : pockets) accessor.setValueOnly(ijk, inside);
  return pockets.size();
}

/// Meshes a field tile by tile (cubes of 32 voxels) and keeps each tile's triangles until the field
/// around the tile changes, so that incremental meshing's mesher cost follows what changed (issue 4).
/// A tile is meshed from a copy of the field over the tile and one leaf (8 voxels) around it by
/// OpenVDB's mesher, and keeps the polygons whose centroid rounds to one of its own voxels. In dual
/// contouring a polygon joins the points of the 4 cubes around a sign-changing edge, each point
/// inside its cube, so a kept polygon's cubes lie within 2 voxels of the tile: it is made from the
/// field's true values, the same as in the whole field's mesh, and the copy's cut (which the mesher
/// closes) stays 4 voxels away. The tiles' meshes are joined by welding bit-equal points near
/// the tiles' faces (two distinct mesher points that coincide exactly, which needs a voxel value
/// equal to the iso-value, would be joined there and not elsewhere). A tile is meshed again when
/// a hash of the field over its copy changes.
class TiledMesher {
 public:
  struct Result {
    TriangleMesh mesh;
    std::size_t tiles = 0, meshed_tiles = 0;
  };

  /// Outward, closed where the material is. `fill_pockets`: fill_voxel_pockets in each tile's copy
  /// (as in the whole field). `max_cavity_volume` > 0: drop inside-out pieces smaller (m³).
  Result mesh(const openvdb::FloatGrid& grid, double isovalue, bool fill_pockets, double max_cavity_volume) {
    using LeafT = openvdb::FloatTree::LeafNodeType;
    const openvdb::FloatTree& tree = grid.tree();
    std::set<std::uint64_t> keys;  // the tiles to mesh or reuse
    // Every tile whose copy (the tile and one leaf-sized block around) holds a block from
    // `low` to `high` (block indices: voxel >> 3).
    auto add_tiles_holding = [&](const openvdb::Coord& low, const openvdb::Coord& high) {
      std::array<std::array<int, 2>, 3> range;
      for (int axis = 0; axis < 3; ++axis)
        range[axis] = {floor_divide(low[axis] - 1, kTileBlocks), floor_divide(high[axis] + 1, kTileBlocks)};
      for (int x = range[0][0]; x <= range[0][1]; ++x)
        for (int y = range[1][0]; y <= range[1][1]; ++y)
          for (int z = range[2][0]; z <= range[2][1]; ++z) keys.insert(coord_key(openvdb::Coord(x, y, z)));
    };
    auto block_of = [](const openvdb::Coord& voxel) {
      return openvdb::Coord(voxel.x() >> LeafT::LOG2DIM, voxel.y() >> LeafT::LOG2DIM, voxel.z() >> LeafT::LOG2DIM);
    };
    for (auto leaf = tree.cbeginLeaf(); leaf; ++leaf) add_tiles_holding(block_of(leaf->origin()), block_of(leaf->origin()));
    // Active tiles above the leaf level (a fill of whole leaf-sized blocks or more): the mesher also
    // makes surfaces at their borders, leaves or not.
    auto tile_value = tree.cbeginValueOn();
    tile_value.setMaxDepth(openvdb::FloatTree::ValueOnCIter::LEAF_DEPTH - 1);
    for (; tile_value; ++tile_value) {
      openvdb::CoordBBox box;
      tile_value.getBoundingBox(box);
      box.expand(1);
      add_tiles_holding(block_of(box.min()), block_of(box.max()));
    }
    const std::vector<std::uint64_t> tile_keys(keys.begin(), keys.end());
    std::map<std::uint64_t, Tile> previous;
    previous.swap(tiles_);
    std::vector<Tile> made(tile_keys.size());
    std::vector<char> was_meshed(tile_keys.size(), 0);
    const double voxel = grid.voxelSize()[0];
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, tile_keys.size(), 1), [&](const auto& range) {
      for (std::size_t n = range.begin(); n != range.end(); ++n) {
        const openvdb::Coord tile = coord_of_key(tile_keys[n]);
        const std::uint64_t hash = hash_of_copy(tree, tile);
        const auto found = previous.find(tile_keys[n]);
        if (found != previous.end() && found->second.hash == hash) {
          made[n] = std::move(found->second);  // each key is visited by one task only
          continue;
        }
        made[n] = mesh_tile(grid, tile, isovalue, fill_pockets, voxel);
        made[n].hash = hash;
        was_meshed[n] = 1;
      }
    });
    Result result;
    result.tiles = tile_keys.size();
    result.meshed_tiles = static_cast<std::size_t>(std::count(was_meshed.begin(), was_meshed.end(), 1));
    // Join in key order (the same mesh for the same field), welding equal seam points and joining
    // the pieces they connect.
    std::size_t vertex_total = 0, triangle_total = 0, seam_total = 0, piece_total = 0;
    std::vector<std::size_t> first_piece(made.size());
    for (std::size_t n = 0; n < made.size(); ++n) {
      vertex_total += made[n].vertices.size();
      triangle_total += made[n].triangles.size();
      seam_total += made[n].seam_vertices.size();
      first_piece[n] = piece_total;
      piece_total += made[n].piece_six_volume.size();
    }
    std::vector<Index> piece_parent(piece_total);
    std::iota(piece_parent.begin(), piece_parent.end(), Index(0));
    auto find = [&](Index piece) {
      while (piece_parent[piece] != piece) piece = piece_parent[piece] = piece_parent[piece_parent[piece]];
      return piece;
    };
    TriangleMesh& mesh = result.mesh;
    mesh.vertices.reserve(vertex_total);
    mesh.triangles.reserve(triangle_total);
    // Seam points by their bits, in an open-addressing table (a node per entry was half the time).
    struct Welded {
      std::array<std::uint32_t, 3> bits;
      Index vertex = ~Index(0), piece = 0;
    };
    const std::size_t slot_mask = std::bit_ceil(2 * seam_total + 16) - 1;
    std::vector<Welded> seam_table(slot_mask + 1);
    std::vector<Index> global;
    for (std::size_t n = 0; n < made.size(); ++n) {
      const Tile& t = made[n];
      global.resize(t.vertices.size());
      std::size_t next_seam = 0;
      for (std::size_t v = 0; v < t.vertices.size(); ++v) {
        const auto piece = static_cast<Index>(first_piece[n] + t.vertex_piece[v]);
        if (next_seam < t.seam_vertices.size() && t.seam_vertices[next_seam] == v) {
          ++next_seam;
          const auto bits = bits_of(t.vertices[v]);
          std::size_t slot = PointBitsHash()(bits) & slot_mask;
          while (seam_table[slot].vertex != ~Index(0) && seam_table[slot].bits != bits) slot = (slot + 1) & slot_mask;
          Welded& entry = seam_table[slot];
          if (entry.vertex != ~Index(0)) {
            global[v] = entry.vertex;
            piece_parent[find(piece)] = find(entry.piece);
            continue;
          }
          entry = Welded{bits, static_cast<Index>(mesh.vertices.size()), piece};
        }
        global[v] = static_cast<Index>(mesh.vertices.size());
        mesh.vertices.push_back(t.vertices[v]);
      }
      for (const auto& tri : t.triangles) mesh.triangles.push_back({global[tri[0]], global[tri[1]], global[tri[2]]});
    }
    // The mesher winds every field's triangles one way: turn them outwards by the total volume.
    std::vector<double> six_volume(piece_total, 0.0);
    double total = 0;
    for (std::size_t n = 0; n < made.size(); ++n)
      for (std::size_t k = 0; k < made[n].piece_six_volume.size(); ++k) {
        six_volume[find(static_cast<Index>(first_piece[n] + k))] += made[n].piece_six_volume[k];
        total += made[n].piece_six_volume[k];
      }
    const double sign = total < 0 ? -1.0 : 1.0;
    if (total < 0) flip_orientation(mesh);
    if (max_cavity_volume > 0) {
      // Closed inside-out pieces smaller than the limit are gaps between particles, not cavities.
      std::vector<char> drop(piece_total, 0);
      bool any = false;
      for (std::size_t piece = 0; piece < piece_total; ++piece) {
        const double volume = sign * six_volume[find(static_cast<Index>(piece))] / 6;
        drop[piece] = volume < 0 && -volume < max_cavity_volume;
        any = any || drop[piece];
      }
      if (any) {
        std::size_t kept = 0, triangle = 0;
        for (std::size_t n = 0; n < made.size(); ++n)
          for (const auto& tri : made[n].triangles) {
            if (!drop[first_piece[n] + made[n].vertex_piece[tri[0]]]) mesh.triangles[kept++] = mesh.triangles[triangle];
            ++triangle;
          }
        mesh.triangles.resize(kept);
        remove_unused_vertices(mesh);
      }
    }
    for (std::size_t n = 0; n < tile_keys.size(); ++n) tiles_.emplace(tile_keys[n], std::move(made[n]));
    return result;
  }

 private:
  static constexpr int kTileBlocks = 4;  // leaf-sized blocks per tile edge: 32 voxels
  static constexpr int kBlock = 8;       // voxels per leaf edge
  static constexpr int kTileVoxels = kTileBlocks * kBlock;
  // A point lies in its cube c, and the polygons around it have centroids rounding to voxels c to
  // c + 2 on each axis: only points within 1.5 voxels of a tile's face can be shared across it.
  static constexpr double kSeamVoxels = 2;

  struct Tile {
    std::uint64_t hash = 0;
    std::vector<Vec3> vertices;
    std::vector<std::array<Index, 3>> triangles;
    std::vector<Index> seam_vertices;  // ascending local indices of points near the tile's faces
    // Pieces of the tile's mesh (connected within the tile) and six times their signed volumes: the
    // whole mesh's pieces are these joined at welded points, so cavities are found per piece.
    std::vector<Index> vertex_piece;
    std::vector<double> piece_six_volume;
  };
  std::map<std::uint64_t, Tile> tiles_;  // by tile key, from the last call (one iso-value and set of settings)
  struct PointBitsHash {
    std::size_t operator()(const std::array<std::uint32_t, 3>& bits) const {
      std::uint64_t h = (static_cast<std::uint64_t>(bits[0]) << 32 | bits[1]) * 0x9E3779B97F4A7C15ull;
      h ^= (h >> 29) ^ (static_cast<std::uint64_t>(bits[2]) * 0xBF58476D1CE4E5B9ull);
      return static_cast<std::size_t>(h ^ (h >> 32));
    }
  };
  static std::array<std::uint32_t, 3> bits_of(const Vec3& p) {
    return {std::bit_cast<std::uint32_t>(static_cast<float>(p.x())), std::bit_cast<std::uint32_t>(static_cast<float>(p.y())),
            std::bit_cast<std::uint32_t>(static_cast<float>(p.z()))};
  }
  static int floor_divide(int a, int b) { return a >= 0 ? a / b : -((-a + b - 1) / b); }
  /// Calls visit(block_origin) for the leaf-sized blocks of a tile's copy: the tile and one block around.
  template <class Visit>
  static void for_each_block_of_copy(const openvdb::Coord& tile, Visit&& visit) {
    for (int bx = -1; bx <= kTileBlocks; ++bx)
      for (int by = -1; by <= kTileBlocks; ++by)
        for (int bz = -1; bz <= kTileBlocks; ++bz)
          visit(openvdb::Coord((tile.x() * kTileBlocks + bx) * kBlock, (tile.y() * kTileBlocks + by) * kBlock,
                               (tile.z() * kTileBlocks + bz) * kBlock));
  }
  static std::uint64_t hash_of_copy(const openvdb::FloatTree& tree, const openvdb::Coord& tile) {
    std::uint64_t hash = 0xcbf29ce484222325ull;
    // splitmix64's finaliser on every word: each input bit reaches every hash bit (a bare FNV step
    // only carries bits upwards, so two flips of a word's top bit would cancel).
    auto mix = [&hash](std::uint64_t word) {
      std::uint64_t z = (hash ^ word) + 0x9E3779B97F4A7C15ull;
      z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
      z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
      hash = z ^ (z >> 31);
    };
    for_each_block_of_copy(tile, [&](const openvdb::Coord& origin) {
      if (const auto* leaf = tree.probeConstLeaf(origin)) {
        mix(0x1eaf);
        for (openvdb::Index word = 0; word < leaf->getValueMask().WORD_COUNT; ++word) mix(leaf->getValueMask().getWord<openvdb::Index64>(word));
        const float* values = leaf->buffer().data();
        for (openvdb::Index v = 0; v < leaf->SIZE; ++v) mix(std::bit_cast<std::uint32_t>(values[v]));
      } else {
        mix(std::bit_cast<std::uint32_t>(tree.getValue(origin)));
        mix(tree.isValueOn(origin) ? 1 : 2);
      }
    });
    return hash;
  }
  static Tile mesh_tile(const openvdb::FloatGrid& grid, const openvdb::Coord& tile, double isovalue, bool fill_pockets,
                        double voxel) {
    const openvdb::FloatTree& tree = grid.tree();
    auto copy = openvdb::FloatGrid::create(grid.background());
    copy->setTransform(grid.transform().copy());
    copy->setGridClass(grid.getGridClass());
    for_each_block_of_copy(tile, [&](const openvdb::Coord& origin) {
      if (const auto* leaf = tree.probeConstLeaf(origin)) {
        copy->tree().addLeaf(new openvdb::FloatTree::LeafNodeType(*leaf));
      } else {
        const float value = tree.getValue(origin);
        const bool active = tree.isValueOn(origin);
        if (active || value != grid.background())
          copy->tree().fill(openvdb::CoordBBox(origin, origin.offsetBy(kBlock - 1)), value, active);
      }
    });
    if (fill_pockets) fill_voxel_pockets(*copy);
    std::vector<openvdb::Vec3s> points;
    std::vector<openvdb::Vec3I> triangles;
    std::vector<openvdb::Vec4I> quads;
    openvdb::tools::volumeToMesh(*copy, points, triangles, quads, isovalue, /*adaptivity=*/0.0);
    // Keep the polygons whose centroid rounds to a voxel of this tile.
    const openvdb::Coord low(tile.x() * kTileVoxels, tile.y() * kTileVoxels, tile.z() * kTileVoxels);
    auto owned = [&](std::initializer_list<unsigned> corners) {
      openvdb::Vec3d sum(0, 0, 0);
      for (const unsigned corner : corners) sum += openvdb::Vec3d(points[corner]);
      for (int axis = 0; axis < 3; ++axis) {
        const int voxel_index = static_cast<int>(std::floor(sum[axis] / static_cast<double>(corners.size()) / voxel + 0.5));
        if (voxel_index < low[axis] || voxel_index >= low[axis] + kTileVoxels) return false;
      }
      return true;
    };
    Tile result;
    TriangleMesh mesh;
    mesh.vertices.reserve(points.size());
    for (const auto& p : points) mesh.vertices.emplace_back(p.x(), p.y(), p.z());
    for (const auto& t : triangles)
      if (owned({t[0], t[1], t[2]})) mesh.triangles.push_back({t[0], t[1], t[2]});
    for (const auto& q : quads)
      if (owned({q[0], q[1], q[2], q[3]})) {  // split as extract_mesh splits
        mesh.triangles.push_back({q[0], q[1], q[2]});
        mesh.triangles.push_back({q[0], q[2], q[3]});
      }
    remove_unused_vertices(mesh);
    // Points near the tile's faces may belong to the next tile's polygons too.
    auto near_face = [&](const Vec3& p) {
      for (int axis = 0; axis < 3; ++axis) {
        const double index = p[axis] / voxel;
        if (index - (low[axis] - 0.5) < kSeamVoxels || (low[axis] + kTileVoxels - 0.5) - index < kSeamVoxels) return true;
      }
      return false;
    };
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
      if (near_face(mesh.vertices[v])) result.seam_vertices.push_back(static_cast<Index>(v));
    const std::vector<Index> root = component_roots(mesh);
    std::vector<Index> piece_of_root(mesh.vertices.size(), ~Index(0));
    result.vertex_piece.resize(mesh.vertices.size());
    for (std::size_t v = 0; v < mesh.vertices.size(); ++v) {
      Index& piece = piece_of_root[root[v]];
      if (piece == ~Index(0)) {
        piece = static_cast<Index>(result.piece_six_volume.size());
        result.piece_six_volume.push_back(0);
      }
      result.vertex_piece[v] = piece;
    }
    for (const auto& t : mesh.triangles)
      result.piece_six_volume[result.vertex_piece[t[0]]] +=
          mesh.vertices[t[0]].cast<double>().dot(mesh.vertices[t[1]].cast<double>().cross(mesh.vertices[t[2]].cast<double>()));
    result.vertices = std::move(mesh.vertices);
    result.triangles = std::move(mesh.triangles);
    return result;
  }
};

/// The mesh of a field. With `tiles`, by tiles whose meshes are kept between calls (incremental
/// meshing); without, by one mesher call over the whole field. Both give the same triangles (with
/// smoothing, up to rounding: the vertices are numbered differently).
TriangleMesh mesh_of_field(const Field& field, const SurfaceSettings& settings, SurfaceStats& stats,
                           TiledMesher* tiles = nullptr) {
  stats.active_voxels = field.grid->activeVoxelCount();
  stats.grid_bytes = std::max<std::size_t>(stats.grid_bytes, field.grid->memUsage());
  const auto start = Clock::now();
  // Spheres leave closed pockets between them (a lattice cell's centre is √3 r from its corners):
  // each is a small inside-out shell. Pockets smaller than a particle are gaps, not holes in the
  // material. Voxel-sized ones are filled in the field, only where their shells are certain to be
  // dropped anyway (8 voxels³ ≤ the particle volume).
  const Real spacing = 2 * settings.particle_radius;
  const bool spherical = field_method(settings.method).fills_pockets;
  const bool fill_pockets = spherical && 8 * std::pow(settings.voxel_size, 3) <= std::pow(spacing, 3);
  const double max_cavity_volume = spherical ? std::pow(spacing, 3) : 0.0;
  TriangleMesh mesh;
  if (tiles) {
    TiledMesher::Result tiled = tiles->mesh(*field.grid, field.isovalue, fill_pockets, max_cavity_volume);
    mesh = std::move(tiled.mesh);
    stats.mesh_tiles = tiled.tiles;
    stats.remeshed_tiles = tiled.meshed_tiles;
  } else {
    if (fill_pockets) fill_voxel_pockets(*field.grid);
    mesh = extract_mesh(*field.grid, field.isovalue);
    remove_unused_vertices(mesh);
    // The mesher winds triangles one way for every field here; make them face outwards.
    if (signed_volume(mesh) < 0) flip_orientation(mesh);
    if (spherical) remove_small_cavities(mesh, max_cavity_volume);
  }
  taubin_smooth(mesh, settings.smoothing_iterations, settings.smoothing_lambda, settings.smoothing_mu);
  stats.mesh_seconds = seconds_since(start);
  return mesh;
}

/// Cells of a given size that hold a particle of a set. A point whose 27 surrounding cells include
/// an occupied one may lie within that size of the set; every point that does is found.
class OccupiedCells {
 public:
  OccupiedCells(std::span<const Vec3> positions, Real cell_size) : inverse_(Real(1) / cell_size) {
    cells_.reserve(positions.size() / 8 + 16);
    for (const Vec3& p : positions) {
      const auto c = cell_of(p);
      cells_.insert(key(c));
      for (int k = 0; k < 3; ++k) {
        low_[k] = std::min(low_[k], c[k] - 1);
        high_[k] = std::max(high_[k], c[k] + 1);
      }
    }
  }
  [[nodiscard]] bool near(const Vec3& p) const {
    const auto c = cell_of(p);
    // Most points of a large set are far from a small one: the box around the cells answers first.
    for (int k = 0; k < 3; ++k)
      if (c[k] < low_[k] || c[k] > high_[k]) return false;
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (cells_.count(key({c[0] + dx, c[1] + dy, c[2] + dz}))) return true;
    return false;
  }

 private:
  [[nodiscard]] std::array<std::int32_t, 3> cell_of(const Vec3& p) const {
    return {static_cast<std::int32_t>(std::floor(p.x() * inverse_)), static_cast<std::int32_t>(std::floor(p.y() * inverse_)),
            static_cast<std::int32_t>(std::floor(p.z() * inverse_))};
  }
  static std::uint64_t key(const std::array<std::int32_t, 3>& c) { return sph::morton_code(c[0], c[1], c[2]); }
  Real inverse_;
  std::unordered_set<std::uint64_t> cells_;
  std::array<std::int32_t, 3> low_{INT32_MAX, INT32_MAX, INT32_MAX}, high_{INT32_MIN, INT32_MIN, INT32_MIN};
};

}  // namespace

const FieldMethod& field_method(Method method) {
  for (const FieldMethod* entry : kFieldMethods)
    if (entry->method == method) return *entry;
  throw Error("surface reconstruction: unknown method");
}

namespace {
/// Particle list in the form ParticlesToLevelSet reads (the reference the tests compare against).
struct ParticleList {
  using PosType = openvdb::Vec3R;
  std::span<const Vec3> positions;
  Real radius;
  [[nodiscard]] std::size_t size() const { return positions.size(); }
  void getPos(std::size_t n, openvdb::Vec3R& xyz) const { xyz = openvdb::Vec3R(positions[n].x(), positions[n].y(), positions[n].z()); }
  void getPosRad(std::size_t n, openvdb::Vec3R& xyz, openvdb::Real& rad) const {
    getPos(n, xyz);
    rad = radius;
  }
};

}  // namespace

namespace detail {
SphericalFieldComparison compare_spherical_field_with_openvdb(std::span<const Vec3> centres, Real sphere_radius,
                                                              Real voxel_size) {
  initialize_openvdb();
  auto reference = openvdb::createLevelSet<openvdb::FloatGrid>(voxel_size, kSphereBandVoxels);
  openvdb::tools::ParticlesToLevelSet<openvdb::FloatGrid> raster(*reference);
  raster.setRmin(0.5);  // spheres smaller than 1.5 voxels are kept, not dropped as the default does
  raster.rasterizeSpheres(ParticleList{centres, sphere_radius}, sphere_radius);
  raster.finalize(true);
  const auto ours = union_of_spheres(centres, sphere_radius, voxel_size);
  SphericalFieldComparison result;
  result.reference_active_voxels = reference->activeVoxelCount();
  result.active_voxels = ours->activeVoxelCount();
  // Every voxel either grid stores in a leaf, looked up in the other one.
  auto compare = [&](const openvdb::FloatGrid& a, const openvdb::FloatGrid& b) {
    auto other = b.getConstAccessor();
    for (auto leaf = a.tree().cbeginLeaf(); leaf; ++leaf)
      for (auto voxel = leaf->cbeginValueAll(); voxel; ++voxel) {
        const openvdb::Coord ijk = voxel.getCoord();
        if (voxel.isValueOn() != other.isValueOn(ijk)) ++result.activity_mismatches;
        result.max_difference = std::max(result.max_difference, std::abs(static_cast<double>(*voxel) - other.getValue(ijk)));
      }
  };
  // And the values above the leaf level (tiles), at each tile's first voxel.
  auto compare_tiles = [&](const openvdb::FloatGrid& a, const openvdb::FloatGrid& b) {
    auto value = a.tree().cbeginValueAll();
    value.setMaxDepth(openvdb::FloatTree::ValueAllCIter::LEAF_DEPTH - 1);
    for (; value; ++value) {
      const openvdb::Coord ijk = value.getCoord();
      if (value.isValueOn() != b.tree().isValueOn(ijk)) ++result.activity_mismatches;
      result.max_difference = std::max(result.max_difference, std::abs(static_cast<double>(*value) - b.tree().getValue(ijk)));
    }
  };
  compare(*reference, *ours);
  compare(*ours, *reference);
  compare_tiles(*reference, *ours);
  compare_tiles(*ours, *reference);
  return result;
}
}  // namespace detail


TriangleMesh reconstruct_surface(std::span<const Vec3> positions, const SurfaceSettings& input_settings, SurfaceStats* stats) {
  const SurfaceSettings settings = input_settings.resolved();
  SurfaceStats local_stats;
  local_stats.particles = positions.size();
  TriangleMesh mesh;
  if (positions.empty()) {
    if (stats) *stats = local_stats;
    return mesh;
  }
  check_finite(positions);
  initialize_openvdb();
  const auto start = Clock::now();
  Field field = field_of(positions, settings, local_stats);
  local_stats.field_seconds = seconds_since(start);
  mesh = mesh_of_field(field, settings, local_stats);
  if (stats) *stats = local_stats;
  return mesh;
}

/// The kernel an anisotropic field splatted for one particle (to take it back out when it changes).
struct KernelRecord {
  Vec3 centre;
  Eigen::Matrix3f transform;
  Real determinant;
  Vec3 half_extent;
};

struct IncrementalSurface::Cache {
  SurfaceSettings settings;                 // resolved
  openvdb::FloatGrid::Ptr resting_field;    // field of the particles in `kept`; null when none
  std::unordered_map<std::uint64_t, Vec3> kept;  // id → position of every particle in resting_field
  std::unordered_map<std::uint64_t, KernelRecord> kernels;  // anisotropic: id → kernel in resting_field
  std::unordered_map<std::uint64_t, Vec3> previous_frame;   // reconstruct_frame: id → position last time
  TiledMesher tiles;                                         // the mesh, tile by tile, kept too

  void clear() {
    kept.clear();
    kernels.clear();
    resting_field.reset();
  }
  void add_to_resting_field(openvdb::FloatGrid::Ptr part) {
    if (resting_field)
      merge_field(settings.method, *resting_field, *part);
    else
      resting_field = std::move(part);
  }
  void record_kernels(const SplattedKernels& splatted, std::span<const std::uint64_t> ids) {
    const auto& k = splatted.kernels;
    for (std::size_t n = 0; n < splatted.particles.size(); ++n)
      kernels[ids[splatted.particles[n]]] = KernelRecord{k.centre[n], k.transform[n], k.determinant[n], k.half_extent[n]};
  }
  std::size_t refresh_kernels(std::span<const Vec3> moving, std::span<const Vec3> resting, std::span<const std::uint64_t> ids,
                              const std::vector<char>& is_added);
};

/// Anisotropic kernels depend on their neighbours: a kept particle near material that arrived or
/// moved since its kernel was made gets a new kernel, and the field swaps the old one for it. Only
/// kernels that change are swapped. Returns how many.
std::size_t IncrementalSurface::Cache::refresh_kernels(std::span<const Vec3> moving, std::span<const Vec3> resting,
                                                       std::span<const std::uint64_t> ids, const std::vector<char>& is_added) {
  const Real radius = settings.anisotropy_neighborhood;
  std::vector<Vec3> changing(moving.begin(), moving.end());
  for (std::size_t i = 0; i < resting.size(); ++i)
    if (is_added[i]) changing.push_back(resting[i]);
  if (changing.empty()) return 0;
  const OccupiedCells near_change(changing, radius);
  // Kept particles with a kernel near the change first, then every other particle near them.
  std::vector<Vec3> local;
  std::vector<std::uint64_t> candidate_ids;
  std::vector<char> is_candidate(resting.size(), 0);
  for (std::size_t i = 0; i < resting.size(); ++i)
    if (!is_added[i] && near_change.near(resting[i]) && kernels.count(ids[i])) {
      is_candidate[i] = 1;
      local.push_back(resting[i]);
      candidate_ids.push_back(ids[i]);
    }
  if (local.empty()) return 0;
  const std::size_t candidates = local.size();
  const OccupiedCells near_candidates(std::span<const Vec3>(local), radius);
  for (std::size_t i = 0; i < resting.size(); ++i)
    if (!is_candidate[i] && near_candidates.near(resting[i])) local.push_back(resting[i]);
  for (const Vec3& p : moving)
    if (near_candidates.near(p)) local.push_back(p);
  std::vector<Index> which(candidates);
  std::iota(which.begin(), which.end(), Index(0));
  const AnisotropicKernels fresh = compute_anisotropic_kernels(local, settings, which);

  AnisotropicKernels added_kernels, removed_kernels;
  auto push = [](AnisotropicKernels& list, const KernelRecord& k) {
    list.centre.push_back(k.centre);
    list.transform.push_back(k.transform);
    list.determinant.push_back(k.determinant);
    list.half_extent.push_back(k.half_extent);
  };
  const Real position_tolerance = Real(1e-5) * settings.particle_radius;
  for (std::size_t n = 0; n < candidates; ++n) {
    KernelRecord& old_kernel = kernels[candidate_ids[n]];
    const KernelRecord new_kernel{fresh.centre[n], fresh.transform[n], fresh.determinant[n], fresh.half_extent[n]};
    // Same neighbours give the same kernel up to the order of the sums.
    if ((new_kernel.centre - old_kernel.centre).norm() < position_tolerance &&
        (new_kernel.transform - old_kernel.transform).norm() < Real(1e-5) * old_kernel.transform.norm())
      continue;
    push(removed_kernels, old_kernel);
    push(added_kernels, new_kernel);
    old_kernel = new_kernel;
  }
  if (added_kernels.centre.empty()) return 0;
  const auto transform = openvdb::math::Transform::createLinearTransform(settings.voxel_size);
  auto change = splat_anisotropic_kernels(added_kernels, settings, transform, 1.f);
  auto removal = splat_anisotropic_kernels(removed_kernels, settings, transform, -1.f);
  openvdb::tools::compSum(*change, *removal);
  add_to_resting_field(change);
  return added_kernels.centre.size();
}

IncrementalSurface::IncrementalSurface(const SurfaceSettings& settings) : cache_(std::make_unique<Cache>()) {
  cache_->settings = settings.resolved();
}

IncrementalSurface::~IncrementalSurface() = default;

TriangleMesh IncrementalSurface::reconstruct(std::span<const Vec3> moving, std::span<const Vec3> resting,
                                             std::span<const std::uint64_t> resting_ids, SurfaceStats* stats) {
  if (resting.size() != resting_ids.size()) throw Error("incremental surface: one id per resting particle is needed");
  check_finite(moving);
  check_finite(resting);
  const SurfaceSettings& settings = cache_->settings;
  initialize_openvdb();
  if (!field_method(settings.method).sum_over_particles) {
    // Not a sum over particles: the field is made whole; the mesh of unchanged tiles is kept.
    std::vector<Vec3> all(moving.begin(), moving.end());
    all.insert(all.end(), resting.begin(), resting.end());
    SurfaceStats local_stats;
    local_stats.particles = all.size();
    TriangleMesh mesh;
    if (!all.empty()) {
      const auto start = Clock::now();
      const Field field = field_of(all, settings, local_stats);
      local_stats.field_seconds = seconds_since(start);
      mesh = mesh_of_field(field, settings, local_stats, &cache_->tiles);
    }
    if (stats) *stats = local_stats;
    return mesh;
  }
  SurfaceStats local_stats;
  local_stats.particles = moving.size() + resting.size();
  const auto start = Clock::now();

  // Which resting particles are new; drop the kept field if a kept one woke, moved or left.
  std::vector<char> is_added(resting.size(), 0);
  std::size_t still_kept = 0;
  bool changed = false;
  for (std::size_t i = 0; i < resting.size() && !changed; ++i) {
    const auto found = cache_->kept.find(resting_ids[i]);
    if (found == cache_->kept.end())
      is_added[i] = 1;
    else if (found->second == resting[i])
      ++still_kept;
    else
      changed = true;
  }
  if (changed || still_kept != cache_->kept.size()) {
    local_stats.rebuilt = !cache_->kept.empty();
    cache_->clear();
    std::fill(is_added.begin(), is_added.end(), 1);
  }
  std::vector<Vec3> added, kept;
  std::vector<std::uint64_t> added_ids;
  for (std::size_t i = 0; i < resting.size(); ++i) {
    (is_added[i] ? added : kept).push_back(resting[i]);
    if (is_added[i]) added_ids.push_back(resting_ids[i]);
  }
  local_stats.reused_particles = cache_->kept.size();
  local_stats.added_particles = added.size();

  // Anisotropic kernels see every particle near them, whichever part it belongs to. The other
  // fields are sums over particles alone.
  const bool anisotropic = field_method(settings.method).kernels_see_neighbours;
  auto neighbours_of = [&](std::span<const Vec3> part, std::span<const Vec3> first, std::span<const Vec3> second) {
    std::vector<Vec3> near;
    if (!anisotropic) return near;
    const OccupiedCells cells(part, settings.anisotropy_neighborhood);
    for (const auto list : {first, second})
      for (const Vec3& p : list)
        if (cells.near(p)) near.push_back(p);
    return near;
  };
  if (anisotropic) local_stats.refreshed_kernels = cache_->refresh_kernels(moving, resting, resting_ids, is_added);
  if (!added.empty()) {
    SplattedKernels splatted;
    const std::vector<Vec3> neighbours = neighbours_of(added, kept, moving);
    Field part = field_of(added, settings, local_stats, {neighbours, anisotropic ? &splatted : nullptr});
    cache_->add_to_resting_field(part.grid);
    if (anisotropic) cache_->record_kernels(splatted, added_ids);
    for (std::size_t n = 0; n < added.size(); ++n) cache_->kept.emplace(added_ids[n], added[n]);
  }

  Field field;
  field.isovalue = isovalue_of(settings);
  if (!moving.empty()) {
    const std::vector<Vec3> neighbours = neighbours_of(moving, resting, {});
    field = field_of(moving, settings, local_stats, {neighbours, nullptr});
    if (cache_->resting_field) {
      openvdb::FloatGrid::Ptr copy = cache_->resting_field->deepCopy();
      merge_field(settings.method, *copy, *field.grid);
      field.grid = copy;
    }
  } else {
    // No copy (null when nothing rests): the tiled mesher only reads it (pockets are filled in the
    // tiles' copies).
    field.grid = cache_->resting_field;
  }
  local_stats.field_seconds = seconds_since(start);
  TriangleMesh mesh;
  if (field.grid) mesh = mesh_of_field(field, settings, local_stats, &cache_->tiles);
  if (stats) *stats = local_stats;
  return mesh;
}

TriangleMesh IncrementalSurface::reconstruct_frame(std::span<const Vec3> positions, std::span<const std::uint64_t> ids,
                                                   SurfaceStats* stats) {
  if (positions.size() != ids.size()) throw Error("incremental surface: one id per particle is needed");
  std::vector<Vec3> moving, resting;
  std::vector<std::uint64_t> resting_ids;
  auto& previous = cache_->previous_frame;
  for (std::size_t i = 0; i < positions.size(); ++i) {
    const auto found = previous.find(ids[i]);
    if (found != previous.end() && found->second == positions[i]) {
      resting.push_back(positions[i]);
      resting_ids.push_back(ids[i]);
    } else {
      moving.push_back(positions[i]);
    }
  }
  previous.clear();
  for (std::size_t i = 0; i < positions.size(); ++i) previous.emplace(ids[i], positions[i]);
  return reconstruct(moving, resting, resting_ids, stats);
}

}  // namespace m3dp::surface
