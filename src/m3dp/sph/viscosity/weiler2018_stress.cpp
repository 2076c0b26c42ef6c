// The implicit viscosity's stress form (SolverSettings::stress_form_viscosity; see weiler2018.cpp for
// the pair form it shares the system with). The pair form's force Σ_j c_ij x_ij x_ijᵀ v_ij weighs each
// pair's relative velocity along the pair: on a cubic lattice with a support of four radii its normal
// stress along a lattice axis is 2.05 × the isotropic one (its fourth moments are cubic, and the
// calibration fits shear), so a thread drawn along an axis resisted twice as much as Trouton says.
// The stress form takes the velocity gradient first and then the divergence of the stress,
//   G_i = Σ_j (v_j − v_i) ⊗ V∇W_ij M_i,   τ_i = μ_i (G_i + G_iᵀ),   F_i = V Σ_j (τ_i M_iᵀ + τ_j M_jᵀ) V∇W_ij,
// with M_i = B_i⁻¹, B_i = Σ_j (x_j − x_i) ⊗ V∇W_ij, the renormalisation that makes the gradient exact
// for linear fields inside and at a free surface alike (Bonet & Lok 1999), regularised where B_i is
// nearly singular (a particle with few neighbours). F = −∂E/∂v
// of E = Σ_i V μ_i |G_i + G_iᵀ|²/4, so −Δt F adds a symmetric positive semi-definite part to the
// system and conjugate gradients still apply. A wall the material does not slip on (sticks_to_walls)
// is in the gradient at its own velocity, Σ_b (v_b − v_i) ⊗ V_b∇W_ib: the part in v_b goes to the
// right-hand side (the stress of the walls' motion alone), the one in v_i stays in the operator; other
// walls are air to the stress form (their friction is the pair form's wall term, which stays whole).
// Resting particles have no stress of their own (their velocity gradient is not taken).
// (Two-pass SPH viscosity: Watkins, Bhattal, Francis, Turner & Whitworth 1996, A&AS 119, 177; the
// symmetric form as Bonet & Lok 1999.)
#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/viscosity/weiler2018.hpp"

