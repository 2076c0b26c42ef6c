#pragma once
// Viscous threads against closed forms (issue 55): a Newtonian filament drawn apart between two plates
// at a constant Hencky rate, and a column hanging from a plate under its weight (Stokes's slender
// thread, Newtonian or Bingham). Used by test_tension (coarse) and tension_cases (the fine table).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>
#include <vector>

#include "m3dp/sph/boundary_sampling.hpp"
#include "m3dp/sph/solver.hpp"

namespace m3dp::tension {

/// Particles on the cubic lattice of spacing d inside the cylinder of radius `radius` about the z axis,
/// z from `bottom` to `bottom + length` (centres half a spacing inside the ends).
inline std::vector<Vec3> cylinder_lattice(Real radius, Real bottom, Real length, Real d) {
  std::vector<Vec3> points;
  const int across = static_cast<int>(std::ceil(radius / d));
  const int layers = static_cast<int>(std::lround(length / d));
  for (int k = 0; k < layers; ++k)
    for (int a = -across; a < across; ++a)
      for (int b = -across; b < across; ++b) {
        const Real x = (Real(a) + Real(0.5)) * d, y = (Real(b) + Real(0.5)) * d;
        if (x * x + y * y < radius * radius) points.emplace_back(x, y, bottom + (Real(k) + Real(0.5)) * d);
      }
  return points;
}

/// The section (m²) of the material within `half_width` of height z: a disc with the particles' second
/// moment about the axis through their centroid, each particle a cell of side d (⟨r²⟩ of the cells =
/// ⟨r²⟩ of the centres + d²/6, and a disc's area is 2π⟨r²⟩). Dilated material reads wider than its mass.
inline double section_at(const sph::FluidParticles& fluid, Real z, Real half_width, Real d) {
  double sx = 0, sy = 0, n = 0;
  for (std::size_t i = 0; i < fluid.size(); ++i)
    if (std::abs(fluid.position[i].z() - z) < half_width) sx += fluid.position[i].x(), sy += fluid.position[i].y(), n += 1;
  if (n < 3) return 0;
  sx /= n, sy /= n;
  double second = 0;
  for (std::size_t i = 0; i < fluid.size(); ++i)
    if (std::abs(fluid.position[i].z() - z) < half_width) {
      const double x = fluid.position[i].x() - sx, y = fluid.position[i].y() - sy;
      second += x * x + y * y;
    }
  return 2 * M_PI * (second / n + double(d) * d / 6);
}

/// The volume (m³) between heights `low` and `high` as sections of width d stacked.
inline double volume_between(const sph::FluidParticles& fluid, Real low, Real high, Real d) {
  double volume = 0;
  for (Real z = low + d / 2; z < high; z += d) volume += section_at(fluid, z, d / 2, d) * d;
  return volume;
}

/// The least distance between two particles (m), by brute force over pairs close in z.
inline double closest_pair(const sph::FluidParticles& fluid) {
  std::vector<std::size_t> order(fluid.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return fluid.position[a].z() < fluid.position[b].z(); });
  double closest = 1e30;
  for (std::size_t a = 0; a < order.size(); ++a)
    for (std::size_t b = a + 1; b < order.size(); ++b) {
      const Vec3 r = fluid.position[order[b]] - fluid.position[order[a]];
      if (r.z() >= closest) break;
      closest = std::min(closest, double(r.norm()));
    }
  return closest;
}

struct FilamentCase {
  Real particle_radius = Real(0.0004);  // m
  Real radius = Real(0.004);            // R0, m
  Real length = Real(0.024);            // L0 between the plates, m
  Real viscosity = 100;                 // μ, Pa·s
  Real density = 1000;                  // kg/m³
  Real strain_rate = 1;                 // ε̇, 1/s
  Real hencky_strain = Real(1.5);       // drawn to L0 e^ε
  bool tension = true;
  Real support_radius_factor = 4;       // the kernel's support in particle radii (the engine's default)
  Real stress_form_viscosity = 0;       // SolverSettings::stress_form_viscosity
  int samples = 5;                      // figures at Hencky strains ε/samples, 2ε/samples, …
};

struct FilamentSample {
  double strain = 0;           // Hencky strain of the plates, ε̇ t
  double radius_ratio = 0;     // R_mid/R0
  double force = 0;            // N, the top plate's pull (averaged over the last tenth of the interval)
  double trouton_force = 0;    // 3 μ ε̇ π R_mid², N
  double volume_ratio = 0;     // the material's volume between the plates over its first
  double closest_pair = 0;     // in particle diameters
  double median_density = 0;   // ρ/ρ0 of the interior particles within the middle third
  std::size_t interior_particles = 0;  // how many there are (a support radius inside the surface)
  bool whole = false;          // material across every slab two spacings thick between the plates (no crack)
  double mean_pressure = 0;    // Pa, of the particles within the middle third (a stretched thread's is −μ ε̇)
};

