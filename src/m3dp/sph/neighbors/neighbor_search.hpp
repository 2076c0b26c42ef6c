#pragma once
// Neighbour search on a uniform grid (cell = support radius) stored as a spatial hash:
// points are counting-sorted by hashed cell, so memory grows with the points, not with the
// scene's size. Lists are compact per particle and reused by every solver sweep of a step.
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

#include <tbb/enumerable_thread_specific.h>

#include "m3dp/core/types.hpp"

namespace m3dp::sph {

/// Neighbour lists back to back in particle order: particle i's neighbours are
/// indices[firsts[i], firsts[i] + counts[i]). The search writes fixed-stride lists (staging, `stride`
/// slots a particle, grown outside the hot loop when a particle has more) in its own query order, then
/// packs them: the solvers' sweeps stream the lists and their per-pair arrays (indexed like
/// `indices`), and the unused slots of fixed-stride lists made each sweep read a third more memory.
/// SkinnedNeighborSearch writes
/// them back to back within blocks of particles, with unused room after each block (no packing pass).
struct NeighborLists {
  Index stride = 48;
  std::vector<Index> counts;
  std::vector<std::size_t> firsts;
  std::vector<Index> indices;
  std::vector<Index> staging;  // the search's lists before packing: at most `stride` slots per query
  std::vector<std::size_t> staged_firsts;  // find_neighbors: where each query's list starts in staging

  /// Per-thread copy of the grid points around one cell: consecutive queries (Z-ordered) mostly
  /// share a cell, so the 27 hashed buckets are gathered once per cell, not once per query.
  struct CandidateBuffer {
    std::array<std::int32_t, 3> cell{};
    bool valid = false;
    std::size_t count = 0;              // candidates held; the arrays only grow (no zero-fill per gather)
    std::vector<Index> index;
    std::vector<Real> x, y, z;          // positions as separate arrays: the distance loop vectorises
    std::vector<Real> distance_squared;
    std::vector<Index> found;            // candidates within the radius, before the copy into the list
  };
  tbb::enumerable_thread_specific<CandidateBuffer> candidate_buffers;

  [[nodiscard]] std::span<const Index> of(std::size_t particle) const {
    return {indices.data() + firsts[particle], counts[particle]};
  }
  [[nodiscard]] std::size_t first(std::size_t particle) const { return firsts[particle]; }
  /// Slots of `indices` (and of the per-pair arrays): every pair, and any unused room between blocks.
  [[nodiscard]] std::size_t total() const { return indices.size(); }
};

/// Points sorted into cubic cells. Where the points' bounding box holds few cells (at most
/// kDenseCellsPerPoint per point, and any box up to kDenseCellsAlways cells) the cells are a dense
/// array in x-fastest order: no collisions, and the 27 cells around one are nine runs of three
/// consecutive cells, each run one contiguous range of points. Elsewhere (a few particles on a large
/// bed) the cells are hashed into buckets.
class SpatialHashGrid {
 public:
  static constexpr std::size_t kDenseCellsPerPoint = 4;
  static constexpr std::size_t kDenseCellsAlways = 1 << 12;

  /// Sorts `positions` into cells of size `cell_size` (m). Reuses its buffers between calls.
  void build(std::span<const Vec3> positions, Real cell_size);
  /// Same over the points positions[subset[k]] only; candidates report the index into `positions`.
  /// (The solver keeps static and moving boundaries in separate grids: static ones are sorted once.)
  void build(std::span<const Vec3> positions, std::span<const Index> subset, Real cell_size);

  /// Calls visit(point_index, point_position) for every point in the 27 cells around `query`
  /// (each point once, even where hashed cells collide).
  template <class Visit>
  void for_each_candidate(const Vec3& query, Visit&& visit) const {
    for_each_point_around_cell(cell_of(query), visit);
  }
  /// Calls visit(point_index, point_position) for every point in the 27 cells around `cell`.
  template <class Visit>
  void for_each_point_around_cell(const std::array<std::int32_t, 3>& cell, Visit&& visit) const;
  /// Appends the points in the 27 cells around `cell` (indices and coordinates) to the buffer's
  /// candidates, each point once: whole bucket ranges, copied, for the neighbour search.
  void append_points_around_cell(const std::array<std::int32_t, 3>& cell, NeighborLists::CandidateBuffer& buffer) const;

