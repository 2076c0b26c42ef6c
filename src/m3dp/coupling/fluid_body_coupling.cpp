#include "m3dp/coupling/fluid_body_coupling.hpp"

#include "m3dp/sph/boundary_sampling.hpp"

namespace m3dp::coupling {

FluidBodyCoupling::FluidBodyCoupling(world::World& world, sph::Solver& solver) : world_(world), solver_(solver) {
  sample_new_links();
}

void FluidBodyCoupling::sample_new_links() {
  const auto& settings = solver_.parameters().settings;
  const Real spacing = settings.boundary_spacing_factor * solver_.particle_diameter();
  for (; links_seen_ < world_.link_count(); ++links_seen_) {
    if (!world_.link_feels_fluid(links_seen_)) continue;
    const world::LinkShapes link = world_.link_shapes(links_seen_);
    // One boundary body per link: all its shapes, sampled like static walls (the layer a particle
    // radius inside the solid) and placed in the link frame.
    sph::SurfaceSamples samples;
    for (std::size_t s = 0; s < link.shapes.size(); ++s) {
      const sph::SurfaceSamples shape_samples = sph::sample_shape_surface(link.shapes[s], spacing, -settings.particle_radius);
      for (std::size_t k = 0; k < shape_samples.points.size(); ++k)
        samples.add(link.poses[s].apply(shape_samples.points[k]), link.poses[s].rotate(shape_samples.normals[k]));
    }
    if (samples.points.empty()) continue;
    sph::remove_close_points(samples, Real(0.5) * spacing);  // where a link's shapes overlap
    const Index body = solver_.add_body(link.name, samples.points, world_.link_pose(links_seen_), false);
    solver_.set_body_motion(body, world_.link_pose(links_seen_), world_.link_linear_velocity(links_seen_),
                            world_.link_angular_velocity(links_seen_));
    links_.emplace_back(links_seen_, body);
  }
}

void FluidBodyCoupling::push_link_motion() {
  if (links_seen_ < world_.link_count()) sample_new_links();
  for (const auto& [link, body] : links_)
    solver_.set_body_motion(body, world_.link_pose(link), world_.link_linear_velocity(link), world_.link_angular_velocity(link));
}

void FluidBodyCoupling::pull_fluid_wrenches() {
  for (const auto& [link, body] : links_) {
    const sph::BoundaryBody& boundary_body = solver_.bodies()[body];
    // The solver sums the torque about the body pose's origin, which is the link frame's origin.
    world_.set_link_wrench(link, boundary_body.fluid_force, boundary_body.fluid_torque);
  }
}

std::optional<Index> FluidBodyCoupling::solver_body_of(world::LinkIndex link) const {
  for (const auto& [world_link, body] : links_)
    if (world_link == link) return body;
  return std::nullopt;
}

}  // namespace m3dp::coupling
