#include "m3dp/sph/model.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace m3dp::sph {

namespace {

/// Disc samples inside radius D/2 (at least the centre): on a square lattice of spacing `spacing`, or
/// inside a bore in rings.
NozzleGeometry make_nozzle_geometry(const NozzleSettings& nozzle, Real spacing) {
  NozzleGeometry geometry;
  const bool bore = nozzle.bore_length > 0;
  if (bore) {
    // Inside a bore the material fills the section at rest density: rings a spacing apart from
    // D/2 − d/2 inwards (the wall's particles half a spacing outside D/2), each ring a spacing
    // between points, so that a disc holds π D²/4 / d² particles and keeps d from the wall.
    for (Real ring_radius = nozzle.inner_diameter / 2 - spacing / 2; ring_radius > Real(0.25) * spacing; ring_radius -= spacing) {
      const int count = std::max(3, static_cast<int>(std::lround(2 * kPi * ring_radius / spacing)));
      for (int k = 0; k < count; ++k) {
        const double angle = 2 * kPi * k / count;
        geometry.disc_offsets.emplace_back(ring_radius * Real(std::cos(angle)), ring_radius * Real(std::sin(angle)), 0);
      }
    }
    const Real innermost = std::fmod(nozzle.inner_diameter / 2 - spacing / 2, spacing);
    if (innermost <= Real(0.25) * spacing + Real(1e-6) * spacing) geometry.disc_offsets.emplace_back(Vec3::Zero());
  }
  const Real radius = nozzle.inner_diameter / 2;
  const int half_count = static_cast<int>(std::ceil(radius / spacing)) + 1;
  // Offset the lattice by half a spacing when that packs more points (even counts across).
  for (const Real shift : {Real(0), Real(0.5)}) {
    if (bore) break;
    std::vector<Vec3> offsets;
    for (int i = -half_count; i <= half_count; ++i)
      for (int j = -half_count; j <= half_count; ++j) {
        const Vec3 point((i + shift) * spacing, (j + shift) * spacing, 0);
        if (point.head<2>().norm() <= radius + Real(1e-6) * spacing) offsets.push_back(point);
      }
    if (offsets.size() > geometry.disc_offsets.size()) geometry.disc_offsets = std::move(offsets);
  }
  if (geometry.disc_offsets.empty()) geometry.disc_offsets.push_back(Vec3::Zero());
  const double particle_volume = std::pow(static_cast<double>(spacing), 3);
  const double flux = kPi * nozzle.inner_diameter * nozzle.inner_diameter / 4 * nozzle.exit_speed;  // m³/s
  geometry.flux = flux;
  geometry.layer_period = flux > 0 ? geometry.disc_offsets.size() * particle_volume / flux : 0;
  if (bore) {
    // Akinci particles half a spacing inside the solid: the bore's wall at radius D/2 + d/2 from the
    // tip (z = d/2) to a spacing above the bore's top, the tip's annulus at z = d/2 out to the outer
    // radius − d/2, and the outside at that radius, each ring at the spacing along its circumference.
    const Real half = spacing / 2;
    const Real inner = nozzle.inner_diameter / 2 + half;
    const Real outer = std::max(nozzle.outer_diameter / 2 - half, inner + 2 * spacing);
    auto ring = [&](Real ring_radius, Real z) {
      const int count = std::max(6, static_cast<int>(std::lround(2 * kPi * ring_radius / spacing)));
      for (int k = 0; k < count; ++k) {
        const double angle = 2 * kPi * (k + Real(0.5) * (static_cast<int>(std::lround(z / spacing)) & 1)) / count;
        geometry.bore_points.emplace_back(ring_radius * Real(std::cos(angle)), ring_radius * Real(std::sin(angle)), z);
      }
    };
    for (Real ring_radius = inner; ring_radius <= outer + Real(1e-3) * spacing; ring_radius += spacing) ring(ring_radius, half);
    const Real top = nozzle.bore_length + spacing;
    for (Real z = half + spacing; z <= top + Real(1e-3) * spacing; z += spacing) {
      ring(inner, z);
      ring(outer, z);
    }
    // The piston: a lid a spacing above where discs come in (the pump's face: the material cannot
    // escape upwards, so the pressure that drives it out builds), and the top two spacings of the
    // bore, whose material the pump moves at the commanded flow.
    const int lid_half_count = static_cast<int>(std::ceil(inner / spacing));
    for (int i = -lid_half_count; i <= lid_half_count; ++i)
      for (int j = -lid_half_count; j <= lid_half_count; ++j)
        if (std::hypot(i * spacing, j * spacing) < inner - Real(0.5) * spacing)
          geometry.piston_points.emplace_back(i * spacing, j * spacing, nozzle.bore_length + spacing);
    geometry.piston_depth = 2 * spacing;
  }
  return geometry;
}

/// Σ_b V_b W over a flat square-lattice wall layer (spacing `wall_spacing`, Akinci volumes
/// V_b = 1 / Σ_in-plane W) at `distance` from the layer.
Real wall_share(KernelType type, Real support_radius, Real wall_spacing, Real distance) {
  return with_kernel(type, support_radius, [&](const auto& kernel) {
    const int reach = static_cast<int>(std::ceil(support_radius / wall_spacing)) + 1;
    double in_plane = 0, share = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j) {
        in_plane += kernel.W(Vec3(i * wall_spacing, j * wall_spacing, 0).norm());
        share += kernel.W(Vec3(i * wall_spacing, j * wall_spacing, distance).norm());
      }
    return static_cast<Real>(share / in_plane);
  });
}

