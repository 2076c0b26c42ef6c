// Divergence-free SPH.
// J. Bender, D. Koschier: "Divergence-Free Smoothed Particle Hydrodynamics", SCA 2015, and
// "Divergence-Free SPH for Incompressible and Viscous Fluids", IEEE TVCG 23(3), 2017.
// Boundaries: N. Akinci et al., "Versatile Rigid-Fluid Coupling for Incompressible SPH", SIGGRAPH 2012.
//
// Densities are handled relative to each particle's own rest density (ρ/ρ0_i), with volumes: every
// fluid particle has the rest volume V = d³ (m_i = ρ0_i V), so ρ_i/ρ0_i = Σ_j V W_ij + Σ_b V_b W_ib
// whatever the phases (the number-density form of Solenthaler & Pajarola 2008, which keeps
// interfaces between fluids of different densities free of spurious tension). κ_i = ρ0_i p_i / ρ_i²
// (≈ p_i/ρ0_i), and a pressure velocity update conserves momentum between unequal masses:
//   v_i −= (Δt/m_i) Σ_j V_j (m_i κ_i + m_j κ_j) ∇W_ij + Δt Σ_b V_b κ_i ∇W_ib   (eq. 9 with eq. 12)
// The force of that update on boundary particle b is m_i κ_i V_b ∇W_ib (Akinci 2012, eq. 10). With
// one rest density this is Bender & Koschier's form exactly; the factor α gains m_i/m_j in its sum.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>  // parallel_deterministic_reduce: sums independent of thread count

#include <algorithm>
#include <atomic>
#include <cmath>
#include <type_traits>
#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/simd/neighbor_sums_avx2.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

namespace {

constexpr Real kFactorEpsilon = Real(1e-12);
// Particles with fewer neighbours are at a free surface; their divergence is not corrected
// (the surface would otherwise be pulled inwards), as in the reference implementation.
constexpr int kMinNeighborsForDivergence = 20;

/// max(value, floor) as one instruction: GCC makes std::max a jump, which a predictor cannot learn
/// (compressed or not follows no order) and each miss discards the next particle's loads. NaN passes
/// through, as with std::max(value, floor).
inline Real max_without_branch(Real value, Real floor) {
#if defined(__SSE2__)
  if constexpr (std::is_same_v<Real, float>)
    return _mm_cvtss_f32(_mm_max_ss(_mm_set_ss(floor), _mm_set_ss(value)));
  else
    return _mm_cvtsd_f64(_mm_max_sd(_mm_set_sd(floor), _mm_set_sd(value)));
#else
  return std::max(value, floor);
#endif
}

/// Raw pointers of everything the solver sweeps touch; built once per solve.
struct SolverView {
  const Vec4* position;  // padded copies (w = 0), see State::solver_position
  Vec4* velocity;
  const Real* density;
  const Real* mass;
  const Real* factor;
  Real* density_advected;
  Real* kappa;  // m_i κ_i of the current iteration (mass-weighted: see the update)
  const Real* rest_allowance;  // ρ/ρ0 − 1 a particle may keep (Workspace::rest_allowance)
  const Workspace::WallSums* wall_sums;
  const std::uint16_t* neighbor_count;
  const Index* fluid_neighbor;           // fluid lists, particle i's from fluid_first[i]
  const Index* fluid_neighbor_count;
  const Real* fluid_pair_gradient;       // V_j (dW/dr)/r per slot
  const std::size_t* fluid_first;
  const Index* boundary_neighbor;
  const Index* boundary_neighbor_count;
  const Real* boundary_pair_gradient;
  const std::size_t* boundary_first;
  Workspace::RestingInterface* interface;  // the resting particles the moving ones touch
};

/// Copies the velocities into the padded array and returns the view of the solve (the padded positions
/// and the walls' sums are the density pass's: positions do not change until the step's advection).
/// Every fluid particle (resting ones are neighbours too); velocities go back with unpack_velocities.
SolverView pack_for_solve(State& state, Workspace& workspace) {
  auto& fluid = state.fluid;
  pack_padded(fluid.velocity, workspace.solver_velocity, state.active_count, workspace, workspace.velocity_copy);
  return SolverView{workspace.solver_position.data(),
                    workspace.solver_velocity.data(),
                    fluid.density.data(),
                    fluid.mass.data(),
                    fluid.dfsph_factor.data(),
                    fluid.density_advected.data(),
                    workspace.kappa.data(),
                    workspace.rest_allowance.data(),
                    workspace.solver_wall_sums.data(),
                    fluid.neighbor_count.data(),
                    workspace.fluid_neighbors.indices.data(),
                    workspace.fluid_neighbors.counts.data(),
                    workspace.fluid_pair_gradient.data(),
                    workspace.fluid_neighbors.firsts.data(),
                    workspace.boundary_neighbors.indices.data(),
                    workspace.boundary_neighbors.counts.data(),
                    workspace.boundary_pair_gradient.data(),
                    workspace.boundary_neighbors.firsts.data(),
                    &workspace.resting_interface};
}

/// The solve's velocities back into the particles (only the active ones changed).
void unpack_velocities(State& state, Workspace& workspace) {
  parallel_for_each_index(state.active_count, [&](std::size_t i) {
    state.fluid.velocity[i] = workspace.solver_velocity[i].head<3>();
  }, 4096);
}

template <class Body>
void for_each_particle_range(std::size_t count, Body&& body) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 128), body);
}

