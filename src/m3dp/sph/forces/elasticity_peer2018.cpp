// Elastic stress after Peer, Gissler, Band, Teschner, "An Implicit SPH Formulation for Incompressible
// Linearly Elastic Solids", CGF 2018 (see material/elasticity/peer2018.hpp), over each particle's
// neighbours of the same elastic material, with reference positions X and volumes V = m/ρ0:
//   L_i = (Σ_j V_j ∇W(X_ij) ⊗ X_ji)⁻¹                    kernel-gradient correction (first-order exact)
//   F_i = Σ_j V_j x_ji ⊗ (L_i ∇W(X_ij))                  deformation gradient (I in the reference shape)
//   R_i = rotation of F_i (polar decomposition),  ε_i = sym(R_iᵀ F_i) − I   (corotated: no stress from
//         rotation)
//   σ_i = 2G dev(ε_i) + K tr(ε_i) I,  K = 2G(1 + ν)/(3(1 − 2ν))
//         Inside the material the pressure solve keeps the volume anyway. At a free surface it cannot
//         (a surface particle's SPH density is low, so the push-only pressure lets it be squeezed), and
//         without K a narrow column sagged 20–35 % more than linear elasticity says.
//   f_i = Σ_j V_i V_j (R_i σ_i L_i + R_j σ_j L_j) ∇W(X_ij)   (antisymmetric in i, j: momentum kept)
// Peer et al. solve the stress implicitly in the velocity. Our velocity solve is already implicit for
// viscosity (Weiler et al. 2018), and the stiffness of a backward-Euler step of shear modulus G is, to
// first order, the Laplacian a viscosity G·Δt gives: the solver adds G·Δt to each elastic particle's
// viscosity in that solve (Solver::step), and this stage adds the stress of the current shape. Shear
// waves then set no time-step limit.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

namespace {

/// The rotation of F (polar decomposition F = R S by SVD; a reflection is turned into a rotation).
Mat3 rotation_of(const Mat3& deformation) {
  const Eigen::JacobiSVD<Mat3> svd(deformation, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 u = svd.matrixU();
  const Mat3& v = svd.matrixV();
  if ((u * v.transpose()).determinant() < 0) u.col(2) = -u.col(2);
  return u * v.transpose();
}

}  // namespace

void add_elastic_forces(const Model& model, State& state, Workspace& workspace) {
  const bool any = std::any_of(model.phases.begin(), model.phases.end(),
                               [](const FluidPhase& phase) { return phase.elasticity.enabled; });
  if (!any) return;
  auto& fluid = state.fluid;
  const std::size_t count = state.active_count;
  const Real volume = model.particle_volume;  // m/ρ0 of every particle
  const auto& lists = workspace.fluid_neighbors;
  const Real support_radius = model.support_radius;
  auto& stress = workspace.elastic_stress;  // R σ L per particle
  stress.resize(fluid.size());
  std::fill(stress.begin() + static_cast<std::ptrdiff_t>(count), stress.end(), Mat3::Zero());
  auto same_material = [&](std::size_t i, Index j) { return fluid.phase[j] == fluid.phase[i]; };
  with_kernel(model.settings.kernel, support_radius, [&](const auto& kernel) {
    parallel_for_each_index(count, [&](std::size_t i) {
      const FluidPhase& phase = model.phases[fluid.phase[i]];
      if (!phase.elasticity.enabled) {
        stress[i].setZero();
        return;
      }
      const Vec3 reference_i = fluid.reference_position[i];
      const Vec3 position_i = fluid.position[i];
      Mat3 moment = Mat3::Zero(), stretch = Mat3::Zero();
      const std::size_t first = lists.first(i);
      for (Index k = 0; k < lists.counts[i]; ++k) {
        const Index j = lists.indices[first + k];
        if (!same_material(i, j)) continue;
        const Vec3 reference_offset = reference_i - fluid.reference_position[j];  // X_ij
        const Vec3 gradient = volume * kernel.gradW(reference_offset);
        moment -= gradient * reference_offset.transpose();                           // ∇W ⊗ X_ji
        stretch -= (position_i - fluid.position[j]) * gradient.transpose();          // x_ji ⊗ ∇W
      }
      // Too few neighbours for a deformation gradient (a lone particle, a thread): no stress.
      if (std::abs(moment.determinant()) < Real(1e-6)) {
        stress[i].setZero();
        return;
      }
      const Mat3 correction = moment.inverse();
      const Mat3 deformation = stretch * correction.transpose();  // Σ V x_ji ⊗ (L ∇W)
      const Mat3 rotation = rotation_of(deformation);
      const Mat3 unrotated = rotation.transpose() * deformation;
      Mat3 strain = Real(0.5) * (unrotated + unrotated.transpose()) - Mat3::Identity();
      const Real volumetric = strain.trace();
      strain -= (volumetric / 3) * Mat3::Identity();
      const Real shear_modulus = phase.elasticity.shear_modulus;
      stress[i] = rotation * (2 * shear_modulus * strain + phase.elasticity.bulk_modulus() * volumetric * Mat3::Identity()) * correction;
    }, 256);
    parallel_for_each_index(count, [&](std::size_t i) {
      if (!model.phases[fluid.phase[i]].elasticity.enabled) return;
      const Vec3 reference_i = fluid.reference_position[i];
            Vec3 force = Vec3::Zero();
      const std::size_t first = lists.first(i);
      for (Index k = 0; k < lists.counts[i]; ++k) {
        const Index j = lists.indices[first + k];
        if (!same_material(i, j)) continue;
        const Vec3 gradient = kernel.gradW(Vec3(reference_i - fluid.reference_position[j]));
        force += (volume * volume) * ((stress[i] + stress[j]) * gradient);
      }
      fluid.acceleration[i] += force / fluid.mass[i];
    }, 256);
  });
}

void add_elastic_stiffness(const Model& model, State& state, Workspace& /*workspace*/) {
  if (!model.any_elastic) return;
  // Elastic materials: their shear stiffness enters the implicit velocity solve as a viscosity G·Δt
  // (see the top of this file); the stress of the current shape was added with the other forces.
  const Real time_step = state.time_step;
  parallel_for_each_index(state.active_count, [&](std::size_t i) {
    const auto& elasticity = model.phases[state.fluid.phase[i]].elasticity;
    if (elasticity.enabled) state.fluid.viscosity[i] += elasticity.shear_modulus * time_step;
  }, 1024);
}

void relax_reference_shape(const Model& model, State& state, Workspace& /*workspace*/) {
  if (!model.any_elastic) return;
  const Real time_step = state.time_step;
  auto& fluid = state.fluid;
  parallel_for_each_index(state.active_count, [&](std::size_t i) {
    const auto& elasticity = model.phases[fluid.phase[i]].elasticity;
    if (!elasticity.enabled || elasticity.relaxation_time <= 0) return;
    // The strain decays as e^(−t/τ) where the shape is held.
    const Real share = 1 - std::exp(-time_step / elasticity.relaxation_time);
    fluid.reference_position[i] += share * (fluid.position[i] - fluid.reference_position[i]);
  }, 1024);
}

}  // namespace m3dp::sph::stages