/// Akinci 2012 volumes make a one-layer wall contribute more density than the fluid it replaces:
/// a particle resting one spacing in front of a flat wall would sit several per cent over rest
/// density, so every fluid block would start compressed where it touches a wall and the first
/// pressure solves push violently. This factor scales the boundary volumes so that a cubic-lattice
/// fluid (spacing d) one spacing from the wall layer is exactly at rest density.
Real calibrated_boundary_volume_scale(KernelType type, Real support_radius, Real fluid_spacing, Real wall_spacing) {
  const double fluid_share = with_kernel(type, support_radius, [&](const auto& kernel) {
    const int reach = static_cast<int>(std::ceil(support_radius / fluid_spacing)) + 1;
    double sum = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j)
        for (int k = 0; k <= reach; ++k) sum += kernel.W(Vec3(i * fluid_spacing, j * fluid_spacing, k * fluid_spacing).norm());
    return sum * std::pow(static_cast<double>(fluid_spacing), 3);  // the half-lattice on the particle's side
  });
  return static_cast<Real>((1.0 - fluid_share) / wall_share(type, support_radius, wall_spacing, fluid_spacing));
}

/// The Morris/Monaghan viscosity sum 2(d+2) Σ_j V_j (v_ij·x_ij)/(r² + 0.01h²) ∇W_ij is the Laplacian
/// only where a kernel has many neighbours: on the rest lattice of a cubic spline with a support of
/// two spacings (our default) it gives 0.70 ∇²v, so every viscosity would act 30 % too weak (the
/// Poiseuille test sees exactly that). `fluid` scales the sum so that it is exact on the rest lattice
/// for a shear flow u = (z², 0, 0). `boundary` scales the wall term so that a linear shear flow
/// u = γ̇ z over a wall is in equilibrium, i.e. the no-slip plane is the geometric surface (a radius in
/// front of the boundary layer), with the Akinci volumes the solver gives a flat wall. The velocity
/// gradient (the rheology's shear rate) gets the same treatment: exact for linear shear inside the
/// fluid and over a wall (with the wall's term alone, a first-layer particle sees 0.77 of its shear
/// rate, and a yield-stress material at the wall behaves too stiff).
ViscosityCalibration calibrated_viscosity(KernelType type, Real support_radius, Real fluid_spacing, Real wall_spacing,
                                          Real boundary_volume_scale) {
  return with_kernel(type, support_radius, [&](const auto& kernel) {
    const double d = fluid_spacing, regularisation = 0.01 * double(support_radius) * support_radius, volume = d * d * d;
    const int reach = static_cast<int>(std::ceil(support_radius / fluid_spacing)) + 1;
    auto pair_term = [&](double distance_squared) {
      return double(kernel.gradient_factor(Real(std::sqrt(distance_squared)))) / (distance_squared + regularisation);
    };
    // Laplacian of (z², 0, 0) at the origin: x-component of 2(d+2) Σ V (u_i − u_j)(x_i − x_j)² f / (r² + ε) = 2.
    double laplacian = 0, fluid_shear = 0, gradient = 0, fluid_gradient_near_wall = 0, coupling = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j)
        for (int k = -reach; k <= reach; ++k) {
          const double x = i * d, y = j * d, z = k * d, r2 = x * x + y * y + z * z;
          if (r2 == 0 || r2 >= double(support_radius) * support_radius) continue;
          laplacian += volume * (-z * z) * x * x * pair_term(r2);
          coupling += volume * std::abs(pair_term(r2)) * r2;
          // Linear shear over the wall: the fluid neighbours of a first-layer particle (k ≥ 0), u = z.
          if (k >= 0) fluid_shear += volume * (-z) * x * x * pair_term(r2);
          // Velocity gradient of u = (z, 0, 0): Σ V (u_j − u_i)(z_i − z_j) f = ∂u/∂z = 1; near the wall only k ≥ 0.
          const double gradient_term = volume * z * (-z) * double(kernel.gradient_factor(Real(std::sqrt(r2))));
          gradient += gradient_term;
          if (k >= 0) fluid_gradient_near_wall += gradient_term;
        }
    laplacian *= 2 * (3 + 2);
    const double fluid_scale = 2.0 / laplacian;
    // The wall layer one spacing below that particle (no-slip plane half a spacing below it), at rest.
    double in_plane = 0, wall_shear = 0, wall_gradient = 0;
    const int wall_reach = static_cast<int>(std::ceil(support_radius / wall_spacing)) + 1;
    for (int i = -wall_reach; i <= wall_reach; ++i)
      for (int j = -wall_reach; j <= wall_reach; ++j) in_plane += kernel.W(Vec3(i * wall_spacing, j * wall_spacing, 0).norm());
    const double wall_volume = boundary_volume_scale / in_plane;
    for (int i = -wall_reach; i <= wall_reach; ++i)
      for (int j = -wall_reach; j <= wall_reach; ++j) {
        const double x = i * wall_spacing, y = j * wall_spacing, r2 = x * x + y * y + d * d;
        if (r2 >= double(support_radius) * support_radius) continue;
        wall_shear += wall_volume * (d / 2) * x * x * pair_term(r2);
        wall_gradient += wall_volume * (-d / 2) * d * double(kernel.gradient_factor(Real(std::sqrt(r2))));
      }
    ViscosityCalibration calibration;
    calibration.fluid = static_cast<Real>(fluid_scale);
    calibration.boundary = static_cast<Real>(-fluid_scale * fluid_shear / wall_shear);
    calibration.fluid_gradient = static_cast<Real>(1 / gradient);
    calibration.boundary_gradient = static_cast<Real>((1 - fluid_gradient_near_wall / gradient) / (wall_gradient / gradient));
    calibration.coupling = static_cast<Real>(2 * (3 + 2) * fluid_scale * coupling);
    return calibration;
  });
}


