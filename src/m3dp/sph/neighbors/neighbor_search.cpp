#include "m3dp/sph/neighbors/neighbor_search.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <limits>

#include <fmt/format.h>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"

#include "m3dp/sph/simd/neighbor_sums_avx2.hpp"  // avx2::available() and the intrinsics

namespace m3dp::sph {

namespace {

// The candidate filter writes whole groups of eight: the found buffer has this much room past the end.
constexpr std::size_t kFoundSlack = 8;

/// The buffer's candidates closer than the radius to `query`, but `self`, into buffer.found, in the
/// candidates' order; returns how many.
Index keep_candidates_within_generic(NeighborLists::CandidateBuffer& buffer, const Vec3& query, Real radius_squared, Index self) {
  const std::size_t candidate_count = buffer.count;
  const Real* x = buffer.x.data();
  const Real* y = buffer.y.data();
  const Real* z = buffer.z.data();
  Real* distance_squared = buffer.distance_squared.data();
  for (std::size_t c = 0; c < candidate_count; ++c) {
    const Real dx = query.x() - x[c], dy = query.y() - y[c], dz = query.z() - z[c];
    distance_squared[c] = dx * dx + dy * dy + dz * dz;
  }
  // Branch-free compaction: about one candidate in seven is a neighbour, too irregular to predict;
  // a group of eight without one (about a third) is skipped whole.
  const Index* candidate = buffer.index.data();
  Index* found = buffer.found.data();
  Index count = 0;
  std::size_t c = 0;
  for (; c + 8 <= candidate_count; c += 8) {
    bool any = false;
    for (std::size_t k = 0; k < 8; ++k) any |= distance_squared[c + k] < radius_squared;
    if (!any) continue;
    for (std::size_t k = c; k < c + 8; ++k) {
      found[count] = candidate[k];
      count += static_cast<Index>((distance_squared[k] < radius_squared) & (candidate[k] != self));
    }
  }
  for (; c < candidate_count; ++c) {
    found[count] = candidate[c];
    count += static_cast<Index>((distance_squared[c] < radius_squared) & (candidate[c] != self));
  }
  return count;
}

#ifdef M3DP_NEIGHBOR_SUMS_AVX2
/// The vector filters' last candidates, from `c` on, one by one after the `count` found so far.
inline Index keep_last_candidates(NeighborLists::CandidateBuffer& buffer, std::size_t c, Index count, const Vec3& query,
                                  Real radius_squared, Index self) {
  const Real* x = buffer.x.data();
  const Real* y = buffer.y.data();
  const Real* z = buffer.z.data();
  for (; c < buffer.count; ++c) {
    const Real dx = query.x() - x[c], dy = query.y() - y[c], dz = query.z() - z[c];
    buffer.found[count] = buffer.index[c];
    count += static_cast<Index>((dx * dx + dy * dy + dz * dz < radius_squared) & (buffer.index[c] != self));
  }
  return count;
}

// For each 8-bit mask, the positions of its set bits, packed to the front (one byte each): the
// permutation that moves a group's neighbours together.
constexpr std::array<std::uint64_t, 256> make_pack_table() {
  std::array<std::uint64_t, 256> table{};
  for (unsigned mask = 0; mask < 256; ++mask) {
    std::uint64_t packed = 0;
    int at = 0;
    for (unsigned bit = 0; bit < 8; ++bit)
      if (mask & (1u << bit)) packed |= std::uint64_t(bit) << (8 * at++);
    table[mask] = packed;
  }
  return table;
}
constexpr std::array<std::uint64_t, 256> kPackTable = make_pack_table();

/// The same with AVX2, eight candidates at a time: distances, the mask of neighbours, and the
/// neighbours' indices packed by a table-driven permutation. Every group is stored, even one without
/// a neighbour (popcount 0 leaves the count as it was): skipping those, about a third of the groups
/// and in no predictable order, would cost a mispredicted branch each.
__attribute__((target("avx2,popcnt"))) Index keep_candidates_within_avx2(NeighborLists::CandidateBuffer& buffer,
                                                                             const Vec3& query, Real radius_squared, Index self) {
  const std::size_t candidate_count = buffer.count;
  const Real* x = buffer.x.data();
  const Real* y = buffer.y.data();
  const Real* z = buffer.z.data();
  const Index* candidate = buffer.index.data();
  Index* found = buffer.found.data();
  const __m256 query_x = _mm256_set1_ps(query.x()), query_y = _mm256_set1_ps(query.y()), query_z = _mm256_set1_ps(query.z());
  const __m256 limit = _mm256_set1_ps(radius_squared);
  const __m256i own = _mm256_set1_epi32(static_cast<int>(self));
  Index count = 0;
  std::size_t c = 0;
  for (; c + 8 <= candidate_count; c += 8) {
    const __m256 dx = _mm256_sub_ps(query_x, _mm256_loadu_ps(x + c));
    const __m256 dy = _mm256_sub_ps(query_y, _mm256_loadu_ps(y + c));
    const __m256 dz = _mm256_sub_ps(query_z, _mm256_loadu_ps(z + c));
    // Not fused (no FMA in this target): the same rounding as the generic filter, the same lists.
    const __m256 distance_squared = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)), _mm256_mul_ps(dz, dz));
    const __m256i indices = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(candidate + c));
    const unsigned within = static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(distance_squared, limit, _CMP_LT_OQ)));
    const unsigned is_self = static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(indices, own))));
    const unsigned mask = within & ~is_self;
    const __m256i permutation = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(kPackTable[mask])));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(found + count), _mm256_permutevar8x32_epi32(indices, permutation));
    count += static_cast<Index>(_mm_popcnt_u32(mask));
  }
  return keep_last_candidates(buffer, c, count, query, radius_squared, self);
}

