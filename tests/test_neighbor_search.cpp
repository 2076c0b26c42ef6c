#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "m3dp/sph/neighbor_search.hpp"

using namespace m3dp;
using namespace m3dp::sph;

namespace {
std::vector<Index> brute_force(const std::vector<Vec3>& points, const Vec3& query, Real radius, std::size_t self) {
  std::vector<Index> found;
  for (std::size_t j = 0; j < points.size(); ++j)
    if (j != self && (points[j] - query).squaredNorm() < radius * radius) found.push_back(static_cast<Index>(j));
  return found;
}

void expect_equal_to_brute_force(const std::vector<Vec3>& points, Real radius) {
  SpatialHashGrid grid;
  grid.build(points, radius);
  NeighborLists lists;
  lists.stride = 8;  // deliberately small: forces the grow-and-redo path
  find_neighbors(grid, points, radius, true, lists);
  std::size_t total = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const auto expected = brute_force(points, points[i], radius, i);
    const auto span = lists.of(i);
    const std::vector<Index> got(span.begin(), span.end());
    ASSERT_EQ(got, expected) << "particle " << i;
    total += got.size();
  }
  EXPECT_EQ(lists.total(), total);
  EXPECT_GT(total, points.size());  // the sets are dense enough to have neighbours
}
}  // namespace

TEST(NeighborSearch, EqualsBruteForceOnUniformRandomPoints) {
  std::mt19937 random(1);
  std::uniform_real_distribution<float> coordinate(-0.5f, 0.5f);
  std::vector<Vec3> points(3000);
  for (auto& p : points) p = Vec3(coordinate(random), coordinate(random), coordinate(random));
  expect_equal_to_brute_force(points, Real(0.08));
}

TEST(NeighborSearch, EqualsBruteForceOnClusteredPointsAndNegativeCoordinates) {
  std::mt19937 random(2);
  std::normal_distribution<float> spread(0, 0.02f);
  std::vector<Vec3> points;
  const Vec3 centres[] = {Vec3(-3, -2, -1), Vec3(0, 0, 0), Vec3(5, 5, 5), Vec3(0.01f, 0.0f, 0.02f)};
  for (const auto& centre : centres)
    for (int n = 0; n < 700; ++n) points.push_back(centre + Vec3(spread(random), spread(random), spread(random)));
  expect_equal_to_brute_force(points, Real(0.015));
}

TEST(NeighborSearch, QueriesAgainstAnotherSet) {
  std::mt19937 random(3);
  std::uniform_real_distribution<float> coordinate(0, 1);
  std::vector<Vec3> grid_points(2000), queries(500);
  for (auto& p : grid_points) p = Vec3(coordinate(random), coordinate(random), coordinate(random));
  for (auto& p : queries) p = Vec3(coordinate(random), coordinate(random), coordinate(random));
  SpatialHashGrid grid;
  grid.build(grid_points, Real(0.1));
  NeighborLists lists;
  find_neighbors(grid, queries, Real(0.1), false, lists);
  for (std::size_t i = 0; i < queries.size(); ++i) {
    const auto span = lists.of(i);
    EXPECT_EQ(std::vector<Index>(span.begin(), span.end()), brute_force(grid_points, queries[i], Real(0.1), grid_points.size()));
  }
}

TEST(NeighborSearch, TwoGridsOverSubsetsFindWhatOneGridFinds) {
  // The solver's static and moving boundary grids: each over a subset of one point set. Points left
  // out of both subsets (a body far from the fluid) must not be found.
  std::mt19937 random(4);
  std::uniform_real_distribution<float> coordinate(0, 1);
  std::vector<Vec3> points(3000), queries(400);
  for (auto& p : points) p = Vec3(coordinate(random), coordinate(random), coordinate(random));
  for (auto& p : queries) p = Vec3(coordinate(random), coordinate(random), coordinate(random));
  std::vector<Index> first, second;
  std::vector<Vec3> kept;
  std::vector<Index> kept_index;
  for (Index k = 0; k < points.size(); ++k) {
    if (k % 3 == 0) first.push_back(k);
    if (k % 3 == 1) second.push_back(k);
    if (k % 3 != 2) {
      kept.push_back(points[k]);
      kept_index.push_back(k);
    }
  }
  SpatialHashGrid grid_a, grid_b;
  grid_a.build(points, first, Real(0.1));
  grid_b.build(points, second, Real(0.1));
  const SpatialHashGrid* grids[] = {&grid_a, &grid_b};
  NeighborLists lists;
  find_neighbors(grids, queries, Real(0.1), false, lists);
  for (std::size_t i = 0; i < queries.size(); ++i) {
    std::vector<Index> expected;
    for (const Index k : brute_force(kept, queries[i], Real(0.1), kept.size())) expected.push_back(kept_index[k]);
    const auto span = lists.of(i);
    EXPECT_EQ(std::vector<Index>(span.begin(), span.end()), expected) << "query " << i;
  }
}

TEST(NeighborSearch, MortonCodeOrdersByOctant) {
  EXPECT_LT(morton_code(0, 0, 0), morton_code(1, 0, 0));
  EXPECT_LT(morton_code(1, 1, 1), morton_code(2, 0, 0));
  EXPECT_LT(morton_code(-1, -1, -1), morton_code(0, 0, 0));
  EXPECT_EQ(morton_code(0, 1, 0), morton_code(0, 0, 0) + 2 * (morton_code(1, 0, 0) - morton_code(0, 0, 0)));
}