namespace m3dp::sph::stages::weiler2018 {

namespace {
/// Whether particle i's material does not slip on some walls (the stress form then sees those).
bool sticks_to_walls(const Model& model, const State& state, std::size_t i) {
  const FluidPhase& phase = model.phases[state.fluid.phase[i]];
  return phase.sticks_to_walls || phase.sticks_to_static_walls;
}

/// Whether the stress form sees wall particle b from particle i: a wall i sticks to, never a bore
/// (the bore has its own slip setting).
bool stress_form_sees(const Model& model, const State& state, std::size_t i, Index b) {
  const material::Wall wall = state.boundary.wall_kind[b];
  return wall != material::Wall::nozzle_bore && model.phases[state.fluid.phase[i]].sticks_to(wall);
}

/// P_i = μ_i (G + Gᵀ) M_iᵀ of particle i's gradient G (already renormalised).
Mat3 corrected_stress(const State& state, const Workspace& workspace, std::size_t i, const Mat3& gradient) {
  const Mat3& correction = workspace.viscosity_system.gradient_correction[i];
  return state.fluid.viscosity[i] * (gradient + gradient.transpose()) * correction.transpose();
}

/// Σ_j (P_i + P_j) V∇W_ij + P_i Σ_b V_b∇W_ib of the stresses in system.stress (P_j = 0 at resting j):
/// the stress form's force on i over V.
Vec3 stress_divergence(const State& state, const Workspace& workspace, std::size_t i) {
  const auto& system = workspace.viscosity_system;
  const auto& lists = workspace.fluid_neighbors;
  const Vec4* position = workspace.solver_position.data();
  const std::size_t count = state.active_count, first = lists.first(i);
  const Mat3 stress_i = system.stress[i];
  Vec3 force = Vec3::Zero();
  for (Index k = 0; k < lists.counts[i]; ++k) {
    const Index j = lists.indices[first + k];
    const Vec3 along = workspace.fluid_pair_gradient[first + k] * (position[i] - position[j]).head<3>();
    force += (std::size_t(j) < count ? Mat3(stress_i + system.stress[j]) : stress_i) * along;
  }
  return force + stress_i * system.no_slip_wall_sum[i];
}
}  // namespace

void prepare_gradient_correction(const Model& model, const State& state, Workspace& workspace) {
  auto& system = workspace.viscosity_system;
  if (system.stress_product.empty()) return;
  const std::size_t count = state.active_count;
  const auto& lists = workspace.fluid_neighbors;
  const Vec4* position = workspace.solver_position.data();
  const Real* pair_gradient = workspace.fluid_pair_gradient.data();
  const Real calibration = model.viscosity_calibration.fluid_gradient;
  system.gradient_correction.resize(state.fluid.size());
  system.no_slip_wall_sum.resize(state.fluid.size());
  const auto& walls = workspace.boundary_neighbors;
  parallel_for_each_index(count, [&](std::size_t i) {
    Mat3 moment = Mat3::Zero();  // B_i
    const std::size_t first = lists.first(i);
    for (Index k = 0; k < lists.counts[i]; ++k) {
      const Index j = lists.indices[first + k];
      const Vec3 offset = (position[i] - position[j]).head<3>();
      moment -= offset * (pair_gradient[first + k] * offset).transpose();
    }
    Vec3 wall_sum = Vec3::Zero();
    if (sticks_to_walls(model, state, i)) {
      const std::size_t wall_first = walls.first(i);
      for (Index k = 0; k < walls.counts[i]; ++k) {
        const Index b = walls.indices[wall_first + k];
        if (!stress_form_sees(model, state, i, b)) continue;
        const Vec3 offset = state.fluid.position[i] - state.boundary.position[b];
        const Vec3 along = workspace.boundary_pair_gradient[wall_first + k] * offset;
        moment -= offset * along.transpose();
        wall_sum += along;
      }
    }
    system.no_slip_wall_sum[i] = wall_sum;
    // c B_i is the identity on the rest lattice, about ½ I at a flat free surface, nearly singular for a
    // particle with few neighbours: its inverse regularised, (c B_i + δ I)⁻¹ (1 + δ) c, so that no
    // direction is amplified more than (1 + δ)/δ (a flat surface's gradient then reads 0.92 of its own).
    constexpr Real kRegularisation = Real(0.1);
    const Mat3 scaled = calibration * moment + kRegularisation * Mat3::Identity();
    system.gradient_correction[i] = ((1 + kRegularisation) * calibration) * scaled.inverse();
  }, 1024);
}

void prepare_stress_product(const Model& model, const State& state, Workspace& workspace) {
  auto& system = workspace.viscosity_system;
  if (system.stress_product.empty()) return;
  const std::size_t count = state.active_count;
  const auto& lists = workspace.fluid_neighbors;
  const Vec4* position = workspace.solver_position.data();
  const Vec4* operand = system.padded_operand.data();
  const Real* pair_gradient = workspace.fluid_pair_gradient.data();
  parallel_for_each_index(count, [&](std::size_t i) {
    Mat3 gradient = Mat3::Zero();
    const std::size_t first = lists.first(i);
    for (Index k = 0; k < lists.counts[i]; ++k) {
      const Index j = lists.indices[first + k];
      const Vec3 along = pair_gradient[first + k] * (position[i] - position[j]).head<3>();  // V ∇W_ij
      gradient += (operand[j] - operand[i]).head<3>() * along.transpose();
    }
    gradient -= operand[i].head<3>() * system.no_slip_wall_sum[i].transpose();  // the walls' part in v_i
    system.stress[i] = corrected_stress(state, workspace, i, gradient * system.gradient_correction[i]);
  }, 512);
  const Real scale = -state.time_step * model.settings.stress_form_viscosity * model.particle_volume;
  parallel_for_each_index(count, [&](std::size_t i) { system.stress_product[i] = scale * stress_divergence(state, workspace, i); }, 512);
}

void add_stress_form_walls_to_rhs(const Model& model, const State& state, Workspace& workspace) {
  auto& system = workspace.viscosity_system;
  if (system.stress_product.empty()) return;
  const std::size_t count = state.active_count;
  const auto& walls = workspace.boundary_neighbors;
  // The stress of the walls' velocities alone, Σ_b v_b ⊗ V_b∇W_ib M_i, into system.stress; whether any is not zero.
  const double moving = deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
    Mat3 gradient = Mat3::Zero();
    if (system.no_slip_wall_sum[i].squaredNorm() > 0) {
      const std::size_t wall_first = walls.first(i);
      for (Index k = 0; k < walls.counts[i]; ++k) {
        const Index b = walls.indices[wall_first + k];
        if (!stress_form_sees(model, state, i, b)) continue;
        const Vec3 along = workspace.boundary_pair_gradient[wall_first + k] * (state.fluid.position[i] - state.boundary.position[b]);
        gradient += state.boundary.velocity[b] * along.transpose();
      }
    }
    system.stress[i] = corrected_stress(state, workspace, i, gradient * system.gradient_correction[i]);
    sums[0] += gradient.isZero(0) ? 0 : 1;
  })[0];
  if (moving == 0) return;
  // b_i += Δt θ V (Σ_j (P_i + P_j) V∇W_ij + P_i Σ_b V_b∇W_ib) (minus the operator's sign).
  const Real scale = state.time_step * model.settings.stress_form_viscosity * model.particle_volume;
  parallel_for_each_index(count, [&](std::size_t i) { system.rhs[i] += scale * stress_divergence(state, workspace, i); }, 512);
}

}  // namespace m3dp::sph::stages::weiler2018