/// The same with AVX-512, sixteen candidates at a time: the mask of neighbours compresses their
/// indices to the front of a register (no table), which is stored whole.
__attribute__((target("avx512f,avx2,popcnt"))) Index keep_candidates_within_avx512(NeighborLists::CandidateBuffer& buffer,
                                                                                   const Vec3& query, Real radius_squared, Index self) {
  const std::size_t candidate_count = buffer.count;
  const Real* x = buffer.x.data();
  const Real* y = buffer.y.data();
  const Real* z = buffer.z.data();
  const Index* candidate = buffer.index.data();
  Index* found = buffer.found.data();
  const __m512 query_x = _mm512_set1_ps(query.x()), query_y = _mm512_set1_ps(query.y()), query_z = _mm512_set1_ps(query.z());
  const __m512 limit = _mm512_set1_ps(radius_squared);
  const __m512i own = _mm512_set1_epi32(static_cast<int>(self));
  Index count = 0;
  std::size_t c = 0;
  for (; c + 16 <= candidate_count; c += 16) {
    const __m512 dx = _mm512_sub_ps(query_x, _mm512_loadu_ps(x + c));
    const __m512 dy = _mm512_sub_ps(query_y, _mm512_loadu_ps(y + c));
    const __m512 dz = _mm512_sub_ps(query_z, _mm512_loadu_ps(z + c));
    // Not fused: the same rounding as the generic filter, the same lists.
    const __m512 distance_squared = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(dx, dx), _mm512_mul_ps(dy, dy)), _mm512_mul_ps(dz, dz));
    const __m512i indices = _mm512_loadu_si512(candidate + c);
    const __mmask16 mask = _mm512_cmp_ps_mask(distance_squared, limit, _CMP_LT_OQ) & ~_mm512_cmpeq_epi32_mask(indices, own);
    // Compressed in a register, then stored whole (a compressing store to memory is slow on some CPUs).
    _mm512_storeu_si512(found + count, _mm512_maskz_compress_epi32(mask, indices));
    count += static_cast<Index>(_mm_popcnt_u32(mask));
  }
  return keep_last_candidates(buffer, c, count, query, radius_squared, self);
}
#endif

Index keep_candidates_within(NeighborLists::CandidateBuffer& buffer, const Vec3& query, Real radius_squared, Index self) {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
  if (avx512::available()) return keep_candidates_within_avx512(buffer, query, radius_squared, self);
  if (avx2::available()) return keep_candidates_within_avx2(buffer, query, radius_squared, self);
#endif
  return keep_candidates_within_generic(buffer, query, radius_squared, self);
}

/// Runs pass(stride, note_needed) until every list fits its stride: note_needed(n) says a list needed
/// n slots, and a pass in which one needed more than `stride` runs again with a stride that fits it
/// (rare: a denser region than ever before). The staging holds `list_count` strides.
template <class Pass>
void with_growing_stride(NeighborLists& lists, std::size_t list_count, Pass&& pass) {
  for (;;) {
    const Index stride = lists.stride;
    if (lists.staging.size() < list_count * stride) lists.staging.resize(list_count * stride);
    std::atomic<Index> most_needed{0};
    auto note_needed = [&](Index needed) {
      if (needed <= stride) return;
      Index previous = most_needed.load(std::memory_order_relaxed);
      while (needed > previous && !most_needed.compare_exchange_weak(previous, needed)) {
      }
    };
    pass(stride, note_needed);
    if (most_needed.load() == 0) return;
    lists.stride = most_needed.load() + 16;
  }
}

}  // namespace

void SpatialHashGrid::build(std::span<const Vec3> positions, Real cell_size) {
  build_points(positions, nullptr, positions.size(), cell_size);
}

void SpatialHashGrid::build(std::span<const Vec3> positions, std::span<const Index> subset, Real cell_size) {
  build_points(positions, subset.data(), subset.size(), cell_size);
}