/// Σ_k w_k (v_i − v_j) ⊙ (x_i − x_j), j = neighbor[k], lane by lane: the lanes' sum is Σ_k w_k (v_i − v_j)·(x_i − x_j).
Vec4 velocity_position_products(const Vec4* velocity, const Vec4* position, const Index* neighbor, const Real* weight,
                                Index count, const Vec4& velocity_i, const Vec4& position_i) {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
  if (avx512::available()) return avx512::difference_products(velocity, position, neighbor, weight, count, velocity_i, position_i);
  if (avx2::available()) return avx2::difference_products(velocity, position, neighbor, weight, count, velocity_i, position_i);
#endif
  Vec4 sum = Vec4::Zero();  // no horizontal add per neighbour
  for (Index k = 0; k < count; ++k) {
    const Index j = neighbor[k];
    sum += weight[k] * (velocity_i - velocity[j]).cwiseProduct(position_i - position[j]);
  }
  return sum;
}

/// The density change rate from the fluid pairs' lane sums (velocity_position_products): adds the walls,
/// Σ_b g_b (v_i − v_b)·r_b = v_i·Σ_b g_b r_b − Σ_b g_b v_b·r_b.
Real rate_with_walls(const SolverView& view, std::size_t i, const Vec4& fluid_lanes) {
  // Only where there are walls: the sums are zero elsewhere, and reading them cost a 48-byte record a
  // particle. Whether a particle touches a wall follows its place, which the branch predictor learns.
  if (view.boundary_neighbor_count[i] == 0) return fluid_lanes.sum();
  const Workspace::WallSums& walls = view.wall_sums[i];
  return fluid_lanes.sum() + view.velocity[i].dot(walls.gradient) - walls.velocity_flux;
}

/// Σ_j V_j (v_i − v_j)·∇W_ij + Σ_b V_b (v_i − v_b)·∇W_ib: the rate of change of ρ_i/ρ0 (1/s), with minus sign.
Real density_change_rate(const SolverView& view, std::size_t i) {
  const std::size_t fluid_first = view.fluid_first[i];
  const Vec4 rate = velocity_position_products(view.velocity, view.position, view.fluid_neighbor + fluid_first,
                                               view.fluid_pair_gradient + fluid_first, view.fluid_neighbor_count[i], view.velocity[i],
                                               view.position[i]);
  return rate_with_walls(view, i, rate);
}

/// Σ_{i in range} finish(i, density change rate of i), the rates' sweep of a solver iteration.
template <class Finish>
Real sum_over_rates(const SolverView& view, const tbb::blocked_range<std::size_t>& range, Finish&& finish) {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
  // One call for the range: a call per particle into the AVX2 code cost as much as its pairs.
  if (avx512::available())
    return avx512::difference_product_rows(range.begin(), range.end(), view.velocity, view.position, view.fluid_neighbor,
                                           view.fluid_neighbor_count, view.fluid_first, view.fluid_pair_gradient,
                                           [&](std::size_t i, const Vec4& lanes) { return finish(i, rate_with_walls(view, i, lanes)); });
  if (avx2::available())
    return avx2::difference_product_rows(range.begin(), range.end(), view.velocity, view.position, view.fluid_neighbor,
                                         view.fluid_neighbor_count, view.fluid_first, view.fluid_pair_gradient,
                                         [&](std::size_t i, const Vec4& lanes) { return finish(i, rate_with_walls(view, i, lanes)); });
#endif
  Real total = 0;
  for (std::size_t i = range.begin(); i != range.end(); ++i) total += finish(i, density_change_rate(view, i));
  return total;
}

