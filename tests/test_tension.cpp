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

// No material gains tension at rest (issue 55): a squat cylinder of the Bingham paste (τ0 = 200 Pa, which
// holds 8 mm: ρ g h/√3 = 95 Pa; R = 5 mm, r = 0.5 mm) set on a plate it sticks to, with tension and the
// stress form, settles under its weight for 2 s. Its pressure stays that of a push: the least
// particle's p (the three solves' κ, as Solver::pressure) is no lower than 2 % of ρ g h, and its
// footprint does not draw in. (A Newtonian 1000 Pa·s one still spreads over these seconds, and a
// spreading drop's top is rightly pulled: p = 2μ ∂w/∂z < 0 there, −8.5 Pa measured.)
TEST(Tension, ARestingBeadHoldsNoPull) {
  const Real d = Real(0.001), radius = Real(0.005), height = Real(0.008);
  sph::Parameters parameters;
  parameters.settings.particle_radius = d / 2;
  parameters.settings.max_time_step = Real(2e-3);
  parameters.settings.tension = true;
  parameters.settings.stress_form_viscosity = Real(0.9);
  parameters.settings.rest_detection = false;  // every particle in the solves: resting ones hold no κ at all
  parameters.settings.bounds.min = Vec3(-1, -1, -1);
  parameters.settings.bounds.max = Vec3(1, 1, 1);
  material::Material paste = tension::bingham_paste(Real(1e5));
  paste.sticks_to_walls = true;
  parameters.phases.push_back(paste);
  sph::Solver solver(parameters);
  solver.add_particles(tension::cylinder_lattice(radius, 0, height, d), Vec3::Zero(), 0);
  const BoxShape plate{Vec3(4 * radius, 4 * radius, 3 * d)};
  solver.add_body("plate", sph::sample_box_surface(plate, d).points, Pose{Vec3(0, 0, -Real(1.5) * d), Quat::Identity()}, true);
  auto footprint = [&]() {  // the mean distance from the axis of the particles in the lowest two layers
    double sum = 0, n = 0;
    for (const Vec3& p : solver.fluid().position)
      if (p.z() < 2 * d) sum += p.head<2>().norm(), n += 1;
    return sum / std::max(n, 1.0);
  };
  const double footprint0 = footprint();
  double least_pressure = 0;
  while (solver.time() < 2) {
    solver.step();
    if (solver.time() < 1) continue;
    for (std::size_t i = 0; i < solver.fluid().size(); ++i) least_pressure = std::min(least_pressure, double(solver.pressure(i)));
  }
  const double weight_pressure = double(paste.density) * 9.81 * double(height);
  double fastest = 0;
  for (const Vec3& v : solver.fluid().velocity) fastest = std::max(fastest, double(v.norm()));
  std::printf("resting bead: least pressure %.3g Pa over the last second (rho g h %.0f Pa); fastest particle %.3g mm/s; footprint %.3f -> %.3f mm\n",
              least_pressure, weight_pressure, 1e3 * fastest, 1e3 * footprint0, 1e3 * footprint());
  EXPECT_GT(least_pressure, -0.02 * weight_pressure);
  EXPECT_GT(footprint(), footprint0 * 0.99) << "the bead drew in";
}

