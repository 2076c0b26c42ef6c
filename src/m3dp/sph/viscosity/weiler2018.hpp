#pragma once
// Internal to the implicit viscosity (viscosity/weiler2018*.cpp): the linear system's operator and
// the deterministic sums its conjugate gradients take. See weiler2018.cpp for the method.
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <array>

#include "m3dp/core/deterministic_sums.hpp"
#include "m3dp/sph/simd/neighbor_sums_avx2.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages::weiler2018 {

inline constexpr Real kDimensionFactor = 2 * (3 + 2);  // 2(d+2), d = 3

using m3dp::deterministic_range_sums;
using m3dp::deterministic_sums;

/// y = A x, x in the system's padded_operand (padded: one SIMD operation per neighbour; the positions
/// are the density pass's padded copies, unchanged until advection).
class ViscousOperator {
 public:
  explicit ViscousOperator(const Workspace& workspace)
      : position_(workspace.solver_position.data()),
        operand_(workspace.viscosity_system.padded_operand.data()),
        lists_(workspace.fluid_neighbors),
        coefficient_(workspace.viscosity_system.fluid_pair_coefficient.data()),
        own_block_(workspace.viscosity_system.own_block.data()),
        stress_product_(workspace.viscosity_system.stress_product.empty() ? nullptr : workspace.viscosity_system.stress_product.data()) {}

  /// (A x)_i.
  [[nodiscard]] Vec3 row(std::size_t i) const {
    const Vec3 pair_part = pair_row(i);
    return stress_product_ ? Vec3(pair_part + stress_product_[i]) : pair_part;
  }

  /// visit(i, (A x)_i) for the particles of a range, in order: the AVX-512 or AVX2 sweep where there is one.
  template <class Visit>
  void rows(const tbb::blocked_range<std::size_t>& range, Visit&& visit) const {
    if (stress_product_) {  // the stress form's share, made for this operand by prepare_stress_product
      pair_rows(range, [&](std::size_t i, const Vec3& row) { visit(i, Vec3(row + stress_product_[i])); });
      return;
    }
    pair_rows(range, visit);
  }

  /// The N sums of body(i, (A x)_i, sums) over the particles, in a fixed order.
  template <std::size_t N, class Body>
  std::array<double, N> row_sums(std::size_t count, Body&& body) const {
    return deterministic_range_sums<N>(count, [&](const tbb::blocked_range<std::size_t>& range, std::array<double, N>& sums) {
      rows(range, [&](std::size_t i, const Vec3& row) { body(i, row, sums); });
    });
  }

 private:
  /// visit(i, the pair form's and the walls' (A x)_i) for the particles of a range.
  template <class Visit>
  void pair_rows(const tbb::blocked_range<std::size_t>& range, Visit&& visit) const {
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
    if (avx512::available()) {
      avx512::viscous_product_rows(range.begin(), range.end(), position_, operand_, lists_.indices.data(), lists_.counts.data(),
                                   lists_.firsts.data(), coefficient_, own_block_, visit);
      return;
    }
    if (avx2::available()) {
      avx2::viscous_product_rows(range.begin(), range.end(), position_, operand_, lists_.indices.data(), lists_.counts.data(),
                                 lists_.firsts.data(), coefficient_, own_block_, visit);
      return;
    }
#endif
    for (std::size_t i = range.begin(); i != range.end(); ++i) visit(i, pair_row(i));
  }

  /// The pair form's and the walls' (A x)_i.
  [[nodiscard]] Vec3 pair_row(std::size_t i) const {
    const Vec4 position_i = position_[i];
    const Vec4 x_i = operand_[i];
    Vec4 result = Vec4::Zero();
    const std::size_t first = lists_.first(i);
    const Index* neighbor = lists_.indices.data() + first;
    const Real* coefficient = coefficient_ + first;
    for (Index k = 0; k < lists_.counts[i]; ++k) {
      const Index j = neighbor[k];
      const Vec4 r = position_i - position_[j];
      result += (coefficient[k] * r.dot(x_i - operand_[j])) * r;
    }
    // The walls' pairs (fixed velocities, on the right-hand side) leave c r rᵀ x_i, summed in own_block.
    return Vec3(result.head<3>() + own_block_[i] * x_i.head<3>());
  }

  const Vec4* position_;
  const Vec4* operand_;
  const NeighborLists& lists_;
  const Real* coefficient_;
  const Mat3* own_block_;
  const Vec3* stress_product_;  // null without the stress form
};

/// The stress form's share of A times the system's padded operand x into stress_product (a no-op
/// without it; weiler2018_stress.cpp): −Δt θ V Σ_j (τ_i M_iᵀ + τ_j M_jᵀ) V∇W_ij with τ = μ (G + Gᵀ) of
/// x and G_i its renormalised gradient. Run before each product of a new operand.
void prepare_stress_product(const Model& model, const State& state, Workspace& workspace);
/// The stress form's gradient corrections M_i of this step's positions (weiler2018_stress.cpp).
void prepare_gradient_correction(const Model& model, const State& state, Workspace& workspace);
/// The stress form's share of the right-hand side: the stress of the no-slip walls' own motion.
void add_stress_form_walls_to_rhs(const Model& model, const State& state, Workspace& workspace);

/// The system A v = b of this step: pair coefficients, block-Jacobi preconditioner, right-hand side,
/// and the warm start v* + last step's viscous change in state.fluid.velocity (weiler2018_system.cpp).
void build_system(const Model& model, State& state, Workspace& workspace);
/// The first residual, and the blended start where v* is far off (weiler2018_start.cpp). Returns
/// ‖r‖ and ‖b‖.
struct StartResidual {
  double residual_norm = 0, rhs_norm = 0;
};
StartResidual start_solve(const Model& model, State& state, Workspace& workspace);
/// Preconditioned conjugate gradients from the start to the tolerance (weiler2018_cg.cpp). Returns iterations.
int run_conjugate_gradients(const Model& model, State& state, Workspace& workspace, const StartResidual& start);
/// Wall friction as a reaction on the bodies (weiler2018_wall_reaction.cpp).
void add_wall_reaction(const Model& model, State& state, Workspace& workspace);

}  // namespace m3dp::sph::stages::weiler2018
