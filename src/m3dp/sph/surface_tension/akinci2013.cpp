// Surface tension and wall adhesion after N. Akinci, G. Akinci, M. Teschner, "Versatile Surface
// Tension and Adhesion for SPH Fluids", ACM Trans. Graph. 32(6), 182, 2013.
//
// On particle i, with K_ij = 2ρ0/(ρ_i + ρ_j) (stronger where the neighbourhood is thin; with unequal rest
// densities, 2/(ρ_i/ρ0_i + ρ_j/ρ0_j)):
//   cohesion   F_i = −γ Σ_j K_ij m_i m_j C(|x_ij|) x_ij/|x_ij|                                (eq. 1)
//   curvature  F_i = −γ Σ_j K_ij m_i (n_i − n_j),  n_i = h Σ_j (m_j/ρ_j) ∇W_ij                 (eqs. 4, 5)
//   adhesion   F_i = −β Σ_b m_i Ψ_b A(|x_ib|) x_ib/|x_ib|,  Ψ_b = ρ0 V_b                          (eq. 7)
// with the paper's spline kernels C (attracts beyond h/2, repels closer) and A (attracts between h/2
// and h), h the support radius.
//
// The paper's γ and β are coefficients, not the physical surface tension σ (N/m). We derive them from
// σ and from the work of adhesion W_a (N/m) with the mean-field surface energy of a pair force: a
// pair potential φ(r) in a body of number density n has σ = −(π n²/2) ∫ φ(r) r³ dr (half the work
// of splitting the body in two). For the cohesion, φ' = γ m² C, which gives γ = 8σ / (π ρ0² ∫ C r⁴ dr).
// The adhesion is matched the same way to the work of pulling a fluid half-space (from the geometric
// surface, a radius in front of the wall layer) off a flat wall layer with the solver's Akinci
// volumes. The curvature term has no tangential part on flat surfaces and is left out of the mapping.
// The mapping is a mean field: it sets the scale, it is not validated. On Rayleigh's oscillating droplet
// (R = 10 mm, 16–20 particles across) the model oscillates 2.6–3× too fast and is damped within a
// period or two, so σ here is an order of magnitude, not a measured surface tension; the continuum
// surface force (surface_tension_brackbill1992.cpp) is the model that meets the droplet's period.
// Resting particles (rest detection) attract as neighbours but have no normal; their pairs skip the
// curvature term.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph {

namespace {

/// Akinci 2013 eq. 2: the cohesion spline (1/m⁶ · 1/m³ = m⁻⁹ scaled by h⁶ terms), support h.
Real cohesion_kernel(Real distance, Real h) {
  if (distance <= 0 || distance > h) return 0;
  const Real coefficient = Real(32) / (kPi * std::pow(h, Real(9)));
  const Real outer = (h - distance) * (h - distance) * (h - distance) * distance * distance * distance;
  if (2 * distance > h) return coefficient * outer;
  return coefficient * (2 * outer - std::pow(h, Real(6)) / 64);
}

/// Akinci 2013 eq. 8: the adhesion spline, non-zero for h/2 < r ≤ h.
Real adhesion_kernel(Real distance, Real h) {
  if (2 * distance <= h || distance > h) return 0;
  const Real inner = -4 * distance * distance / h + 6 * distance - 2 * h;
  return Real(0.007) / std::pow(h, Real(3.25)) * std::pow(std::max(inner, Real(0)), Real(0.25));
}

}  // namespace

