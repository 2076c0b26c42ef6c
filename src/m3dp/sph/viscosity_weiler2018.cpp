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
// The shear rate for the rheology is γ̇ = √(2 D:D) with D = sym(∇v), ∇v_i = Σ_j V_j (v_j − v_i) ⊗ ∇W_ij.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <Eigen/LU>
#include <Eigen/SparseCholesky>
#include <algorithm>
#include <cmath>
#include <array>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/neighbor_sums_avx2.hpp"
#include "m3dp/sph/solver.hpp"

namespace m3dp::sph::stages {

namespace {

constexpr Real kDimensionFactor = 2 * (3 + 2);  // 2(d+2), d = 3

bool phase_needs_shear_rate(const FluidPhase& phase) {
  return phase.rheology.model != material::RheologyModel::newtonian || phase.ageing.enabled();
}

/// Runs range_body(range, sums) over ranges of the particles and returns the N sums (double), added in a
/// fixed order: the same on every run, so two identical simulations stay identical.
template <std::size_t N, class RangeBody>
std::array<double, N> deterministic_range_sums(std::size_t count, RangeBody&& range_body) {
  using Sums = std::array<double, N>;
  return tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, count, 256), Sums{},
      [&](const tbb::blocked_range<std::size_t>& range, Sums sums) {
        range_body(range, sums);
        return sums;
      },
      [](Sums a, const Sums& b) {
        for (std::size_t n = 0; n < N; ++n) a[n] += b[n];
        return a;
      });
}

/// body(i, sums) for every particle.
template <std::size_t N, class Body>
std::array<double, N> deterministic_sums(std::size_t count, Body&& body) {
  return deterministic_range_sums<N>(count, [&](const tbb::blocked_range<std::size_t>& range, std::array<double, N>& sums) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) body(i, sums);
  });
}

/// The same over the rows of a matrix-vector product: rows(range, visit) calls visit(i, y_i) for the
/// range's particles in order, and body(i, y_i, sums) adds particle i's terms.
template <std::size_t N, class Rows, class Body>
std::array<double, N> deterministic_row_sums(std::size_t count, Rows&& rows, Body&& body) {
  return deterministic_range_sums<N>(count, [&](const tbb::blocked_range<std::size_t>& range, std::array<double, N>& sums) {
    rows(range, [&](std::size_t i, const Vec3& row) { body(i, row, sums); });
  });
}

// Aggregates of the coarse level: cells of this many particle spacings (up to 512 particles). In the clay
// bench (48.8k particles) 4 spacings took 26 CG iterations a step but the factorisation of their
// 4.5k unknowns cost more than it saved (280 ms a step in the solve), 6 took 33 (181 ms), 8 took 42
// (153 ms).
constexpr Real kAggregateSpacings = 8;
// Aggregates a coarse cell can couple to: its own and the 26 around it (cells ≥ the support radius).
constexpr std::size_t kMaxCoarseNeighbours = 27;
// The coarse level is built when the last solve needed more CG iterations than this: it costs about as
// much as five iterations, so a runny material's solve (a few iterations) does without it.
constexpr int kCoarseLevelFromIterations = 12;

}  // namespace

/// The coarse level of the viscosity solve's preconditioner. A stiff paste is nearly rigid over many
/// particles, and block Jacobi, which sees one particle at a time, needs about as many CG iterations as
/// the material is particles across to move it as a whole (122 a step in the clay bench). The coarse
/// level lets each aggregate of particles move as a rigid body: z = D⁻¹ r + P A_c⁻¹ Pᵀ r, with
/// P_i = [I  −[x_i − c]×] (v_i = t + ω × (x_i − c), c the aggregate's centroid) and A_c = Pᵀ A P,
/// built and factorised for every solve (six unknowns per aggregate of up to 512 particles). It lives
/// in the solver's state: its buffers are reused, and so is the factorisation's symbolic analysis
/// (the AMD ordering, 0.66 of 1.5 ms in the clay bench) while A_c keeps its pattern. Rigid motions
/// are what the viscous term cannot see: a pair's c r rᵀ (v_i − v_j) vanishes for a common
/// translation and for a common rotation.
class CoarseViscosityLevel {
 public:
  using Block = Eigen::Matrix<double, 6, 6>;