ParameterProblem phase_problem(std::size_t phase, std::string field, std::string message) {
  return {ParameterProblem::Subject::phase, phase, std::move(field), std::move(message)};
}
ParameterProblem settings_problem(std::string field, std::string message) {
  return {ParameterProblem::Subject::settings, 0, std::move(field), std::move(message)};
}

}  // namespace

std::string ParameterProblem::str(const Parameters& parameters) const {
  std::string owner;
  if (subject == Subject::phase && index < parameters.phases.size()) owner = fmt::format("material '{}'", parameters.phases[index].name);
  if (subject == Subject::nozzle && index < parameters.nozzles.size()) owner = fmt::format("nozzle '{}'", parameters.nozzles[index].name);
  if (subject == Subject::settings) owner = "solver";
  return field.empty() ? fmt::format("{}: {}", owner, message) : fmt::format("{}: {} {}", owner, field, message);
}

ParameterError::ParameterError(std::vector<ParameterProblem> problems, const Parameters& parameters)
    : Error([&] {
        std::string text = "invalid engine parameters:";
        for (const auto& problem : problems) text += "\n  " + problem.str(parameters);
        return text;
      }()),
      problems_(std::move(problems)) {}

// The rules that tie fields together (a model that needs a solver, a bore against the particle size,
// every material granular or none). Each field's own range is the scene table's (scene/schema.cpp),
// which every scene, preset and Python run is read through; only fields no scene element sets are
// checked here alone.
std::vector<ParameterProblem> check_parameters(const Parameters& parameters) {
  std::vector<ParameterProblem> problems;
  const auto& settings = parameters.settings;
  if (!(settings.neighbor_skin >= 0)) problems.push_back(settings_problem("neighbor_skin", fmt::format("must be >= 0 (support radii), got {}", settings.neighbor_skin)));
  if (parameters.phases.empty()) problems.push_back(settings_problem("", "at least one material is needed"));
  const bool granular = !parameters.phases.empty() && parameters.phases.front().granular.enabled;
  for (std::size_t p = 0; p < parameters.phases.size(); ++p) {
    const FluidPhase& phase = parameters.phases[p];
    // Akinci's adhesion pulls against Akinci's cohesion; without it the contact line sprays apart.
    if (phase.adhesion > 0 && settings.surface_tension_model == SurfaceTensionModel::csf_brackbill1992)
      problems.push_back(phase_problem(p, "adhesion", "needs the akinci2013 surface tension model: brackbill1992 wets walls "
                                                      "at 90° and has no adhesion"));
    if (phase.elasticity.enabled && settings.viscosity_solver != ViscositySolver::implicit_weiler2018)
      problems.push_back(phase_problem(p, "elasticity", "needs the implicit viscosity solver: an elastic material's "
                                                        "stiffness is solved with its viscosity"));
    // Granular mode: every phase or none (a fluid and discrete spheres do not interact yet).
    if (phase.granular.enabled != granular)
      problems.push_back(phase_problem(
          p, "", fmt::format("is {} but material '{}' is {}; one scene's materials are all fluids or all granular for now",
                             phase.granular.enabled ? "granular" : "a fluid", parameters.phases.front().name,
                             granular ? "granular" : "a fluid")));
  }
  for (std::size_t n = 0; n < parameters.nozzles.size(); ++n) {
    const NozzleSettings& nozzle = parameters.nozzles[n];
    if (nozzle.phase >= parameters.phases.size())
      problems.push_back({ParameterProblem::Subject::nozzle, n, "material", "names no material"});
    if (nozzle.bore_length > 0 && nozzle.bore_length < 2 * settings.particle_radius * 2)
      problems.push_back({ParameterProblem::Subject::nozzle, n, "bore_length",
                          fmt::format("must be 0 (no bore) or at least two particle diameters ({} m), got {}; a bore of two nozzle "
                                      "diameters is usual", 4 * settings.particle_radius, nozzle.bore_length)});
  }
  return problems;
}

