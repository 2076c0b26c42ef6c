// Micropolar materials after Bender, Koschier, Kugelstadt, Weiler, "A Micropolar Material Model for
// Turbulent SPH Fluids", SCA 2017 (see material/vorticity/micropolar_bender2017.hpp), with the curls in
// their difference form, (∇×a)_i = Σ_j V_j (a_i − a_j) × ∇W_ij, V_j = m_j/ρ_j:
//   a_i += (μ_t/ρ_i) ρ0 Σ_j V_j (ω_i − ω_j) × ∇W_ij        (walls: ω_b = 0, their reaction to the body)
//   ω_i' = [ω_i + Δt (μ_t/(ρ_i Θ)) (∇×v)_i + smoothing] / (1 + 2Δt μ_t/(ρ_i Θ))
// The relaxation −2μ_t ω/(ρΘ) is integrated implicitly: Θ is tiny (a particle's own inertia), and an
// explicit step would need Δt < ρΘ/μ_t. In a rigid rotation at Ω the curl of v is 2Ω, so ω settles to
// Ω and, uniform, exerts no force. The smoothing pulls ω towards its neighbours' Shepard mean.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>

#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void apply_micropolar(const Model& model, State& state, Workspace& workspace) {
  const Real time_step = state.time_step;
  const auto& microinertia = model.microinertia;
  const bool any = std::any_of(model.phases.begin(), model.phases.end(),
                               [](const FluidPhase& phase) { return phase.micropolar.enabled; });
  if (!any) return;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const std::size_t count = state.active_count;
  const Real inverse_volume = 1 / model.particle_volume;  // ρ0_j = m_j / V
  const auto& fluid_lists = workspace.fluid_neighbors;
  const auto& boundary_lists = workspace.boundary_neighbors;
  const Real support_radius = model.support_radius;
  // New ω into scratch first: every particle reads its neighbours' old ω.
  auto& next = workspace.scratch_vec3;
  next.resize(count);
  with_kernel(model.settings.kernel, support_radius, [&](const auto& kernel) {
    for_each_wrench_chunk(state, workspace, count, [&](const tbb::blocked_range<std::size_t>& range, std::span<Wrench> wrenches) {
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
        const FluidPhase& phase = model.phases[fluid.phase[i]];
        if (!phase.micropolar.enabled) {
          next[i] = Vec3::Zero();
          continue;
        }
        const Vec3 position_i = fluid.position[i];
        const Vec3 velocity_i = fluid.velocity[i];
        const Vec3 omega_i = fluid.angular_velocity[i];
        const Real coupling = phase.micropolar.vortex_viscosity / fluid.density[i];  // μ_t/ρ_i (m²/s)
        Vec3 curl_omega = Vec3::Zero(), curl_velocity = Vec3::Zero(), smoothed = Vec3::Zero();
        Real weight_sum = kernel.W_zero() * fluid.mass[i] / fluid.density[i];
        smoothed += weight_sum * omega_i;
        const std::size_t fluid_first = fluid_lists.first(i);
        for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
          const Index j = fluid_lists.indices[fluid_first + k];
          const Vec3 r = position_i - fluid.position[j];
          // V_j ∇W_ij with V_j = m_j/ρ_j: the stored pair gradient holds V = m_j/ρ0_j.
          const Vec3 gradient = ((fluid.mass[j] * inverse_volume / fluid.density[j]) * workspace.fluid_pair_gradient[fluid_first + k]) * r;
          curl_omega += (omega_i - fluid.angular_velocity[j]).cross(gradient);
          curl_velocity += (velocity_i - fluid.velocity[j]).cross(gradient);
          const Real weight = fluid.mass[j] / fluid.density[j] * kernel.W(r.norm());
          smoothed += weight * fluid.angular_velocity[j];
          weight_sum += weight;
        }
        const std::size_t boundary_first = boundary_lists.first(i);
        for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
          const Index b = boundary_lists.indices[boundary_first + k];
          const Vec3 r = position_i - boundary.position[b];
          const Vec3 gradient = workspace.boundary_pair_gradient[boundary_first + k] * r;
          curl_omega += omega_i.cross(gradient);
          curl_velocity += (velocity_i - boundary.velocity[b]).cross(gradient);
          const Vec3 force = -fluid.mass[i] * (coupling * omega_i.cross(gradient));
          Wrench& wrench = wrenches[boundary.body[b]];
          wrench.force += force;
          wrench.torque += (boundary.position[b] - state.bodies[boundary.body[b]].pose.position).cross(force);
        }
        fluid.acceleration[i] += coupling * curl_omega;
        const Real relaxation = time_step * coupling / microinertia[fluid.phase[i]];  // Δt μ_t/(ρΘ)
        Vec3 omega = omega_i + phase.micropolar.angular_smoothing * (smoothed / weight_sum - omega_i);
        next[i] = (omega + relaxation * curl_velocity) / (1 + 2 * relaxation);
      }
    });
  });
  for (std::size_t i = 0; i < count; ++i) fluid.angular_velocity[i] = next[i];
}

}  // namespace m3dp::sph::stages