/// One pressure velocity update with the m κ in view.kappa; with kWallReaction, adds the reaction on
/// the bodies (the volume correction moves particles without a force, and has none).
template <bool kWallReaction = true>
void apply_pressure_velocity_update(const SolverView& view, State& state, Workspace& workspace, Real time_step) {
  for_each_wrench_chunk(state, workspace, state.active_count, [&](const tbb::blocked_range<std::size_t>& range, std::span<Wrench> wrenches) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const Real weighted_kappa_i = view.kappa[i];  // m_i κ_i
      const Vec4 position_i = view.position[i];
      Vec4 momentum_change = Vec4::Zero();  // per Δt: m_i Δv_i / Δt (w stays 0)
      const Index* neighbor = view.fluid_neighbor + view.fluid_first[i];
      const Real* pair_gradient = view.fluid_pair_gradient + view.fluid_first[i];
      const Index fluid_count = view.fluid_neighbor_count[i];
      // Two sums, even and odd neighbours: one would make each pair wait for the last one's subtraction.
      Vec4 odd_change = Vec4::Zero();
      Index k = 0;
      for (; k + 1 < fluid_count; k += 2) {
        const Index j0 = neighbor[k], j1 = neighbor[k + 1];
        momentum_change -= ((weighted_kappa_i + view.kappa[j0]) * pair_gradient[k]) * (position_i - view.position[j0]);
        odd_change -= ((weighted_kappa_i + view.kappa[j1]) * pair_gradient[k + 1]) * (position_i - view.position[j1]);
      }
      if (fluid_count > 0) {
        // The last neighbour once more, weighted where the count is odd and zero where it is even: a
        // branch on the count's parity would be mispredicted for half of the particles.
        const Index last = fluid_count - 1, j = neighbor[last];
        const Real weight = pair_gradient[last] * Real(fluid_count & 1);
        odd_change -= ((weighted_kappa_i + view.kappa[j]) * weight) * (position_i - view.position[j]);
      }
      momentum_change += odd_change;
      const Workspace::WallSums& walls = view.wall_sums[i];
      // Not also skipped where κ_i = 0 (it would add zeros): whether a particle touches a wall follows
      // its place, which the branch predictor learns; whether it is compressed does not.
      if (view.boundary_neighbor_count[i] > 0) {
        // The walls' share, −m_i κ_i Σ_b g_b r_b, and its reaction on the bodies, +m_i κ_i g_b r_b each.
        momentum_change -= weighted_kappa_i * walls.gradient;
        if constexpr (!kWallReaction) {
        } else if (walls.body != Workspace::kSeveralBodies) {
          Wrench& wrench = wrenches[walls.body];
          wrench.force += weighted_kappa_i * walls.gradient.head<3>();
          wrench.torque += weighted_kappa_i * walls.torque;
        } else if (weighted_kappa_i != 0) {
          // Wall neighbours of several bodies (a corner where two meet): each body its own share.
          const std::size_t boundary_first = view.boundary_first[i];
          for (Index k = 0; k < view.boundary_neighbor_count[i]; ++k) {
            const Index b = view.boundary_neighbor[boundary_first + k];
            const Vec3 force = (weighted_kappa_i * view.boundary_pair_gradient[boundary_first + k]) *
                               (state.fluid.position[i] - state.boundary.position[b]);
            const Index body = state.boundary.body[b];
            Wrench& body_wrench = wrenches[body];
            body_wrench.force += force;
            body_wrench.torque += (state.boundary.position[b] - state.bodies[body].pose.position).cross(force);
          }
        }
      }
      view.velocity[i] += (time_step / view.mass[i]) * momentum_change;
    }
  });
}