void SpatialHashGrid::build_points(std::span<const Vec3> positions, const Index* subset, std::size_t point_count,
                                   Real cell_size) {
  cell_size_ = cell_size;
  inverse_cell_size_ = Real(1) / cell_size;
  auto source = [&](std::size_t k) { return subset ? subset[k] : static_cast<Index>(k); };
  point_bucket_.resize(point_count);
  sorted_index_.resize(point_count);
  sorted_position_.resize(point_count);
  const bool was_dense = dense_;
  dense_ = point_count > 0 && choose_dense_cells(positions, subset, point_count);
  if (dense_) {
    // Dense cells: a counting sort in cell order. A point outside the box (not finite) sends the
    // grid back to hashing.
    const std::size_t cells = std::size_t(dense_extent_[0]) * dense_extent_[1] * dense_extent_[2];
    empty_bucket_ = static_cast<std::uint32_t>(cells);
    bucket_range_.assign(cells + 1, BucketRange{});
    const std::size_t outside = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, point_count, 1024), std::size_t(0),
        [&](const tbb::blocked_range<std::size_t>& range, std::size_t found) {
          for (std::size_t k = range.begin(); k != range.end(); ++k) {
            const auto cell = cell_of(positions[source(k)]);
            point_bucket_[k] = bucket_of_cell(cell[0], cell[1], cell[2]);
            found += point_bucket_[k] == empty_bucket_;
          }
          return found;
        },
        std::plus<std::size_t>());
    if (outside == 0) {
      for (std::size_t k = 0; k < point_count; ++k) ++bucket_range_[point_bucket_[k]].end;  // counts for now
      std::uint32_t slot = 0;
      for (BucketRange& range : bucket_range_) {
        const std::uint32_t points = range.end;
        range = BucketRange{slot, slot};  // end is the scatter's cursor
        slot += points;
      }
      for (std::size_t k = 0; k < point_count; ++k) sorted_index_[bucket_range_[point_bucket_[k]].end++] = source(k);
    } else {
      dense_ = false;
    }
  }
  if (!dense_) {
    // About two buckets per point keeps collisions rare; power of two so the hash is a mask.
    const std::size_t bucket_count = std::bit_ceil(std::max<std::size_t>(2 * point_count, 64));
    bucket_mask_ = static_cast<std::uint32_t>(bucket_count - 1);
    // Only the buckets the last build filled need clearing (a tank's 2^17 buckets, 1 MB, each step otherwise).
    if (was_dense || bucket_range_.size() != bucket_count) {
      bucket_range_.assign(bucket_count, BucketRange{});
    } else {
      for (const std::uint32_t bucket : filled_buckets_) bucket_range_[bucket] = BucketRange{};
    }
    parallel_for_each_index(point_count, [&](std::size_t k) {
      const auto cell = cell_of(positions[source(k)]);
      point_bucket_[k] = bucket_of_cell(cell[0], cell[1], cell[2]);
    }, 1024);
    // Counting sort with the buckets laid out in the order the points first touch them, not in hash
    // order: points in Z-order (the solver's reordering) give cells in about Z-order, so consecutive
    // cells' 27-cell gathers read mostly what the last one read (in hash order each gather's 27 buckets
    // lay anywhere in the sorted arrays). Sequential passes: memory-bound and cheap next to the queries.
    filled_buckets_.clear();
    for (std::size_t k = 0; k < point_count; ++k) {
      const std::uint32_t bucket = point_bucket_[k];
      if (bucket_range_[bucket].end++ == 0) filled_buckets_.push_back(bucket);  // end counts for now
    }
    std::uint32_t slot = 0;
    for (const std::uint32_t bucket : filled_buckets_) {
      const std::uint32_t points = bucket_range_[bucket].end;
      bucket_range_[bucket] = BucketRange{slot, slot};  // end is the scatter's cursor
      slot += points;
    }
    for (std::size_t k = 0; k < point_count; ++k) sorted_index_[bucket_range_[point_bucket_[k]].end++] = source(k);
  }
  sorted_x_.resize(point_count);
  sorted_y_.resize(point_count);
  sorted_z_.resize(point_count);
  parallel_for_each_index(point_count, [&](std::size_t slot) {
    const Vec3& position = positions[sorted_index_[slot]];
    sorted_position_[slot] = position;
    sorted_x_[slot] = position.x();
    sorted_y_[slot] = position.y();
    sorted_z_[slot] = position.z();
  }, 2048);
}

void SpatialHashGrid::remove_point(std::size_t k, Index index) {
  if (k >= point_bucket_.size()) return;
  // Far, yet finite: its squared distance to any query stays a float (1e30), above every radius.
  constexpr Real kFar = Real(1e15);
  const BucketRange range = bucket_range_[point_bucket_[k]];
  for (std::uint32_t slot = range.begin; slot < range.end; ++slot) {
    if (sorted_index_[slot] != index) continue;
    sorted_position_[slot] = Vec3::Constant(kFar);
    sorted_x_[slot] = sorted_y_[slot] = sorted_z_[slot] = kFar;
    return;
  }
}

