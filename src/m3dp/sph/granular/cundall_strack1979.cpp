// Granular mode: discrete spheres of one particle diameter d with linear spring–dashpot contacts and
// Coulomb friction (Cundall & Strack 1979; see material/granular/cundall_strack1979.hpp), and no
// fluid forces. For a pair in contact (distance < d), with n the unit vector from j to i, overlap
// δ = d − |x_ij|, relative velocity v_ij split into v_n = v_ij·n and v_t = v_ij − v_n n:
//   F_n = max(0, k δ − c v_n) n                     (no pull: the spheres only push)
//   F_t = −min(μ |F_n|, c_t |v_t|) v_t/|v_t|          (Coulomb, regularised by a viscous law at low slip)
// c = 2ζ√(m* k) from the restitution, c_t = 2√(m* k) (critically damped), m* the reduced mass.
// The spheres do not rotate (no rolling), so a heap's slope comes from sliding friction alone.
// Walls are their boundary particles, each a sphere of one diameter, a radius behind the surface:
// rough at the particle scale, like a real bed. Their reaction goes to the body wrenches.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

namespace {

struct ContactLaw {
  Real stiffness;   // N/m
  Real damping;     // N·s/m, normal dashpot
  Real tangential;  // N·s/m, tangential viscous regularisation
  Real friction;    // μ
};

ContactLaw contact_law(const GranularContact& a, const GranularContact& b, Real reduced_mass) {
  ContactLaw law;
  law.stiffness = 2 * a.stiffness * b.stiffness / (a.stiffness + b.stiffness);  // the same phase: its own k
  const Real critical = 2 * std::sqrt(reduced_mass * law.stiffness);
  law.damping = (a.damping_ratio + b.damping_ratio) / 2 * critical;
  law.tangential = critical;
  law.friction = (a.friction + b.friction) / 2;
  return law;
}

/// The contact force on i (N) from a sphere at relative position r = x_i − x_j moving at relative
/// velocity v = v_i − v_j; zero when apart.
Vec3 contact_force(const Vec3& r, const Vec3& v, Real diameter, const ContactLaw& law) {
  const Real distance_squared = r.squaredNorm();
  if (distance_squared >= diameter * diameter || distance_squared <= 0) return Vec3::Zero();
  const Real distance = std::sqrt(distance_squared);
  const Vec3 normal = r / distance;
  const Real normal_speed = v.dot(normal);
  const Real normal_force = std::max(Real(0), law.stiffness * (diameter - distance) - law.damping * normal_speed);
  Vec3 force = normal_force * normal;
  const Vec3 slip = v - normal_speed * normal;
  const Real slip_speed = slip.norm();
  if (slip_speed > 0) force -= (std::min(law.friction * normal_force, law.tangential * slip_speed) / slip_speed) * slip;
  return force;
}

}  // namespace

void compute_granular_contacts(const Model& model, State& state, Workspace& workspace) {
  const auto& phases = model.granular_contacts;
  const auto& settings = model.settings;
  auto& fluid = state.fluid;
  const auto& boundary = state.boundary;
  const Real diameter = 2 * settings.particle_radius;
  const auto& fluid_lists = workspace.fluid_neighbors;
  const auto& boundary_lists = workspace.boundary_neighbors;
  for_each_wrench_chunk(state, workspace, state.active_count, [&](const tbb::blocked_range<std::size_t>& range, std::span<Wrench> wrenches) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const GranularContact& contact_i = phases[fluid.phase[i]];
      const Real mass_i = fluid.mass[i];
      const Vec3 position_i = fluid.position[i];
      const Vec3 velocity_i = fluid.velocity[i];
      Vec3 force = Vec3::Zero();
      const std::size_t fluid_first = fluid_lists.first(i);
      for (Index k = 0; k < fluid_lists.counts[i]; ++k) {
        const Index j = fluid_lists.indices[fluid_first + k];
        const Vec3 r = position_i - fluid.position[j];
        if (r.squaredNorm() >= diameter * diameter) continue;
        const Real reduced_mass = mass_i * fluid.mass[j] / (mass_i + fluid.mass[j]);
        const ContactLaw law = contact_law(contact_i, phases[fluid.phase[j]], reduced_mass);
        force += contact_force(r, velocity_i - fluid.velocity[j], diameter, law);
      }
      // A wall does not move under the impact: the reduced mass is the particle's own.
      const ContactLaw wall_law = contact_law(contact_i, contact_i, mass_i);
      const std::size_t boundary_first = boundary_lists.first(i);
      for (Index k = 0; k < boundary_lists.counts[i]; ++k) {
        const Index b = boundary_lists.indices[boundary_first + k];
        const Vec3 contact = contact_force(position_i - boundary.position[b], velocity_i - boundary.velocity[b], diameter, wall_law);
        if (contact.isZero()) continue;
        force += contact;
        Wrench& wrench = wrenches[boundary.body[b]];
        wrench.force -= contact;
        wrench.torque -= (boundary.position[b] - state.bodies[boundary.body[b]].pose.position).cross(contact);
      }
      fluid.acceleration[i] = settings.gravity + force / mass_i;
    }
  });
}

}  // namespace m3dp::sph::stages