/// The resting particles this step's moving ones touch (Workspace::RestingInterface): each with its
/// moving neighbours (the moving particles' lists transposed, in index order: the same on any number of
/// threads), its density now, the density it may reach and its factor.
template <class Kernel>
void build_resting_interface(const Model& model, State& state, Workspace& workspace, const Kernel& kernel) {
  auto& interface = workspace.resting_interface;
  const auto& fluid = state.fluid;
  const std::size_t active = state.active_count, count = fluid.size();
  interface.particles.clear();
  interface.first.assign(1, 0);
  if (active == count || active == 0) return;
  if (interface.slot_of.size() < count) interface.slot_of.resize(count, Workspace::RestingInterface::kNone);
  const auto& lists = workspace.fluid_neighbors;
  // Each resting neighbour's place, in the order first reached, and how many moving ones reach it.
  auto& reach_count = interface.first;  // counts at [1 + slot], then their running sum
  for (std::size_t i = 0; i < active; ++i)
    for (const Index j : lists.of(i)) {
      if (j < active) continue;
      Index& slot = interface.slot_of[j];
      if (slot == Workspace::RestingInterface::kNone) {
        slot = static_cast<Index>(interface.particles.size());
        interface.particles.push_back(j);
        reach_count.push_back(0);
      }
      ++reach_count[1 + slot];
    }
  const std::size_t interface_count = interface.particles.size();
  for (std::size_t k = 0; k < interface_count; ++k) reach_count[k + 1] += reach_count[k];
  interface.neighbor.resize(reach_count[interface_count]);
  interface.pair_slot.resize(reach_count[interface_count]);
  auto& fill = workspace.sort_keys;  // each one's next free place
  fill.assign(reach_count.begin(), reach_count.end() - 1);
  for (std::size_t i = 0; i < active; ++i) {
    const std::size_t first = lists.first(i);
    for (Index k = 0; k < lists.counts[i]; ++k) {
      const Index j = lists.indices[first + k];
      if (j < active) continue;
      const std::size_t place = fill[interface.slot_of[j]]++;
      interface.neighbor[place] = static_cast<Index>(i);
      interface.pair_slot[place] = first + k;
    }
  }
  for (const Index j : interface.particles) interface.slot_of[j] = Workspace::RestingInterface::kNone;
  interface.density.resize(interface_count);
  interface.limit.resize(interface_count);
  interface.factor.resize(interface_count);
  interface.predicted.resize(interface_count);
  const Real support_squared = model.support_radius * model.support_radius;
  const Real volume = model.particle_volume;
  const auto& boundary = state.boundary;
  if (interface.fixed_part.size() < count) {
    interface.fixed_part.resize(count);
    interface.fixed_part_version.resize(count, ~std::uint64_t(0));
  }
  const std::uint64_t version = workspace.fixed_grids_version;
  parallel_for_each_index(interface_count, [&](std::size_t k) {
    const Index j = interface.particles[k];
    const Vec3 position = fluid.position[j];
    // Its density where everything is now, as measure_density sums it: the resting neighbours from
    // their grids (j itself among them) and the static walls, kept while those stand; the moving
    // neighbours from its list and the moving walls from theirs, each step.
    if (interface.fixed_part_version[j] != version) {
      Real resting_sum = 0, resting_squares = 0, static_wall_sum = 0;
      for (const SpatialHashGrid* grid : {&workspace.resting_grid, &workspace.recent_resting_grid})
        grid->for_each_candidate(position, [&](Index, const Vec3& other) {
          const Vec3 r = position - other;
          const Real distance_squared = r.squaredNorm();
          if (distance_squared >= support_squared) return;
          const auto [value, gradient_factor] = kernel.value_and_gradient_factor(std::sqrt(distance_squared));
          resting_sum += value;
          resting_squares += (volume * gradient_factor * r).squaredNorm();
        });
      workspace.static_boundary_grid.for_each_candidate(position, [&](Index b, const Vec3& wall) {
        const Real distance_squared = (position - wall).squaredNorm();
        if (distance_squared < support_squared) static_wall_sum += boundary.volume[b] * kernel.W(std::sqrt(distance_squared));
      });
      interface.fixed_part[j] = Vec3(resting_sum, resting_squares, static_wall_sum);
      interface.fixed_part_version[j] = version;
    }
    const Vec3& fixed = interface.fixed_part[j];
    Real fluid_sum = fixed.x(), resting_squares = fixed.y(), wall_volume_sum = fixed.z();
    Real squares = 0;
    for (std::size_t place = interface.first[k]; place < interface.first[k + 1]; ++place) {
      const Index i = interface.neighbor[place];
      const Vec3 r = position - fluid.position[i];
      fluid_sum += kernel.W(r.norm());
      squares += (fluid.mass[j] / fluid.mass[i]) * (workspace.fluid_pair_gradient[interface.pair_slot[place]] * r).squaredNorm();
    }
    workspace.moving_boundary_grid.for_each_candidate(position, [&](Index b, const Vec3& wall) {
      const Real distance_squared = (position - wall).squaredNorm();
      if (distance_squared < support_squared) wall_volume_sum += boundary.volume[b] * kernel.W(std::sqrt(distance_squared));
    });
    interface.density[k] = volume * fluid_sum + wall_volume_sum;
    // The density pass left a resting particle's own density as it was when it last moved.
    interface.limit[k] = std::max(fluid.density[j] / model.phases[fluid.phase[j]].density, Real(1));
    // Only its moving neighbours move, but a Jacobi step on that sum alone diverged where few of them
    // reach it (near the support's edge): at least half of its whole neighbourhood's sum, as the
    // moving particles deep in resting material keep.
    squares = std::max(squares, Real(0.5) * (squares + resting_squares));
    interface.factor[k] = squares > kFactorEpsilon ? Real(1) / squares : Real(0);
  }, 256);
}

}  // namespace

