// Tension in viscous material: a two-sided pressure projection after the implicit viscosity, with its
// pressure kept from step to step.
//   S. J. Cummins, M. Rudman: "An SPH Projection Method", J. Comput. Phys. 152(2), 584–607, 1999
//   (the velocity's divergence as the source, the pressure unclamped, the air beyond a free surface at
//   p = 0);
//   the pressure carried to the next step and applied before its solves, an incremental pressure
//   correction (van Kan 1986) that is, for a stiff material, one outer round of the pressure–viscosity
//   coupling a step (the adapted SIMPLE of Liu, He, Wang & Wu, IEEE TVCG 28(9), 3168, 2022).
//
// The DFSPH solves (dfsph_bender2017.cpp) only push: a stretched thread's particles were never pulled
// together, so it dilated and cracked instead of thinning. Here, after the viscosity solve, the
// velocities' divergence (Σ_j V (v_i − v_j)·∇W_ij over fluid neighbours) is taken out with both signs,
// by the pressure p = m κ solving
//   B M⁻¹ Bᵀ p = B v / Δt,   (Bᵀ p)_i = Σ_j V (p_i + p_j) ∇W_ij,   v ← v − Δt M⁻¹ Bᵀ p,
// the same symmetric gradient as the DFSPH update. Its missing neighbours at a free surface count as air
// at p = 0 (the self term p_i Σ_j V ∇W_ij), so the surface is neither clamped nor given a Dirichlet
// value: with the symmetric viscous sum this leaves the traction σ·n = 0 there, and a stretched thread's
// pressure is −μ ε̇ to its surface (Trouton's 3μ). The source is the divergence, not the density: a
// surface's density deficit is no reason to pull, and material at rest is not pulled at all. Walls
// take no part (they are air for this projection): material never sticks to a wall by suction, and
// the DFSPH solves keep it out of walls. Resting particles are neighbours at their fixed velocity and
// κ = 0. The system is symmetric positive definite, solved by conjugate gradients with Jacobi's
// diagonal (Jacobi alone stalls on the long wavelengths of a thread).
//
// The pull found (κ < 0; compression is the density solve's) is added to FluidParticles::kappa_tension
// and applied again in the next step right before the viscosity solve (apply_tension_pressure, after
// the DFSPH density solve, which would push a kept pull back): the viscosity solve then balances it,
// and the next projection only corrects the change. The dilation of the material's interior is taken
// back by moving positions, with the same conjugate gradients.
#include <algorithm>
#include <array>
#include <cmath>

#include "m3dp/core/deterministic_sums.hpp"
#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/simd/neighbor_sums_avx2.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

