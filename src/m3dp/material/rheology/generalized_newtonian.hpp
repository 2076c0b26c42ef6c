#pragma once
// Generalised Newtonian rheology: a dynamic viscosity μ(γ̇) (Pa·s) from the local shear rate
// γ̇ = √(2 D:D) (1/s), D the strain-rate tensor. The solver evaluates it per particle every step
// and feeds the result to the (implicit) viscosity solve.
//
//   newtonian          μ = μ0
//   power law          μ = K γ̇^(n−1)                         Ostwald 1925, de Waele 1923
//   Cross              μ = μ∞ + (μ0 − μ∞) / (1 + (λγ̇)^n)      M. M. Cross, J. Colloid Sci. 20, 417–437, 1965
//   Carreau            μ = μ∞ + (μ0 − μ∞)(1 + (λγ̇)²)^((n−1)/2) P. J. Carreau, Trans. Soc. Rheol. 16, 99–127, 1972
//   Bingham            τ = τ0 + μp γ̇ above the yield stress     E. C. Bingham, 1916
//   Herschel–Bulkley   τ = τ0 + K γ̇^n above the yield stress    W. H. Herschel, R. Bulkley, Kolloid-Z. 39, 291–300, 1926
//
// Yield stresses are regularised after T. C. Papanastasiou, "Flows of materials with yield",
// J. Rheol. 31, 385–404, 1987: τ0/γ̇ becomes τ0 (1 − e^(−mγ̇))/γ̇, which tends to τ0·m as γ̇ → 0,
// so unyielded material is a very viscous fluid (creep rate ≈ stress / (τ0 m)) instead of a
// singular one. Every model is finally capped at `max_viscosity`, which also bounds a power law
// with n < 1 at rest.
#include <algorithm>
#include <cmath>
#include <string_view>

#include "m3dp/core/types.hpp"

namespace m3dp::material {

enum class RheologyModel { newtonian, power_law, cross, carreau, bingham, herschel_bulkley };

constexpr std::string_view to_string(RheologyModel model) {
  switch (model) {
    case RheologyModel::newtonian: return "newtonian";
    case RheologyModel::power_law: return "power_law";
    case RheologyModel::cross: return "cross";
    case RheologyModel::carreau: return "carreau";
    case RheologyModel::bingham: return "bingham";
    case RheologyModel::herschel_bulkley: return "herschel_bulkley";
  }
  return "?";
}

constexpr bool has_yield_stress(RheologyModel model) {
  return model == RheologyModel::bingham || model == RheologyModel::herschel_bulkley;
}

/// Parameters of one rheology model (SI). Fields a model does not use are ignored.
struct Rheology {
  RheologyModel model = RheologyModel::newtonian;
  Real viscosity = Real(1e-3);            // Pa·s: Newtonian μ; Bingham plastic viscosity μp; Cross/Carreau zero-shear μ0
  Real infinite_shear_viscosity = 0;      // Pa·s: Cross/Carreau μ∞
  Real consistency = 1;                   // Pa·sⁿ: power law and Herschel–Bulkley K
  Real flow_index = 1;                    // n (1): power law, Herschel–Bulkley, Cross, Carreau
  Real time_constant = 1;                 // s: Cross/Carreau λ
  Real yield_stress = 0;                  // Pa: Bingham/Herschel–Bulkley τ0 (before ageing)
  Real regularization = 1000;             // s: Papanastasiou exponent m; unyielded viscosity ≈ τ0·m
  Real max_viscosity = Real(1e6);         // Pa·s: cap of every model (power law at rest, regularised plug)

  /// The viscosity the model has at rest (γ̇ → 0), capped: the stiffest the solver will see.
  [[nodiscard]] Real rest_viscosity() const { return effective_viscosity(0, yield_stress, 1); }

  /// μ(γ̇) in Pa·s. `yield_stress` (Pa) is this particle's (ageing raises it); `viscosity_scale`
  /// multiplies the model's viscosity parameter (μ, μp, K or μ0; ageing raises it too).
  [[nodiscard]] Real effective_viscosity(Real shear_rate, Real particle_yield_stress, Real viscosity_scale) const {
    const Real rate = std::max(shear_rate, Real(0));
    Real mu = 0;
    switch (model) {
      case RheologyModel::newtonian: mu = viscosity * viscosity_scale; break;
      case RheologyModel::power_law:
        mu = rate > 0 ? consistency * viscosity_scale * std::pow(rate, flow_index - 1) : max_viscosity;
        break;
      case RheologyModel::cross:
        mu = infinite_shear_viscosity +
             (viscosity * viscosity_scale - infinite_shear_viscosity) / (1 + std::pow(time_constant * rate, flow_index));
        break;
      case RheologyModel::carreau:
        mu = infinite_shear_viscosity + (viscosity * viscosity_scale - infinite_shear_viscosity) *
                                            std::pow(1 + (time_constant * rate) * (time_constant * rate), (flow_index - 1) / 2);
        break;
      case RheologyModel::bingham:
        if (yield_term_reaches_cap(rate, particle_yield_stress)) return max_viscosity;
        mu = viscosity * viscosity_scale + regularised_yield_term(rate, particle_yield_stress);
        break;
      case RheologyModel::herschel_bulkley:
        if (yield_term_reaches_cap(rate, particle_yield_stress)) return max_viscosity;
        mu = (rate > 0 ? consistency * viscosity_scale * std::pow(rate, flow_index - 1) : max_viscosity) +
             regularised_yield_term(rate, particle_yield_stress);
        break;
    }
    return std::min(mu, max_viscosity);
  }

 private:
  /// Whether the yield term alone reaches the cap, from its lower bound τ0 m/(1 + mγ̇) ((1 − e^(−x))/x ≥
  /// 1/(1 + x)): unyielded material, most of a settled print, is then capped without an exp and a pow.
  /// Equal to the full formula at γ̇ = 0.
  [[nodiscard]] bool yield_term_reaches_cap(Real rate, Real tau0) const {
    return tau0 > 0 && tau0 * regularization >= max_viscosity * (1 + regularization * rate);
  }
  /// τ0 (1 − e^(−mγ̇))/γ̇, which is τ0·m at γ̇ = 0 (series form for small mγ̇ keeps float accurate).
  [[nodiscard]] Real regularised_yield_term(Real rate, Real tau0) const {
    if (tau0 <= 0) return 0;
    const Real x = regularization * rate;
    if (x < Real(1e-4)) return tau0 * regularization * (1 - x / 2);
    return tau0 * -std::expm1(-x) / rate;
  }
};

}  // namespace m3dp::material