  /// Groups the active particles into aggregates and factorises A_c, from A's pair coefficients c (a
  /// pair's block is c r rᵀ) and `own_block(i)`, the part of A that acts on x_i alone (m_i I and walls).
  template <class OwnBlock>
  bool build(State& state, std::size_t count, Real aggregate_size, OwnBlock&& own_block) {
    auto& system = state.viscosity_system;
    const auto& fluid = state.fluid;
    const auto& lists = state.fluid_neighbors;
    sort_by_cell(fluid.position, count, aggregate_size, system.aggregate_key, system.aggregate_order);
    system.aggregate_of.resize(count);
    system.aggregate_offset.resize(count);
    system.aggregate_start.clear();
    for (std::size_t k = 0; k < count; ++k) {
      if (k == 0 || system.aggregate_key[system.aggregate_order[k]] != system.aggregate_key[system.aggregate_order[k - 1]])
        system.aggregate_start.push_back(static_cast<Index>(k));
      system.aggregate_of[system.aggregate_order[k]] = static_cast<Index>(system.aggregate_start.size() - 1);
    }
    system.aggregate_start.push_back(static_cast<Index>(count));
    aggregates_ = system.aggregate_start.size() - 1;
    centroid_.resize(aggregates_);
    parallel_for_each_index(aggregates_, [&](std::size_t aggregate) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      for (Index k = system.aggregate_start[aggregate]; k < system.aggregate_start[aggregate + 1]; ++k)
        sum += fluid.position[system.aggregate_order[k]].template cast<double>();
      centroid_[aggregate] = sum / double(system.aggregate_start[aggregate + 1] - system.aggregate_start[aggregate]);
      for (Index k = system.aggregate_start[aggregate]; k < system.aggregate_start[aggregate + 1]; ++k) {
        const Index i = system.aggregate_order[k];
        system.aggregate_offset[i] = (fluid.position[i].template cast<double>() - centroid_[aggregate]).template cast<Real>();
      }
    }, 16);