/// Draws the filament apart at the constant Hencky rate: the plates at ±L(t)/2, L = L0 e^{ε̇ t}, no slip.
inline std::vector<FilamentSample> stretch_filament(const FilamentCase& filament) {
  const Real d = 2 * filament.particle_radius;
  sph::Parameters parameters;
  parameters.settings.particle_radius = filament.particle_radius;
  parameters.settings.gravity = Vec3::Zero();
  parameters.settings.max_time_step = Real(2e-3);
  parameters.settings.rest_detection = false;
  parameters.settings.tension = filament.tension;
  parameters.settings.support_radius_factor = filament.support_radius_factor;
  parameters.settings.stress_form_viscosity = filament.stress_form_viscosity;
  const Real reach = filament.length * std::exp(filament.hencky_strain) + 10 * d;
  parameters.settings.bounds.min = Vec3(-reach, -reach, -reach);
  parameters.settings.bounds.max = Vec3(reach, reach, reach);
  material::Material material = material::newtonian("filament", filament.density, filament.viscosity);
  material.sticks_to_walls = true;
  parameters.phases.push_back(material);
  sph::Solver solver(parameters);
  const Real plate_thickness = 3 * d;
  const BoxShape plate{Vec3(2 * filament.radius + 8 * d, 2 * filament.radius + 8 * d, plate_thickness)};
  const auto plate_points = sph::sample_box_surface(plate, d).points;
  // Plate faces half a spacing from the outer particle centres.
  auto plate_pose = [&](Real half_length, Real side) {
    return Pose{Vec3(0, 0, side * (half_length + plate_thickness / 2)), Quat::Identity()};
  };
  const Real half = filament.length / 2;
  // The material first: added after the plates, its outer layers would be skipped as too close to them.
  solver.add_particles(cylinder_lattice(filament.radius, -half, filament.length, d), Vec3::Zero(), 0);
  const Index bottom = solver.add_body("bottom plate", plate_points, plate_pose(half, -1), false);
  const Index top = solver.add_body("top plate", plate_points, plate_pose(half, 1), false);

  const double volume0 = volume_between(solver.fluid(), -half, half, d);
  const double section0 = section_at(solver.fluid(), 0, d, d);
  std::vector<FilamentSample> samples;
  const double end_time = filament.hencky_strain / filament.strain_rate;
  double force_sum = 0, force_time = 0;
  const int sample_count = filament.samples;
  for (int s = 1; s <= sample_count; ++s) {
    const double sample_time = end_time * s / sample_count;
    const double average_from = sample_time - 0.1 * end_time / sample_count;
    force_sum = force_time = 0;
    while (solver.time() < sample_time - 1e-9) {
      const double t = solver.time();
      const Real half_now = static_cast<Real>(half * std::exp(filament.strain_rate * t));
      const Real speed = filament.strain_rate * half_now;
      solver.set_body_motion(bottom, plate_pose(half_now, -1), Vec3(0, 0, -speed), Vec3::Zero());
      solver.set_body_motion(top, plate_pose(half_now, 1), Vec3(0, 0, speed), Vec3::Zero());
      const auto& stats = solver.step();
      if (t >= average_from) {
        force_sum += double(-solver.bodies()[top].fluid_force.z()) * stats.time_step;  // the material pulls the plate down
        force_time += stats.time_step;
      }
    }
    const auto& fluid = solver.fluid();
    const Real half_now = static_cast<Real>(half * std::exp(filament.strain_rate * solver.time()));
    FilamentSample sample;
    sample.strain = filament.strain_rate * solver.time();
    const double section = section_at(fluid, 0, d, d);
    sample.radius_ratio = std::sqrt(section / section0);
    sample.force = force_time > 0 ? force_sum / force_time : 0;
    sample.trouton_force = 3 * filament.viscosity * filament.strain_rate * section;
    sample.volume_ratio = volume_between(fluid, -half_now, half_now, d) / volume0;
    sample.closest_pair = closest_pair(fluid) / d;
    // Interior particles (a support radius inside the section's surface): their SPH density is whole.
    std::vector<double> densities;
    const double inner = std::sqrt(section / M_PI) - 2 * d;
    for (std::size_t i = 0; i < fluid.size(); ++i)
      if (std::abs(fluid.position[i].z()) < half_now / 3 && fluid.position[i].head<2>().norm() < inner)
        densities.push_back(fluid.density[i] / filament.density);
    double pressure_sum = 0, pressure_count = 0;
    for (std::size_t i = 0; i < fluid.size(); ++i)
      if (std::abs(fluid.position[i].z()) < half_now / 3) pressure_sum += solver.pressure(i), pressure_count += 1;
    sample.mean_pressure = pressure_sum / std::max(pressure_count, 1.0);
    // A crack: a slab two spacings thick with no particle, between a spacing from each plate (the
    // lattice's layers may stand apart by more than one spacing where stretched material has not yet
    // rearranged).
    sample.whole = true;
    for (Real low = -half_now + d; low + 2 * d <= half_now - d; low += 2 * d)
      sample.whole = sample.whole && std::any_of(fluid.position.begin(), fluid.position.end(),
                                                 [&](const Vec3& p) { return p.z() >= low && p.z() < low + 2 * d; });
    std::nth_element(densities.begin(), densities.begin() + densities.size() / 2, densities.end());
    sample.median_density = densities.empty() ? 0 : densities[densities.size() / 2];
    sample.interior_particles = densities.size();
    samples.push_back(sample);
    std::printf("filament eps %.2f: R/R0 %.4f (ideal %.4f), force %.4g N (Trouton %.4g), volume %.4f, %s, closest pair %.3f d, median rho %.4f, "
                "mid pressure %.1f Pa (-mu epsdot %.1f), tension its %d, viscosity its %d\n",
                sample.strain, sample.radius_ratio, std::exp(-sample.strain / 2), sample.force, sample.trouton_force,
                sample.volume_ratio, sample.whole ? "whole" : "CRACKED", sample.closest_pair, sample.median_density, sample.mean_pressure,
                -double(filament.viscosity * filament.strain_rate), solver.state().last_step.tension_iterations,
                solver.state().last_step.viscosity_iterations);
    std::fflush(stdout);
  }
  return samples;
}

