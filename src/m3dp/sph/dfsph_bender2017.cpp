// Divergence-free SPH.
// J. Bender, D. Koschier: "Divergence-Free Smoothed Particle Hydrodynamics", SCA 2015, and
// "Divergence-Free SPH for Incompressible and Viscous Fluids", IEEE TVCG 23(3), 2017.
// Boundaries: N. Akinci et al., "Versatile Rigid-Fluid Coupling for Incompressible SPH", SIGGRAPH 2012.
//
// Densities are handled relative to the rest density (ρ/ρ0), volumes V_j = m_j/ρ0, and
// κ_i = ρ0 p_i / ρ_i² so that a pressure velocity update reads
//   v_i −= Δt Σ_j V_j (κ_i + κ_j) ∇W_ij + Δt Σ_b V_b κ_i ∇W_ib          (eq. 9 with eq. 12)
// The force of that update on boundary particle b is m_i κ_i V_b ∇W_ib (Akinci 2012, eq. 10).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>  // parallel_deterministic_reduce: sums independent of thread count

#include <algorithm>
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/solver.hpp"

namespace m3dp::sph::stages {

namespace {

constexpr Real kFactorEpsilon = Real(1e-12);
// Particles with fewer neighbours are at a free surface; their divergence is not corrected
// (the surface would otherwise be pulled inwards), as in the reference implementation.
constexpr int kMinNeighborsForDivergence = 20;

struct SolverView {
  const Vec3* position;
  Vec3* velocity;
  const Real* mass;
  const Real* density;
  const Real* factor;
  Real* density_advected;
  Real* kappa;
  const Vec3* boundary_position;
  const Vec3* boundary_velocity;
  const Real* boundary_volume;
  const Index* boundary_body;
  const std::uint16_t* neighbor_count;
  Real inverse_rest_density;
};

SolverView view_of(State& state, Real rest_density) {
  auto& fluid = state.fluid;
  auto& boundary = state.boundary;
  return SolverView{fluid.position.data(),        fluid.velocity.data(),  fluid.mass.data(),
                    fluid.density.data(),         fluid.dfsph_factor.data(), fluid.density_advected.data(),
                    state.kappa.data(),           boundary.position.data(), boundary.velocity.data(),
                    boundary.volume.data(),       boundary.body.data(),     fluid.neighbor_count.data(),
                    Real(1) / rest_density};
}

Real rest_density_of(const Parameters& parameters) { return parameters.phases.front().rest_density; }

template <class Body>
void for_each_particle_range(std::size_t count, Body&& body) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 128), body);
}

/// Σ_j V_j (v_i − v_j)·∇W_ij + Σ_b V_b (v_i − v_b)·∇W_ib: the rate of change of ρ_i/ρ0 (1/s), with minus sign.
template <class Kernel>
Real density_change_rate(const Kernel& kernel, const SolverView& view, const State& state, std::size_t i) {
  const Vec3 position_i = view.position[i];
  const Vec3 velocity_i = view.velocity[i];
  Real rate = 0;
  for (const Index j : state.fluid_neighbors.of(i))
    rate += view.mass[j] * view.inverse_rest_density * (velocity_i - view.velocity[j]).dot(kernel.gradW(position_i - view.position[j]));
  for (const Index b : state.boundary_neighbors.of(i))
    rate += view.boundary_volume[b] *
            (velocity_i - view.boundary_velocity[b]).dot(kernel.gradW(position_i - view.boundary_position[b]));
  return rate;
}

/// One pressure velocity update with the κ in view.kappa; adds the reaction on the bodies.
template <class Kernel>
void apply_pressure_velocity_update(const Kernel& kernel, const SolverView& view, State& state, Real time_step) {
  for_each_particle_range(state.fluid.size(), [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<Wrench>& wrenches = thread_body_wrenches(state);
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const Real kappa_i = view.kappa[i];
      const Vec3 position_i = view.position[i];
      Vec3 velocity_change = Vec3::Zero();
      for (const Index j : state.fluid_neighbors.of(i)) {
        const Real kappa_sum = kappa_i + view.kappa[j];
        if (std::abs(kappa_sum) > kFactorEpsilon)
          velocity_change -= (kappa_sum * view.mass[j] * view.inverse_rest_density) * kernel.gradW(position_i - view.position[j]);
      }
      if (std::abs(kappa_i) > kFactorEpsilon) {
        const Real mass_i = view.mass[i];
        for (const Index b : state.boundary_neighbors.of(i)) {
          const Vec3 boundary_position = view.boundary_position[b];
          const Vec3 change = -(kappa_i * view.boundary_volume[b]) * kernel.gradW(position_i - boundary_position);
          velocity_change += change;
          // Reaction on the body: −m_i Δv_i / Δt, with Δv_i = Δt · change.
          const Vec3 force = -mass_i * change;
          Wrench& wrench = wrenches[view.boundary_body[b]];
          wrench.force += force;
          wrench.torque += (boundary_position - state.bodies[view.boundary_body[b]].pose.position).cross(force);
        }
      }
      view.velocity[i] += time_step * velocity_change;
    }
  });
}

}  // namespace