bool SpatialHashGrid::choose_dense_cells(std::span<const Vec3> positions, const Index* subset, std::size_t point_count) {
  struct Box {
    Vec3 low = Vec3::Constant(std::numeric_limits<Real>::max()), high = Vec3::Constant(std::numeric_limits<Real>::lowest());
  };
  const Box box = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, point_count, 4096), Box{},
      [&](const tbb::blocked_range<std::size_t>& range, Box found) {
        for (std::size_t k = range.begin(); k != range.end(); ++k) {
          const Vec3& position = positions[subset ? subset[k] : k];
          found.low = found.low.cwiseMin(position);
          found.high = found.high.cwiseMax(position);
        }
        return found;
      },
      [](const Box& a, const Box& b) { return Box{a.low.cwiseMin(b.low), a.high.cwiseMax(b.high)}; });
  if (!box.low.allFinite() || !box.high.allFinite()) return false;
  // The box in cells (a query outside it still finds the cells inside: its runs are clipped to the box).
  const Vec3 low = box.low * inverse_cell_size_, high = box.high * inverse_cell_size_;
  constexpr Real kLargestCell = Real(1 << 30);
  if (low.minCoeff() < -kLargestCell || high.maxCoeff() > kLargestCell) return false;
  const std::size_t limit = std::max(kDenseCellsAlways, kDenseCellsPerPoint * point_count);
  std::size_t cells = 1;
  for (int axis = 0; axis < 3; ++axis) {
    const auto first = static_cast<std::int64_t>(std::floor(low[axis])), last = static_cast<std::int64_t>(std::floor(high[axis]));
    const auto extent = static_cast<std::size_t>(last - first + 1);
    cells *= extent;
    if (cells > limit) return false;
    dense_origin_[axis] = static_cast<std::int32_t>(first);
    dense_extent_[axis] = static_cast<std::uint32_t>(extent);
  }
  return true;
}

void SpatialHashGrid::append_points_around_cell(const std::array<std::int32_t, 3>& cell, NeighborLists::CandidateBuffer& buffer) const {
  if (sorted_index_.empty()) return;
  BucketRange ranges[27];
  int range_count = 0;
  if (dense_) {
    // The three cells along x of each of the nine rows around `cell` are consecutive buckets, and
    // their points one range of the sorted arrays: nine copies, not 27.
    const std::int64_t first_x = std::max<std::int64_t>(std::int64_t(cell[0]) - dense_origin_[0] - 1, 0);
    const std::int64_t last_x = std::min<std::int64_t>(std::int64_t(cell[0]) - dense_origin_[0] + 1, std::int64_t(dense_extent_[0]) - 1);
    if (first_x > last_x) return;
    for (std::int64_t dz = -1; dz <= 1; ++dz) {
      const std::int64_t z = std::int64_t(cell[2]) - dense_origin_[2] + dz;
      if (z < 0 || z >= std::int64_t(dense_extent_[2])) continue;
      for (std::int64_t dy = -1; dy <= 1; ++dy) {
        const std::int64_t y = std::int64_t(cell[1]) - dense_origin_[1] + dy;
        if (y < 0 || y >= std::int64_t(dense_extent_[1])) continue;
        const std::size_t row = std::size_t(dense_extent_[0]) * std::size_t(y + std::int64_t(dense_extent_[1]) * z);
        ranges[range_count++] = BucketRange{bucket_range_[row + std::size_t(first_x)].begin, bucket_range_[row + std::size_t(last_x)].end};
      }
    }
  } else {
    std::uint32_t buckets[27];
    range_count = buckets_around_cell(cell, buckets);
    for (int k = 0; k < range_count; ++k) ranges[k] = bucket_range_[buckets[k]];
  }
  std::size_t total = 0;
  for (int k = 0; k < range_count; ++k) total += ranges[k].end - ranges[k].begin;
  std::size_t at = buffer.count;
  if (buffer.index.size() < at + total) {  // grow only; values past `count` are never read
    buffer.index.resize(at + total);
    buffer.x.resize(at + total);
    buffer.y.resize(at + total);
    buffer.z.resize(at + total);
  }
  // One loop over the four arrays: a bucket holds about eight points, too few for four library copies.
  Index* index_out = buffer.index.data();
  Real *x_out = buffer.x.data(), *y_out = buffer.y.data(), *z_out = buffer.z.data();
  for (int k = 0; k < range_count; ++k)
    for (std::uint32_t slot = ranges[k].begin; slot < ranges[k].end; ++slot, ++at) {
      index_out[at] = sorted_index_[slot];
      x_out[at] = sorted_x_[slot];
      y_out[at] = sorted_y_[slot];
      z_out[at] = sorted_z_[slot];
    }
  buffer.count = at;
}

