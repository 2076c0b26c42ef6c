#include <gtest/gtest.h>

#include <algorithm>
#include <numeric>
#include <random>

#include "m3dp/core/error.hpp"
#include "m3dp/sph/neighbors/neighbor_search.hpp"

using namespace m3dp;
using namespace m3dp::sph;

namespace {
std::vector<Index> brute_force(const std::vector<Vec3>& points, const Vec3& query, Real radius, std::size_t self) {
  std::vector<Index> found;
  for (std::size_t j = 0; j < points.size(); ++j)
    if (j != self && (points[j] - query).squaredNorm() < radius * radius) found.push_back(static_cast<Index>(j));
  return found;
}

void expect_equal_to_brute_force(const std::vector<Vec3>& points, Real radius, bool dense_cells) {
  SpatialHashGrid grid;
  grid.build(points, radius);
  EXPECT_EQ(grid.dense(), dense_cells);
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
  expect_equal_to_brute_force(points, Real(0.08), true);  // 13³ cells for 3000 points
}

TEST(NeighborSearch, EqualsBruteForceOnClusteredPointsAndNegativeCoordinates) {
  std::mt19937 random(2);
  std::normal_distribution<float> spread(0, 0.02f);
  std::vector<Vec3> points;
  const Vec3 centres[] = {Vec3(-3, -2, -1), Vec3(0, 0, 0), Vec3(5, 5, 5), Vec3(0.01f, 0.0f, 0.02f)};
  for (const auto& centre : centres)
    for (int n = 0; n < 700; ++n) points.push_back(centre + Vec3(spread(random), spread(random), spread(random)));
  expect_equal_to_brute_force(points, Real(0.015), false);  // a box of 533³ cells: hashed
}

TEST(NeighborSearch, QueriesOutsideADenseGridsBoxFindThePointsAtItsEdges) {
  // Dense cells cover the points' box only; queries around and far outside it, on every side.
  std::mt19937 random(5);
  std::uniform_real_distribution<float> inside(0, 1), around(-0.35f, 1.35f);
  std::vector<Vec3> grid_points(2000), queries(3000);
  for (auto& p : grid_points) p = Vec3(inside(random), inside(random), inside(random));
  for (auto& p : queries) p = Vec3(around(random), around(random), around(random));
  queries.push_back(Vec3(-1e6f, 0.5f, 0.5f));
  queries.push_back(Vec3(0.5f, 3e5f, -2e5f));
  SpatialHashGrid grid;
  grid.build(grid_points, Real(0.1));
  ASSERT_TRUE(grid.dense());
  NeighborLists lists;
  find_neighbors(grid, queries, Real(0.1), false, lists);
  std::size_t outside_with_neighbors = 0;
  for (std::size_t i = 0; i < queries.size(); ++i) {
    const auto span = lists.of(i);
    const std::vector<Index> expected = brute_force(grid_points, queries[i], Real(0.1), grid_points.size());
    EXPECT_EQ(std::vector<Index>(span.begin(), span.end()), expected) << "query " << i;
    const bool outside = (queries[i].array() < 0).any() || (queries[i].array() > 1).any();
    outside_with_neighbors += outside && !expected.empty();
  }
  EXPECT_GT(outside_with_neighbors, 100u);  // the edges were exercised
  // The same grid rebuilt hashed (points spread over a large box) and dense again: both modes reuse
  // the same buffers.
  std::vector<Vec3> spread = grid_points;
  spread.back() = Vec3(1000, 1000, 1000);
  grid.build(spread, Real(0.1));
  EXPECT_FALSE(grid.dense());
  grid.build(grid_points, Real(0.1));
  EXPECT_TRUE(grid.dense());
  NeighborLists again;
  find_neighbors(grid, queries, Real(0.1), false, again);
  EXPECT_EQ(again.indices, lists.indices);
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

namespace {
/// A fluid of active and resting particles beside static and moving boundary particles, for the kept
/// lists: the grids as the solver keeps them (cells of radius + skin).
struct KeptListsScene {
  static constexpr Real kRadius = Real(0.08), kSkin = Real(0.01);
  static constexpr std::size_t kActive = 2000, kResting = 500, kStatic = 800, kMoving = 300;
  std::mt19937 random{5};
  std::vector<Vec3> fluid, boundary;
  std::vector<std::uint64_t> ids;
  std::vector<Index> resting_subset, static_subset, moving_subset;
  SpatialHashGrid resting_grid, static_grid, moving_grid;
  SkinnedNeighborSearch search;
  NeighborLists fluid_lists, boundary_lists;

  KeptListsScene() {
    std::uniform_real_distribution<float> coordinate(0, 1);
    fluid.resize(kActive + kResting);
    for (auto& p : fluid) p = Vec3(coordinate(random), coordinate(random), coordinate(random));
    boundary.resize(kStatic + kMoving);
    for (auto& p : boundary) p = Vec3(coordinate(random), coordinate(random), coordinate(random));
    ids.resize(fluid.size());
    std::iota(ids.begin(), ids.end(), std::uint64_t(100));
    for (Index k = kActive; k < fluid.size(); ++k) resting_subset.push_back(k);
    for (Index k = 0; k < boundary.size(); ++k) (k < kStatic ? static_subset : moving_subset).push_back(k);
    resting_grid.build(fluid, resting_subset, kRadius + kSkin);
    static_grid.build(boundary, static_subset, kRadius + kSkin);
  }
  /// The first `active` fluid particles query (the rest, resting_subset, are in resting_grid).
  bool update(std::size_t max_movers, std::size_t active = kActive) {
    moving_grid.build(boundary, moving_subset, kRadius + kSkin);
    SkinnedNeighborSearch::Inputs inputs;
    inputs.fluid_positions = fluid;
    inputs.fluid_ids = ids;
    inputs.active_count = active;
    inputs.resting_grid = &resting_grid;
    inputs.static_boundary_grid = &static_grid;
    inputs.moving_boundary_grid = &moving_grid;
    inputs.boundary_positions = boundary;
    inputs.moving_boundary_indices = moving_subset;
    return search.update(inputs, kRadius, kSkin, max_movers, fluid_lists, boundary_lists);
  }
  /// Every active particle's lists hold exactly its neighbours within the radius (any order), and
  /// the fluid pairs between active particles come from both ends.
  void expect_exact_lists(std::size_t active = kActive) const {
    for (std::size_t i = 0; i < active; ++i) {
      auto fluid_span = fluid_lists.of(i);
      std::vector<Index> got(fluid_span.begin(), fluid_span.end());
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got, brute_force(fluid, fluid[i], kRadius, i)) << "fluid list of particle " << i;
      for (const Index j : got)
        if (j < active) {
          const auto back = fluid_lists.of(j);
          ASSERT_NE(std::find(back.begin(), back.end(), Index(i)), back.end()) << "pair " << i << "-" << j << " from one end only";
        }
      auto boundary_span = boundary_lists.of(i);
      got.assign(boundary_span.begin(), boundary_span.end());
      std::sort(got.begin(), got.end());
      ASSERT_EQ(got, brute_force(boundary, fluid[i], kRadius, boundary.size())) << "boundary list of particle " << i;
    }
  }
};
}  // namespace

TEST(SkinnedNeighborSearch, KeptListsStayExactWhileParticlesDriftAFewJumpAndBodiesMove) {
  KeptListsScene scene;
  EXPECT_TRUE(scene.update(50));  // the first update searches
  scene.expect_exact_lists();
  const std::vector<Vec3> searched_at(scene.fluid.begin(), scene.fluid.end());
  std::uniform_real_distribution<float> unit(-1, 1);
  std::uniform_int_distribution<std::size_t> pick(0, KeptListsScene::kActive - 1);
  for (int step = 1; step <= 6; ++step) {
    // Every active particle within skin/2 of where the search saw it (kept lists must hold), 30 of them
    // anywhere nearby (movers), and the moving body's particles anywhere.
    const Real drift = Real(0.45) * KeptListsScene::kSkin / std::sqrt(Real(3));
    for (std::size_t i = 0; i < KeptListsScene::kActive; ++i)
      scene.fluid[i] = searched_at[i] + drift * Vec3(unit(scene.random), unit(scene.random), unit(scene.random));
    for (int n = 0; n < 30; ++n) scene.fluid[pick(scene.random)] += Real(0.1) * Vec3(unit(scene.random), unit(scene.random), unit(scene.random));
    for (std::size_t k = KeptListsScene::kStatic; k < scene.boundary.size(); ++k)
      scene.boundary[k] += Real(0.05) * Vec3(unit(scene.random), unit(scene.random), unit(scene.random));
    EXPECT_FALSE(scene.update(50)) << "step " << step << ": the lists should have been kept";
    EXPECT_GT(scene.search.mover_count(), 20u);
    scene.expect_exact_lists();
  }
  // Too many movers: a new search, and lists as exact.
  for (int n = 0; n < 200; ++n) scene.fluid[pick(scene.random)] += Real(0.1) * Vec3(unit(scene.random), unit(scene.random), unit(scene.random));
  EXPECT_TRUE(scene.update(50));
  EXPECT_EQ(scene.search.mover_count(), 0u);
  scene.expect_exact_lists();
  // Particles appended after the active ones (a nozzle's layer; none resting): movers, no search.
  {
    KeptListsScene fresh;
    fresh.fluid.resize(KeptListsScene::kActive);  // no resting particles: the layer appends to the active range
    fresh.ids.resize(KeptListsScene::kActive);
    fresh.resting_subset.clear();
    fresh.resting_grid.build(fresh.fluid, fresh.resting_subset, KeptListsScene::kRadius + KeptListsScene::kSkin);
    EXPECT_TRUE(fresh.update(50, fresh.fluid.size()));
    std::uniform_real_distribution<float> coordinate(0.4f, 0.6f);
    for (int n = 0; n < 25; ++n) {
      fresh.fluid.push_back(Vec3(coordinate(scene.random), coordinate(scene.random), coordinate(scene.random)));
      fresh.ids.push_back(100000 + n);
    }
    EXPECT_FALSE(fresh.update(50, fresh.fluid.size()));
    EXPECT_EQ(fresh.search.mover_count(), 25u);
    fresh.expect_exact_lists(fresh.fluid.size());
    // More than the mover budget appended: a new search.
    for (int n = 0; n < 40; ++n) {
      fresh.fluid.push_back(Vec3(coordinate(scene.random), coordinate(scene.random), coordinate(scene.random)));
      fresh.ids.push_back(200000 + n);
    }
    EXPECT_TRUE(fresh.update(50, fresh.fluid.size()));
  }
  // Reordered particles (the ids moved): a new search.
  std::swap(scene.fluid[3], scene.fluid[7]);
  std::swap(scene.ids[3], scene.ids[7]);
  EXPECT_TRUE(scene.update(50));
  scene.expect_exact_lists();
  EXPECT_FALSE(scene.update(50));
}

TEST(SkinnedNeighborSearch, RefusesGridsWithoutTheSkin) {
  KeptListsScene scene;
  scene.static_grid.build(scene.boundary, scene.static_subset, KeptListsScene::kRadius);
  try {
    scene.update(50);
    FAIL() << "expected an error";
  } catch (const Error& error) {
    EXPECT_NE(std::string(error.what()).find("radius + skin"), std::string::npos) << error.what();
  }
}
