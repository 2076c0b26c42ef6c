// Non-pressure accelerations: gravity and laminar viscosity.
// Viscosity: J. P. Morris, P. J. Fox, Y. Zhu, "Modeling Low Reynolds Number Incompressible Flows
// Using SPH", J. Comput. Phys. 136, 1997, in the form of Monaghan 2005 (eq. 6.19) used by SPlisHSPlasH:
//   a_i += 2(d+2)/ρ_i Σ_j μ_ij (m_j/ρ_j) (v_ij·x_ij) / (|x_ij|² + 0.01 h²) ∇W_ij,  μ_ij their harmonic mean
// with each particle's dynamic viscosity μ (Pa·s, from the rheology). Explicit: the time step is
// bounded by the viscous limit in Solver::step. Uses the pair gradients of the density pass.
// The default is the implicit solver (viscosity_weiler2018.cpp); this one is the cheaper option for water.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void add_gravity_and_explicit_viscosity(const Model& model, State& state, Workspace& workspace) {
  const auto& calibration = model.viscosity_calibration;
  const bool explicit_viscosity = model.settings.viscosity_solver == ViscositySolver::explicit_morris1997;
  const auto& settings = model.settings;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const Real support_radius = model.support_radius;
  const Real regularisation = Real(0.01) * support_radius * support_radius;
  constexpr Real kDimensionFactor = 2 * (3 + 2);
  const Real inverse_volume = 1 / model.particle_volume;  // ρ0_j = m_j / V
  if (!explicit_viscosity) {
    parallel_for_each_index(state.active_count, [&](std::size_t i) { fluid.acceleration[i] = settings.gravity; }, 1024);
    return;
  }

  // V_j ∇W_ij = pair_gradient · x_ij (filled with the densities this step), so
  // (m_j/ρ_j) ∇W_ij = (ρ0/ρ_j) · pair_gradient · x_ij.
  const auto& fluid_lists = workspace.fluid_neighbors;
  const auto& boundary_lists = workspace.boundary_neighbors;
  for_each_wrench_chunk(state, workspace, state.active_count, [&](const tbb::blocked_range<std::size_t>& range, std::span<Wrench> wrenches) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const FluidPhase& phase = model.phases[fluid.phase[i]];
      const Vec3 position_i = fluid.position[i];
      const Vec3 velocity_i = fluid.velocity[i];
      Vec3 acceleration = settings.gravity;
      const Real inverse_density_i = Real(1) / fluid.density[i];
      {
        Vec3 viscous = Vec3::Zero();
        const Real mu_i = fluid.viscosity[i];
        const std::size_t first = fluid_lists.first(i);
        for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
          const Index j = fluid_lists.indices[first + k];
          const Vec3 r = position_i - fluid.position[j];
          const Real mu_ij = pair_viscosity(mu_i, fluid.viscosity[j]);
          viscous += mu_ij * (fluid.mass[j] * inverse_volume / fluid.density[j]) * workspace.fluid_pair_gradient[first + k] *
                     (velocity_i - fluid.velocity[j]).dot(r) / (r.squaredNorm() + regularisation) * r;
        }
        acceleration += kDimensionFactor * calibration.fluid * inverse_density_i * viscous;
      }
      if (phase.has_wall_friction()) {
        const Real mass_i = fluid.mass[i];
        const std::size_t first = boundary_lists.first(i);
        for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
          const Index b = boundary_lists.indices[first + k];
          const Vec3 r = position_i - boundary.position[b];
          const Real wall_viscosity = phase.wall_viscosity(fluid.viscosity[i], boundary.wall_kind[b]);
          const Vec3 a = kDimensionFactor * calibration.boundary * wall_viscosity * inverse_density_i * workspace.boundary_pair_gradient[first + k] *
                         (velocity_i - boundary.velocity[b]).dot(r) / (r.squaredNorm() + regularisation) * r;
          acceleration += a;
          const Vec3 force = -mass_i * a;
          Wrench& wrench = wrenches[boundary.body[b]];
          wrench.force += force;
          wrench.torque += (boundary.position[b] - state.bodies[boundary.body[b]].pose.position).cross(force);
        }
      }
      fluid.acceleration[i] = acceleration;
    }
  });
}

}  // namespace m3dp::sph::stages