struct ColumnCase {
  Real particle_radius = Real(0.0005);  // m
  Real radius = Real(0.005);            // R0, m
  Real length = Real(0.05);             // L0, m
  material::Material material = material::newtonian("column", 1800, 1000);
  bool tension = true;
  Real support_radius_factor = 4;       // the kernel's support in particle radii (the engine's default)
  Real stress_form_viscosity = 0;       // SolverSettings::stress_form_viscosity
  std::vector<double> sample_fractions = {0.2, 0.4, 0.6, 0.8};  // of the expected break time
  double longest_fraction = 1.3;        // gives up on a break after this fraction of it
};

struct ColumnSample {
  double time = 0;            // s
  double section_ratio = 0;   // A/A0 of the material that started at mid-height, where it is now
  double length = 0;          // m, from the plate to the free end
};

struct ColumnResult {
  std::vector<ColumnSample> samples;
  double break_time = 0;      // s, when the column first parts (a gap over two spacings along it); 0: never
  double break_height = 0;    // m, where (the lower side of the gap; the plate's face is at L0)
  double lower_part_strain = 0;  // the stretch of the material that started below `lower_height`, over its first length
};

/// Stokes's break time of a Newtonian column, t* = 3μ/(ρ g L0).
inline double stokes_break_time(const ColumnCase& column) {
  return 3 * double(column.material.rheology.viscosity) / (double(column.material.density) * 9.81 * double(column.length));
}
/// The Bingham paste: τ0 = 200 Pa, μp = 500 Pa·s, ρ = 2100 kg/m³, its viscosity capped at `cap`.
inline material::Material bingham_paste(Real cap) {
  material::Material paste = material::newtonian("bingham paste", 2100, 500);
  paste.rheology.model = material::RheologyModel::bingham;
  paste.rheology.yield_stress = 200;
  paste.rheology.max_viscosity = cap;
  return paste;
}
/// The length below which a hanging Bingham column does not yield: L_c = √3 τ0/(ρ g).
inline double critical_length(const material::Material& paste) {
  return std::sqrt(3.0) * double(paste.rheology.yield_stress) / (double(paste.density) * 9.81);
}
/// The top's break time of a hanging Bingham column: t* = (√3 μp/τ0) ln(1/(1 − L_c/L0)).
inline double bingham_break_time(const ColumnCase& column) {
  const auto& rheology = column.material.rheology;
  return std::sqrt(3.0) * double(rheology.viscosity) / double(rheology.yield_stress) *
         std::log(1 / (1 - critical_length(column.material) / double(column.length)));
}

