// Where the implicit viscosity's conjugate gradients start (Weiler et al. 2018; see weiler2018.cpp):
// the warm start's residual, and where it is far off, the best blend of it and the last solution.
#include <cmath>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/viscosity/weiler2018.hpp"

namespace m3dp::sph::stages::weiler2018 {

StartResidual start_solve(const Model& model, State& state, Workspace& workspace) {
  const ViscousOperator product(workspace);  // A times the system's operand: the warm start v* + last change
  auto& system = workspace.viscosity_system;
  auto& fluid = state.fluid;
  auto& velocity = fluid.velocity;
  const std::size_t count = state.active_count;
  const auto& settings = model.settings;
  prepare_stress_product(model, state, workspace);
  // A particle a pump drives keeps its velocity (Workspace::piston_driven): no residual of its own, so
  // conjugate gradients never move it; its pull on its neighbours stays in theirs. One an exit holds
  // along its axis keeps only the residual across the axis (Workspace::free_part).
  const std::uint8_t* driven = workspace.any_piston_driven ? workspace.piston_driven.data() : nullptr;
  const auto start = product.row_sums<2>(count, [&](std::size_t i, const Vec3& row, std::array<double, 2>& sums) {
    const Vec3 residual = driven != nullptr && driven[i] ? Vec3::Zero() : Vec3(system.rhs[i] - row);
    system.residual[i] = residual;
    sums[0] += double(system.rhs[i].squaredNorm());
    sums[1] += double(residual.squaredNorm());
  });
  double residual_squares = start[1];
  if (driven != nullptr)  // held along an exit's axis: the residual across it (apart, so the sweep above stays as it was)
    residual_squares += deterministic_sums<1>(count, [&](std::size_t i, std::array<double, 1>& sums) {
      if (driven[i] < 2) return;
      system.residual[i] = workspace.free_part(i, system.rhs[i] - product.row(i));
      sums[0] += double(system.residual[i].squaredNorm());
    })[0];
  double residual_norm = std::sqrt(residual_squares);
  // A second start: the velocity the last solve ended with. v* carries this step's pressure and gravity
  // kicks, rough on the particle scale, which a stiff paste's viscosity takes out again at the cost of
  // most of CG's iterations; the last solution lacks this step's acceleration, which CG would not put
  // back within its tolerance. So the start is the combination α v_A + β v_B of both that is best in
  // A's energy norm (a 2×2 Galerkin system from the two products), and only where the first start is
  // far off (a stiff material): a runny one's blend would take part of this step's kicks away.
  constexpr double kFarOff = 10;
  if (settings.warm_start && residual_norm > kFarOff * settings.viscosity_tolerance * std::sqrt(start[0])) {
    parallel_for_each_index(count, [&](std::size_t i) { system.padded_operand[i] = padded(fluid.viscous_velocity[i]); }, 1024);
    prepare_stress_product(model, state, workspace);
    // v_A = velocity, r_A = residual; v_B = viscous_velocity, r_B into product. A v = b − r.
    const auto sums = product.row_sums<5>(count, [&](std::size_t i, const Vec3& row, std::array<double, 5>& sums) {
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
        if (driven != nullptr && driven[i]) return;  // kept as the pump drives it (an exit's hold: below)
        velocity[i] = alpha * velocity[i] + beta * fluid.viscous_velocity[i];
        system.residual[i] = (1 - alpha - beta) * system.rhs[i] + alpha * system.residual[i] + beta * system.product[i];
        sums[0] += double(system.residual[i].squaredNorm());
      })[0]);
      if (driven != nullptr) {
        // The driven particles kept their velocity, which the blended residuals assumed blended too:
        // each coupling is ~ m ν Δt/h² (10² m in a stiff paste), so their neighbours' residuals were off
        // by that times the change (a 300 Pa·s rope's column kicked to 4 m/s). Taken again from A v.
        parallel_for_each_index(count, [&](std::size_t i) {
          // Held along an exit's axis: blended across it.
          if (driven[i] > 1) velocity[i] += workspace.free_part(i, (alpha - 1) * velocity[i] + beta * fluid.viscous_velocity[i]);
          system.padded_operand[i] = padded(velocity[i]);
        }, 1024);
        prepare_stress_product(model, state, workspace);
        residual_norm = std::sqrt(product.row_sums<1>(count, [&](std::size_t i, const Vec3& row, std::array<double, 1>& sums) {
          system.residual[i] = workspace.free_part(i, system.rhs[i] - row);
          sums[0] += double(system.residual[i].squaredNorm());
        })[0]);
      }
    }
  }
  return {residual_norm, std::sqrt(start[0])};
}

}  // namespace m3dp::sph::stages::weiler2018