// Tension does not make water cling (issue 55): a water drop set against the underside of a sphere, in
// a scene where a 1000 Pa·s paste rests on a plate (so that the viscosity solve and the projection run
// every step, water included), falls off as it does without tension. Walls are air to the projection:
// nothing sticks to them by suction.
TEST(Tension, AWaterDropUnderASphereFallsOff) {
  auto fall = [](bool tension) {
    const Real d = Real(0.0005);
    sph::Parameters parameters;
    parameters.settings.particle_radius = d / 2;
    parameters.settings.tension = tension;
    parameters.settings.stress_form_viscosity = tension ? Real(0.9) : Real(0);
    parameters.settings.bounds.min = Vec3(-1, -1, -1);
    parameters.settings.bounds.max = Vec3(1, 1, 1);
    parameters.phases.push_back(material::newtonian("water", 1000, Real(1e-3)));
    material::Material paste = material::newtonian("paste", 1800, 1000);
    paste.sticks_to_walls = true;
    parameters.phases.push_back(paste);
    sph::Solver solver(parameters);
    // The sphere (R = 10 mm) whose lowest point is half a spacing above the origin; the drop (R = 3 mm)
    // below it, its top particles a spacing from the sphere's.
    const Real sphere_radius = Real(0.01), drop_radius = Real(0.003);
    solver.add_body("sphere", sph::sample_sphere_surface(SphereShape{sphere_radius}, d).points, Pose{Vec3(0, 0, sphere_radius + d / 2), Quat::Identity()},
                    true);
    std::vector<Vec3> drop;
    for (const Vec3& p : tension::cylinder_lattice(drop_radius, -2 * drop_radius, 2 * drop_radius, d))
      if ((p - Vec3(0, 0, -drop_radius)).norm() < drop_radius) drop.push_back(p);
    solver.add_particles(drop, Vec3::Zero(), 0);
    // The paste, 50 mm away on its own plate.
    std::vector<Vec3> block = tension::cylinder_lattice(Real(0.004), Real(-0.02), Real(0.004), d);
    for (Vec3& p : block) p.x() += Real(0.05);
    solver.add_particles(block, Vec3::Zero(), 1);
    solver.add_body("plate", sph::sample_box_surface(BoxShape{Vec3(Real(0.02), Real(0.02), 3 * d)}, d).points,
                    Pose{Vec3(Real(0.05), 0, Real(-0.02) - Real(1.5) * d), Quat::Identity()}, true);
    auto drop_centre = [&]() {
      double z = 0, n = 0;
      for (std::size_t i = 0; i < solver.fluid().size(); ++i)
        if (solver.fluid().phase[i] == 0) z += solver.fluid().position[i].z(), n += 1;
      return z / std::max(n, 1.0);
    };
    const double start = drop_centre();
    bool projected = false;
    while (solver.time() < 0.1) {
      solver.step();
      projected |= solver.state().last_step.tension_iterations > 0;
    }
    if (tension) {
      EXPECT_TRUE(projected) << "the projection ran";
    }
    return start - drop_centre();
  };
  const double with = fall(true), without = fall(false);
  std::printf("water drop under a sphere: its centre fell %.2f mm in 0.1 s with tension, %.2f mm without (free fall 49 mm)\n", 1e3 * with,
              1e3 * without);
  EXPECT_GT(with, 0.8 * 0.5 * 9.81 * 0.01);
  EXPECT_NEAR(with / without, 1, 0.05);
}

// A viscous stream hangs from the nozzle that extrudes it (issue 57, goal 3): a 1000 Pa·s paste
// leaving a 50 mm exit-plane inlet at 0.5 m/s, 0.4 m above a floor, for 0.4 s. As a slender Stokes
// thread (ν = 1 m²/s) hanging from the exit, its front 0.2 m below gains g L²/(6ν) = 0.07 m/s; let
// go at the exit, it falls freely (2.9 m/s at the floor), which sets 5x smaller CFL steps. With
// tension the exit holds what the stream draws out faster than the exit speed
// (stages::hold_drawn_exits); without, the inlet only pushes.
TEST(Tension, AViscousStreamHangsFromItsNozzle) {
  auto fastest_speed = [](bool tension) {
    const Real d = Real(0.00625), exit_speed = Real(0.5), height = Real(0.4);
    sph::Parameters parameters;
    parameters.settings.particle_radius = d / 2;
    parameters.settings.tension = tension;
    parameters.settings.bounds.min = Vec3(-1, -1, -0.1f);
    parameters.settings.bounds.max = Vec3(1, 1, 1);
    parameters.phases.push_back(material::newtonian("paste", 1000, 1000));
    parameters.nozzles.push_back(sph::NozzleSettings{"nozzle", Real(0.05), exit_speed, 0});
    sph::Solver solver(parameters);
    solver.add_body("floor", sph::sample_box_surface(BoxShape{Vec3(Real(0.6), Real(0.6), 3 * d)}, d).points,
                    Pose{Vec3(0, 0, -Real(1.5) * d), Quat::Identity()}, true);
    double fastest = 0;
    while (solver.time() < 0.4) {
      const Real creep = Real(1e-3);  // m/s: a nozzle that stays where it is
      solver.set_nozzle(0, Pose{Vec3(creep * Real(solver.time()), 0, height), Quat::Identity()}, Vec3(creep, 0, 0), true);
      solver.step();
      for (const Vec3& v : solver.fluid().velocity) fastest = std::max(fastest, double(v.norm()));
    }
    EXPECT_GT(solver.fluid().size(), 1000u) << "the nozzle extruded";
    return fastest;
  };
  const double held = fastest_speed(true), let_go = fastest_speed(false);
  const double free_fall = std::sqrt(0.5 * 0.5 + 2 * 9.81 * 0.4);
  std::printf("a 1000 Pa.s stream falling 0.4 m from a 0.5 m/s exit: fastest particle %.2f m/s held (tension), %.2f m/s let go; free fall %.2f m/s\n",
              held, let_go, free_fall);
  EXPECT_LT(held, 0.5 + 0.15) << "Stokes: 0.57 m/s";
  EXPECT_GT(let_go, 0.8 * free_fall) << "the control: an inlet that only pushes lets the stream fall";
}