void reset_body_wrenches(State& state) {
  for (auto& wrenches : state.body_wrench_per_thread) wrenches.assign(state.bodies.size(), Wrench{});
}

void collect_body_wrenches(State& state) {
  for (auto& body : state.bodies) {
    body.fluid_force.setZero();
    body.fluid_torque.setZero();
  }
  for (const auto& wrenches : state.body_wrench_per_thread)
    for (std::size_t b = 0; b < wrenches.size() && b < state.bodies.size(); ++b) {
      state.bodies[b].fluid_force += wrenches[b].force;
      state.bodies[b].fluid_torque += wrenches[b].torque;
    }
}

Real compute_density_and_factor(const Parameters& parameters, State& state) {
  const Real rest_density = rest_density_of(parameters);
  const SolverView view = view_of(state, rest_density);
  auto& fluid = state.fluid;
  const Real boundary_neighbor_weight = parameters.settings.boundary_spacing_factor * parameters.settings.boundary_spacing_factor;
  return with_kernel(parameters.settings.kernel,
                     parameters.settings.support_radius_factor * parameters.settings.particle_radius,
                     [&](const auto& kernel) {
                       return tbb::parallel_reduce(
                           tbb::blocked_range<std::size_t>(0, fluid.size(), 128), Real(0),
                           [&](const tbb::blocked_range<std::size_t>& range, Real max_error) {
                             for (std::size_t i = range.begin(); i != range.end(); ++i) {
                               const Vec3 position_i = view.position[i];
                               Real density_ratio = view.mass[i] * view.inverse_rest_density * kernel.W_zero();
                               Vec3 gradient_sum = Vec3::Zero();
                               Real gradient_squares = 0;
                               for (const Index j : state.fluid_neighbors.of(i)) {
                                 const Vec3 r = position_i - view.position[j];
                                 const Real volume_j = view.mass[j] * view.inverse_rest_density;
                                 density_ratio += volume_j * kernel.W(r.norm());
                                 const Vec3 gradient = volume_j * kernel.gradW(r);
                                 gradient_sum += gradient;
                                 gradient_squares += gradient.squaredNorm();
                               }
                               for (const Index b : state.boundary_neighbors.of(i)) {
                                 const Vec3 r = position_i - view.boundary_position[b];
                                 density_ratio += view.boundary_volume[b] * kernel.W(r.norm());
                                 gradient_sum += view.boundary_volume[b] * kernel.gradW(r);
                               }
                               fluid.density[i] = density_ratio * rest_density;
                               const Real denominator = gradient_sum.squaredNorm() + gradient_squares;
                               fluid.dfsph_factor[i] = denominator > kFactorEpsilon ? Real(1) / denominator : Real(0);
                               // Boundary neighbours counted as the fluid particles they stand for: a wall
                               // layer is sampled finer than the fluid (a sheet: count ∝ 1/spacing²), and a
                               // free-surface particle at a wall must still count as at the surface.
                               fluid.neighbor_count[i] = static_cast<std::uint16_t>(std::min<Real>(
                                   65535, Real(state.fluid_neighbors.counts[i]) + boundary_neighbor_weight *
                                                                                     Real(state.boundary_neighbors.counts[i])));
                               max_error = std::max(max_error, density_ratio - Real(1));
                             }
                             return max_error;
                           },
                           [](Real a, Real b) { return std::max(a, b); });
                     });
}