    // A_c block rows: each aggregate's diagonal block and its couplings to the aggregates around it.
    neighbour_.assign(aggregates_ * kMaxCoarseNeighbours, 0);
    block_.assign(aggregates_ * kMaxCoarseNeighbours, Block::Zero());
    used_.assign(aggregates_, 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, aggregates_, 8), [&](const tbb::blocked_range<std::size_t>& range) {
      for (std::size_t aggregate = range.begin(); aggregate != range.end(); ++aggregate) {
        Index* neighbours = neighbour_.data() + aggregate * kMaxCoarseNeighbours;
        Block* blocks = block_.data() + aggregate * kMaxCoarseNeighbours;
        std::size_t used = 1;
        neighbours[0] = static_cast<Index>(aggregate);
        // Particle i's pairs to an earlier aggregate B add −Σ_j c (P_iᵀ r)(P_jᵀ r)ᵀ to block (A, B), with
        // Pᵀ r = (r, d × r), d = x − c: that is [[S, T], [d_i]×[S, T]] with S = Σ_j c r rᵀ and
        // T = Σ_j c r (d_j × r)ᵀ, summed per B in single precision (a few pairs each) and then
        // added once (a 6×6 product in double per pair cost most of the build).
        std::array<Index, kMaxCoarseNeighbours> group_other;
        std::array<Mat3, kMaxCoarseNeighbours> group_s, group_t;
        for (Index k = system.aggregate_start[aggregate]; k < system.aggregate_start[aggregate + 1]; ++k) {
          const std::size_t i = system.aggregate_order[k];
          const Vec3 position_i = fluid.position[i];
          // A_ii less the pairs inside the aggregate (which move with it and cancel exactly): the part
          // that acts on x_i alone, and the pairs to resting particles (fixed) or other aggregates.
          Mat3 own = own_block(i);
          std::size_t groups = 0;
          const std::size_t first = lists.first(i);
          for (Index slot = 0; slot < lists.counts[i]; ++slot) {
            const Index j = lists.indices[first + slot];
            const Index other = j < count ? system.aggregate_of[j] : Index(aggregate);
            if (j < count && other == aggregate) continue;
            const Vec3 r = position_i - fluid.position[j];
            const Vec3 scaled = system.fluid_pair_coefficient[first + slot] * r;
            const Mat3 pair_block = scaled * r.transpose();
            own += pair_block;
            // Only the lower triangle of A_c is factorised: the blocks of aggregates after this one are
            // not needed.
            if (j >= count || other > aggregate) continue;
            std::size_t group = 0;
            while (group < groups && group_other[group] != other) ++group;
            if (group == groups) {
              group_other[groups++] = other;
              group_s[group].setZero();
              group_t[group].setZero();
            }
            group_s[group] += pair_block;
            group_t[group] += scaled * system.aggregate_offset[j].cross(r).transpose();
          }
          const Eigen::Vector3d offset_i = system.aggregate_offset[i].template cast<double>();
          Eigen::Matrix3d cross_i;  // [d_i]×
          cross_i << 0, -offset_i.z(), offset_i.y(), offset_i.z(), 0, -offset_i.x(), -offset_i.y(), offset_i.x(), 0;
          for (std::size_t group = 0; group < groups; ++group) {
            const Index other = group_other[group];
            std::size_t at = 1;
            while (at < used && neighbours[at] != other) ++at;
            if (at == used) {
              if (used == kMaxCoarseNeighbours) continue;  // cannot happen with cells ≥ the support radius
              neighbours[used++] = other;
            }
            const Eigen::Matrix3d pairs_s = group_s[group].template cast<double>(), pairs_t = group_t[group].template cast<double>();
            blocks[at].template topLeftCorner<3, 3>() -= pairs_s;
            blocks[at].template topRightCorner<3, 3>() -= pairs_t;
            blocks[at].template bottomLeftCorner<3, 3>() -= cross_i * pairs_s;
            blocks[at].template bottomRightCorner<3, 3>() -= cross_i * pairs_t;
          }
          // P_iᵀ O P_i with P_i = [I  −[d_i]×]: [[O, −O [d_i]×], [[d_i]× O, −[d_i]× O [d_i]×]].
          const Eigen::Matrix3d own_d = own.template cast<double>();
          const Eigen::Matrix3d own_cross = own_d * cross_i;
          blocks[0].template topLeftCorner<3, 3>() += own_d;
          blocks[0].template topRightCorner<3, 3>() -= own_cross;
          blocks[0].template bottomLeftCorner<3, 3>() -= own_cross.transpose();  // [d]× O = −(O [d]×)ᵀ, O symmetric
          blocks[0].template bottomRightCorner<3, 3>() -= cross_i * own_cross;
        }
        // An aggregate of one or two particles (or a line of them) has a rotation nothing resists: A_c
        // would be singular there, and its factorisation sent the coarse correction astray (CG needed
        // twice the iterations). A hundredth of a solid cube's moment of inertia keeps it invertible
        // without changing the others, whose rotations the viscous couplings hold hundreds of times
        // more strongly.
        double mass = 0;
        for (Index k = system.aggregate_start[aggregate]; k < system.aggregate_start[aggregate + 1]; ++k)
          mass += double(fluid.mass[system.aggregate_order[k]]);
        blocks[0].bottomRightCorner<3, 3>().diagonal().array() += 1e-2 * mass * double(aggregate_size) * double(aggregate_size) / 6;
        used_[aggregate] = static_cast<Index>(used);
      }
    });
    triplets_.clear();
    for (std::size_t aggregate = 0; aggregate < aggregates_; ++aggregate)
      for (std::size_t at = 0; at < used_[aggregate]; ++at) {
        const Index other = neighbour_[aggregate * kMaxCoarseNeighbours + at];
        if (other > aggregate) continue;  // the lower triangle is all the factorisation reads
        const Block& block = block_[aggregate * kMaxCoarseNeighbours + at];
        for (int row = 0; row < 6; ++row)
          for (int column = 0; column < 6; ++column)
            if (other < aggregate || row >= column)
              triplets_.emplace_back(int(6 * aggregate) + row, int(6 * other) + column, block(row, column));
      }
    matrix_.resize(int(6 * aggregates_), int(6 * aggregates_));
    matrix_.setFromTriplets(triplets_.begin(), triplets_.end());
    // The analysis depends on the pattern alone: redo it only when the pattern changed.
    const bool same_pattern =
        !pattern_outer_.empty() && pattern_outer_.size() == std::size_t(matrix_.outerSize() + 1) &&
        pattern_inner_.size() == std::size_t(matrix_.nonZeros()) &&
        std::equal(pattern_outer_.begin(), pattern_outer_.end(), matrix_.outerIndexPtr()) &&
        std::equal(pattern_inner_.begin(), pattern_inner_.end(), matrix_.innerIndexPtr());
    if (same_pattern) {
      factorisation_.factorize(matrix_);
    } else {
      factorisation_.compute(matrix_);
      pattern_outer_.assign(matrix_.outerIndexPtr(), matrix_.outerIndexPtr() + matrix_.outerSize() + 1);
      pattern_inner_.assign(matrix_.innerIndexPtr(), matrix_.innerIndexPtr() + matrix_.nonZeros());
    }
    system.coarse_residual.resize(6 * aggregates_);
    system.coarse_correction.resize(6 * aggregates_);
    system.coarse_motion.resize(6 * aggregates_);
    return factorisation_.info() == Eigen::Success;
  }

  /// system.coarse_correction = A_c⁻¹ Pᵀ residual.
  void solve(State& state, const std::vector<Vec3>& residual) {
    auto& system = state.viscosity_system;
    parallel_for_each_index(aggregates_, [&](std::size_t aggregate) {
      Eigen::Matrix<double, 6, 1> sum = Eigen::Matrix<double, 6, 1>::Zero();
      for (Index k = system.aggregate_start[aggregate]; k < system.aggregate_start[aggregate + 1]; ++k) {
        const Index i = system.aggregate_order[k];
        // P_iᵀ r = (r, (x_i − c) × r).
        const Eigen::Vector3d r = residual[i].cast<double>();
        sum.head<3>() += r;
        sum.tail<3>() += system.aggregate_offset[i].cast<double>().cross(r);
      }
      for (int row = 0; row < 6; ++row) system.coarse_residual[6 * aggregate + row] = sum[row];
    }, 16);
    const Eigen::Map<const Eigen::VectorXd> right(system.coarse_residual.data(), Eigen::Index(system.coarse_residual.size()));
    Eigen::Map<Eigen::VectorXd>(system.coarse_correction.data(), Eigen::Index(system.coarse_correction.size())) =
        factorisation_.solve(right);
    std::transform(system.coarse_correction.begin(), system.coarse_correction.end(), system.coarse_motion.begin(),
                   [](double value) { return static_cast<Real>(value); });
  }

  /// The coarse correction at particle i: t + ω × (x_i − c), in single precision (the sums and the
  /// factorisation are double; this is a per-particle sweep of every CG iteration).
  [[nodiscard]] static Vec3 correction(const State& state, std::size_t i) {
    const auto& system = state.viscosity_system;
    const Real* motion = system.coarse_motion.data() + 6 * system.aggregate_of[i];  // t, then ω
    return Vec3(motion[0], motion[1], motion[2]) + Vec3(motion[3], motion[4], motion[5]).cross(system.aggregate_offset[i]);
  }

 private:
  std::size_t aggregates_ = 0;
  std::vector<Eigen::Vector3d> centroid_;
  std::vector<Index> neighbour_, used_;
  std::vector<Block> block_;
  std::vector<Eigen::Triplet<double>> triplets_;
  Eigen::SparseMatrix<double> matrix_;
  std::vector<int> pattern_outer_, pattern_inner_;  // A_c's pattern at the last analysis
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>, Eigen::Lower> factorisation_;
};

