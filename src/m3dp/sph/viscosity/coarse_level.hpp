#pragma once
// The coarse level of the implicit viscosity's preconditioner (viscosity/weiler2018_cg.cpp): aggregates
// of particles that move as rigid bodies.
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>

#include <vector>

#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

// Aggregates of the coarse level: cells of this many particle spacings (up to 512 particles). Smaller
// ones save iterations but their factorisation costs more than it saves (docs/decisions.md).
constexpr Real kAggregateSpacings = 8;
// Aggregates a coarse cell can couple to: its own and the 26 around it (cells ≥ the support radius).
constexpr std::size_t kMaxCoarseNeighbours = 27;
// The coarse level is built when the last solve needed more CG iterations than this: it costs about as
// much as five iterations, so a runny material's solve (a few iterations) does without it.
constexpr int kCoarseLevelFromIterations = 12;

/// The coarse level of the viscosity solve's preconditioner. A stiff paste is nearly rigid over many
/// particles, and block Jacobi, which sees one particle at a time, needs about as many CG iterations as
/// the material is particles across to move it as a whole. The coarse
/// level lets each aggregate of particles move as a rigid body: z = D⁻¹ r + P A_c⁻¹ Pᵀ r, with
/// P_i = [I  −[x_i − c]×] (v_i = t + ω × (x_i − c), c the aggregate's centroid) and A_c = Pᵀ A P,
/// built and factorised for every solve (six unknowns per aggregate of up to 512 particles). It lives
/// in the workspace: its buffers are reused, and so is the factorisation's symbolic analysis (the
/// AMD ordering) while A_c keeps its pattern. Rigid motions
/// are what the viscous term cannot see: a pair's c r rᵀ (v_i − v_j) vanishes for a common
/// translation and for a common rotation.
class CoarseViscosityLevel {
 public:
  using Block = Eigen::Matrix<double, 6, 6>;

  /// Groups the active particles into aggregates and factorises A_c, from A's pair coefficients c (a
  /// pair's block is c r rᵀ) and `own_block(i)`, the part of A that acts on x_i alone (m_i I and walls).
  bool build(const State& state, Workspace& workspace, std::size_t count, Real aggregate_size);
  /// system.coarse_correction = A_c⁻¹ Pᵀ residual.
  void solve(Workspace& workspace, const std::vector<Vec3>& residual);
  /// The coarse correction at particle i: t + ω × (x_i − c), in single precision (the sums and the
  /// factorisation are double; this is a per-particle sweep of every CG iteration).
  [[nodiscard]] static Vec3 correction(const Workspace& workspace, std::size_t i) {
    const auto& system = workspace.viscosity_system;
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


}  // namespace m3dp::sph::stages