void compute_density_and_factor(const Model& model, State& state, Workspace& workspace) {
  const Real volume = model.particle_volume;  // every fluid particle's V = m/ρ0
  auto& fluid = state.fluid;
  // The solves' κ per iteration: zero for the resting particles, which every sweep reads as neighbours.
  // Padded positions, for this pass's AVX2 sums and the solves' sweeps; the resting ones and their κ
  // (0: they are fixed) only when the resting set changed.
  const std::uint64_t copied_builds = workspace.position_copy.settled_builds;
  const std::size_t copied_size = std::min(workspace.position_copy.size, workspace.kappa.size());
  const bool resting_packed =
      pack_padded(fluid.position, workspace.solver_position, state.active_count, workspace, workspace.position_copy);
  workspace.kappa.resize(fluid.size());
  if (resting_packed)
    workspace.for_each_unsettled_range(state.active_count, fluid.size(), copied_builds, copied_size, [&](std::size_t begin, std::size_t end) {
      std::fill(workspace.kappa.begin() + static_cast<std::ptrdiff_t>(begin), workspace.kappa.begin() + static_cast<std::ptrdiff_t>(end), Real(0));
    });
  const auto& boundary = state.boundary;
  const auto& fluid_lists = workspace.fluid_neighbors;
  const auto& boundary_lists = workspace.boundary_neighbors;
  workspace.fluid_pair_gradient.resize(fluid_lists.indices.size());
  workspace.boundary_pair_gradient.resize(boundary_lists.indices.size());
  workspace.solver_wall_sums.resize(fluid.size());
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
  const bool use_avx2 = avx2::available();
  // One rest density, so one mass (m = ρ0 V): the factor's mass ratios are all 1.
  const bool one_mass = std::all_of(model.phases.begin(), model.phases.end(),
                                    [&](const auto& phase) { return phase.density == model.phases.front().density; });
#endif
  const Real boundary_neighbor_weight = model.settings.boundary_spacing_factor * model.settings.boundary_spacing_factor;
  // Resting material (indices from active_count on) is in the neighbour lists but does not move.
  const std::size_t active = state.active_count;
  const bool any_resting = active < fluid.size();
  workspace.rest_allowance.resize(fluid.size());  // written for every active particle below
  // Half what rest detection lets resting material keep: a woken particle left at the whole could
  // never rest again (it rests at or below it), and the woken band grew layer by layer.
  const Real woken_allowance = Real(0.5) * model.settings.rest_compression;
  state.last_step.max_density_error = with_kernel(model.settings.kernel, model.support_radius, [&](const auto& kernel) {
                       return tbb::parallel_reduce(
                           tbb::blocked_range<std::size_t>(0, state.active_count, 128), Real(0),
                           [&](const tbb::blocked_range<std::size_t>& range, Real max_error) {
                             for (std::size_t i = range.begin(); i != range.end(); ++i) {
                               const Vec3 position_i = fluid.position[i];
                               Real density_ratio = volume * kernel.W_zero();
                               const Real mass_i = fluid.mass[i];
                               Vec3 gradient_sum = Vec3::Zero();
                               Real gradient_squares = 0;
                               const std::size_t fluid_first = fluid_lists.first(i);
                               Index k = 0;
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
                               if (use_avx2) {
                                 const auto pair_sums = one_mass ? avx2::density_pair_sums<true, std::decay_t<decltype(kernel)>>
                                                                 : avx2::density_pair_sums<false, std::decay_t<decltype(kernel)>>;
                                 const avx2::DensityPairSums sums = pair_sums(
                                     kernel, workspace.solver_position.data(), fluid.mass.data(), fluid_lists.indices.data() + fluid_first,
                                     fluid_lists.counts[i], workspace.solver_position[i], mass_i, volume,
                                     workspace.fluid_pair_gradient.data() + fluid_first);
                                 density_ratio += sums.density_ratio;
                                 gradient_sum += sums.gradient_sum;
                                 gradient_squares += sums.gradient_squares;
                                 k = sums.pairs_done;
                               }
#endif
                               for (; k < fluid_lists.counts[i]; ++k) {
                                 const Index j = fluid_lists.indices[fluid_first + k];
                                 const Vec3 r = position_i - fluid.position[j];
                                 const auto [value, gradient_factor] = kernel.value_and_gradient_factor(r.norm());
                                 density_ratio += volume * value;
                                 const Real pair_gradient = volume * gradient_factor;
                                 workspace.fluid_pair_gradient[fluid_first + k] = pair_gradient;
                                 const Vec3 gradient = pair_gradient * r;
                                 gradient_sum += gradient;
                                 gradient_squares += (mass_i / fluid.mass[j]) * gradient.squaredNorm();
                               }
                               // Resting neighbours do not move under the solve (their κ is 0 and their
                               // velocity fixed): like walls, they take no share of the diagonal's sum of
                               // squares, or a layer laid on resting material gets half the κ it needs
                               // and the solve stalls (a 60 s wall: 4 iterations on the floor, 36-40 on
                               // the first layer). Deeper in resting material (over half the neighbourhood
                               // resting) the diagonal keeps half its sum: Jacobi diverged without it.
                               workspace.rest_allowance[i] = 0;
                               if (any_resting) {
                                 Real resting_squares = 0;
                                 Index resting = 0;
                                 for (Index k2 = 0; k2 < fluid_lists.counts[i]; ++k2) {
                                   const Index j = fluid_lists.indices[fluid_first + k2];
                                   if (j < active) continue;
                                   const Vec3 gradient = workspace.fluid_pair_gradient[fluid_first + k2] * (position_i - fluid.position[j]);
                                   resting_squares += (mass_i / fluid.mass[j]) * gradient.squaredNorm();
                                   ++resting;
                                 }
                                 gradient_squares = std::max(gradient_squares - resting_squares, Real(0.5) * gradient_squares);
                                 // A particle woken inside resting material cannot lose the compression it
                                 // rested with (its few moving neighbours would have to carry it): the
                                 // solve leaves it what rest detection allowed, as deep as it is embedded.
                                 const Real share = fluid_lists.counts[i] > 0 ? Real(resting) / Real(fluid_lists.counts[i]) : Real(0);
                                 workspace.rest_allowance[i] = woken_allowance * std::clamp(2 * share - 1, Real(0), Real(1));
                               }
                               const std::size_t boundary_first = boundary_lists.first(i);
                               // The walls' sums for the solves' sweeps (Workspace::WallSums).
                               Workspace::WallSums walls{Vec4::Zero(), Vec3::Zero(), Real(0), Workspace::kSeveralBodies};
                               for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
                                 const Index b = boundary_lists.indices[boundary_first + k];
                                 const Vec3 r = position_i - boundary.position[b];
                                 const auto [value, gradient_factor] = kernel.value_and_gradient_factor(r.norm());
                                 density_ratio += boundary.volume[b] * value;
                                 const Real pair_gradient = boundary.volume[b] * gradient_factor;
                                 workspace.boundary_pair_gradient[boundary_first + k] = pair_gradient;
                                 const Vec3 gradient = pair_gradient * r;
                                 gradient_sum += gradient;
                                 const Index body = boundary.body[b];
                                 walls.gradient.head<3>() += gradient;
                                 walls.velocity_flux += boundary.velocity[b].dot(gradient);
                                 walls.torque += (boundary.position[b] - state.bodies[body].pose.position).cross(gradient);
                                 walls.body = (k == 0 || walls.body == body) ? body : Workspace::kSeveralBodies;
                               }
                               workspace.solver_wall_sums[i] = walls;
                               fluid.density[i] = density_ratio * (mass_i / volume);
                               const Real denominator = gradient_sum.squaredNorm() + gradient_squares;
                               fluid.dfsph_factor[i] = denominator > kFactorEpsilon ? Real(1) / denominator : Real(0);
                               // Boundary neighbours counted as the fluid particles they stand for: a wall
                               // layer is sampled finer than the fluid (a sheet: count ∝ 1/spacing²), and a
                               // free-surface particle at a wall must still count as at the surface.
                               fluid.neighbor_count[i] = static_cast<std::uint16_t>(std::min<Real>(
                                   65535, Real(fluid_lists.counts[i]) + boundary_neighbor_weight * Real(boundary_lists.counts[i])));
                               max_error = std::max(max_error, density_ratio - Real(1));
                             }
                             return max_error;
                           },
                           [](Real a, Real b) { return std::max(a, b); });
                     });
  if (any_resting)
    with_kernel(model.settings.kernel, model.support_radius,
                [&](const auto& kernel) { build_resting_interface(model, state, workspace, kernel); });
  else
    workspace.resting_interface.particles.clear(), workspace.resting_interface.first.assign(1, 0);
}