  /// Takes point k of the last build (positions[index], index = subset[k] or k) out of every later
  /// query without sorting again: its stored coordinates go far away, where no distance test keeps
  /// it. For a kept grid of which a few points left (resting particles woken).
  void remove_point(std::size_t k, Index index);

  [[nodiscard]] Real cell_size() const { return cell_size_; }
  /// Whether the last build chose dense cells (see the class comment) rather than hashed buckets.
  [[nodiscard]] bool dense() const { return dense_; }
  [[nodiscard]] std::size_t point_count() const { return sorted_index_.size(); }
  /// The points' indices in grid order: the points of one cell come together.
  [[nodiscard]] std::span<const Index> points_in_grid_order() const { return sorted_index_; }
  [[nodiscard]] std::array<std::int32_t, 3> cell_of(const Vec3& point) const {
    return {static_cast<std::int32_t>(std::floor(point.x() * inverse_cell_size_)),
            static_cast<std::int32_t>(std::floor(point.y() * inverse_cell_size_)),
            static_cast<std::int32_t>(std::floor(point.z() * inverse_cell_size_))};
  }

 private:
  /// Sorts positions[subset[k]] for k < point_count, or the first point_count positions if subset is null.
  void build_points(std::span<const Vec3> positions, const Index* subset, std::size_t point_count, Real cell_size);
  [[nodiscard]] std::uint32_t bucket_of_cell(std::int32_t x, std::int32_t y, std::int32_t z) const {
    if (dense_) {
      // Cells outside the box share the last bucket, which is always empty.
      const auto ux = static_cast<std::uint32_t>(x - dense_origin_[0]), uy = static_cast<std::uint32_t>(y - dense_origin_[1]),
                 uz = static_cast<std::uint32_t>(z - dense_origin_[2]);
      const bool inside = (ux < dense_extent_[0]) & (uy < dense_extent_[1]) & (uz < dense_extent_[2]);
      return inside ? ux + dense_extent_[0] * (uy + dense_extent_[1] * uz) : empty_bucket_;
    }
    const auto hash = (static_cast<std::uint32_t>(x) * 73856093u) ^ (static_cast<std::uint32_t>(y) * 19349663u) ^
                      (static_cast<std::uint32_t>(z) * 83492791u);
    return hash & bucket_mask_;
  }
  /// Whether the points' box (plus a cell each side) is small enough for dense cells; if so sets the
  /// box's origin and extent.
  bool choose_dense_cells(std::span<const Vec3> positions, const Index* subset, std::size_t point_count);