void find_neighbors(const SpatialHashGrid& grid, std::span<const Vec3> query_positions, Real radius,
                    bool exclude_same_index, NeighborLists& out, bool sort_lists, std::span<const Index> query_order) {
  const SpatialHashGrid* grids[] = {&grid};
  find_neighbors(grids, query_positions, radius, exclude_same_index, out, sort_lists, query_order);
}

void find_neighbors(std::span<const SpatialHashGrid* const> grids, std::span<const Vec3> query_positions, Real radius,
                    bool exclude_same_index, NeighborLists& out, bool sort_lists, std::span<const Index> query_order) {
  const SpatialHashGrid& grid = *grids.front();
  const std::size_t query_count = query_positions.size();
  const Real radius_squared = radius * radius;
  out.counts.resize(query_count);
  out.staged_firsts.resize(query_count);
  const std::size_t order_count = query_order.empty() ? query_count : query_order.size();
  with_growing_stride(out, std::max(order_count, query_count), [&](const Index stride, auto&& note_needed) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, order_count, 64), [&](const tbb::blocked_range<std::size_t>& range) {
      NeighborLists::CandidateBuffer& buffer = out.candidate_buffers.local();
      buffer.valid = false;  // the grid may have changed since this thread's last search
      // The range's lists go back to back, in query order, into its own stride per query: the stores
      // run forward (by particle index, i · stride, they landed all over 9 MB, and waited for their
      // cache lines); the packing reads them back in index order.
      std::size_t cursor = range.begin() * stride;
      for (std::size_t at = range.begin(); at != range.end(); ++at) {
        const std::size_t i = query_order.empty() ? at : query_order[at];
        if (i >= query_count) continue;
        const Vec3 query = query_positions[i];
        const auto cell = grid.cell_of(query);
        if (!buffer.valid || cell != buffer.cell) {
          buffer.count = 0;
          for (const SpatialHashGrid* each : grids) each->append_points_around_cell(cell, buffer);
          if (buffer.distance_squared.size() < buffer.count) buffer.distance_squared.resize(buffer.count);
          if (buffer.found.size() < buffer.count + kFoundSlack) buffer.found.resize(buffer.count + kFoundSlack);
          buffer.cell = cell;
          buffer.valid = true;
        }
        if (buffer.count == 0) {
          // No candidates around this cell (most cells, for the boundary lists): nothing to filter or copy.
          out.counts[i] = 0;
          out.staged_firsts[i] = cursor;
          continue;
        }
        const Index self = exclude_same_index ? static_cast<Index>(i) : std::numeric_limits<Index>::max();
        const Index count = keep_candidates_within(buffer, query, radius_squared, self);
        const Index* found = buffer.found.data();
        Index* slots = out.staging.data() + cursor;
        if ((count + 7) / 8 * 8 <= stride) {
          // Whole groups of eight, past the list's end within its own slots (the found buffer has the
          // slack): no library call per query.
          for (Index group = 0; group < count; group += 8)
            for (Index lane = 0; lane < 8; ++lane) slots[group + lane] = found[group + lane];
        } else {
          std::copy_n(found, std::min(count, stride), slots);
        }
        out.counts[i] = std::min(count, stride);
        out.staged_firsts[i] = cursor;
        cursor += out.counts[i];
        note_needed(count);
      }
    });
  });
  pack_staged_lists(out, query_count, sort_lists);
}

void pack_staged_lists(NeighborLists& out, std::size_t query_count, bool sort_lists) {
  // Back to back in particle order (see NeighborLists).
  out.firsts.resize(query_count);
  std::size_t total = 0;
  for (std::size_t i = 0; i < query_count; ++i) {
    out.firsts[i] = total;
    total += out.counts[i];
  }
  out.indices.resize(total);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, query_count, 512), [&](const tbb::blocked_range<std::size_t>& range) {
    // One copy loop over the range, not a memmove call per list (a few dozen indices each).
    Index* packed = out.indices.data() + out.firsts[range.begin()];
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const Index* staged = out.staging.data() + out.staged_firsts[i];
      const Index count = out.counts[i];
      for (Index k = 0; k < count; ++k) packed[k] = staged[k];
      // Sorted by index, neighbours sit in memory order (after Z-order reordering).
      if (sort_lists) std::sort(packed, packed + count);
      packed += count;
    }
  });
}

namespace {

/// Fills `lists` with `count` fixed-stride lists: fill(k, slots, stride) writes list k into slots (at
/// most `stride` of them) and returns its full length.
template <class Fill>
void fill_staged_lists(NeighborLists& lists, std::size_t count, std::size_t grain, Fill&& fill) {
  lists.counts.resize(count);
  with_growing_stride(lists, count, [&](const Index stride, auto&& note_needed) {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, grain), [&](const tbb::blocked_range<std::size_t>& range) {
      for (std::size_t k = range.begin(); k != range.end(); ++k) {
        const Index found = fill(k, lists.staging.data() + k * stride, stride);
        lists.counts[k] = std::min(found, stride);
        note_needed(found);
      }
    });
  });
}

