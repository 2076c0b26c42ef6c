#include "m3dp/sph/viscosity/coarse_level.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>

#include "m3dp/core/parallel.hpp"

namespace m3dp::sph::stages {

/// Groups the active particles into aggregates and factorises A_c, from A's pair coefficients c (a
/// pair's block is c r rᵀ) and each particle's own block (the part of A that acts on x_i alone: m_i I
/// and walls). Returns false where the factorisation failed.
bool CoarseViscosityLevel::build(const State& state, Workspace& workspace, std::size_t count, Real aggregate_size) {
  auto& system = workspace.viscosity_system;
  const auto& fluid = state.fluid;
  const auto& lists = workspace.fluid_neighbors;
  const auto& own_blocks = system.own_block;
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
        Mat3 own = own_blocks[i];
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

void CoarseViscosityLevel::solve(Workspace& workspace, const std::vector<Vec3>& residual) {
  auto& system = workspace.viscosity_system;
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

}  // namespace m3dp::sph::stages
