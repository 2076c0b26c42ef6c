// The implicit viscosity's preconditioned conjugate gradients (Weiler et al. 2018; see weiler2018.cpp):
// block Jacobi, with the coarse level of viscosity/coarse_level.hpp for stiff materials.
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/viscosity/coarse_level.hpp"
#include "m3dp/sph/viscosity/weiler2018.hpp"

namespace m3dp::sph::stages::weiler2018 {

int run_conjugate_gradients(const Model& model, State& state, Workspace& workspace, const StartResidual& start) {
  const auto& settings = model.settings;
  auto& fluid = state.fluid;
  const std::size_t count = state.active_count;
  auto& system = workspace.viscosity_system;
  const ViscousOperator product(workspace);
  auto& velocity = fluid.velocity;
  double residual_norm = start.residual_norm;
  // The coarse level (see CoarseViscosityLevel), from A's blocks: each particle's own block and the pairs' c r rᵀ.
  CoarseViscosityLevel& coarse = system.coarse_level.get();
  const bool two_level = state.previous_viscosity_iterations > kCoarseLevelFromIterations &&
                         coarse.build(state, workspace, count, kAggregateSpacings * model.particle_diameter);
  // Particles a pump drives keep their velocity: their residual and direction stay zero (along an
  // exit's axis only, for those it holds: a conjugate gradients projected on what is free).
  const std::uint8_t* driven = workspace.any_piston_driven ? workspace.piston_driven.data() : nullptr;
  // z = D⁻¹ r (+ the coarse correction) into system.preconditioned; returns r·z.
  auto precondition = [&]() {
    if (two_level) coarse.solve(workspace, system.residual);
    return deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
      Vec3 z = system.inverse_diagonal[i] * system.residual[i];
      if (two_level) z += CoarseViscosityLevel::correction(workspace, i);
      if (driven != nullptr && driven[i]) z = workspace.free_part(i, z);
      system.preconditioned[i] = z;
      sums[0] += double(system.residual[i].dot(z));
    })[0];
  };

  // Each iteration is four sweeps: A p with p·Ap, the update with r·r, the preconditioner with r·z,
  // and the new direction.
  double residual_dot = precondition();
  parallel_for_each_index(count, [&](std::size_t i) { system.padded_operand[i] = padded(system.preconditioned[i]); }, 1024);
  // Relative to the momentum ‖b‖, not to the first residual: the first residual is mostly the rough,
  // particle-scale part of the change, which CG removes first; the smooth part (a stiff paste spreading
  // like water after the pressure solve) has small residuals but is what moves the material. Stopping
  // at 10⁻³ of the first residual lets an unyielded column collapse.
  const double tolerance = settings.viscosity_tolerance * start.rhs_norm;
  int iterations = 0;
  while (residual_norm > tolerance && iterations < settings.max_viscosity_iterations) {
    prepare_stress_product(model, state, workspace);
    const double curvature = product.row_sums<1>(count, [&](std::size_t i, const Vec3& row, std::array<double, 1>& sums) {
      system.product[i] = row;
      sums[0] += double(system.padded_operand[i].head<3>().dot(row));
    })[0];
    if (!(curvature > 0)) break;
    const Real step = static_cast<Real>(residual_dot / curvature);
    const auto next = deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
      velocity[i] += step * system.padded_operand[i].head<3>();
      if (driven == nullptr || !driven[i])
        system.residual[i] -= step * system.product[i];
      else
        system.residual[i] -= step * workspace.free_part(i, system.product[i]);
      sums[0] += double(system.residual[i].squaredNorm());
    });
    residual_norm = std::sqrt(next[0]);
    const double next_residual_dot = precondition();
    const Real beta = static_cast<Real>(next_residual_dot / residual_dot);
    residual_dot = next_residual_dot;
    parallel_for_each_index(count, [&](std::size_t i) {
      system.padded_operand[i] = padded(system.preconditioned[i]) + beta * system.padded_operand[i];
    }, 1024);
    ++iterations;
  }

  // Without the coarse level, the count decides whether the next solve builds one; with it, a solve that
  // still needs many iterations keeps it.
  state.previous_viscosity_iterations = two_level ? std::max(iterations, kCoarseLevelFromIterations + 1) : iterations;
  return iterations;
}

}  // namespace m3dp::sph::stages::weiler2018