/// Squared distance written out term by term: the same value from either end of a pair (a − b and
/// b − a round alike), so a pair is kept from both ends or from neither.
inline Real distance_squared(const Vec3& a, const Vec3& b) {
  const Real dx = a.x() - b.x(), dy = a.y() - b.y(), dz = a.z() - b.z();
  return dx * dx + dy * dy + dz * dz;
}

}  // namespace

bool SkinnedNeighborSearch::update(const Inputs& inputs, Real radius, Real skin, std::size_t max_movers,
                                   NeighborLists& fluid_out, NeighborLists& boundary_out) {
  const std::size_t active = inputs.active_count;
  const std::span<const Vec3> positions = inputs.fluid_positions;
  const Real cell_size = radius + skin;
  for (const SpatialHashGrid* grid : {inputs.resting_grid, inputs.recent_resting_grid, inputs.static_boundary_grid, inputs.moving_boundary_grid})
    if (grid != nullptr && grid->point_count() > 0 && grid->cell_size() != cell_size)
      throw Error(fmt::format("SkinnedNeighborSearch: a grid's cells are {} m, not radius + skin = {} m", grid->cell_size(), cell_size));
  const bool same_setup = valid_ && radius == radius_ && skin == skin_ && inputs.fixed_grids_version == fixed_grids_version_;
  const bool same_particles = same_setup && active == active_count_ && ids_.size() == inputs.fluid_ids.size() &&
                              std::equal(ids_.begin(), ids_.end(), inputs.fluid_ids.begin());
  // Particles emitted since the search, appended after the others (none resting): movers until the
  // next one, so that a nozzle's layers do not force searches.
  const bool only_appended = same_setup && !same_particles && active > active_count_ && inputs.fluid_ids.size() == active &&
                             ids_.size() == active_count_ && std::equal(ids_.begin(), ids_.end(), inputs.fluid_ids.begin());
  bool search_anew = !same_particles && !only_appended;
  query_count_ = active;
  is_mover_.resize(positions.size());
  movers_.clear();
  if (!search_anew) {
    // With |Δx_i| + |Δx_j| ≤ skin a pair now within r was within r + skin at the search. A hair under
    // half the skin: the bound must survive rounding.
    const Real limit = Real(0.499) * skin;
    const Real limit_squared = limit * limit;
    const std::size_t mover_total = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, active, 2048), std::size_t(0),
        [&](const tbb::blocked_range<std::size_t>& range, std::size_t found) {
          for (std::size_t i = range.begin(); i != range.end(); ++i) {
            const bool moved = i >= active_count_ || distance_squared(positions[i], reference_positions_[i]) > limit_squared;
            is_mover_[i] = moved;
            found += moved;
          }
          return found;
        },
        std::plus<std::size_t>());
    search_anew = mover_total > max_movers;
    if (!search_anew && mover_total > 0)
      for (std::size_t i = 0; i < active; ++i)
        if (is_mover_[i]) movers_.push_back(static_cast<Index>(i));
  }
  if (search_anew) search(inputs, radius, skin);
  std::fill(is_mover_.begin() + std::ptrdiff_t(active), is_mover_.end(), std::uint8_t(0));

  const Real radius_squared = radius * radius;
  find_mover_lists(inputs, radius_squared);
  find_moving_boundary_pairs(inputs, radius_squared);
  filter_lists(fluid_superset_, positions, positions, radius_squared, !movers_.empty(), mover_fluid_, added_fluid_, fluid_out);
  filter_lists(boundary_superset_, inputs.boundary_positions, positions, radius_squared, false, mover_boundary_, added_boundary_,
               boundary_out);
  return search_anew;
}

void SkinnedNeighborSearch::search(const Inputs& inputs, Real radius, Real skin) {
  const std::size_t active = inputs.active_count;
  const std::span<const Vec3> active_positions = inputs.fluid_positions.first(active);
  active_grid_.build(active_positions, radius + skin);
  const std::span<const Index> query_order = active_grid_.points_in_grid_order();
  const SpatialHashGrid* fluid_grids[] = {&active_grid_, inputs.resting_grid, inputs.recent_resting_grid};
  find_neighbors(std::span(fluid_grids, inputs.recent_resting_grid ? 3 : 2), active_positions, radius + skin, true, fluid_superset_, false, query_order);
  const SpatialHashGrid* static_grids[] = {inputs.static_boundary_grid};
  find_neighbors(static_grids, active_positions, radius + skin, false, boundary_superset_, false, query_order);
  reference_positions_.assign(active_positions.begin(), active_positions.end());
  ids_.assign(inputs.fluid_ids.begin(), inputs.fluid_ids.end());
  radius_ = radius;
  skin_ = skin;
  active_count_ = active;
  fixed_grids_version_ = inputs.fixed_grids_version;
  std::fill(is_mover_.begin(), is_mover_.end(), std::uint8_t(0));
  movers_.clear();
  valid_ = true;
}