namespace {

/// The projection stops when its residual divergence is this fraction of the one it started with…
constexpr double kRelativeTolerance = 1e-3;
/// …or when the mean relative density change a step it leaves is this fraction of the divergence
/// solve's tolerance: slow viscous flows change their density by less than that tolerance in a step,
/// and their divergence would otherwise stay, step after step.
constexpr double kAbsoluteToleranceFraction = 1e-2;
/// A neighbourhood this lopsided (|Σ_j V ∇W_ij| over a flat face's) is at a free surface.
constexpr Real kSurfaceLopsidedness = Real(0.25);

/// Σ_j V (a_i − a_j)·∇W_ij over i's fluid neighbours: the rate of compression of field a at i (1/s for
/// a velocity).
Real compression_rate(const Workspace& workspace, const Vec4* field, std::size_t i) {
  const auto& lists = workspace.fluid_neighbors;
  const std::size_t first = lists.first(i);
  const Index* neighbor = lists.indices.data() + first;
  const Real* pair_gradient = workspace.fluid_pair_gradient.data() + first;
  const Vec4* position = workspace.solver_position.data();
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
  if (avx512::available())
    return avx512::difference_products(field, position, neighbor, pair_gradient, lists.counts[i], field[i], position[i]).sum();
  if (avx2::available())
    return avx2::difference_products(field, position, neighbor, pair_gradient, lists.counts[i], field[i], position[i]).sum();
#endif
  Vec4 sum = Vec4::Zero();
  for (Index k = 0; k < lists.counts[i]; ++k) {
    const Index j = neighbor[k];
    sum += pair_gradient[k] * (field[i] - field[j]).cwiseProduct(position[i] - position[j]);
  }
  return sum.sum();
}

/// (M⁻¹ Bᵀ p)_i = (1/m_i) Σ_j V (p_i + p_j) ∇W_ij over i's fluid neighbours (p_j = 0 for resting j).
Vec4 pressure_velocity_change(const Workspace& workspace, const Real* mass, const Real* pressure, std::size_t i, std::size_t active) {
  const auto& lists = workspace.fluid_neighbors;
  const std::size_t first = lists.first(i);
  const Index* neighbor = lists.indices.data() + first;
  const Real* pair_gradient = workspace.fluid_pair_gradient.data() + first;
  const Vec4* position = workspace.solver_position.data();
  const Vec4 position_i = position[i];
  const Real pressure_i = pressure[i];
  Vec4 sum = Vec4::Zero(), odd_sum = Vec4::Zero();
  const Index count = lists.counts[i];
  auto pressure_of = [&](Index j) { return std::size_t(j) < active ? pressure[j] : Real(0); };
  Index k = 0;
  for (; k + 1 < count; k += 2) {
    const Index j0 = neighbor[k], j1 = neighbor[k + 1];
    sum += ((pressure_i + pressure_of(j0)) * pair_gradient[k]) * (position_i - position[j0]);
    odd_sum += ((pressure_i + pressure_of(j1)) * pair_gradient[k + 1]) * (position_i - position[j1]);
  }
  if (k < count) sum += ((pressure_i + pressure_of(neighbor[k])) * pair_gradient[k]) * (position_i - position[neighbor[k]]);
  return (sum + odd_sum) / mass[i];
}

/// |Σ_j V ∇W_ij| (1/m) of a particle on a flat face of the rest lattice (its half-space of neighbours):
/// how lopsided a free surface makes a neighbourhood.
Real flat_surface_gradient_sum(const Model& model) {
  return with_kernel(model.settings.kernel, model.support_radius, [&](const auto& kernel) {
    const Real spacing = model.particle_diameter;
    const int reach = static_cast<int>(std::ceil(model.support_radius / spacing));
    Real sum = 0;  // the normal component; the others cancel
    for (int a = -reach; a <= reach; ++a)
      for (int b = -reach; b <= reach; ++b)
        for (int c = 1; c <= reach; ++c) {
          const Vec3 r = spacing * Vec3(Real(a), Real(b), Real(c));
          sum += model.particle_volume * kernel.gradient_factor(r.norm()) * r.z();
        }
    return std::abs(sum);
  });
}

/// The kept pressure's velocity change at i with tensile instability control (after Sun et al. 2017's
/// δ+-SPH): the symmetric form (p_i + p_j) is the difference form (p_j − p_i) plus 2 p_i Σ_j V ∇W_ij.
/// That last term is the traction −p n of the air at a free surface, but inside the material it is only
/// the lattice's disorder, and under tension it draws particles into pairs. It is weighted by how
/// lopsided the neighbourhood is: fully from half a flat face's gradient sum, not at all below a quarter.
Vec4 kept_pressure_velocity_change(const Workspace& workspace, const Real* mass, const Real* pressure, std::size_t i,
                                   std::size_t active, const std::uint8_t* driven, Real flat_surface_sum) {
  const auto& lists = workspace.fluid_neighbors;
  const std::size_t first = lists.first(i);
  const Index* neighbor = lists.indices.data() + first;
  const Real* pair_gradient = workspace.fluid_pair_gradient.data() + first;
  const Vec4* position = workspace.solver_position.data();
  const Vec4 position_i = position[i];
  const Real pressure_i = pressure[i];
  Vec4 difference = Vec4::Zero(), gradient_sum = Vec4::Zero(), fixed_sum = Vec4::Zero();
  for (Index k = 0; k < lists.counts[i]; ++k) {
    const Index j = neighbor[k];
    const Vec4 gradient = pair_gradient[k] * (position_i - position[j]);
    if (std::size_t(j) >= active || (driven != nullptr && driven[j])) {
      fixed_sum += gradient;
      continue;
    }
    gradient_sum += gradient;
    difference += (pressure[j] - pressure_i) * gradient;
  }
  const Real lopsided = (gradient_sum + fixed_sum).norm() / flat_surface_sum;
  const Real surface = std::clamp((lopsided - kSurfaceLopsidedness) / kSurfaceLopsidedness, Real(0), Real(1));
  // A neighbour of fixed velocity (resting, or driven by a pump) takes p_i ∇W_ij, as in the solve's
  // operator (its own pressure is not an unknown): i is drawn towards it. The difference form there,
  // (0 − p_i) ∇W_ij, pushed i away from it, and a slug in a bore fell off its piston zone.
  return (difference + pressure_i * fixed_sum + (2 * surface * pressure_i) * gradient_sum) / mass[i];
}

/// Conjugate gradients on B M⁻¹ Bᵀ p = r from the right-hand side in system.residual (1/s²) and the
/// inverse diagonal, p from 0 into system.solution; each step's velocity change, times Δt, subtracted
/// from `change` (padded, active particles; none at particles a pump drives). Stops at the relative
/// tolerance, or where the mean |r| Δt² is under `absolute` (a relative density change a step). Returns the iterations and the last mean.
struct ProjectionResult {
  int iterations = 0;
  double mean_change = 0;  // mean |r| Δt² at the end
};
ProjectionResult solve_projection(const Model& model, const State& state, Workspace& workspace, Vec4* change, double absolute,
                                  bool any_driven) {
  const std::size_t count = state.active_count;
  auto& system = workspace.tension_system;
  const Real time_step = state.time_step;
  const Real* mass = state.fluid.mass.data();
  const auto start = deterministic_sums<2>(count, [&](std::size_t i, std::array<double, 2>& sums) {
    system.solution[i] = 0;
    sums[0] += double(system.residual[i]) * double(system.residual[i]);
    sums[1] += std::abs(double(system.residual[i]));
  });
  const double squared_step = double(time_step) * double(time_step);
  const double rhs_norm = std::sqrt(start[0]);
  double residual_norm = rhs_norm, mean_change = start[1] / double(count) * squared_step;
  auto precondition = [&]() {
    return deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
      system.preconditioned[i] = system.inverse_diagonal[i] * system.residual[i];
      sums[0] += double(system.residual[i]) * double(system.preconditioned[i]);
    })[0];
  };
  double residual_dot = precondition();
  parallel_for_each_index(count, [&](std::size_t i) { system.direction[i] = system.preconditioned[i]; }, 4096);
  ProjectionResult result;
  while (residual_norm > kRelativeTolerance * rhs_norm && mean_change > absolute && result.iterations < model.settings.max_tension_iterations) {
    // q = B M⁻¹ Bᵀ d: the velocity change of the direction, then its compression rate.
    parallel_for_each_index(count, [&](std::size_t i) {
      system.velocity_change[i] = any_driven && workspace.piston_driven[i] ? Vec4::Zero()
                                                                  : pressure_velocity_change(workspace, mass, system.direction.data(), i, count);
    });
    const double curvature = deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
      system.product[i] = compression_rate(workspace, system.velocity_change.data(), i);
      sums[0] += double(system.direction[i]) * double(system.product[i]);
    })[0];
    if (!(curvature > 0)) break;
    const Real step = static_cast<Real>(residual_dot / curvature);
    const auto next = deterministic_sums<2>(count, [&](std::size_t i, std::array<double, 2>& sums) {
      system.solution[i] += step * system.direction[i];
      change[i] -= (time_step * step) * system.velocity_change[i];
      // A particle out of the projection (inverse diagonal 0: nearly alone) keeps p = 0 and no residual.
      system.residual[i] = system.inverse_diagonal[i] != 0 ? system.residual[i] - step * system.product[i] : Real(0);
      sums[0] += double(system.residual[i]) * double(system.residual[i]);
      sums[1] += std::abs(double(system.residual[i]));
    });
    residual_norm = std::sqrt(next[0]);
    mean_change = next[1] / double(count) * squared_step;
    const double next_residual_dot = precondition();
    const Real beta = static_cast<Real>(next_residual_dot / residual_dot);
    residual_dot = next_residual_dot;
    parallel_for_each_index(count, [&](std::size_t i) { system.direction[i] = system.preconditioned[i] + beta * system.direction[i]; }, 4096);
    ++result.iterations;
  }
  result.mean_change = mean_change;
  return result;
}

}  // namespace