void solve_divergence(const Model& model, State& state, Workspace& workspace) {
  const auto& settings = model.settings;
  const std::size_t count = state.active_count;
  if (!settings.divergence_solver || count == 0) return;
  const Real time_step = state.time_step;  // the last step's: this one's is chosen after the forces
  const SolverView view = pack_for_solve(state, workspace);
  const Real inverse_time_step = Real(1) / time_step;
  // Σ κ over this step's updates: a pressure (κ = ρ0 p / ρ²), so it carries over when Δt changes.
  auto& kappa_total = state.fluid.kappa_divergence;

  {
    auto update_divergence = [&]() {
      return tbb::parallel_deterministic_reduce(
          tbb::blocked_range<std::size_t>(0, count, 256), Real(0),
          [&](const tbb::blocked_range<std::size_t>& range, Real sum) {
            return sum + sum_over_rates(view, range, [&](std::size_t i, Real rate) {
                     rate = view.neighbor_count[i] < kMinNeighborsForDivergence ? Real(0) : max_without_branch(rate, Real(0));
                     view.density_advected[i] = rate;
                     return rate;
                   });
          },
          std::plus<Real>());
    };

    Real mean_error = update_divergence() / Real(count) * time_step;
    const bool converged = settings.min_divergence_iterations == 0 && mean_error <= settings.divergence_tolerance;
    if (settings.warm_start && !converged) {
      // Half of last step's κ as the initial guess, where the flow diverges now (as the density solve).
      // Not where the flow is divergence-free already: then the guess would only cost two sweeps.
      parallel_for_each_index(count, [&](std::size_t i) {
        kappa_total[i] = view.density_advected[i] > Real(0) ? Real(0.5) * kappa_total[i] : Real(0);
        view.kappa[i] = view.mass[i] * kappa_total[i];
      });
      apply_pressure_velocity_update(view, state, workspace, time_step);
      mean_error = update_divergence() / Real(count) * time_step;
    } else {
      parallel_for_each_index(count, [&](std::size_t i) { kappa_total[i] = 0; });
    }

    int iterations = 0;
    while ((iterations < settings.min_divergence_iterations || mean_error > settings.divergence_tolerance) &&
           iterations < settings.max_divergence_iterations) {
      parallel_for_each_index(count, [&](std::size_t i) {
        const Real kappa = view.density_advected[i] * view.factor[i] * inverse_time_step;
        kappa_total[i] += kappa;
        view.kappa[i] = view.mass[i] * kappa;
      });
      apply_pressure_velocity_update(view, state, workspace, time_step);
      mean_error = update_divergence() / Real(count) * time_step;
      ++iterations;
    }
    unpack_velocities(state, workspace);
    state.last_step.divergence_iterations = iterations;
  }
}

