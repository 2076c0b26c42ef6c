// Implicit viscosity after M. Weiler, D. Koschier, M. Brand, J. Bender, "A Physically Consistent
// Implicit Viscosity Solver for SPH Fluids", Computer Graphics Forum 37(2), 145–155, 2018.
//
// The viscous force on particle i is the Morris-type Laplacian in its momentum-conserving form,
// with each particle's own dynamic viscosity μ (Pa·s, from the rheology):
//   F_i = Σ_j 2(d+2) μ_ij V_i V_j (v_ij·x_ij) / (|x_ij|² + 0.01 h²) ∇W_ij,   μ_ij = 2μ_iμ_j/(μ_i + μ_j),
// plus the same sum over boundary particles with the phase's boundary viscosity and the wall's
// velocity. Backward Euler, m_i v_i' = m_i v_i* + Δt F_i(v'), is the linear system A v' = b with
//   (A v)_i = m_i v_i + Σ_j c_ij x_ij x_ijᵀ (v_i − v_j) + Σ_b c_ib x_ib x_ibᵀ v_i
//   b_i     = m_i v_i* + Σ_b c_ib x_ib x_ibᵀ v_b,
// c = −Δt · 2(d+2) μ V_i V_j (dW/dr)/r / (r² + 0.01h²) ≥ 0, times the calibration that makes the sum
// the Laplacian on the rest lattice (ViscosityCalibration: the sum alone is 30 % short at our kernel sizes). A is symmetric positive definite (c_ij =
// c_ji, and the sum is a dissipation), so it is solved matrix-free by conjugate gradients with a
// 3×3 block-Jacobi preconditioner, starting from v*. Stable at any viscosity and time step.
//
// The parts: the system (weiler2018_system.cpp), the start (weiler2018_start.cpp), the conjugate
// gradients (weiler2018_cg.cpp, with the coarse level of coarse_level.hpp) and the walls' reaction
// (weiler2018_wall_reaction.cpp). The shear rate and effective viscosity are effective_viscosity.cpp's.
#include <algorithm>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/viscosity/weiler2018.hpp"

namespace m3dp::sph::stages {

// Solved after the pressure solve, right before the velocities move the particles. In the usual DFSPH
// order (viscosity with the other non-pressure forces) every step's pressure correction would move a
// stiff material as if it were water, by about g Δt² per step: an unyielded column on a floor then
// creeps at g Δt and never stands. The next step's divergence solve corrects what the viscous
// smoothing changes in the divergence.
void solve_implicit_viscosity(const Model& model, State& state, Workspace& workspace) {
  if (model.settings.viscosity_solver != ViscositySolver::implicit_weiler2018) return;
  const auto& settings = model.settings;
  auto& fluid = state.fluid;
  const std::size_t count = state.active_count;
  if (count == 0) return;
  const bool any_viscosity =
      std::any_of(model.phases.begin(), model.phases.end(), [](const FluidPhase& phase) {
        return phase.rheology.model != material::RheologyModel::newtonian || phase.rheology.viscosity > 0 ||
               phase.has_wall_friction() || phase.elasticity.enabled;
      });
  if (!any_viscosity) return;
  // Where the largest viscous change any phase can have is below the solve's tolerance, CG would take
  // v* as it is: ‖A v* − b‖ ≤ 2 Σ_j |c_ij| r² |v| ≈ 2 (Δt μ/ρ0) coupling ‖b‖. Nothing to solve then
  // (water at centimetre spacing). The factor 1.5 covers neighbourhoods denser than the rest lattice.
  const bool negligible = std::all_of(model.phases.begin(), model.phases.end(), [&](const FluidPhase& phase) {
    if (phase.elasticity.enabled || phase.ageing.enabled()) return false;
    const Real mu = phase.rheology.model == material::RheologyModel::newtonian ? phase.rheology.viscosity
                                                                                 : phase.rheology.max_viscosity;
    const Real largest = std::max(mu, phase.has_wall_friction() ? phase.largest_wall_viscosity(mu) : Real(0));
    return 2 * Real(1.5) * state.time_step * largest / phase.density * model.viscosity_calibration.coupling < settings.viscosity_tolerance;
  });
  if (negligible) {
    parallel_for_each_index(count, [&](std::size_t i) {
      fluid.viscous_change[i] = Vec3::Zero();
      fluid.viscous_velocity[i] = fluid.velocity[i];
    }, 4096);
    return;
  }

  state.last_step.viscosity_solved = true;
  weiler2018::build_system(model, state, workspace);
  const weiler2018::StartResidual start = weiler2018::start_solve(model, state, workspace);
  const int iterations = weiler2018::run_conjugate_gradients(model, state, workspace, start);
  const auto& system = workspace.viscosity_system;
  parallel_for_each_index(count, [&](std::size_t i) {
    fluid.viscous_change[i] = fluid.velocity[i] - system.start_velocity[i];
    fluid.viscous_velocity[i] = fluid.velocity[i];
  }, 1024);
  weiler2018::add_wall_reaction(model, state, workspace);
  state.last_step.viscosity_iterations = iterations;
}

}  // namespace m3dp::sph::stages