void apply_tension_pressure(const Model& model, State& state, Workspace& workspace) {
  const std::size_t count = state.active_count;
  if (!model.settings.tension || count == 0) return;
  auto& fluid = state.fluid;
  const bool any = deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
                     sums[0] += fluid.kappa_tension[i] != 0 ? 1 : 0;
                   })[0] > 0;
  if (!any) return;
  auto& system = workspace.tension_system;
  system.solution.resize(fluid.size());
  parallel_for_each_index(count, [&](std::size_t i) { system.solution[i] = fluid.mass[i] * fluid.kappa_tension[i]; }, 4096);
  system.velocity_change.resize(fluid.size());
  const Real time_step = state.time_step;
  const Real flat_surface_sum = flat_surface_gradient_sum(model);
  const std::uint8_t* driven = workspace.any_piston_driven ? workspace.piston_driven.data() : nullptr;
  parallel_for_each_index(count, [&](std::size_t i) {
    system.velocity_change[i] = kept_pressure_velocity_change(workspace, fluid.mass.data(), system.solution.data(), i, count, driven, flat_surface_sum);
  });
  parallel_for_each_index(count, [&](std::size_t i) {
    if (driven == nullptr || !driven[i]) fluid.velocity[i] -= time_step * system.velocity_change[i].head<3>();
  }, 4096);
}