Model compile_model(Parameters parameters) {
  if (auto problems = check_parameters(parameters); !problems.empty()) throw ParameterError(std::move(problems), parameters);
  Model model;
  static_cast<Parameters&>(model) = std::move(parameters);
  const SolverSettings& settings = model.settings;
  model.particle_radius = settings.particle_radius;
  model.particle_diameter = 2 * settings.particle_radius;
  model.particle_volume = model.particle_diameter * model.particle_diameter * model.particle_diameter;
  model.support_radius = settings.support_radius_factor * settings.particle_radius;
  model.wall_spacing = settings.boundary_spacing_factor * model.particle_diameter;
  const Real diameter = model.particle_diameter, support = model.support_radius;
  for (const auto& nozzle : model.nozzles) {
    model.nozzle_geometry.push_back(make_nozzle_geometry(nozzle, diameter));
    model.widest_nozzle = std::max(model.widest_nozzle, nozzle.inner_diameter);
  }
  model.boundary_volume_scale = calibrated_boundary_volume_scale(settings.kernel, support, diameter, model.wall_spacing);
  model.viscosity_calibration =
      calibrated_viscosity(settings.kernel, support, diameter, model.wall_spacing, model.boundary_volume_scale);
  model.surface_tension_calibration =
      calibrated_surface_tension(settings.kernel, support, diameter, model.wall_spacing, model.boundary_volume_scale);
  model.surface_tension_calibration.layer_kernel_sum = csf_layer_kernel_sum(settings.kernel, support, diameter);
  // A centre on the geometric surface is a radius from the layer; the limit sits a tenth of a radius
  // in front of it, so that rounding never leaves a centre on the wrong side.
  model.boundary_share_at_surface =
      model.boundary_volume_scale * wall_share(settings.kernel, support, model.wall_spacing, Real(1.1) * settings.particle_radius);
  model.full_neighbourhood = full_neighbourhood_count(support, diameter);

  model.lightest_rest_density = std::numeric_limits<Real>::max();
  // Micropolar: Θ of the sphere of one particle's volume unless the material gives one.
  const Real sphere_radius = diameter * std::cbrt(Real(3) / (4 * kPi));
  for (const auto& phase : model.phases) {
    model.particle_mass.push_back(phase.density * diameter * diameter * diameter);  // in this order: the same bits as ever
    model.largest_surface_tension = std::max(model.largest_surface_tension, phase.surface_tension);
    model.lightest_rest_density = std::min(model.lightest_rest_density, phase.density);
    model.any_elastic |= phase.elasticity.enabled;
    model.any_shear_rate |= phase.rheology.model != material::RheologyModel::newtonian || phase.ageing.enabled();
    model.any_wall_friction |= phase.has_wall_friction();
    model.microinertia.push_back(phase.micropolar.microinertia > 0 ? phase.micropolar.microinertia
                                                                   : Real(0.4) * sphere_radius * sphere_radius);
  }
  model.granular = model.phases.front().granular.enabled;
  if (model.granular) {
    // The default spring: a column of ten particles under gravity compresses each contact by 1 % of
    // a diameter (stiff enough to keep the particle size, soft enough for ~1e-4 s steps at d = 2 mm).
    const Real gravity = settings.gravity.norm() > 0 ? settings.gravity.norm() : Real(9.81);
    for (std::size_t p = 0; p < model.phases.size(); ++p) {
      const auto& granular = model.phases[p].granular;
      const Real mass = model.particle_mass[p];
      const Real stiffness = granular.stiffness > 0 ? granular.stiffness : 1000 * mass * gravity / diameter;
      model.granular_contacts.push_back(GranularContact{stiffness, granular.damping_ratio(), granular.friction});
      // Contact duration π√(m*/k), m* = m/2 between two particles; ten steps per contact.
      const Real contact_time = kPi * std::sqrt(mass / 2 / stiffness);
      model.granular_time_step = model.granular_time_step > 0 ? std::min(model.granular_time_step, contact_time / 10) : contact_time / 10;
    }
  }
  return model;
}

}  // namespace m3dp::sph