SurfaceTensionCalibration calibrated_surface_tension(KernelType kernel_type, Real support_radius, Real fluid_spacing,
                                                     Real wall_spacing, Real boundary_volume_scale) {
  const double h = support_radius;
  constexpr int kSamples = 4000;
  const double dr = h / kSamples;
  // Cohesion: γ per σ = 8 / (π ρ0_i ρ0_j ∫ C r⁴ dr) (midpoint rule); stored without the densities.
  double cohesion_moment = 0;
  for (int k = 0; k < kSamples; ++k) {
    const double r = (k + 0.5) * dr;
    cohesion_moment += double(cohesion_kernel(Real(r), Real(h))) * r * r * r * r * dr;
  }
  SurfaceTensionCalibration calibration;
  calibration.cohesion_per_tension = Real(8 / (kPi * cohesion_moment));

  // Adhesion: a wall layer of area density 1/s² with Ψ_b = ρ0 V_b against fluid of density ρ0 from
  // z = d/2 on. Pair potential φ(r) = −β m Ψ_b G(r), G(r) = ∫_r^h A ds; the energy per area is
  // E = −β ρ0 (Ψ_b/s²) 2π ∫_{d/2}^h dz ∫_z^h G(r) r dr, and W_a = −E.
  const double wall_volume = with_kernel(kernel_type, support_radius, [&](const auto& kernel) {
    const int reach = static_cast<int>(std::ceil(support_radius / wall_spacing)) + 1;
    double in_plane = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j) in_plane += kernel.W(Vec3(i * wall_spacing, j * wall_spacing, 0).norm());
    return double(boundary_volume_scale) / in_plane;
  });
  std::vector<double> outer_integral(kSamples + 1, 0.0);  // G(r_k) from the top down
  for (int k = kSamples - 1; k >= 0; --k)
    outer_integral[k] = outer_integral[k + 1] + double(adhesion_kernel(Real((k + 0.5) * dr), Real(h))) * dr;
  std::vector<double> radial_integral(kSamples + 1, 0.0);  // ∫_z^h G(r) r dr
  for (int k = kSamples - 1; k >= 0; --k) {
    const double r = (k + 0.5) * dr;
    radial_integral[k] = radial_integral[k + 1] + 0.5 * (outer_integral[k] + outer_integral[k + 1]) * r * dr;
  }
  double layer_integral = 0;
  const int first = static_cast<int>(std::lround(0.5 * fluid_spacing / dr));
  for (int k = first; k < kSamples; ++k) layer_integral += 0.5 * (radial_integral[k] + radial_integral[k + 1]) * dr;
  // β ρ0² per W_a (the fluid's ρ0 twice: its number density × mass, and Ψ_b = ρ0 V_b).
  const double wall_volume_per_area = wall_volume / (double(wall_spacing) * wall_spacing);
  calibration.adhesion_per_work = Real(1 / (wall_volume_per_area * 2 * kPi * layer_integral));
  return calibration;
}

namespace stages {

namespace {

/// Akinci 2013 eq. 7: each particle of an adhering phase is drawn to the wall particles near it.
void add_wall_adhesion(const Model& model, State& state, Workspace& workspace) {
  const auto& calibration = model.surface_tension_calibration;
  const bool any = std::any_of(model.phases.begin(), model.phases.end(),
                               [](const FluidPhase& phase) { return phase.adhesion > 0; });
  if (!any) return;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const Real h = model.support_radius;
  const Real inverse_volume = 1 / model.particle_volume;
  const auto& boundary_lists = workspace.boundary_neighbors;
  for_each_wrench_chunk(state, workspace, state.active_count, [&](const tbb::blocked_range<std::size_t>& range, std::span<Wrench> wrenches) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const FluidPhase& phase_i = model.phases[fluid.phase[i]];
      if (phase_i.adhesion <= 0) continue;
      const Real rest_density_i = fluid.mass[i] * inverse_volume;
      const Real beta = calibration.adhesion_per_work * phase_i.adhesion / (rest_density_i * rest_density_i);
      Vec3 acceleration = Vec3::Zero();
      const std::size_t boundary_first = boundary_lists.first(i);
      for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
        const Index b = boundary_lists.indices[boundary_first + k];
        const Vec3 r = fluid.position[i] - boundary.position[b];
        const Real distance = r.norm();
        if (distance <= Real(1e-9) * h) continue;
        const Vec3 a = (-beta * rest_density_i * boundary.volume[b] * adhesion_kernel(distance, h) / distance) * r;
        acceleration += a;
        const Vec3 force = -fluid.mass[i] * a;
        Wrench& wrench = wrenches[boundary.body[b]];
        wrench.force += force;
        wrench.torque += (boundary.position[b] - state.bodies[boundary.body[b]].pose.position).cross(force);
      }
      fluid.acceleration[i] += acceleration;
    }
  });
}