  Real cell_size_ = 1;
  Real inverse_cell_size_ = 1;
  std::uint32_t bucket_mask_ = 0;
  bool dense_ = false;
  std::array<std::int32_t, 3> dense_origin_{};   // the box's first cell
  std::array<std::uint32_t, 3> dense_extent_{};  // cells along x, y and z
  std::uint32_t empty_bucket_ = 0;               // dense: the last bucket, for every cell outside the box
  struct BucketRange {
    std::uint32_t begin = 0, end = 0;  // slots of the sorted arrays
  };
  std::vector<BucketRange> bucket_range_;    // (bucket_count, dense: cells + 1)
  std::vector<std::uint32_t> filled_buckets_;  // hashed: the non-empty buckets, in the order of their slots
  std::vector<std::uint32_t> point_bucket_;  // per input point
  std::vector<Index> sorted_index_;  // input indices ordered by bucket: dense in cell order, hashed in first-touch order
  std::vector<Vec3> sorted_position_;        // positions in the same order, for cache-friendly queries
  std::vector<Real> sorted_x_, sorted_y_, sorted_z_;  // the same, as separate arrays (candidate copies)
  /// The distinct buckets of the 27 cells around `cell`; returns how many.
  int buckets_around_cell(const std::array<std::int32_t, 3>& cell, std::uint32_t (&buckets)[27]) const;
};

/// Fills `out` with, for each query point, the grid points within `radius` (strictly closer).
/// With `exclude_same_index` the point with the query's own index is skipped (fluid–fluid lists).
/// With `sort_lists` each list is in index order (memory order for the solver's sweeps); without,
/// in grid order, which is as deterministic and cheaper for users that only sum over the list.
/// `query_order`, if given, is the order in which the queries are answered (every query index once;
/// larger indices are skipped): queries of one cell that come together share one gather of the 27
/// cells' points, e.g. the query points' own grid order. The lists are the same in any order.
void find_neighbors(const SpatialHashGrid& grid, std::span<const Vec3> query_positions, Real radius,
                    bool exclude_same_index, NeighborLists& out, bool sort_lists = true,
                    std::span<const Index> query_order = {});
/// Same over the points of several grids of one point set (same cell size), e.g. static and moving
/// boundary particles: each list holds the neighbours from every grid.
void find_neighbors(std::span<const SpatialHashGrid* const> grids, std::span<const Vec3> query_positions, Real radius,
                    bool exclude_same_index, NeighborLists& out, bool sort_lists = true,
                    std::span<const Index> query_order = {});

/// Packs the lists in out.staging (out.counts[i] slots from out.staged_firsts[i], for the first `count`
/// particles) back to back in particle order into out.indices and out.firsts; with `sort_lists` each
/// list in index order.
void pack_staged_lists(NeighborLists& out, std::size_t count, bool sort_lists);

/// Neighbour lists kept across steps with a skin (Verlet lists): one search of radius r + skin gives
/// every particle a superset of its neighbours, and while no two particles have together moved more
/// than the skin since, every pair within r is in it; a step's lists are then the superset's pairs
/// still within r, found without the grids. For slow material: a settled print costs its 27-cell
/// search once in many steps.
///
/// A few fast particles ("movers", farther than skin/2 from where they were at the search: a strand
/// falling from the nozzle onto a settled print; or appended since, where none rest) do not force a
/// new search. They search the kept grids
/// themselves, and their pairs join their neighbours' lists. Moving bodies' boundary particles never
/// enter the supersets: each step they search the kept fluid grid the same way.
///
/// The lists hold the same pairs as a search of radius r would give (in another order: summation
/// order only), symmetric, and the same for any number of threads.
class SkinnedNeighborSearch {
 public:
  struct Inputs {
    std::span<const Vec3> fluid_positions;          // every fluid particle; the first active_count query
    std::span<const std::uint64_t> fluid_ids;       // to notice added, removed and reordered particles
    std::size_t active_count = 0;
    const SpatialHashGrid* resting_grid = nullptr;  // fixed fluid neighbours that do not query
    const SpatialHashGrid* recent_resting_grid = nullptr;  // more of them (optional)
    const SpatialHashGrid* static_boundary_grid = nullptr;
    const SpatialHashGrid* moving_boundary_grid = nullptr;
    std::span<const Vec3> boundary_positions;
    std::span<const Index> moving_boundary_indices;  // the boundary particles in moving_boundary_grid
    std::uint64_t fixed_grids_version = 0;           // changes whenever the resting or static grid changed
  };
  /// This step's lists of radius `radius` (m) into fluid_out and boundary_out, as find_neighbors with
  /// lists in grid order would give them. The three grids' cells must be radius + skin. Searches anew
  /// when the particles or the fixed grids changed, or when more than max_movers moved too far;
  /// returns true when it did.
  bool update(const Inputs& inputs, Real radius, Real skin, std::size_t max_movers, NeighborLists& fluid_out,
              NeighborLists& boundary_out);
  /// The next update searches anew.
  void invalidate() { valid_ = false; }
  [[nodiscard]] std::size_t mover_count() const { return movers_.size(); }

