// No globals: two simulations in one process give identical results, also across thread counts.
#include <gtest/gtest.h>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/simulation.hpp"

using namespace m3dp;

namespace {
scene::Scene small_dam_break() {
  sim::DamBreakSetup setup;
  setup.column_width = Real(0.06);
  setup.depth = Real(0.02);
  setup.particle_radius = Real(0.002);
  return sim::dam_break_scene(setup);
}
}  // namespace

TEST(Determinism, TwoSimulationsSideBySideAreIdentical) {
  const scene::Scene scene = small_dam_break();
  sim::Simulation first(scene), second(scene);
  for (int step = 0; step < 60; ++step) {
    first.step();
    second.step();
  }
  ASSERT_EQ(first.solver().fluid().size(), second.solver().fluid().size());
  EXPECT_EQ(first.time(), second.time());
  EXPECT_TRUE(first.solver().fluid().position == second.solver().fluid().position);
  EXPECT_TRUE(first.solver().fluid().velocity == second.solver().fluid().velocity);
}

TEST(Determinism, SameResultWithOneAndTwoThreads) {
  const scene::Scene scene = small_dam_break();
  std::vector<Vec3> positions[2];
  for (int threads = 1; threads <= 2; ++threads) {
    ThreadLimit limit(threads);
    sim::Simulation simulation(scene);
    for (int step = 0; step < 60; ++step) simulation.step();
    positions[threads - 1] = simulation.solver().fluid().position;
  }
  EXPECT_TRUE(positions[0] == positions[1]);
}