namespace {

/// ρ*/ρ0 = ρ/ρ0 + Δt · (rate of change) of every active particle into view.density_advected, clamped
/// at `floor` plus the particle's rest allowance: the solver only pushes, never pulls (free surface).
/// Returns the mean of ρ*/ρ0 less that clamp.
Real update_predicted_density(const Model& model, const State& state, const SolverView& view, Real time_step,
                              Real floor = 1) {
  const std::size_t count = state.active_count;
  const Real volume = model.particle_volume;
  const Real active_sum = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, count, 256), Real(0),
      [&](const tbb::blocked_range<std::size_t>& range, Real sum) {
        return sum + sum_over_rates(view, range, [&](std::size_t i, Real rate) {
                 const Real predicted = view.density[i] * volume / view.mass[i] + time_step * rate;
                 const Real floor_i = floor + view.rest_allowance[i];
                 view.density_advected[i] = max_without_branch(predicted, floor_i);
                 return view.density_advected[i] - floor_i;
               });
      },
      std::plus<Real>());
  // The resting particles the moving ones touch: ρ*/ρ0 from their moving neighbours' velocities (they
  // do not move), against the density they rested with.
  auto& interface = *view.interface;
  const std::size_t interface_count = interface.particles.size();
  if (interface_count == 0) return active_sum / Real(count);
  const Real interface_sum = tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, interface_count, 256), Real(0),
      [&](const tbb::blocked_range<std::size_t>& range, Real sum) {
        for (std::size_t k = range.begin(); k != range.end(); ++k) {
          const Index j = interface.particles[k];
          const Vec4 position_j = view.position[j], velocity_j = view.velocity[j];
          Real rate = 0;
          for (std::size_t place = interface.first[k]; place < interface.first[k + 1]; ++place) {
            const Index i = interface.neighbor[place];
            rate += view.fluid_pair_gradient[interface.pair_slot[place]] * (velocity_j - view.velocity[i]).dot(position_j - view.position[i]);
          }
          const Real limit = std::max(interface.limit[k], floor);
          interface.predicted[k] = max_without_branch(interface.density[k] + time_step * rate, limit);
          sum += interface.predicted[k] - limit;
        }
        return sum;
      },
      std::plus<Real>());
  return (active_sum + interface_sum) / Real(count + interface_count);
}

/// The resting interface's m κ for this iteration (Jacobi, as the moving particles'), each κ added into
/// the interface's `kappa_total` with `accumulate`; or zero after a solve.
void set_interface_kappa(const SolverView& view, Real inverse_time_step_squared, Real floor, bool accumulate, bool clear = false) {
  auto& interface = *view.interface;
  parallel_for_each_index(interface.particles.size(), [&](std::size_t k) {
    const Index j = interface.particles[k];
    const Real limit = std::max(interface.limit[k], floor);
    const Real kappa = clear ? Real(0) : (interface.predicted[k] - limit) * interface.factor[k] * inverse_time_step_squared;
    if (accumulate) interface.kappa_total[k] += kappa;
    view.kappa[j] = view.mass[j] * kappa;
  }, 1024);
}

/// Jacobi iterations of the constant-density solve (Bender & Koschier 2017, Algorithm 3) from the
/// predicted densities in view.density_advected (mean error `mean_error`) until the tolerance, each
/// κ added into `kappa_total` where given. Returns the iterations; `mean_error` ends as the last one.
template <bool kWallReaction>
int iterate_density(const Model& model, State& state, Workspace& workspace, const SolverView& view, Real time_step,
                    int min_iterations, std::vector<Real>* kappa_total, Real& mean_error, Real floor = 1) {
  const auto& settings = model.settings;
  const std::size_t count = state.active_count;
  const Real inverse_time_step_squared = Real(1) / (time_step * time_step);
  int iterations = 0;
  while ((iterations < min_iterations || mean_error > settings.density_tolerance) && iterations < settings.max_density_iterations) {
    parallel_for_each_index(count, [&](std::size_t i) {
      const Real kappa = (view.density_advected[i] - floor - view.rest_allowance[i]) * view.factor[i] * inverse_time_step_squared;
      if (kappa_total) (*kappa_total)[i] += kappa;
      view.kappa[i] = view.mass[i] * kappa;
    });
    set_interface_kappa(view, inverse_time_step_squared, floor, kappa_total != nullptr);
    apply_pressure_velocity_update<kWallReaction>(view, state, workspace, time_step);
    mean_error = update_predicted_density(model, state, view, time_step, floor);
    ++iterations;
  }
  set_interface_kappa(view, inverse_time_step_squared, floor, false, true);  // resting particles' κ is 0 to every other sweep
  return iterations;
}

/// Resting material that held the moving material back this step with a pressure past its unconfined
/// yield stress √3 τ0 (Roussel 2018; τ0 as aged) yields: it wakes. A layer's weight on the one below
/// (ρ g h) is far below it for a printable mortar, a column's growing load is not.
void wake_yielding_interface(const Model& model, State& state, Workspace& workspace) {
  auto& interface = workspace.resting_interface;
  if (interface.particles.empty() || !model.settings.rest_detection) return;
  auto& fluid = state.fluid;
  const Real time = static_cast<Real>(state.time);
  const Real unconfined = std::sqrt(Real(3));
  std::atomic<int> woken{0};
  parallel_for_each_index(interface.particles.size(), [&](std::size_t k) {
    const Index j = interface.particles[k];
    const FluidPhase& phase = model.phases[fluid.phase[j]];
    const Real pressure = phase.density * interface.kappa_total[k];  // κ = ρ0 p / ρ² ≈ p / ρ0
    if (!(pressure > unconfined * phase.ageing.yield_stress(phase.rheology.yield_stress, time - fluid.birth_time[j]))) return;
    fluid.rest_time[j] = 0;
    woken.store(1, std::memory_order_relaxed);
  }, 1024);
  if (woken.load()) state.resting_woken = 1;
}

}  // namespace