 private:
  /// Each particle's pairs from the movers' searches (fluid) or the moving boundary particles' (boundary),
  /// as lists by particle: items[firsts[i], firsts[i + 1]).
  struct AddedPairs {
    std::vector<Index> firsts, cursor, items;
  };
  void search(const Inputs& inputs, Real radius, Real skin);
  void find_mover_lists(const Inputs& inputs, Real radius_squared);
  void find_moving_boundary_pairs(const Inputs& inputs, Real radius_squared);
  void filter_lists(const NeighborLists& superset, std::span<const Vec3> neighbor_positions, std::span<const Vec3> positions,
                    Real radius_squared, bool skip_movers, const NeighborLists& mover_lists, const AddedPairs& added,
                    NeighborLists& out) const;

  bool valid_ = false;
  Real radius_ = 0, skin_ = 0;
  std::uint64_t fixed_grids_version_ = 0;
  std::size_t active_count_ = 0;           // the active particles at the search
  std::size_t query_count_ = 0;            // this update's: the search's and any appended since
  std::vector<std::uint64_t> ids_;
  std::vector<Vec3> reference_positions_;  // the active particles' at the search
  SpatialHashGrid active_grid_;            // the active particles at the search
  NeighborLists fluid_superset_, boundary_superset_;  // radius r + skin; boundary: static bodies only
  std::vector<std::uint8_t> is_mover_;     // (fluid particles)
  std::vector<Index> movers_;              // in index order
  std::vector<Index> mover_slot_;          // (active) a mover's place in movers_
  NeighborLists mover_fluid_, mover_boundary_;  // fixed-stride lists of the movers, by slot
  NeighborLists moving_boundary_hits_;     // fixed-stride: each moving boundary particle's fluid particles
  AddedPairs added_fluid_, added_boundary_;
};

/// 63-bit Morton (Z-order) code of a grid cell; used to reorder particles so neighbours sit near in memory.
std::uint64_t morton_code(std::int32_t x, std::int32_t y, std::int32_t z);
/// The first `count` positions in Z-order of cells of size `cell_size`: keys[i] is the Morton code of
/// point i's cell, order the points sorted by it, ties by index (the same order on every run).
void sort_by_cell(std::span<const Vec3> positions, std::size_t count, Real cell_size, std::vector<std::uint64_t>& keys,
                  std::vector<Index>& order);

// ---- template implementation ----
inline int SpatialHashGrid::buckets_around_cell(const std::array<std::int32_t, 3>& cell, std::uint32_t (&buckets)[27]) const {
  // Distinct cells rarely share a bucket: a 256-bit filter of the buckets seen so far sends only the
  // few that may repeat one to the full comparison.
  std::uint64_t seen_filter[4] = {0, 0, 0, 0};
  int count = 0;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const std::uint32_t bucket = bucket_of_cell(cell[0] + dx, cell[1] + dy, cell[2] + dz);
        const std::uint32_t bit = (bucket ^ (bucket >> 8)) & 255u;
        const std::uint64_t mask = std::uint64_t(1) << (bit & 63u);
        bool seen = false;
        if (seen_filter[bit >> 6] & mask)
          for (int k = 0; k < count; ++k) seen |= (buckets[k] == bucket);
        seen_filter[bit >> 6] |= mask;
        if (!seen) buckets[count++] = bucket;
      }
  return count;
}

template <class Visit>
void SpatialHashGrid::for_each_point_around_cell(const std::array<std::int32_t, 3>& cell, Visit&& visit) const {
  if (sorted_index_.empty()) return;
  std::uint32_t buckets[27];
  const int count = buckets_around_cell(cell, buckets);
  for (int k = 0; k < count; ++k) {
    const BucketRange range = bucket_range_[buckets[k]];
    for (std::uint32_t slot = range.begin; slot < range.end; ++slot) visit(sorted_index_[slot], sorted_position_[slot]);
  }
}

}  // namespace m3dp::sph
