#include "m3dp/sph/neighbor_search.hpp"

#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <limits>

#include "m3dp/core/parallel.hpp"

#include "m3dp/sph/neighbor_sums_avx2.hpp"  // avx2::available() and the intrinsics

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
/// neighbours' indices packed by a table-driven permutation (the neighbour stage of the 47k dam break
/// went from 18.7-21.0 to 15.1-16.4 ms a step).
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
    if (mask == 0) continue;
    const __m256i permutation = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(static_cast<long long>(kPackTable[mask])));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(found + count), _mm256_permutevar8x32_epi32(indices, permutation));
    count += static_cast<Index>(_mm_popcnt_u32(mask));
  }
  for (; c < candidate_count; ++c) {
    const Real dx = query.x() - x[c], dy = query.y() - y[c], dz = query.z() - z[c];
    found[count] = candidate[c];
    count += static_cast<Index>((dx * dx + dy * dy + dz * dz < radius_squared) & (candidate[c] != self));
  }
  return count;
}
#endif

Index keep_candidates_within(NeighborLists::CandidateBuffer& buffer, const Vec3& query, Real radius_squared, Index self) {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
  if (avx2::available()) return keep_candidates_within_avx2(buffer, query, radius_squared, self);
#endif
  return keep_candidates_within_generic(buffer, query, radius_squared, self);
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
  // About two buckets per point keeps collisions rare; power of two so the hash is a mask.
  const std::size_t bucket_count = std::bit_ceil(std::max<std::size_t>(2 * point_count, 64));
  bucket_mask_ = static_cast<std::uint32_t>(bucket_count - 1);

  bucket_start_.assign(bucket_count + 1, 0);
  point_bucket_.resize(point_count);
  sorted_index_.resize(point_count);
  sorted_position_.resize(point_count);

  parallel_for_each_index(point_count, [&](std::size_t k) {
    const auto cell = cell_of(positions[source(k)]);
    point_bucket_[k] = bucket_of_cell(cell[0], cell[1], cell[2]);
  }, 1024);
  // Counting sort: histogram, exclusive prefix sum, scatter. Sequential passes are memory-bound
  // and cheap next to the neighbour queries.
  for (std::size_t k = 0; k < point_count; ++k) ++bucket_start_[point_bucket_[k] + 1];
  for (std::size_t b = 0; b < bucket_count; ++b) bucket_start_[b + 1] += bucket_start_[b];
  // Scatter using bucket_start_ as cursors, then shift back.
  for (std::size_t k = 0; k < point_count; ++k) {
    const std::uint32_t slot = bucket_start_[point_bucket_[k]]++;
    sorted_index_[slot] = source(k);
  }
  for (std::size_t b = bucket_count; b > 0; --b) bucket_start_[b] = bucket_start_[b - 1];
  bucket_start_[0] = 0;
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

void SpatialHashGrid::append_points_around_cell(const std::array<std::int32_t, 3>& cell, NeighborLists::CandidateBuffer& buffer) const {
  if (sorted_index_.empty()) return;
  std::uint32_t buckets[27];
  const int count = buckets_around_cell(cell, buckets);
  std::size_t total = 0;
  for (int k = 0; k < count; ++k) total += bucket_start_[buckets[k] + 1] - bucket_start_[buckets[k]];
  std::size_t at = buffer.count;
  if (buffer.index.size() < at + total) {  // grow only; values past `count` are never read
    buffer.index.resize(at + total);
    buffer.x.resize(at + total);
    buffer.y.resize(at + total);
    buffer.z.resize(at + total);
  }
  // One loop over the four arrays: a bucket holds about eight points, too few for four library copies
  // (their calls cost more than the copying: 5 % of the dam break).
  Index* index_out = buffer.index.data();
  Real *x_out = buffer.x.data(), *y_out = buffer.y.data(), *z_out = buffer.z.data();
  for (int k = 0; k < count; ++k) {
    const std::uint32_t begin = bucket_start_[buckets[k]], end = bucket_start_[buckets[k] + 1];
    for (std::uint32_t slot = begin; slot < end; ++slot, ++at) {
      index_out[at] = sorted_index_[slot];
      x_out[at] = sorted_x_[slot];
      y_out[at] = sorted_y_[slot];
      z_out[at] = sorted_z_[slot];
    }
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
  for (;;) {
    const std::size_t needed = query_count * out.stride;
    if (out.staging.size() < needed) out.staging.resize(needed);
    std::atomic<Index> most_needed{0};
    const Index stride = out.stride;
    const std::size_t order_count = query_order.empty() ? query_count : query_order.size();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, order_count, 64), [&](const tbb::blocked_range<std::size_t>& range) {
      NeighborLists::CandidateBuffer& buffer = out.candidate_buffers.local();
      buffer.valid = false;  // the grid may have changed since this thread's last search
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
        const Index self = exclude_same_index ? static_cast<Index>(i) : std::numeric_limits<Index>::max();
        const Index count = keep_candidates_within(buffer, query, radius_squared, self);
        const Index* found = buffer.found.data();
        std::copy_n(found, std::min(count, stride), out.staging.data() + i * stride);
        out.counts[i] = std::min(count, stride);
        if (count > stride) {
          Index previous = most_needed.load(std::memory_order_relaxed);
          while (count > previous && !most_needed.compare_exchange_weak(previous, count)) {
          }
        }
      }
    });
    if (most_needed.load() == 0) break;
    // Rare: a denser region than ever before. Grow and redo this search.
    out.stride = most_needed.load() + 16;
  }
  // Pack the lists back to back in particle order (see NeighborLists).
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
      const Index* staged = out.staging.data() + i * out.stride;
      const Index count = out.counts[i];
      for (Index k = 0; k < count; ++k) packed[k] = staged[k];
      // Sorted by index, neighbours sit in memory order (after Z-order reordering).
      if (sort_lists) std::sort(packed, packed + count);
      packed += count;
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
