#pragma once
// Two-way coupling of the rigid world with the fluid (Akinci et al. 2012, "Versatile rigid-fluid
// coupling for incompressible SPH", ACM TOG 31(4)): every movable link of the world (free rigid
// bodies, robot links, tools) is sampled into boundary particles that move with it, and the
// fluid's force and torque on those particles act back on the link in the world.
//
// The clocks are staggered: a fluid step sees the links where the world left them, and the world
// steps that follow (to the fluid's new time) feel the force of that fluid step. Explicit, so a
// body much lighter than the fluid it displaces (added-mass ratio ≫ 1) would need smaller steps.
#include <optional>
#include <utility>
#include <vector>

#include "m3dp/sph/solver.hpp"
#include "m3dp/world/world.hpp"

namespace m3dp::coupling {

class FluidBodyCoupling {
 public:
  FluidBodyCoupling(world::World& world, sph::Solver& solver);

  /// World → fluid, before a fluid step: each link's pose and velocity onto its boundary particles.
  /// Links added to the world since the last call are sampled first.
  void push_link_motion();
  /// Fluid → world, after a fluid step: the fluid's force and torque on each link, held for the
  /// world steps up to the fluid's clock.
  void pull_fluid_wrenches();

  [[nodiscard]] std::size_t coupled_links() const { return links_.size(); }
  /// The solver body of a world link, if it was coupled (it has collision shapes the fluid can see).
  [[nodiscard]] std::optional<Index> solver_body_of(world::LinkIndex link) const;

 private:
  void sample_new_links();

  world::World& world_;
  sph::Solver& solver_;
  std::size_t links_seen_ = 0;
  std::vector<std::pair<world::LinkIndex, Index>> links_;  // world link, solver body
};

}  // namespace m3dp::coupling
