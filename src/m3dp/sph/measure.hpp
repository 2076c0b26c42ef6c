#pragma once
// Measurements of the engine's state that outputs and tests trust: computed afresh from positions,
// not taken from what a stage estimated on the way.
#include <span>
#include <vector>

#include "m3dp/sph/solver.hpp"

namespace m3dp::sph {

/// Every fluid particle's SPH density (kg/m³) where it is now, moving or resting, as the density pass
/// sums it: ρ0_i (Σ_j V W_ij + Σ_b V_b W_ib), V = d³ every fluid particle's volume and V_b the walls'
/// Akinci volumes. Into `density`, one per particle in the solver's order.
void measure_density(const Solver& solver, std::vector<Real>& density);

/// Statistics of ρ/ρ0 − 1 over particles: what the run reports of its density. Particles at a free
/// surface lack neighbours and read low, so the mean and median fall below 0 where much of the
/// material is surface; compression shows in the 99th percentile and the max. Percentiles as numpy's
/// default (linear between the order statistics around the rank).
struct DensityStatistics {
  std::size_t particles = 0;
  double mean = 0, median = 0, p99 = 0, max = 0;
};
/// The `fraction` (0..1) percentile of `sorted` (ascending, not empty) as numpy's default computes it:
/// linear between the order statistics around the rank.
double percentile_of_sorted(std::span<const double> sorted, double fraction);
/// Of `density` (kg/m³, one per particle) against each particle's phase's rest density.
DensityStatistics density_statistics(const Solver& solver, const std::vector<Real>& density);

/// The fluid particles inside nozzle `nozzle`'s bore now (stages::BoreRegion), moving or resting; 0
/// for a nozzle without a bore. The volume balance's material that has not left the exit.
std::size_t particles_in_bore(const Solver& solver, std::size_t nozzle);

}  // namespace m3dp::sph
