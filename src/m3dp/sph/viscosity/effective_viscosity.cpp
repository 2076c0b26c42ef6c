// Each particle's shear rate and effective viscosity (stage "forces"): γ̇ = √(2 D:D) with
// D = sym(∇v), ∇v_i = Σ_j V_j (v_j − v_i) ⊗ ∇W_ij (calibrated on the rest lattice, walls included
// where the material has wall friction), and μ from the phase's rheology at that rate and its age.
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/simd/neighbor_sums_avx2.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

namespace {
bool phase_needs_shear_rate(const FluidPhase& phase) {
  return phase.rheology.model != material::RheologyModel::newtonian || phase.ageing.enabled();
}
}  // namespace

void update_effective_viscosity(const Model& model, State& state, Workspace& workspace) {
  const auto& calibration = model.viscosity_calibration;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const std::size_t count = state.active_count;
  const Real inverse_volume = 1 / model.particle_volume;  // ρ0_j = m_j / V
  const bool any_shear_rate = model.any_shear_rate;
  const auto& fluid_lists = workspace.fluid_neighbors;
  const auto& boundary_lists = workspace.boundary_neighbors;
  const Real time = static_cast<Real>(state.time);
  auto wants_shear_rate = [&](std::size_t i) { return any_shear_rate && phase_needs_shear_rate(model.phases[fluid.phase[i]]); };
  // Particle i's viscosity, given the symmetric part of its fluid neighbours' velocity gradient
  // ∇v_i = Σ_j V_j (v_j − v_i) x_ijᵀ (dW/dr)/r, V_j f = (ρ0_j/ρ_j) × the pair gradient; returns its μ/ρ.
  auto finish_particle = [&](std::size_t i, const Mat3& fluid_gradient) {
    const FluidPhase& phase = model.phases[fluid.phase[i]];
    if (!wants_shear_rate(i)) {
      fluid.viscosity[i] = phase.rheology.viscosity;
      fluid.shear_rate[i] = 0;
    } else {
      Mat3 gradient = fluid_gradient;
      // Walls shear the material only where it sticks to them.
      if (phase.has_wall_friction()) {
        const Vec3 position_i = fluid.position[i];
        const Vec3 velocity_i = fluid.velocity[i];
        const std::size_t boundary_first = boundary_lists.first(i);
        for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
          const Index b = boundary_lists.indices[boundary_first + k];
          if (phase.wall_viscosity(fluid.viscosity[i], boundary.wall_kind[b]) <= 0) continue;  // slips there
          gradient += (calibration.boundary_gradient * workspace.boundary_pair_gradient[boundary_first + k] * (boundary.velocity[b] - velocity_i)) *
                      (position_i - boundary.position[b]).transpose();
        }
      }
      const Mat3 strain_rate = Real(0.5) * (gradient + gradient.transpose());
      const Real shear_rate = std::sqrt(2 * strain_rate.squaredNorm());
      const Real age = time - fluid.birth_time[i];
      fluid.shear_rate[i] = shear_rate;
      fluid.viscosity[i] = phase.rheology.effective_viscosity(
          shear_rate, phase.ageing.yield_stress(phase.rheology.yield_stress, age), phase.ageing.viscosity_scale(age));
    }
    return std::max(fluid.viscosity[i], phase.largest_wall_viscosity(fluid.viscosity[i])) / phase.density;
  };
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
  const bool use_avx2 = any_shear_rate && avx2::available();
  if (use_avx2) {  // padded velocities for the AVX2 sweep (the positions are the density pass's)
    pack_padded(fluid.velocity, workspace.solver_velocity, state.active_count, workspace, workspace.velocity_copy);
  }
#endif
  workspace.largest_kinematic_viscosity = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, count, 256), Real(0),
      [&](const tbb::blocked_range<std::size_t>& range, Real largest) {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
        if (use_avx2) {
          avx2::velocity_gradient_rows(range.begin(), range.end(), workspace.solver_position.data(), workspace.solver_velocity.data(),
                                       fluid.mass.data(), fluid.density.data(), fluid_lists.indices.data(), fluid_lists.counts.data(),
                                       fluid_lists.firsts.data(), workspace.fluid_pair_gradient.data(), calibration.fluid_gradient * inverse_volume,
                                       wants_shear_rate,
                                       [&](std::size_t i, const Mat3& gradient) { largest = std::max(largest, finish_particle(i, gradient)); });
          return largest;
        }
#endif
        for (std::size_t i = range.begin(); i != range.end(); ++i) {
          Mat3 gradient = Mat3::Zero();
          if (wants_shear_rate(i)) {
            const Vec3 position_i = fluid.position[i];
            const Vec3 velocity_i = fluid.velocity[i];
            const std::size_t fluid_first = fluid_lists.first(i);
            for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
              const Index j = fluid_lists.indices[fluid_first + k];
              const Real weight =
                  calibration.fluid_gradient * (fluid.mass[j] * inverse_volume / fluid.density[j]) * workspace.fluid_pair_gradient[fluid_first + k];
              gradient += (weight * (fluid.velocity[j] - velocity_i)) * (position_i - fluid.position[j]).transpose();
            }
          }
          largest = std::max(largest, finish_particle(i, gradient));
        }
        return largest;
      },
      [](Real a, Real b) { return std::max(a, b); });
}

}  // namespace m3dp::sph::stages