/// Akinci 2013 eqs. 1, 4, 5: cohesion and curvature between particles of phases with surface tension.
void add_akinci_surface_tension(const Model& model, State& state, Workspace& workspace) {
  const auto& calibration = model.surface_tension_calibration;
  auto& fluid = state.fluid;
  const std::size_t count = state.active_count;
  const Real h = model.support_radius;
  const Real volume = model.particle_volume;  // every particle's m/ρ0
  const Real inverse_volume = 1 / volume;
  const auto& fluid_lists = workspace.fluid_neighbors;

  // Normals n_i = h (Σ_j (m_j/ρ_j) ∇W_ij + Σ_b V_b ∇W_ib). Walls count as material here: a face resting
  // on a wall is no free surface, and the curvature term would push it into the wall (a drop without
  // adhesion would be kicked off a ceiling).
  auto& normal = workspace.surface_normal;
  normal.resize(fluid.size());
  std::fill(normal.begin() + static_cast<std::ptrdiff_t>(count), normal.end(), Vec3::Zero());
  parallel_for_each_index(count, [&](std::size_t i) { normal[i] = h * colour_gradient(state, workspace, i, volume); }, 512);

  parallel_for_each_index(count, [&](std::size_t i) {
    const FluidPhase& phase_i = model.phases[fluid.phase[i]];
    const Vec3 position_i = fluid.position[i];
    const Real density_ratio_i = fluid.density[i] * volume / fluid.mass[i];  // ρ_i/ρ0_i
    const Real rest_density_i = fluid.mass[i] * inverse_volume;
    Vec3 acceleration = Vec3::Zero();
    const std::size_t fluid_first = fluid_lists.first(i);
    for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
      const Index j = fluid_lists.indices[fluid_first + k];
      const Real tension = Real(0.5) * (phase_i.surface_tension + model.phases[fluid.phase[j]].surface_tension);
      if (tension <= 0) continue;
      const Real rest_density_j = fluid.mass[j] * inverse_volume;
      const Real gamma = calibration.cohesion_per_tension * tension / (rest_density_i * rest_density_j);
      const Vec3 r = position_i - fluid.position[j];
      const Real distance = r.norm();
      const Real correction = 2 / (density_ratio_i + fluid.density[j] * volume / fluid.mass[j]);
      Vec3 pair = Vec3::Zero();
      if (distance > Real(1e-9) * h) pair -= (fluid.mass[j] * cohesion_kernel(distance, h) / distance) * r;
      if (j < count) pair -= normal[i] - normal[j];
      acceleration += (correction * gamma) * pair;
    }
    fluid.acceleration[i] += acceleration;
  }, 128);
}

}  // namespace

Vec3 colour_gradient(const State& state, const Workspace& workspace, std::size_t i, Real rest_volume) {
  const auto& fluid = state.fluid;
  const auto& fluid_lists = workspace.fluid_neighbors;
  const auto& boundary_lists = workspace.boundary_neighbors;
  // The pair factor holds V (dW/dr)/r with V the rest volume; m_j/ρ_j = (m_j/(V ρ_j)) V.
  const Real inverse_volume = rest_volume > 0 ? 1 / rest_volume : Real(0);
  Vec3 sum = Vec3::Zero();
  const std::size_t first = fluid_lists.first(i);
  for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
    const Index j = fluid_lists.indices[first + k];
    const Real scale = rest_volume > 0 ? fluid.mass[j] * inverse_volume / fluid.density[j] : Real(1);
    sum += (scale * workspace.fluid_pair_gradient[first + k]) * (fluid.position[i] - fluid.position[j]);
  }
  const std::size_t boundary_first = boundary_lists.first(i);
  for (Index k = 0; k < boundary_lists.counts[i]; ++k)
    sum += workspace.boundary_pair_gradient[boundary_first + k] *
           (fluid.position[i] - state.boundary.position[boundary_lists.indices[boundary_first + k]]);
  return sum;
}

void add_surface_tension(const Model& model, State& state, Workspace& workspace) {
  const bool any_tension = std::any_of(model.phases.begin(), model.phases.end(),
                                       [](const FluidPhase& phase) { return phase.surface_tension > 0; });
  if (model.settings.surface_tension_model == SurfaceTensionModel::csf_brackbill1992) {
    // No adhesion: the Solver refuses it with this model (walls are wetted at 90°).
    if (any_tension) add_csf_surface_tension(model, state, workspace);
    return;
  }
  if (any_tension) add_akinci_surface_tension(model, state, workspace);
  add_wall_adhesion(model, state, workspace);
}

}  // namespace stages

}  // namespace m3dp::sph