/// A column hanging from a plate (no slip) under gravity, its free end down.
inline ColumnResult hang_column(const ColumnCase& column, double expected_break, Real lower_height = 0) {
  const Real d = 2 * column.particle_radius;
  sph::Parameters parameters;
  parameters.settings.particle_radius = column.particle_radius;
  parameters.settings.max_time_step = Real(2e-3);
  parameters.settings.rest_detection = false;
  parameters.settings.tension = column.tension;
  parameters.settings.support_radius_factor = column.support_radius_factor;
  parameters.settings.stress_form_viscosity = column.stress_form_viscosity;
  parameters.settings.bounds.min = Vec3(-1, -1, -1);
  parameters.settings.bounds.max = Vec3(1, 1, 1);
  material::Material material = column.material;
  material.sticks_to_walls = true;
  parameters.phases.push_back(material);
  sph::Solver solver(parameters);
  solver.add_particles(cylinder_lattice(column.radius, 0, column.length, d), Vec3::Zero(), 0);
  const Real plate_thickness = 3 * d;
  const BoxShape plate{Vec3(2 * column.radius + 8 * d, 2 * column.radius + 8 * d, plate_thickness)};
  solver.add_body("plate", sph::sample_box_surface(plate, d).points, Pose{Vec3(0, 0, column.length + plate_thickness / 2), Quat::Identity()}, true);

  const auto& fluid = solver.fluid();
  const double section0 = section_at(fluid, column.length / 2, d, d);
  const double density = material.density, g = 9.81;
  const double k = density * g / (3 * double(material.rheology.viscosity));  // Stokes's (Newtonian)
  std::vector<std::uint64_t> lower_ids;
  for (std::size_t i = 0; i < fluid.size(); ++i)
    if (fluid.position[i].z() < lower_height) lower_ids.push_back(fluid.id[i]);
  std::sort(lower_ids.begin(), lower_ids.end());
  auto lower_extent = [&]() {
    Real low = 1, high = -1;
    for (std::size_t i = 0; i < fluid.size(); ++i)
      if (std::binary_search(lower_ids.begin(), lower_ids.end(), fluid.id[i])) low = std::min(low, fluid.position[i].z()), high = std::max(high, fluid.position[i].z());
    return double(high - low) + d;
  };
  const double lower0 = lower_ids.empty() ? 0 : lower_extent();
  auto lowest = [&]() {
    Real low = 1;
    for (const Vec3& p : fluid.position) low = std::min(low, p.z());
    return double(low);
  };
  auto largest_gap = [&]() {  // along the column, between the plate and the lowest particle
    std::vector<Real> heights;
    for (const Vec3& p : fluid.position) heights.push_back(p.z());
    std::sort(heights.begin(), heights.end());
    Real gap = 0, where = 0;
    for (std::size_t n = 1; n < heights.size(); ++n)
      if (heights[n] - heights[n - 1] > gap) gap = heights[n] - heights[n - 1], where = heights[n - 1];
    return std::pair<double, double>(gap, where);
  };
  ColumnResult result;
  std::size_t next_sample = 0;
  const double end_time = column.longest_fraction * expected_break;
  while (solver.time() < end_time) {
    solver.step();
    if (solver.state().step % 10 == 0 && result.break_time == 0) {
      const auto [gap, where] = largest_gap();
      if (gap > 2 * d) {
        result.break_time = solver.time();
        result.break_height = where;
        std::printf("column parted at %.3f s (expected %.3f s, %.3f of it), %.1f mm below the plate\n", result.break_time, expected_break,
                    result.break_time / expected_break, 1e3 * (column.length - where));
      }
    }
    if (next_sample < column.sample_fractions.size() && solver.time() >= column.sample_fractions[next_sample] * expected_break) {
      ColumnSample sample;
      sample.time = solver.time();
      const double end = lowest() - d / 2;
      sample.length = column.length - end;
      // The material that started at mid-height (X = L0/2 above the free end) is now this far above it.
      const double t = sample.time, X = column.length / 2;
      const double height = -std::log(1 - k * X * t) / (k * t);
      sample.section_ratio = section_at(fluid, static_cast<Real>(end + height), d, d) / section0;
      const double stokes_length = -std::log(1 - k * column.length * t) / (k * t);
      std::printf("column t %.3f s (%.2f t*): mid-height section %.4f (Stokes %.4f), length %.2f mm (Stokes %.2f), lowest part %.2f mm, "
                  "tension its %d, viscosity its %d\n",
                  t, t / expected_break, sample.section_ratio, 1 - k * X * t, 1e3 * sample.length, 1e3 * stokes_length,
                  lower_ids.empty() ? 0.0 : 1e3 * lower_extent(), solver.state().last_step.tension_iterations,
                  solver.state().last_step.viscosity_iterations);
      std::fflush(stdout);
      result.samples.push_back(sample);
      ++next_sample;
    }
    if (result.break_time > 0 && next_sample >= column.sample_fractions.size()) break;
  }
  if (!lower_ids.empty()) result.lower_part_strain = lower_extent() / lower0 - 1;
  return result;
}

}  // namespace m3dp::tension
