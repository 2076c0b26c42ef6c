// Where the material is deep, a particle's contribution cannot reach the surface: each method splats
// only the particles near it and fills the deep cells afterwards (find_deep_region).
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <unordered_map>

#include "m3dp/sph/neighbors/neighbor_search.hpp"
#include "m3dp/surface/field.hpp"

namespace m3dp::surface {

namespace {

/// Particle indices in Z-order of a coarse grid (so each thread's splats stay in a compact region),
/// and each one's cell's Morton key: particles of one cell come out consecutive.
struct SpatialOrder {
  std::vector<Index> order;
  std::vector<std::uint64_t> key;  // key[n]: the cell key of particle order[n]
};

std::array<std::int32_t, 3> coarse_cell_of(const Vec3& p, Real inverse_cell_size) {
  return {static_cast<std::int32_t>(std::floor(p.x() * inverse_cell_size)),
          static_cast<std::int32_t>(std::floor(p.y() * inverse_cell_size)),
          static_cast<std::int32_t>(std::floor(p.z() * inverse_cell_size))};
}

SpatialOrder spatial_order(std::span<const Vec3> positions, Real cell_size) {
  std::vector<std::pair<std::uint64_t, Index>> keyed(positions.size());
  const Real inverse = Real(1) / cell_size;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, positions.size(), 4096), [&](const auto& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const auto cell = coarse_cell_of(positions[i], inverse);
      keyed[i] = {sph::morton_code(cell[0], cell[1], cell[2]), static_cast<Index>(i)};
    }
  });
  tbb::parallel_sort(keyed.begin(), keyed.end());
  SpatialOrder result;
  result.order.resize(keyed.size());
  result.key.resize(keyed.size());
  for (std::size_t n = 0; n < keyed.size(); ++n) {
    result.key[n] = keyed[n].first;
    result.order[n] = keyed[n].second;
  }
  return result;
}

}  // namespace

DeepRegion find_deep_region(std::span<const Vec3> positions, Real cell_size, Real particle_radius) {
  DeepRegion region;
  region.cell_size = cell_size;
  const Real inverse = Real(1) / cell_size;
  const SpatialOrder sorted = spatial_order(positions, cell_size);
  // The occupied cells: runs of one key in the sorted order.
  struct Cell {
    std::array<std::int32_t, 3> coord;
    std::size_t first, end;  // its particles: sorted.order[first, end)
    bool full = false, interior = false, deep = false;
  };
  std::vector<Cell> cells;
  for (std::size_t n = 0; n < sorted.order.size();) {
    std::size_t end = n;
    while (end < sorted.order.size() && sorted.key[end] == sorted.key[n]) ++end;
    cells.push_back(Cell{coarse_cell_of(positions[sorted.order[n]], inverse), n, end});
    n = end;
  }
  std::unordered_map<std::uint64_t, std::size_t> cell_index;
  cell_index.reserve(2 * cells.size());
  for (std::size_t c = 0; c < cells.size(); ++c) cell_index.emplace(sorted.key[cells[c].first], c);
  const double lattice_capacity = std::pow(static_cast<double>(cell_size / (2 * particle_radius)), 3);
  const auto full_count = static_cast<std::size_t>(std::max(1.0, 0.6 * lattice_capacity));
  for (Cell& cell : cells) cell.full = cell.end - cell.first >= full_count;
  // Whether `flag` holds for the cell and its 26 neighbours (an empty cell has no flag).
  auto all_around = [&](const Cell& cell, bool Cell::*flag) {
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto found =
              cell_index.find(sph::morton_code(cell.coord[0] + dx, cell.coord[1] + dy, cell.coord[2] + dz));
          if (found == cell_index.end() || !(cells[found->second].*flag)) return false;
        }
    return true;
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells.size(), 256), [&](const auto& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) cells[c].interior = all_around(cells[c], &Cell::full);
  });
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cells.size(), 256), [&](const auto& range) {
    for (std::size_t c = range.begin(); c != range.end(); ++c) cells[c].deep = all_around(cells[c], &Cell::interior);
  });
  region.contributing.reserve(positions.size());
  for (const Cell& cell : cells) {
    if (cell.interior) region.interior_cells.push_back(cell.coord);
    if (!cell.deep)
      region.contributing.insert(region.contributing.end(), sorted.order.begin() + static_cast<std::ptrdiff_t>(cell.first),
                                 sorted.order.begin() + static_cast<std::ptrdiff_t>(cell.end));
  }
  return region;
}

}  // namespace m3dp::surface
