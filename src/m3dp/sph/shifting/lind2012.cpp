// Stage "viscosity", last: particle shifting (Lind, Xu, Stansby & Rogers 2012, J. Comput. Phys. 231,
// 1499–1523), scaled by the particle's speed as Skillen, Lind, Stansby & Rogers 2013 (Comput. Methods
// Appl. Mech. Engrg. 265, 163–173) do: δr_i = −A h |v_i| Δt Σ_j V_j (1 + R (W_ij / W(d))⁴) ∇W_ij.
// The density solve keeps each particle's density at ρ0 but not the particles evenly spaced: a
// viscous paste squeezed out of a nozzle keeps pairs and gaps (nearest neighbours at a median of 0.75
// d) that still sum to ρ0. Shifting moves particles down the gradient of their concentration, into
// the gaps; the R term parts pairs (Monaghan 2000's anti-clumping weight). At a free surface only the
// tangential part acts, so the surface does not diffuse outwards (Lind 2012, Sec. 3.3). Only viscous
// flow is shifted (water rearranges itself). A settling particle (slower than the wake speed) does
// not move, nor does unyielded paste (it moves as a solid: shifting it would let a standing column
// sag), nor an elastic material (its stress is where its particles are).
#include <algorithm>
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/simd/neighbor_sums_avx2.hpp"
#include "m3dp/sph/stages.hpp"

#include <tbb/parallel_for.h>

namespace m3dp::sph::stages {
namespace {
/// Σ V W, Σ V g r and Σ (1 + R (W/W(d))⁴) V g r over a particle's neighbours (g = (dW/dr)/r).
struct Sums {
  Real concentration;
  Vec3 gradient, weighted;
};
}  // namespace

void shift_particles(const Model& model, State& state, Workspace& workspace) {
  const Real factor = model.settings.shifting_factor;
  const std::size_t count = state.active_count;
  // With tension on, also where the viscosity solve's warm start already met its tolerance: stretched
  // material rearranges however its viscosity solve went.
  const bool viscous = state.last_step.viscosity_iterations > 0 || (model.settings.tension && state.last_step.viscosity_solved);
  if (!(factor > 0) || count == 0 || !viscous) return;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const Real diameter = model.particle_diameter, support = model.support_radius;
  const Real volume = model.particle_volume;
  const Real time_step = state.time_step;
  const Real settling_speed = model.settings.wake_speed;
  // Below this ratio of its full neighbourhood's kernel sum a particle is at the free surface.
  constexpr Real kSurfaceRatio = Real(0.9);
  constexpr Real kClumping = Real(0.2);                // R
  constexpr Real kViscousRegime = Real(0.1);
  const Real largest_shift = Real(0.1) * diameter;     // per step: shifting is a correction, not a flow
  auto& shift = workspace.scratch_vec3;
  shift.assign(count, Vec3::Zero());
  const auto& fluid_lists = workspace.fluid_neighbors;
  with_kernel(model.settings.kernel, support, [&](const auto& kernel) {
    const Real reference = Real(1) / kernel.W(diameter);
    const Real time = static_cast<Real>(state.time);
    // Whether particle i is shifted at all.
    const auto wants = [&](std::size_t i) {
      const FluidPhase& phase = model.phases[fluid.phase[i]];
      // An elastic material's stress is where its particles are; an unyielded paste moves as a solid.
      if (phase.elasticity.enabled) return false;
      if (unyielded(phase, fluid, i, time)) return false;
      // Only where viscosity rules the step (viscous diffusion number ν Δt / h² above 0.1) do the
      // particles move as a block and keep the pairs they were emitted with; water (1e-3 or less)
      // rearranges itself, and shifting its thin films shed them (a sessile drop lost 8 % of its rim).
      if (fluid.viscosity[i] * time_step < kViscousRegime * phase.density * support * support) return false;
      // Slower than the wake speed it is settling: shifting it, and its neighbours' pressure answering,
      // would keep it from coming to rest (four times the particles kept moving in the ur10_wall print).
      // Unless it is pulled (under tension): stretched material, however slowly, has to take new
      // neighbours along the stretch, or its lattice's layers part and it cracks across.
      return fluid.velocity[i].norm() >= settling_speed || fluid.kappa_tension[i] < 0;
    };
    // Σ V W, Σ V g r and Σ (1 + R (W/W(d))⁴) V g r over the neighbours of particle i at 0 < r < h.
    const auto add = [&](const Vec3& position_i, const Vec3& other, Real other_volume, Sums& sums) {
      const Vec3 r = position_i - other;
      const Real distance = r.norm();
      if (distance >= support || distance == 0) return;
      const auto [value, gradient_factor] = kernel.value_and_gradient_factor(distance);
      sums.concentration += other_volume * value;
      const Vec3 pair = (other_volume * gradient_factor) * r;
      const Real clumping = value * reference;
      sums.gradient += pair;
      sums.weighted += (1 + kClumping * clumping * clumping * clumping * clumping) * pair;
    };
    // The shift from the sums over the particle itself and its fluid neighbours: the walls' added, the
    // surface's normal part taken out.
    const auto finish = [&](std::size_t i, Real fluid_concentration, const Vec3& fluid_gradient, const Vec3& fluid_weighted) {
      const Vec3 position_i = fluid.position[i];
      Sums sums{fluid_concentration, fluid_gradient, fluid_weighted};
      for (const Index b : workspace.boundary_neighbors.of(i)) add(position_i, boundary.position[b], boundary.volume[b], sums);
      // A pulled particle is shifted as one at least at the wake speed.
      const Real speed = fluid.kappa_tension[i] < 0 ? std::max(fluid.velocity[i].norm(), settling_speed) : fluid.velocity[i].norm();
      Vec3 displacement = (-factor * support * speed * time_step) * sums.weighted;
      // The normal counts the walls: with the fluid's alone a slumping paste's foot slid out along the
      // floor (the τ' = 0.2 slump 23 % too far).
      if (sums.concentration < kSurfaceRatio && sums.gradient.squaredNorm() > 0) {
        const Vec3 inward = sums.gradient.normalized();  // the concentration rises into the material
        displacement -= displacement.dot(inward) * inward;
      }
      displacement = without_push_into_nozzles(model, state, position_i, displacement);
      const Real length = displacement.norm();
      if (length > largest_shift) displacement *= largest_shift / length;
      shift[i] = displacement;
    };
#ifdef M3DP_NEIGHBOR_SUMS_AVX2
    if (avx2::available()) {  // the fluid pairs eight at a time, from the density pass's padded positions
      tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 2048), [&](const tbb::blocked_range<std::size_t>& range) {
        avx2::shifting_sum_rows(range.begin(), range.end(), kernel, workspace.solver_position.data(), fluid_lists.indices.data(),
                                fluid_lists.counts.data(), fluid_lists.firsts.data(), volume, reference, kClumping, wants,
                                [&](std::size_t i, Real concentration, const Vec3& gradient, const Vec3& weighted) {
                                  finish(i, volume * kernel.W_zero() + concentration, gradient, weighted);
                                });
      });
      return;
    }
#endif
    parallel_for_each_index(count, [&](std::size_t i) {
      if (!wants(i)) return;
      Sums sums{volume * kernel.W_zero(), Vec3::Zero(), Vec3::Zero()};
      for (const Index j : fluid_lists.of(i)) add(fluid.position[i], fluid.position[j], volume, sums);
      finish(i, sums.concentration, sums.gradient, sums.weighted);
    }, 2048);
  });
  parallel_for_each_index(count, [&](std::size_t i) { fluid.position[i] += shift[i]; }, 8192);
}

}  // namespace m3dp::sph::stages
