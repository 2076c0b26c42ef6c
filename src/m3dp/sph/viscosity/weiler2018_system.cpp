// The implicit viscosity's linear system (Weiler et al. 2018; see weiler2018.cpp): each fluid pair's
// coefficient, each particle's own block (its mass and its walls), the block-Jacobi preconditioner,
// the right-hand side, and the warm start.
#include <tbb/parallel_for.h>

#include <Eigen/LU>

#include <algorithm>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/viscosity/weiler2018.hpp"

namespace m3dp::sph::stages::weiler2018 {

void build_system(const Model& model, State& state, Workspace& workspace) {
  const auto& settings = model.settings;
  const auto& calibration = model.viscosity_calibration;
  const Real time_step = state.time_step;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const std::size_t count = state.active_count;
  const Real regularisation = Real(0.01) * model.support_radius * model.support_radius;
  const auto& fluid_lists = workspace.fluid_neighbors;
  const auto& boundary_lists = workspace.boundary_neighbors;
  auto& system = workspace.viscosity_system;
  system.fluid_pair_coefficient.resize(fluid_lists.indices.size());
  system.boundary_pair_coefficient.resize(boundary_lists.indices.size());
  for (auto* vector : {&system.rhs, &system.residual, &system.preconditioned, &system.product, &system.start_velocity})
    vector->resize(fluid.size());
  // A.x reads x at every neighbour: resting particles are fixed (zero velocity), so zero in the direction.
  // Their part is zeroed again only where it can have changed (the solve writes the active part).
  const std::uint64_t copied_builds = system.operand_copy.settled_builds;
  const std::size_t copied_size = std::min(system.operand_copy.size, system.padded_operand.size());
  const bool resized = system.padded_operand.size() != fluid.size();
  system.padded_operand.resize(fluid.size());
  if (system.operand_copy.take(workspace.fixed_grids_version, fluid.size(), count) || resized) {
    workspace.for_each_unsettled_range(count, fluid.size(), copied_builds, copied_size, [&](std::size_t begin, std::size_t end) {
      std::fill(system.padded_operand.begin() + static_cast<std::ptrdiff_t>(begin),
                system.padded_operand.begin() + static_cast<std::ptrdiff_t>(end), Vec4::Zero());
    });
    system.operand_copy.settled_builds = workspace.settled_builds;
  }
  system.inverse_diagonal.resize(count);
  system.own_block.resize(count);

  // Coefficients, preconditioner and right-hand side (positions do not move during the solve). A fluid
  // pair's c = s_i · 2 μ_i μ_j/(μ_i + μ_j) · (m_j/ρ_j) · g_ij / (r² + ε): μ_ij = 2μ_iμ_j/(μ_i + μ_j) (pair_viscosity)
  // and V_j (dW/dr)/r = (ρ0_j/ρ_j) × the pair gradient g_ij (which holds (m_j/ρ0_j)(dW/dr)/r; negative), with
  // s_i = −Δt 2(d+2) calibration V_i / V.
  const Real volume = model.particle_volume;
  // The pair form's share of the fluid pairs (the rest is the stress form's, weiler2018_stress.cpp).
  const Real stress_share = std::clamp(settings.stress_form_viscosity, Real(0), Real(0.95));
  const Real pair_share = 1 - stress_share;
  auto pair_scale = [&](std::size_t i) {
    return -time_step * kDimensionFactor * calibration.fluid * pair_share * (fluid.mass[i] / fluid.density[i]) / volume;
  };
  if (stress_share > 0) {
    system.stress.assign(fluid.size(), Mat3::Zero());
    system.stress_product.resize(fluid.size());
  } else {
    system.stress.clear();
    system.stress_product.clear();
  }
  // The rest of particle i's set-up, given its fluid pairs' Σ c r rᵀ.
  auto finish_particle = [&](std::size_t i, const Mat3& fluid_coupling) {
    const FluidPhase& phase = model.phases[fluid.phase[i]];
    const Vec3 position_i = fluid.position[i];
    const Real mass_i = fluid.mass[i];
    const Real volume_i = mass_i / fluid.density[i];
    Mat3 own_block = mass_i * Mat3::Identity();  // the mass and the walls' coupling
    Vec3 rhs = mass_i * fluid.velocity[i];
    const std::size_t boundary_first = boundary_lists.first(i);
    for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
      Real coefficient = 0;
      if (phase.has_wall_friction()) {
        const Index b = boundary_lists.indices[boundary_first + k];
        const Vec3 r = position_i - boundary.position[b];
        coefficient = -time_step * kDimensionFactor * calibration.boundary * phase.wall_viscosity(fluid.viscosity[i], boundary.wall_kind[b]) * volume_i *
                      workspace.boundary_pair_gradient[boundary_first + k] / (r.squaredNorm() + regularisation);
        own_block += coefficient * r * r.transpose();
        rhs += (coefficient * r.dot(boundary.velocity[b])) * r;
      }
      system.boundary_pair_coefficient[boundary_first + k] = coefficient;
    }
    system.own_block[i] = own_block;
    // The stress form's diagonal block taken as the pair form's would be (both are the viscous Laplacian).
    system.inverse_diagonal[i] = (own_block + fluid_coupling / pair_share).inverse();
    system.rhs[i] = rhs;
    // Warm start: v* plus last step's viscous change. A stiff paste's viscosity undoes nearly the same
    // pressure-driven spreading every step, so this guess is close and CG needs far fewer iterations.
    system.start_velocity[i] = fluid.velocity[i];
    if (settings.warm_start) fluid.velocity[i] += fluid.viscous_change[i];
    system.padded_operand[i] = padded(fluid.velocity[i]);
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 128), [&](const tbb::blocked_range<std::size_t>& range) {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
    if (avx2::available()) {
      avx2::viscous_coefficient_rows(range.begin(), range.end(), workspace.solver_position.data(), fluid.viscosity.data(), fluid.mass.data(),
                                     fluid.density.data(), fluid_lists.indices.data(), fluid_lists.counts.data(), fluid_lists.firsts.data(),
                                     workspace.fluid_pair_gradient.data(), regularisation, system.fluid_pair_coefficient.data(), pair_scale,
                                     finish_particle);
      return;
    }
#endif
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const Vec3 position_i = fluid.position[i];
      const Real mu_i = fluid.viscosity[i], scale_i = pair_scale(i);
      Mat3 fluid_coupling = Mat3::Zero();
      const std::size_t fluid_first = fluid_lists.first(i);
      for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
        const Index j = fluid_lists.indices[fluid_first + k];
        const Vec3 r = position_i - fluid.position[j];
        const Real denominator = (mu_i + fluid.viscosity[j]) * fluid.density[j] * (r.squaredNorm() + regularisation);
        const Real coefficient = denominator > 0 ? 2 * scale_i * mu_i * fluid.viscosity[j] * fluid.mass[j] *
                                                       workspace.fluid_pair_gradient[fluid_first + k] / denominator
                                                 : Real(0);
        system.fluid_pair_coefficient[fluid_first + k] = coefficient;
        fluid_coupling += coefficient * r * r.transpose();
      }
      finish_particle(i, fluid_coupling);
    }
  });
  // The stress form's renormalisation and no-slip walls (its operator part is made at each product).
  if (stress_share > 0) {
    prepare_gradient_correction(model, state, workspace);
    add_stress_form_walls_to_rhs(model, state, workspace);
  }
}

}  // namespace m3dp::sph::stages::weiler2018
