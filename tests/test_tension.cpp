// Tension in viscous material (issue 55) against closed forms, at a coarse resolution (10 particles
// across): a Newtonian filament drawn apart at a constant Hencky rate between no-slip plates, and a
// column hanging under its weight. The table and what still falls short are in docs/validation.md
// ("Tension").
#include <gtest/gtest.h>

#include <cmath>

#include "tension_cases.hpp"

using namespace m3dp;

// With the projection holding tension and the stress form of the viscosity, the stretched filament
// thins as an incompressible Newtonian thread: its mid-section follows R0 e^{−ε/2} (measured within
// 3.5 % to ε = 1.5, where it is two particles in radius), its volume and its interior density stay,
// the pressure inside is near Trouton's −μ ε̇ (−63 to −112 Pa for −100 Pa), and the pull on a plate
// is Trouton's 3μ ε̇ π R² within 25 % at ε = 0.9 and 1.2 (1.05-1.21 on the AVX-512, AVX2 and generic
// paths; the issue asks 10 %); at ε = 0.6 it is still 0.6-0.9 of it while the kept pressure builds up,
// at 0.3 the plates' sudden start is in it, and at 1.5 the resolution.
TEST(Tension, AStretchedFilamentThinsAsTroutonSays) {
  tension::FilamentCase filament;
  filament.stress_form_viscosity = Real(0.9);
  const auto samples = tension::stretch_filament(filament);
  ASSERT_EQ(samples.size(), 5u);
  for (const auto& sample : samples) {
    SCOPED_TRACE(testing::Message() << "at Hencky strain " << sample.strain);
    EXPECT_TRUE(sample.whole);
    // The vector paths (AVX-512, AVX2, none) round differently: a few per cent apart by ε = 1.5.
    EXPECT_NEAR(sample.radius_ratio / std::exp(-sample.strain / 2), 1, sample.strain < 1.3 ? 0.06 : 0.1);
    EXPECT_NEAR(sample.volume_ratio, 1, 0.04);
    // Where the thread still has an interior a support radius inside its surface (to ε = 1.2 here).
    if (sample.interior_particles >= 20) {
      EXPECT_NEAR(sample.median_density, 1, 0.03) << sample.interior_particles << " interior particles";
    }
    EXPECT_GT(sample.closest_pair, 0.7);
    const double trouton_pressure = -filament.viscosity * filament.strain_rate;
    EXPECT_NEAR(sample.mean_pressure / trouton_pressure, 1, 0.45);
    if (sample.strain > 0.8 && sample.strain < 1.3) {
      EXPECT_NEAR(sample.force / sample.trouton_force, 1, 0.25);
    }
  }
}

// The same filament with the pair form of the viscosity alone: it stays whole, but its normal stress
// along the lattice axis it is drawn on is twice the isotropic one, and the plate pulls 1.4-1.9 ×
// Trouton's force.
TEST(Tension, WithThePairFormAloneTheFilamentResistsTooMuch) {
  tension::FilamentCase filament;
  filament.hencky_strain = Real(0.9);
  filament.samples = 1;
  const auto samples = tension::stretch_filament(filament);
  ASSERT_EQ(samples.size(), 1u);
  EXPECT_TRUE(samples[0].whole);
  EXPECT_GT(samples[0].force / samples[0].trouton_force, 1.3);
}

// The solves as they were (push only): the same filament dilates and cracks across before ε = 0.75.
TEST(Tension, WithoutTensionTheSameFilamentCracks) {
  tension::FilamentCase filament;
  filament.tension = false;
  filament.stress_form_viscosity = Real(0.9);
  filament.hencky_strain = Real(0.75);
  filament.samples = 1;
  const auto samples = tension::stretch_filament(filament);
  ASSERT_EQ(samples.size(), 1u);
  EXPECT_FALSE(samples[0].whole && samples[0].median_density > 0.95);
}

// A Newtonian column hanging from a plate under its weight (ρ = 1800 kg/m³, μ = 1000 Pa·s, L0 = 50 mm,
// R0 = 5 mm, 10 particles across), against Stokes's slender thread: the material that started at
// mid-height has the section A0 (1 − k L0 t/2), k = ρg/(3μ), the length is −ln(1 − k L0 t)/(kt), and
// the top parts at t* = 3μ/(ρ g L0) = 3.40 s. With tension and the stress form of the viscosity (the
// pair form alone stretched it at half the rate: its normal stress along a lattice axis is twice the
// isotropic one).
TEST(Tension, AColumnHangingUnderItsWeightThinsAsStokesSays) {
  tension::ColumnCase column;
  column.stress_form_viscosity = Real(0.9);
  const double break_time = tension::stokes_break_time(column);
  const auto result = tension::hang_column(column, break_time);
  ASSERT_EQ(result.samples.size(), 4u);
  const double k = column.material.density * 9.81 / (3 * column.material.rheology.viscosity);
  for (const auto& sample : result.samples) {
    SCOPED_TRACE(testing::Message() << "at t = " << sample.time << " s");
    EXPECT_NEAR(sample.section_ratio / (1 - k * column.length / 2 * sample.time), 1, 0.05);
    const double stokes_length = -std::log(1 - k * column.length * sample.time) / (k * sample.time);
    EXPECT_NEAR(sample.length / stokes_length, 1, 0.05);
  }
  EXPECT_NEAR(result.break_time / break_time, 1, 0.1);
}
