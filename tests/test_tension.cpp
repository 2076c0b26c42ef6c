// Tension in viscous material (issue 55) against closed forms, at a coarse resolution (10 particles
// across): a Newtonian filament drawn apart at a constant Hencky rate between no-slip plates. The fine
// table and what still falls short are in docs/validation.md ("Tension").
#include <gtest/gtest.h>

#include <cmath>

#include "tension_cases.hpp"

using namespace m3dp;

// With the projection holding tension, the stretched filament thins as an incompressible thread: its
// mid-section follows R0 e^{−ε/2}, its volume and its interior density stay, and the pressure inside
// is Trouton's −μ ε̇ (measured −66 to −97 Pa for −100 Pa). The issue asks for 5 % on the radius to
// ε = 1.5 and 1 % on the volume; here the mid-section runs 2-6 % thin and the volume within 3 %, and
// the plate force (not asserted) is 1.4-1.8 × Trouton's: the viscous sum's stress along a lattice axis
// is twice the isotropic one at this support (docs/decisions.md, "Tension in viscous material").
TEST(Tension, AStretchedFilamentThinsInsteadOfCracking) {
  tension::FilamentCase filament;
  const auto samples = tension::stretch_filament(filament);
  ASSERT_EQ(samples.size(), 5u);
  for (const auto& sample : samples) {
    SCOPED_TRACE(testing::Message() << "at Hencky strain " << sample.strain);
    EXPECT_TRUE(sample.whole);
    // The vector paths (AVX-512, AVX2) round differently and the figures differ by a few per cent
    // from ε = 1.2 on: 0.422 and 0.449 of R0 at ε = 1.5.
    EXPECT_NEAR(sample.radius_ratio / std::exp(-sample.strain / 2), 1, sample.strain < 1 ? 0.06 : 0.13);
    EXPECT_NEAR(sample.volume_ratio, 1, 0.04);
    // Where the thread still has an interior a support radius inside its surface (to ε = 1.2 here).
    if (sample.interior_particles >= 20) {
      EXPECT_NEAR(sample.median_density, 1, 0.02) << sample.interior_particles << " interior particles";
    }
    EXPECT_GT(sample.closest_pair, 0.7);
    const double trouton_pressure = -filament.viscosity * filament.strain_rate;
    EXPECT_NEAR(sample.mean_pressure / trouton_pressure, 1, 0.5);
  }
}

// The solves as they were (push only): the same filament dilates and cracks across before ε = 0.75.
TEST(Tension, WithoutTensionTheSameFilamentCracks) {
  tension::FilamentCase filament;
  filament.tension = false;
  filament.hencky_strain = Real(0.75);
  filament.samples = 1;
  const auto samples = tension::stretch_filament(filament);
  ASSERT_EQ(samples.size(), 1u);
  EXPECT_FALSE(samples[0].whole && samples[0].median_density > 0.95);
}