void project_tension(const Model& model, State& state, Workspace& workspace) {
  const std::size_t count = state.active_count;
  if (!model.settings.tension || count == 0 || !state.last_step.viscosity_solved) return;
  auto& fluid = state.fluid;
  const std::size_t size = fluid.size();
  auto& system = workspace.tension_system;
  for (auto* vector : {&system.residual, &system.solution, &system.direction, &system.preconditioned, &system.product, &system.inverse_diagonal})
    vector->resize(size);
  system.velocity_change.resize(size);
  // The velocity change of a direction is zero at the resting particles (their velocities are fixed)
  // and at those a pump drives (stages::hold_pumps): the pump sets their velocity after the solves,
  // so a pull that counted on moving them would not hold the material below them. They are material
  // of fixed velocity, as the resting particles are: no unknown there, their neighbours drawn to them.
  std::fill(system.velocity_change.begin() + static_cast<std::ptrdiff_t>(count), system.velocity_change.end(), Vec4::Zero());
  const bool any_driven = workspace.any_piston_driven;
  auto& velocity = workspace.solver_velocity;
  pack_padded(fluid.velocity, velocity, count, workspace, workspace.velocity_copy);
  const Real time_step = state.time_step;
  const Real* mass = fluid.mass.data();
  const auto& lists = workspace.fluid_neighbors;
  const Vec4* position = workspace.solver_position.data();

  // Where the material is whole around a particle: neither it nor any of its neighbours has a lopsided
  // neighbourhood (a free surface, a crack's face or a wall, which is air here). There the density
  // is measured whole, and a deficit is dilation to take back; elsewhere a deficit is only the kernel
  // missing its neighbours, no reason to pull.
  const Real flat_surface_sum = flat_surface_gradient_sum(model);
  system.at_surface.resize(size);
  std::fill(system.at_surface.begin() + static_cast<std::ptrdiff_t>(count), system.at_surface.end(), std::uint8_t(0));
  // The diagonal of B M⁻¹ Bᵀ, (1/m_i)|Σ_j V∇W_ij|² + Σ_j (1/m_j)|V∇W_ij|² over active j, with the same sums.
  // A particle with a quarter of a full neighbourhood or less (a drop, a fragment of a torn thread)
  // is air to the projection, p = 0 (inverse diagonal 0): a pair drifting apart cannot be made
  // divergence-free, and its kept pull grew without bound (to 3·10⁷ m²/s² in a falling stream's spray).
  parallel_for_each_index(count, [&](std::size_t i) {
    const std::size_t first = lists.first(i);
    Vec4 gradient_sum = Vec4::Zero();
    Real squares = 0;
    for (Index k = 0; k < lists.counts[i]; ++k) {
      const Index j = lists.indices[first + k];
      const Vec4 gradient = workspace.fluid_pair_gradient[first + k] * (position[i] - position[j]);
      gradient_sum += gradient;
      if (std::size_t(j) < count && !(any_driven && workspace.piston_driven[j])) squares += gradient.squaredNorm() / mass[j];
    }
    system.at_surface[i] = gradient_sum.norm() > kSurfaceLopsidedness * flat_surface_sum || workspace.boundary_neighbors.counts[i] > 0;
    const Real diagonal = gradient_sum.squaredNorm() / mass[i] + squares;
    const bool alone = lists.counts[i] * 4 < std::size_t(model.full_neighbourhood);
    const bool fixed = any_driven && workspace.piston_driven[i];
    system.inverse_diagonal[i] = diagonal > 0 && !alone && !fixed ? Real(1) / diagonal : Real(0);
  });
  const Real volume = model.particle_volume;

  // The velocities: B M⁻¹ Bᵀ p = B v / Δt; each whole particle's dilation, (ρ/ρ0 − 1) where below ρ0,
  // aside for the positions.
  auto& dilation = workspace.scratch_real;
  dilation.assign(count, Real(0));
  const double any_dilation = deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
    if (system.inverse_diagonal[i] == 0) {  // air to the projection, or driven
      system.residual[i] = 0;
      fluid.kappa_tension[i] = 0;
      return;
    }
    bool whole = !system.at_surface[i];
    for (const Index j : lists.of(i)) whole = whole && !system.at_surface[j];
    system.residual[i] = compression_rate(workspace, velocity.data(), i) / time_step;
    dilation[i] = whole ? std::min(fluid.density[i] * volume / mass[i] - 1, Real(0)) : Real(0);
    sums[0] += dilation[i] < 0 ? 1 : 0;
  })[0];
  const double tolerance = kAbsoluteToleranceFraction * double(model.settings.divergence_tolerance);
  const ProjectionResult divergence = solve_projection(model, state, workspace, velocity.data(), tolerance, any_driven);
  // Only the pull is kept: compression is the density solve's (before the viscosity) and the volume
  // correction's. A push kept here as well was pushed twice where a falling stream landed, and grew
  // without bound (to 2·10⁵ m²/s² in the pile of the nozzle bench).
  parallel_for_each_index(count, [&](std::size_t i) {
    fluid.velocity[i] = velocity[i].head<3>();
    fluid.kappa_tension[i] = std::min(fluid.kappa_tension[i] + system.solution[i] / mass[i], Real(0));
  }, 4096);
  state.last_step.tension_iterations = divergence.iterations;
  state.last_step.tension_error = static_cast<Real>(divergence.mean_change);

  // The interior's dilation is taken back by moving positions, as correct_volume takes compression
  // out: a pressure kept for it would pull again next step what this one pulled back.
  if (any_dilation == 0) return;
  auto& change = workspace.solver_velocity;  // the velocities are back in the particles
  parallel_for_each_index(size, [&](std::size_t i) { change[i] = Vec4::Zero(); }, 4096);
  workspace.velocity_copy = {};  // no longer the velocities: packed whole next time
  parallel_for_each_index(count, [&](std::size_t i) { system.residual[i] = dilation[i] / (time_step * time_step); }, 4096);
  const ProjectionResult taken_back = solve_projection(model, state, workspace, change.data(), tolerance, any_driven);
  state.last_step.tension_iterations += taken_back.iterations;
  parallel_for_each_index(count, [&](std::size_t i) { fluid.position[i] += time_step * change[i].head<3>(); }, 4096);
}

}  // namespace m3dp::sph::stages