void SkinnedNeighborSearch::find_mover_lists(const Inputs& inputs, Real radius_squared) {
  const std::span<const Vec3> positions = inputs.fluid_positions;
  mover_slot_.resize(inputs.active_count);
  for (std::size_t k = 0; k < movers_.size(); ++k) mover_slot_[movers_[k]] = static_cast<Index>(k);
  // A mover's fluid neighbours: the others in the kept grids (where they were, within skin/2 of where
  // they are, so inside the 27 cells of r + skin) and the other movers, which may be anywhere.
  fill_staged_lists(mover_fluid_, movers_.size(), 16, [&](std::size_t k, Index* slots, Index stride) {
    const Index mover = movers_[k];
    const Vec3 position = positions[mover];
    Index found = 0;
    auto keep = [&](Index j) {
      if (distance_squared(positions[j], position) >= radius_squared) return;
      if (found < stride) slots[found] = j;
      ++found;
    };
    const auto cell = active_grid_.cell_of(position);
    for (const SpatialHashGrid* grid : {static_cast<const SpatialHashGrid*>(&active_grid_), inputs.resting_grid, inputs.recent_resting_grid})
      if (grid != nullptr) grid->for_each_point_around_cell(cell, [&](Index j, const Vec3&) {
        if (!is_mover_[j]) keep(j);
      });
    for (const Index other : movers_)
      if (other != mover) keep(other);
    return found;
  });
  // Its boundary neighbours: every boundary grid holds its particles where they are.
  fill_staged_lists(mover_boundary_, movers_.size(), 16, [&](std::size_t k, Index* slots, Index stride) {
    const Vec3 position = positions[movers_[k]];
    Index found = 0;
    const auto cell = active_grid_.cell_of(position);
    for (const SpatialHashGrid* grid : {inputs.static_boundary_grid, inputs.moving_boundary_grid})
      grid->for_each_point_around_cell(cell, [&](Index b, const Vec3& point) {
        if (distance_squared(point, position) >= radius_squared) return;
        if (found < stride) slots[found] = b;
        ++found;
      });
    return found;
  });
  // Each mover's pairs with particles that are not movers join those particles' lists.
  auto& added = added_fluid_;
  added.firsts.assign(inputs.active_count + 1, 0);
  for (std::size_t k = 0; k < movers_.size(); ++k)
    for (std::size_t n = 0; n < mover_fluid_.counts[k]; ++n) {
      const Index j = mover_fluid_.staging[k * mover_fluid_.stride + n];
      if (j < inputs.active_count && !is_mover_[j]) ++added.firsts[j + 1];
    }
  for (std::size_t i = 0; i < inputs.active_count; ++i) added.firsts[i + 1] += added.firsts[i];
  added.items.resize(added.firsts.back());
  added.cursor.assign(added.firsts.begin(), added.firsts.end() - 1);
  for (std::size_t k = 0; k < movers_.size(); ++k)
    for (std::size_t n = 0; n < mover_fluid_.counts[k]; ++n) {
      const Index j = mover_fluid_.staging[k * mover_fluid_.stride + n];
      if (j < inputs.active_count && !is_mover_[j]) added.items[added.cursor[j]++] = movers_[k];
    }
}

void SkinnedNeighborSearch::find_moving_boundary_pairs(const Inputs& inputs, Real radius_squared) {
  const std::span<const Vec3> positions = inputs.fluid_positions;
  const std::span<const Index> moving = inputs.moving_boundary_indices;
  // Each moving boundary particle's active fluid neighbours that are not movers (those searched the
  // moving grid themselves), found in the kept grid as the movers find theirs.
  fill_staged_lists(moving_boundary_hits_, moving.size(), 64, [&](std::size_t k, Index* slots, Index stride) {
    const Vec3 position = inputs.boundary_positions[moving[k]];
    Index found = 0;
    active_grid_.for_each_point_around_cell(active_grid_.cell_of(position), [&](Index j, const Vec3&) {
      if (is_mover_[j] || distance_squared(positions[j], position) >= radius_squared) return;
      if (found < stride) slots[found] = j;
      ++found;
    });
    return found;
  });
  auto& added = added_boundary_;
  added.firsts.assign(inputs.active_count + 1, 0);
  const Index stride = moving_boundary_hits_.stride;
  for (std::size_t k = 0; k < moving.size(); ++k)
    for (std::size_t n = 0; n < moving_boundary_hits_.counts[k]; ++n) ++added.firsts[moving_boundary_hits_.staging[k * stride + n] + 1];
  for (std::size_t i = 0; i < inputs.active_count; ++i) added.firsts[i + 1] += added.firsts[i];
  added.items.resize(added.firsts.back());
  added.cursor.assign(added.firsts.begin(), added.firsts.end() - 1);
  for (std::size_t k = 0; k < moving.size(); ++k)
    for (std::size_t n = 0; n < moving_boundary_hits_.counts[k]; ++n) {
      const Index j = moving_boundary_hits_.staging[k * stride + n];
      added.items[added.cursor[j]++] = moving[k];
    }
}