int solve_divergence(const Parameters& parameters, State& state, Real time_step) {
  const auto& settings = parameters.settings;
  const std::size_t count = state.fluid.size();
  if (count == 0) return 0;
  const SolverView view = view_of(state, rest_density_of(parameters));
  const Real inverse_time_step = Real(1) / time_step;
  // Σ κ over this step's updates: a pressure (κ = ρ0 p / ρ²), so it carries over when Δt changes.
  auto& kappa_total = state.fluid.kappa_divergence;

  return with_kernel(settings.kernel, settings.support_radius_factor * settings.particle_radius, [&](const auto& kernel) {
    auto update_divergence = [&]() {
      return tbb::parallel_deterministic_reduce(
          tbb::blocked_range<std::size_t>(0, count, 256), Real(0),
          [&](const tbb::blocked_range<std::size_t>& range, Real sum) {
            for (std::size_t i = range.begin(); i != range.end(); ++i) {
              Real rate = density_change_rate(kernel, view, state, i);
              rate = view.neighbor_count[i] < kMinNeighborsForDivergence ? Real(0) : std::max(rate, Real(0));
              view.density_advected[i] = rate;
              sum += rate;
            }
            return sum;
          },
          std::plus<Real>());
    };

    if (settings.warm_start) {
      // Half of last step's κ as the initial guess, where the flow diverges now (as the density solve).
      update_divergence();
      parallel_for_each_index(count, [&](std::size_t i) {
        view.kappa[i] = view.density_advected[i] > Real(0) ? Real(0.5) * kappa_total[i] : Real(0);
        kappa_total[i] = view.kappa[i];
      });
      apply_pressure_velocity_update(kernel, view, state, time_step);
    } else {
      parallel_for_each_index(count, [&](std::size_t i) { kappa_total[i] = 0; });
    }

    Real mean_error = update_divergence() / Real(count) * time_step;
    int iterations = 0;
    while ((iterations < 1 || mean_error > settings.divergence_tolerance) && iterations < settings.max_divergence_iterations) {
      parallel_for_each_index(count, [&](std::size_t i) {
        view.kappa[i] = view.density_advected[i] * view.factor[i] * inverse_time_step;
        kappa_total[i] += view.kappa[i];
      });
      apply_pressure_velocity_update(kernel, view, state, time_step);
      mean_error = update_divergence() / Real(count) * time_step;
      ++iterations;
    }
    return iterations;
  });
}

int solve_density(const Parameters& parameters, State& state, Real time_step, Real& mean_density_error) {
  const auto& settings = parameters.settings;
  const std::size_t count = state.fluid.size();
  mean_density_error = 0;
  if (count == 0) return 0;
  const SolverView view = view_of(state, rest_density_of(parameters));
  const Real inverse_time_step_squared = Real(1) / (time_step * time_step);
  auto& kappa_total = state.fluid.kappa_density;  // Σ κ over this step's updates (a pressure, see above)
  const Real rest_density = rest_density_of(parameters);

  return with_kernel(settings.kernel, settings.support_radius_factor * settings.particle_radius, [&](const auto& kernel) {
    // ρ*/ρ0 = ρ/ρ0 + Δt · (rate of change), clamped at 1: the solver only pushes, never pulls (free surface).
    auto update_predicted_density = [&]() {
      return tbb::parallel_deterministic_reduce(
          tbb::blocked_range<std::size_t>(0, count, 256), Real(0),
          [&](const tbb::blocked_range<std::size_t>& range, Real sum) {
            for (std::size_t i = range.begin(); i != range.end(); ++i) {
              const Real predicted = view.density[i] / rest_density + time_step * density_change_rate(kernel, view, state, i);
              view.density_advected[i] = std::max(predicted, Real(1));
              sum += view.density_advected[i] - Real(1);
            }
            return sum;
          },
          std::plus<Real>());
    };

    if (settings.warm_start) {
      // Half of last step's pressure, where the particle is compressed now (Bender & Koschier 2017,
      // Sec. 4.4). Not the whole: the solver only pushes (ρ* is clamped at ρ0), so an initial guess
      // that overshoots can never be taken back, and with the whole pressure a settling column
      // gains energy at large time steps.
      update_predicted_density();
      parallel_for_each_index(count, [&](std::size_t i) {
        view.kappa[i] = view.density_advected[i] > Real(1) ? Real(0.5) * kappa_total[i] : Real(0);
        kappa_total[i] = view.kappa[i];
      });
      apply_pressure_velocity_update(kernel, view, state, time_step);
    } else {
      parallel_for_each_index(count, [&](std::size_t i) { kappa_total[i] = 0; });
    }

    mean_density_error = update_predicted_density() / Real(count);
    int iterations = 0;
    while ((iterations < settings.min_density_iterations || mean_density_error > settings.density_tolerance) &&
           iterations < settings.max_density_iterations) {
      parallel_for_each_index(count, [&](std::size_t i) {
        view.kappa[i] = (view.density_advected[i] - Real(1)) * view.factor[i] * inverse_time_step_squared;
        kappa_total[i] += view.kappa[i];
      });
      apply_pressure_velocity_update(kernel, view, state, time_step);
      mean_density_error = update_predicted_density() / Real(count);
      ++iterations;
    }
    return iterations;
  });
}

}  // namespace m3dp::sph::stages