CoarseViscosityLevelHolder::CoarseViscosityLevelHolder() = default;
// A copy starts with a level of its own, empty: every solve builds the level again, and a fresh
// analysis of the same pattern gives the same factorisation (Eigen's factorisations do not copy).
CoarseViscosityLevelHolder::CoarseViscosityLevelHolder(const CoarseViscosityLevelHolder& /*other*/) {}
CoarseViscosityLevelHolder::CoarseViscosityLevelHolder(CoarseViscosityLevelHolder&& other) noexcept = default;
CoarseViscosityLevelHolder& CoarseViscosityLevelHolder::operator=(const CoarseViscosityLevelHolder& other) {
  if (this != &other) level_.reset();
  return *this;
}
CoarseViscosityLevelHolder& CoarseViscosityLevelHolder::operator=(CoarseViscosityLevelHolder&& other) noexcept = default;
CoarseViscosityLevelHolder::~CoarseViscosityLevelHolder() = default;
CoarseViscosityLevel& CoarseViscosityLevelHolder::get() {
  if (!level_) level_ = std::make_unique<CoarseViscosityLevel>();
  return *level_;
}

Real update_effective_viscosity(const Parameters& parameters, State& state, const ViscosityCalibration& calibration) {
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const std::size_t count = state.active_count;
  const Real inverse_volume = 1 / particle_rest_volume(parameters.settings.particle_radius);  // ρ0_j = m_j / V
  const bool any_shear_rate = std::any_of(parameters.phases.begin(), parameters.phases.end(), phase_needs_shear_rate);
  const auto& fluid_lists = state.fluid_neighbors;
  const auto& boundary_lists = state.boundary_neighbors;
  const Real time = static_cast<Real>(state.time);
  auto wants_shear_rate = [&](std::size_t i) { return any_shear_rate && phase_needs_shear_rate(parameters.phases[fluid.phase[i]]); };
  // Particle i's viscosity, given the symmetric part of its fluid neighbours' velocity gradient
  // ∇v_i = Σ_j V_j (v_j − v_i) x_ijᵀ (dW/dr)/r, V_j f = (ρ0_j/ρ_j) × the pair gradient; returns its μ/ρ.
  auto finish_particle = [&](std::size_t i, const Mat3& fluid_gradient) {
    const FluidPhase& phase = parameters.phases[fluid.phase[i]];
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
          gradient += (calibration.boundary_gradient * state.boundary_pair_gradient[boundary_first + k] * (boundary.velocity[b] - velocity_i)) *
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
    return std::max(fluid.viscosity[i], phase.wall_viscosity(fluid.viscosity[i])) / phase.density;
  };
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
  const bool use_avx2 = any_shear_rate && avx2::available();
  if (use_avx2) {  // padded velocities for the AVX2 sweep (the positions are the density pass's)
    state.solver_velocity.resize(fluid.size());
    parallel_for_each_index(fluid.size(), [&](std::size_t i) { state.solver_velocity[i] = padded(fluid.velocity[i]); }, 4096);
  }
#endif
  return tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, count, 256), Real(0),
      [&](const tbb::blocked_range<std::size_t>& range, Real largest) {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
        if (use_avx2) {
          avx2::velocity_gradient_rows(range.begin(), range.end(), state.solver_position.data(), state.solver_velocity.data(),
                                       fluid.mass.data(), fluid.density.data(), fluid_lists.indices.data(), fluid_lists.counts.data(),
                                       fluid_lists.firsts.data(), state.fluid_pair_gradient.data(), calibration.fluid_gradient * inverse_volume,
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
                  calibration.fluid_gradient * (fluid.mass[j] * inverse_volume / fluid.density[j]) * state.fluid_pair_gradient[fluid_first + k];
              gradient += (weight * (fluid.velocity[j] - velocity_i)) * (position_i - fluid.position[j]).transpose();
            }
          }
          largest = std::max(largest, finish_particle(i, gradient));
        }
        return largest;
      },
      [](Real a, Real b) { return std::max(a, b); });
}