void solve_density(const Model& model, State& state, Workspace& workspace) {
  const auto& settings = model.settings;
  const std::size_t count = state.active_count;
  const Real time_step = state.time_step;
  state.last_step.density_error = 0;
  if (count == 0) return;
  const SolverView view = pack_for_solve(state, workspace);
  auto& kappa_total = state.fluid.kappa_density;  // Σ κ over this step's updates (a pressure, see above)
  workspace.resting_interface.kappa_total.assign(workspace.resting_interface.particles.size(), Real(0));
  if (settings.warm_start) {
    // Half of last step's pressure, where the particle is compressed now (Bender & Koschier 2017,
    // Sec. 4.4). Not the whole: the solver only pushes (ρ* is clamped at ρ0), so an initial guess
    // that overshoots can never be taken back, and with the whole pressure a settling column
    // gains energy at large time steps.
    update_predicted_density(model, state, view, time_step);
    parallel_for_each_index(count, [&](std::size_t i) {
      kappa_total[i] = view.density_advected[i] > Real(1) + view.rest_allowance[i] ? Real(0.5) * kappa_total[i] : Real(0);
      view.kappa[i] = view.mass[i] * kappa_total[i];
    });
    apply_pressure_velocity_update(view, state, workspace, time_step);
  } else {
    parallel_for_each_index(count, [&](std::size_t i) { kappa_total[i] = 0; });
  }
  Real mean_error = update_predicted_density(model, state, view, time_step);
  state.last_step.density_iterations =
      iterate_density<true>(model, state, workspace, view, time_step, settings.min_density_iterations, &kappa_total, mean_error);
  state.last_step.density_error = mean_error;
  unpack_velocities(state, workspace);
  wake_yielding_interface(model, state, workspace);
}

void correct_volume(const Model& model, State& state, Workspace& workspace) {
  const std::size_t count = state.active_count;
  const Real time_step = state.time_step;
  // Only the viscosity solve undoes the density solve's work: without it (water, the explicit
  // solver) the velocities are the density solve's own.
  if (count == 0 || state.last_step.viscosity_iterations == 0) return;
  // The compression the velocities after the viscosity solve would leave: the same prediction as the
  // density solve's, from this step's densities.
  const SolverView view = pack_for_solve(state, workspace);
  // Down to the volume tolerance, not to ρ0: the compression of a standing paste's last tenths of a
  // per cent comes back every step, and taking it out kinematically, step after step, made an
  // unyielded column creep (docs/decisions.md).
  const Real floor = 1 + model.settings.volume_tolerance;
  Real mean_error = update_predicted_density(model, state, view, time_step, floor);
  state.last_step.volume_error = mean_error;
  // A stiff material's viscosity undoes most of the pressure solve's relief: each step's compression
  // would stay, and accumulate. Solved again, the correction moves the particles apart but adds no
  // velocity: no force, no wall reaction, and the viscous velocities stay as they were.
  state.last_step.volume_iterations = iterate_density<false>(model, state, workspace, view, time_step, 0, nullptr, mean_error, floor);
  auto& fluid = state.fluid;
  // And no pair closer than the minimum spacing: the cubic spline's repulsion weakens below two
  // thirds of a diameter, so a viscous material's particles pair up (the pairing instability,
  // Dehnen & Aly 2012), and at a free surface, where the density is short, nothing else parts them.
  const Real minimum = model.settings.minimum_spacing * model.particle_diameter;
  // One particle after another in index order, each parted from its close neighbours as they stand
  // (those before it already moved): the same on any number of threads. Moving in place in parallel,
  // while other threads read the particles as neighbours, made a viscous paste's runs differ; parting
  // every pair from the old positions at once (Jacobi) pushed into neighbours (a honey ring's p99
  // density +1.3 → +4.1 %). The correction's own moves are taken in parallel first.
  auto& own_move = workspace.scratch_vec3;
  own_move.resize(count);
  parallel_for_each_index(count, [&](std::size_t i) {
    own_move[i] = time_step * (workspace.solver_velocity[i].head<3>() - fluid.velocity[i]);
  }, 4096);
  for (std::size_t i = 0; i < count; ++i) {
    Vec3 displacement = own_move[i];
    if (minimum > 0) {
      const Vec3 position_i = fluid.position[i];
      for (const Index j : workspace.fluid_neighbors.of(i)) {
        const Vec3 r = position_i - fluid.position[j];
        const Real distance_squared = r.squaredNorm();
        if (distance_squared >= minimum * minimum || distance_squared == 0) continue;
        const Real distance = std::sqrt(distance_squared);
        displacement += ((j < count ? Real(0.5) : Real(1)) * (minimum - distance) / distance) * r;
      }
    }
    // The pump drives the material in a nozzle's exit: the correction never pushes it back in.
    fluid.position[i] += without_push_into_nozzles(model, state, fluid.position[i], displacement);
  }
}

}  // namespace m3dp::sph::stages

