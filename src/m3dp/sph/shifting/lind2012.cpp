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
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void shift_particles(const Model& model, State& state, Workspace& workspace) {
  const Real factor = model.settings.shifting_factor;
  const std::size_t count = state.active_count;
  if (!(factor > 0) || count == 0 || state.last_step.viscosity_iterations == 0) return;
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
  with_kernel(model.settings.kernel, support, [&](const auto& kernel) {
    const Real reference = Real(1) / kernel.W(diameter);
    const Real time = static_cast<Real>(state.time);
    parallel_for_each_index(count, [&](std::size_t i) {
      const FluidPhase& phase = model.phases[fluid.phase[i]];
      // An elastic material's stress is where its particles are; an unyielded paste moves as a solid.
      if (phase.elasticity.enabled) return;
      if (unyielded(phase, fluid, i, time)) return;
      // Only where viscosity rules the step (viscous diffusion number ν Δt / h² above 0.1) do the
      // particles move as a block and keep the pairs they were emitted with; water (1e-3 or less)
      // rearranges itself, and shifting its thin films shed them (a sessile drop lost 8 % of its rim).
      if (fluid.viscosity[i] * time_step < kViscousRegime * phase.density * support * support) return;
      const Real speed = fluid.velocity[i].norm();
      // Slower than the wake speed it is settling: shifting it, and its neighbours' pressure answering,
      // would keep it from coming to rest (four times the particles kept moving in the ur10_wall print).
      if (speed < settling_speed) return;
      const Vec3 position_i = fluid.position[i];
      Real concentration = volume * kernel.W_zero();
      Vec3 gradient = Vec3::Zero(), weighted = Vec3::Zero();
      const auto add = [&](const Vec3& other, Real other_volume) {
        const Vec3 r = position_i - other;
        const Real distance = r.norm();
        if (distance >= support || distance == 0) return;
        const auto [value, gradient_factor] = kernel.value_and_gradient_factor(distance);
        concentration += other_volume * value;
        const Vec3 pair = (other_volume * gradient_factor) * r;
        const Real clumping = value * reference;
        gradient += pair;
        weighted += (1 + kClumping * clumping * clumping * clumping * clumping) * pair;
      };
      for (const Index j : workspace.fluid_neighbors.of(i)) add(fluid.position[j], volume);
      for (const Index b : workspace.boundary_neighbors.of(i)) add(boundary.position[b], boundary.volume[b]);
      Vec3 displacement = (-factor * support * speed * time_step) * weighted;
      // The normal counts the walls: with the fluid's alone a slumping paste's foot slid out along the
      // floor (the τ' = 0.2 slump 23 % too far).
      if (concentration < kSurfaceRatio && gradient.squaredNorm() > 0) {
        const Vec3 inward = gradient.normalized();  // the concentration rises into the material
        displacement -= displacement.dot(inward) * inward;
      }
      displacement = without_push_into_nozzles(model, state, position_i, displacement);
      const Real length = displacement.norm();
      if (length > largest_shift) displacement *= largest_shift / length;
      shift[i] = displacement;
    }, 2048);
  });
  parallel_for_each_index(count, [&](std::size_t i) { fluid.position[i] += shift[i]; }, 8192);
}

}  // namespace m3dp::sph::stages