int solve_implicit_viscosity(const Parameters& parameters, State& state, Real time_step,
                             const ViscosityCalibration& calibration) {
  const auto& settings = parameters.settings;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const std::size_t count = state.active_count;
  if (count == 0) return 0;
  const bool any_viscosity =
      std::any_of(parameters.phases.begin(), parameters.phases.end(), [](const FluidPhase& phase) {
        return phase.rheology.model != material::RheologyModel::newtonian || phase.rheology.viscosity > 0 ||
               phase.has_wall_friction() || phase.elasticity.enabled;
      });
  if (!any_viscosity) return 0;
  // Where the largest viscous change any phase can have is below the solve's tolerance, CG would take
  // v* as it is: ‖A v* − b‖ ≤ 2 Σ_j |c_ij| r² |v| ≈ 2 (Δt μ/ρ0) coupling ‖b‖. Nothing to solve then
  // (water at centimetre spacing and millisecond steps: 13 ms a step in the 47k dam break for a
  // change of 3·10⁻⁴). The factor 1.5 covers neighbourhoods denser than the rest lattice.
  const bool negligible = std::all_of(parameters.phases.begin(), parameters.phases.end(), [&](const FluidPhase& phase) {
    if (phase.elasticity.enabled || phase.ageing.enabled()) return false;
    const Real mu = phase.rheology.model == material::RheologyModel::newtonian ? phase.rheology.viscosity
                                                                                 : phase.rheology.max_viscosity;
    const Real largest = std::max(mu, phase.has_wall_friction() ? phase.wall_viscosity(mu) : Real(0));
    return 2 * Real(1.5) * time_step * largest / phase.density * calibration.coupling < settings.viscosity_tolerance;
  });
  if (negligible) {
    parallel_for_each_index(count, [&](std::size_t i) {
      fluid.viscous_change[i] = Vec3::Zero();
      fluid.viscous_velocity[i] = fluid.velocity[i];
    }, 4096);
    return 0;
  }

  const Real support_radius = settings.support_radius_factor * settings.particle_radius;
  const Real regularisation = Real(0.01) * support_radius * support_radius;
  const auto& fluid_lists = state.fluid_neighbors;
  const auto& boundary_lists = state.boundary_neighbors;
  auto& system = state.viscosity_system;
  system.fluid_pair_coefficient.resize(fluid_lists.indices.size());
  system.boundary_pair_coefficient.resize(boundary_lists.indices.size());
  for (auto* vector : {&system.rhs, &system.residual, &system.preconditioned, &system.product, &system.start_velocity})
    vector->resize(fluid.size());
  // A.x reads x at every neighbour: resting particles are fixed (zero velocity), so zero in the direction.
  system.padded_operand.resize(fluid.size());
  std::fill(system.padded_operand.begin() + static_cast<std::ptrdiff_t>(count), system.padded_operand.end(), Vec4::Zero());
  system.inverse_diagonal.resize(count);
  system.own_block.resize(count);

  // Coefficients, preconditioner and right-hand side (positions do not move during the solve). A fluid
  // pair's c = s_i · 2 μ_i μ_j/(μ_i + μ_j) · (m_j/ρ_j) · g_ij / (r² + ε): μ_ij = 2μ_iμ_j/(μ_i + μ_j) (pair_viscosity)
  // and V_j (dW/dr)/r = (ρ0_j/ρ_j) × the pair gradient g_ij (which holds (m_j/ρ0_j)(dW/dr)/r; negative), with
  // s_i = −Δt 2(d+2) calibration V_i / V.
  const Real volume = particle_rest_volume(settings.particle_radius);
  auto pair_scale = [&](std::size_t i) {
    return -time_step * kDimensionFactor * calibration.fluid * (fluid.mass[i] / fluid.density[i]) / volume;
  };
  // The rest of particle i's set-up, given its fluid pairs' Σ c r rᵀ.
  auto finish_particle = [&](std::size_t i, const Mat3& fluid_coupling) {
    const FluidPhase& phase = parameters.phases[fluid.phase[i]];
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
        coefficient = -time_step * kDimensionFactor * calibration.boundary * phase.wall_viscosity(fluid.viscosity[i]) * volume_i *
                      state.boundary_pair_gradient[boundary_first + k] / (r.squaredNorm() + regularisation);
        own_block += coefficient * r * r.transpose();
        rhs += (coefficient * r.dot(boundary.velocity[b])) * r;
      }
      system.boundary_pair_coefficient[boundary_first + k] = coefficient;
    }
    system.own_block[i] = own_block;
    system.inverse_diagonal[i] = (own_block + fluid_coupling).inverse();
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
      avx2::viscous_coefficient_rows(range.begin(), range.end(), state.solver_position.data(), fluid.viscosity.data(), fluid.mass.data(),
                                     fluid.density.data(), fluid_lists.indices.data(), fluid_lists.counts.data(), fluid_lists.firsts.data(),
                                     state.fluid_pair_gradient.data(), regularisation, system.fluid_pair_coefficient.data(), pair_scale,
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
                                                       state.fluid_pair_gradient[fluid_first + k] / denominator
                                                 : Real(0);
        system.fluid_pair_coefficient[fluid_first + k] = coefficient;
        fluid_coupling += coefficient * r * r.transpose();
      }
      finish_particle(i, fluid_coupling);
    }
  });

  // y = A x for particle i, x in system.padded_operand (padded: one SIMD operation per neighbour; the
  // positions are the density pass's padded copies, unchanged until advection); the generic
  // loop of rows() below, which takes the AVX2 sweep where there is one.
  const Vec4* padded_position = state.solver_position.data();
  const Vec4* padded_operand = system.padded_operand.data();
  auto multiply_row = [&](std::size_t i) {
    const Vec4 position_i = padded_position[i];
    const Vec4 x_i = padded_operand[i];
    Vec4 result = Vec4::Zero();
    const std::size_t fluid_first = fluid_lists.first(i);
    const Index* neighbor = fluid_lists.indices.data() + fluid_first;
    const Real* coefficient = system.fluid_pair_coefficient.data() + fluid_first;
    for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
      const Index j = neighbor[k];
      const Vec4 r = position_i - padded_position[j];
      result += (coefficient[k] * r.dot(x_i - padded_operand[j])) * r;
    }
    // The walls' pairs (fixed velocities, on the right-hand side) leave c r rᵀ x_i, summed in own_block.
    return Vec3(result.head<3>() + system.own_block[i] * x_i.head<3>());
  };
  // visit(i, (A x)_i) for the particles of a range, in order.
  auto rows = [&](const tbb::blocked_range<std::size_t>& range, auto&& visit) {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
    if (avx2::available()) {
      avx2::viscous_product_rows(range.begin(), range.end(), padded_position, padded_operand, fluid_lists.indices.data(),
                                 fluid_lists.counts.data(), fluid_lists.firsts.data(), system.fluid_pair_coefficient.data(),
                                 system.own_block.data(), visit);
      return;
    }
#endif
    for (std::size_t i = range.begin(); i != range.end(); ++i) visit(i, multiply_row(i));
  };

  // The coarse level (see CoarseViscosityLevel), from A's blocks: each particle's own block and the pairs' c r rᵀ.
  CoarseViscosityLevel& coarse = system.coarse_level.get();
  const bool two_level = system.previous_iterations > kCoarseLevelFromIterations &&
                         coarse.build(state, count, kAggregateSpacings * 2 * settings.particle_radius,
                                      [&](std::size_t i) -> const Mat3& { return system.own_block[i]; });
  // z = D⁻¹ r (+ the coarse correction) into system.preconditioned; returns r·z.
  auto precondition = [&]() {
    if (two_level) coarse.solve(state, system.residual);
    return deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
      Vec3 z = system.inverse_diagonal[i] * system.residual[i];
      if (two_level) z += coarse.correction(state, i);
      system.preconditioned[i] = z;
      sums[0] += double(system.residual[i].dot(z));
    })[0];
  };

  // Preconditioned conjugate gradients on v (in fluid.velocity), from the warm start. Each iteration is
  // four sweeps: A p with p·Ap, the update with r·r, the preconditioner with r·z, and the new direction.
  auto& velocity = fluid.velocity;
  const auto start = deterministic_row_sums<2>(count, rows, [&](std::size_t i, const Vec3& row, std::array<double, 2>& sums) {
    const Vec3 residual = system.rhs[i] - row;
    system.residual[i] = residual;
    sums[0] += double(system.rhs[i].squaredNorm());
    sums[1] += double(residual.squaredNorm());
  });
  double residual_norm = std::sqrt(start[1]);
  // A second start: the velocity the last solve ended with. v* carries this step's pressure and gravity
  // kicks, rough on the particle scale, which a stiff paste's viscosity takes out again at the cost of
  // most of CG's iterations (the clay bench's first residual was 10⁴–10⁵ times the tolerance from
  // v* plus the last change). The last solution lacks this step's acceleration, and CG stops within
  // the tolerance before putting it back, step after step (a Bingham channel flow then lagged 2.6 %).
  // So the start is the combination α v_A + β v_B of both that is best in A's energy norm (a 2×2
  // Galerkin system from the two products): clay 41 → 11 iterations a step, the channel flow unbiased.
  // Only where the first start is far off (a stiff material): a runny one starts within a few times the
  // tolerance, and a blend with the last solution, small as it is (3 % in a sessile water drop), would
  // take part of this step's kicks away without an iteration to put them back (the drop then shed 8 %).
  constexpr double kFarOff = 10;
  if (settings.warm_start && residual_norm > kFarOff * settings.viscosity_tolerance * std::sqrt(start[0])) {
    parallel_for_each_index(count, [&](std::size_t i) { system.padded_operand[i] = padded(fluid.viscous_velocity[i]); }, 1024);
    // v_A = velocity, r_A = residual; v_B = viscous_velocity, r_B into product. A v = b − r.
    const auto sums = deterministic_row_sums<5>(count, rows, [&](std::size_t i, const Vec3& row, std::array<double, 5>& sums) {
      const Vec3 residual = system.rhs[i] - row;
      system.product[i] = residual;
      const Vec3 product_a = system.rhs[i] - system.residual[i], product_b = system.rhs[i] - residual;
      sums[0] += double(velocity[i].dot(product_a));                    // v_A·A v_A
      sums[1] += double(fluid.viscous_velocity[i].dot(product_a));      // v_B·A v_A
      sums[2] += double(fluid.viscous_velocity[i].dot(product_b));      // v_B·A v_B
      sums[3] += double(velocity[i].dot(system.rhs[i]));                // v_A·b
      sums[4] += double(fluid.viscous_velocity[i].dot(system.rhs[i]));  // v_B·b
    });
    const double determinant = sums[0] * sums[2] - sums[1] * sums[1];
    if (determinant > 1e-12 * sums[0] * sums[2]) {
      const Real alpha = static_cast<Real>((sums[3] * sums[2] - sums[4] * sums[1]) / determinant);
      const Real beta = static_cast<Real>((sums[4] * sums[0] - sums[3] * sums[1]) / determinant);
      // r = b − A(α v_A + β v_B) = (1 − α − β) b + α r_A + β r_B.
      residual_norm = std::sqrt(deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
        velocity[i] = alpha * velocity[i] + beta * fluid.viscous_velocity[i];
        system.residual[i] = (1 - alpha - beta) * system.rhs[i] + alpha * system.residual[i] + beta * system.product[i];
        sums[0] += double(system.residual[i].squaredNorm());
      })[0]);
    }
  }
  double residual_dot = precondition();
  parallel_for_each_index(count, [&](std::size_t i) { system.padded_operand[i] = padded(system.preconditioned[i]); }, 1024);
  // Relative to the momentum ‖b‖, not to the first residual: the first residual is mostly the rough,
  // particle-scale part of the change, which CG removes first; the smooth part (a stiff paste spreading
  // like water after the pressure solve) has small residuals but is what moves the material. Stopping
  // at 10⁻³ of the first residual lets an unyielded column collapse.
  const double tolerance = settings.viscosity_tolerance * std::sqrt(start[0]);
  int iterations = 0;
  while (residual_norm > tolerance && iterations < settings.max_viscosity_iterations) {
    const double curvature = deterministic_row_sums<1>(count, rows, [&](std::size_t i, const Vec3& row, std::array<double, 1>& sums) {
      system.product[i] = row;
      sums[0] += double(system.padded_operand[i].head<3>().dot(row));
    })[0];
    if (!(curvature > 0)) break;
    const Real step = static_cast<Real>(residual_dot / curvature);
    const auto next = deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
      velocity[i] += step * system.padded_operand[i].head<3>();
      system.residual[i] -= step * system.product[i];
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
  system.previous_iterations = two_level ? std::max(iterations, kCoarseLevelFromIterations + 1) : iterations;
  parallel_for_each_index(count, [&](std::size_t i) {
    fluid.viscous_change[i] = velocity[i] - system.start_velocity[i];
    fluid.viscous_velocity[i] = velocity[i];
  }, 1024);

  // Wall friction as a reaction on the bodies: the body feels −F_ib = (c_ib/Δt) x xᵀ (v_i − v_b).
  const bool any_boundary_viscosity = std::any_of(parameters.phases.begin(), parameters.phases.end(),
                                                  [](const FluidPhase& phase) { return phase.has_wall_friction(); });
  if (any_boundary_viscosity && !state.bodies.empty()) {
    const Real inverse_time_step = Real(1) / time_step;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 128), [&](const tbb::blocked_range<std::size_t>& range) {
      std::vector<Wrench>& wrenches = thread_body_wrenches(state);
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
        const std::size_t boundary_first = boundary_lists.first(i);
        for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
          const Real coefficient = system.boundary_pair_coefficient[boundary_first + k];
          if (coefficient == 0) continue;
          const Index b = boundary_lists.indices[boundary_first + k];
          const Vec3 r = fluid.position[i] - boundary.position[b];
          const Vec3 force = (coefficient * inverse_time_step * r.dot(velocity[i] - boundary.velocity[b])) * r;
          Wrench& wrench = wrenches[boundary.body[b]];
          wrench.force += force;
          wrench.torque += (boundary.position[b] - state.bodies[boundary.body[b]].pose.position).cross(force);
        }
      }
    });
  }
  return iterations;
}

void apply_xsph(const Parameters& parameters, State& state) {
  const Real factor = parameters.settings.xsph_factor;
  if (factor <= 0) return;
  auto& fluid = state.fluid;
  const std::size_t count = state.active_count;
  const Real support_radius = parameters.settings.support_radius_factor * parameters.settings.particle_radius;
  auto& smoothed = state.scratch_vec3;
  smoothed.resize(count);
  with_kernel(parameters.settings.kernel, support_radius, [&](const auto& kernel) {
    parallel_for_each_index(count, [&](std::size_t i) {
      Vec3 change = Vec3::Zero();
      for (const Index j : state.fluid_neighbors.of(i))
        change += (fluid.mass[j] / fluid.density[j] * kernel.W((fluid.position[i] - fluid.position[j]).norm())) *
                  (fluid.velocity[j] - fluid.velocity[i]);
      smoothed[i] = fluid.velocity[i] + factor * change;
    }, 256);
  });
  std::copy(smoothed.begin(), smoothed.end(), fluid.velocity.begin());
}

}  // namespace m3dp::sph::stages
