#pragma once
// Granular mode: printed material as discrete spheres with contacts and no fluid forces (the simple
// "particle dropping" print). Linear spring–dashpot contact with Coulomb friction after
// P. A. Cundall, O. D. L. Strack, "A discrete numerical model for granular assemblies",
// Géotechnique 29(1), 47–65, 1979. The dashpot c = 2ζ√(m* k) is set from the coefficient of
// restitution e. The textbook ζ = −ln e / √(π² + ln² e) assumes the dashpot may pull; ours only pushes
// (the contact ends when the force reaches zero, before the overlap does), which raises the rebound —
// C. Thornton et al., "Investigation of the limitations of the linear spring-dashpot model for
// modelling particle-particle and particle-wall interactions", Powder Technology 233, 30–46, 2013.
// So ζ is solved for the contact as it is simulated.
#include <algorithm>
#include <cmath>

#include "m3dp/core/types.hpp"

namespace m3dp::material {

struct Granular {
  bool enabled = false;
  Real stiffness = 0;              // N/m, normal spring; 0 = derived from the particle size (see the solver)
  Real restitution = Real(0.3);    // normal coefficient of restitution e, 0 < e ≤ 1
  Real friction = Real(0.5);       // Coulomb coefficient μ (tangential force ≤ μ × normal force)

  /// ζ of the normal dashpot that gives the restitution e in a binary collision whose force never pulls.
  [[nodiscard]] Real damping_ratio() const {
    if (restitution >= 1) return 0;
    // Rebound speed over impact speed, falling with ζ: bisection (ζ = 1 is overdamped, e ≈ 0 there).
    double low = 0, high = 1;
    for (int iteration = 0; iteration < 50; ++iteration) {
      const double middle = (low + high) / 2;
      (pushing_contact_restitution(middle) > restitution ? low : high) = middle;
    }
    return Real((low + high) / 2);
  }

  /// Restitution of a linear spring–dashpot contact of damping ratio ζ whose force kδ + cδ' is cut at
  /// zero: δ'' = −δ − 2ζδ' in units of √(k/m*), from δ = 0, δ' = 1, until the force reaches zero.
  [[nodiscard]] static double pushing_contact_restitution(double zeta) {
    double overlap = 0, speed = 1;  // speed = dδ/dt, approach positive
    constexpr double kStep = 1e-3;
    auto acceleration = [zeta](double x, double v) { return -x - 2 * zeta * v; };
    for (int step = 0; step < 100000; ++step) {
      // Classic Runge–Kutta on (δ, δ').
      const double k1x = speed, k1v = acceleration(overlap, speed);
      const double k2x = speed + kStep / 2 * k1v, k2v = acceleration(overlap + kStep / 2 * k1x, speed + kStep / 2 * k1v);
      const double k3x = speed + kStep / 2 * k2v, k3v = acceleration(overlap + kStep / 2 * k2x, speed + kStep / 2 * k2v);
      const double k4x = speed + kStep * k3v, k4v = acceleration(overlap + kStep * k3x, speed + kStep * k3v);
      overlap += kStep / 6 * (k1x + 2 * k2x + 2 * k3x + k4x);
      speed += kStep / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
      if (overlap <= 0 || overlap + 2 * zeta * speed <= 0) break;  // apart, or the force would pull
    }
    return std::max(0.0, -speed);
  }
};

}  // namespace m3dp::material
