// The rheology laws and ageing against their formulas (material module).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "m3dp/material/material.hpp"

using namespace m3dp;
using material::RheologyModel;

namespace {
material::Rheology model(RheologyModel kind) {
  material::Rheology rheology;
  rheology.model = kind;
  return rheology;
}
}  // namespace

TEST(Rheology, NewtonianIsConstant) {
  auto rheology = model(RheologyModel::newtonian);
  rheology.viscosity = Real(2.5);
  for (const Real rate : {0.0f, 0.1f, 100.0f}) EXPECT_FLOAT_EQ(rheology.effective_viscosity(rate, 0, 1), 2.5f);
  EXPECT_FLOAT_EQ(rheology.effective_viscosity(1, 0, 3), 7.5f);  // ageing's viscosity scale
}

TEST(Rheology, PowerLawAndItsCapAtRest) {
  auto rheology = model(RheologyModel::power_law);
  rheology.consistency = 20;
  rheology.flow_index = Real(0.5);
  rheology.max_viscosity = 1000;
  EXPECT_NEAR(rheology.effective_viscosity(4, 0, 1), 20 * std::pow(4.0, -0.5), 1e-5);
  EXPECT_FLOAT_EQ(rheology.effective_viscosity(0, 0, 1), 1000.0f);
  EXPECT_FLOAT_EQ(rheology.effective_viscosity(1e-6f, 0, 1), 1000.0f);
}

TEST(Rheology, CrossAndCarreauBetweenTheirPlateaus) {
  auto cross = model(RheologyModel::cross);
  cross.viscosity = 100;
  cross.infinite_shear_viscosity = 1;
  cross.time_constant = 2;
  cross.flow_index = Real(0.8);
  EXPECT_FLOAT_EQ(cross.effective_viscosity(0, 0, 1), 100.0f);
  EXPECT_NEAR(cross.effective_viscosity(Real(0.5), 0, 1), 1 + 99.0 / 2, 1e-4);  // λγ̇ = 1: half way
  EXPECT_NEAR(cross.effective_viscosity(1e6, 0, 1), 1 + 99 / (1 + std::pow(2e6, 0.8)), 1e-4);

  auto carreau = model(RheologyModel::carreau);
  carreau.viscosity = 100;
  carreau.infinite_shear_viscosity = 0;
  carreau.time_constant = 1;
  carreau.flow_index = Real(0.4);
  EXPECT_FLOAT_EQ(carreau.effective_viscosity(0, 0, 1), 100.0f);
  EXPECT_NEAR(carreau.effective_viscosity(3, 0, 1), 100 * std::pow(10.0, -0.3), 1e-3);
}

TEST(Rheology, BinghamAndHerschelBulkleyRegularisedAfterPapanastasiou) {
  auto bingham = model(RheologyModel::bingham);
  bingham.viscosity = 10;
  bingham.yield_stress = 200;
  bingham.regularization = 100;
  // Well yielded: τ = τ0 + μp γ̇.
  EXPECT_NEAR(bingham.effective_viscosity(5, 200, 1) * 5, 200 + 10 * 5, 1e-3);
  // At rest: μp + τ0 m.
  EXPECT_FLOAT_EQ(bingham.effective_viscosity(0, 200, 1), 10 + 200 * 100);
  // A particle's own (aged) yield stress is what counts.
  EXPECT_NEAR(bingham.effective_viscosity(5, 500, 1) * 5, 500 + 50, 1e-3);
  bingham.max_viscosity = 5000;
  EXPECT_FLOAT_EQ(bingham.effective_viscosity(0, 200, 1), 5000.0f);

  auto herschel_bulkley = model(RheologyModel::herschel_bulkley);
  herschel_bulkley.yield_stress = 100;
  herschel_bulkley.consistency = 30;
  herschel_bulkley.flow_index = Real(0.5);
  herschel_bulkley.regularization = 1000;
  EXPECT_NEAR(herschel_bulkley.effective_viscosity(4, 100, 1) * 4, 100 + 30 * 2, 1e-3);
}

TEST(Rheology, CappedYieldStressMaterialAgreesWithTheFullFormulaAcrossTheCap) {
  // The clay preset's parameters: below about 0.15 1/s the yield term alone exceeds the cap, and the
  // model returns the cap without evaluating the formula; above, the formula. Both sides, and the
  // rates around the switch, against the formula in double.
  for (const RheologyModel kind : {RheologyModel::herschel_bulkley, RheologyModel::bingham}) {
    auto rheology = model(kind);
    rheology.yield_stress = 1500;
    rheology.consistency = 150;
    rheology.flow_index = Real(0.35);
    rheology.viscosity = 20;  // Bingham's plastic viscosity
    rheology.regularization = 1000;
    rheology.max_viscosity = 1e4;
    int capped = 0;
    for (double rate = 1e-6; rate < 100; rate *= 1.05) {
      const double m = rheology.regularization, tau0 = rheology.yield_stress;
      const double yield_term = tau0 * -std::expm1(-m * rate) / rate;
      const double other = kind == RheologyModel::bingham ? rheology.viscosity : rheology.consistency * std::pow(rate, rheology.flow_index - 1);
      const double expected = std::min(other + yield_term, double(rheology.max_viscosity));
      EXPECT_NEAR(rheology.effective_viscosity(Real(rate), rheology.yield_stress, 1), expected, 1e-5 * expected) << "rate " << rate;
      capped += expected == double(rheology.max_viscosity);
    }
    EXPECT_GT(capped, 100);  // the sweep covers the capped range well
  }
}

TEST(Ageing, RousselLinearBuildUpAndViscosityGrowth) {
  material::Ageing ageing;
  EXPECT_FALSE(ageing.enabled());
  ageing.structuration_rate = Real(1.5);  // Pa/s
  ageing.viscosity_growth = Real(0.01);   // 1/s
  EXPECT_TRUE(ageing.enabled());
  EXPECT_FLOAT_EQ(ageing.yield_stress(100, 60), 100 + 1.5f * 60);
  EXPECT_FLOAT_EQ(ageing.viscosity_scale(60), 1.6f);
  EXPECT_FLOAT_EQ(ageing.yield_stress(100, -1), 100.0f);  // not yet deposited: no build-up
}