void SkinnedNeighborSearch::filter_lists(const NeighborLists& superset, std::span<const Vec3> neighbor_positions,
                                         std::span<const Vec3> positions, Real radius_squared, bool skip_movers,
                                         const NeighborLists& mover_lists, const AddedPairs& added, NeighborLists& out) const {
  // Written in place, without staging and packing: each block of particles gets room for its lists'
  // longest possible lengths (superset plus added pairs, or a mover's own list) and fills it from the
  // front. The lists are back to back within a block, with the unused room after it; the sweeps read
  // lists by firsts and counts, and a gap every few hundred lists does not slow them.
  constexpr std::size_t kBlock = 512;
  const std::size_t count = query_count_;
  out.counts.resize(count);
  out.firsts.resize(count);
  std::size_t room = 0;
  for (std::size_t i = 0; i < count; ++i) {
    out.firsts[i] = room;  // the longest lists' starts; a block's first is where its room begins
    room += is_mover_[i] ? mover_lists.counts[mover_slot_[i]] : superset.counts[i] + (added.firsts[i + 1] - added.firsts[i]);
  }
  out.indices.resize(room);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, (count + kBlock - 1) / kBlock, 1), [&](const tbb::blocked_range<std::size_t>& blocks) {
    for (std::size_t block = blocks.begin(); block != blocks.end(); ++block) {
      const std::size_t begin = block * kBlock, end = std::min(count, begin + kBlock);
      std::size_t at = out.firsts[begin];
      for (std::size_t i = begin; i < end; ++i) {
        Index* slots = out.indices.data() + at;
        Index found = 0;
        if (is_mover_[i]) {
          const std::size_t slot = mover_slot_[i];
          found = mover_lists.counts[slot];
          std::copy_n(mover_lists.staging.data() + slot * mover_lists.stride, found, slots);
        } else {
          const Vec3 position = positions[i];
          // Branch-free: about three candidates in four are kept, irregularly.
          for (const Index j : superset.of(i)) {
            slots[found] = j;
            found += static_cast<Index>((distance_squared(neighbor_positions[j], position) < radius_squared) &
                                        !(skip_movers && is_mover_[j]));
          }
          for (std::size_t n = added.firsts[i]; n < added.firsts[i + 1]; ++n) slots[found++] = added.items[n];
        }
        out.firsts[i] = at;
        out.counts[i] = found;
        at += found;
      }
    }
  });
}

namespace {
std::uint64_t spread_bits_21(std::uint64_t value) {
  value &= 0x1fffff;
  value = (value | value << 32) & 0x1f00000000ffffULL;
  value = (value | value << 16) & 0x1f0000ff0000ffULL;
  value = (value | value << 8) & 0x100f00f00f00f00fULL;
  value = (value | value << 4) & 0x10c30c30c30c30c3ULL;
  value = (value | value << 2) & 0x1249249249249249ULL;
  return value;
}
}  // namespace

std::uint64_t morton_code(std::int32_t x, std::int32_t y, std::int32_t z) {
  constexpr std::int64_t offset = 1 << 20;  // cells from −2^20 to 2^20 map to positive 21-bit ints
  return spread_bits_21(static_cast<std::uint64_t>(x + offset)) | spread_bits_21(static_cast<std::uint64_t>(y + offset)) << 1 |
         spread_bits_21(static_cast<std::uint64_t>(z + offset)) << 2;
}

void sort_by_cell(std::span<const Vec3> positions, std::size_t count, Real cell_size, std::vector<std::uint64_t>& keys,
                  std::vector<Index>& order) {
  const Real inverse_cell = Real(1) / cell_size;
  keys.resize(count);
  order.resize(count);
  parallel_for_each_index(count, [&](std::size_t i) {
    const Vec3& p = positions[i];
    keys[i] = morton_code(static_cast<std::int32_t>(std::floor(p.x() * inverse_cell)),
                          static_cast<std::int32_t>(std::floor(p.y() * inverse_cell)),
                          static_cast<std::int32_t>(std::floor(p.z() * inverse_cell)));
    order[i] = static_cast<Index>(i);
  }, 2048);
  tbb::parallel_sort(order.begin(), order.end(),
                     [&](Index a, Index b) { return keys[a] < keys[b] || (keys[a] == keys[b] && a < b); });
}

}  // namespace m3dp::sph
