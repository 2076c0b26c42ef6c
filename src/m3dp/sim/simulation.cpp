#include "m3dp/sim/simulation.hpp"

#include <cmath>

#include "m3dp/sph/boundary_sampling.hpp"

namespace m3dp::sim {

sph::Parameters make_solver_parameters(const scene::Scene& scene) {
  sph::Parameters parameters;
  parameters.settings = scene.solver;
  for (const auto& entry : scene.materials) {
    const auto& material = entry.material;
    parameters.phases.push_back(sph::FluidPhase{material.name, material.density, material.kinematic_viscosity(),
                                                material.boundary_kinematic_viscosity()});
  }
  auto phase_of = [&](const std::string& name) {
    for (std::size_t i = 0; i < scene.materials.size(); ++i)
      if (scene.materials[i].material.name == name) return static_cast<std::uint16_t>(i);
    return std::uint16_t(0);  // the scene loader has checked that every name exists
  };
  for (const auto& head : scene.print_heads)
    parameters.nozzles.push_back(sph::NozzleSettings{head.name, head.inner_diameter, head.exit_speed, phase_of(head.material)});
  return parameters;
}

namespace {
std::uint16_t phase_index(const scene::Scene& scene, const std::string& material) {
  for (std::size_t i = 0; i < scene.materials.size(); ++i)
    if (scene.materials[i].material.name == material) return static_cast<std::uint16_t>(i);
  return 0;
}

std::vector<Vec3> lattice_in_box(const Aabb& box, Real spacing) {
  std::vector<Vec3> points;
  const Vec3 size = box.size();
  // Whole particles only: a block never reaches past its box (into a wall at its edge).
  auto count_along = [&](Real length) { return std::max(1, static_cast<int>(std::floor(length / spacing + Real(1e-3)))); };
  const int nx = count_along(size.x()), ny = count_along(size.y()), nz = count_along(size.z());
  points.reserve(static_cast<std::size_t>(nx) * ny * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) points.push_back(box.min + spacing * Vec3(i + Real(0.5), j + Real(0.5), k + Real(0.5)));
  return points;
}
}  // namespace

Simulation::Simulation(const scene::Scene& scene)
    : scene_(scene), solver_(make_solver_parameters(scene)), world_(world::WorldSettings{scene.solver.gravity}) {
  const Real spacing = solver_.particle_diameter();
  const Real wall_spacing = scene_.solver.boundary_spacing_factor * spacing;
  for (const auto& body : scene_.bodies) {
    for (const auto& collision : body.collisions) {
      const sph::SurfaceSamples samples = sph::sample_shape_surface(collision.shape, wall_spacing, -scene_.solver.particle_radius);
      solver_.add_body(collision.name, samples.points, collision.pose, true);
      world_.add_static_shape(collision.name, collision.shape, collision.pose);
    }
  }
  std::size_t initial_particles = 0;
  for (const auto& block : scene_.fluid_blocks) {
    const auto points = lattice_in_box(block.box, spacing);
    initial_particles += solver_.add_particles(points, block.initial_velocity, phase_index(scene_, block.material));
  }
  // Reserve for everything the print heads will emit, so steps do not reallocate.
  double emitted_volume = 0;
  for (const auto& head : scene_.print_heads) {
    const double duration = std::max(0.0, std::min(head.trajectory.end_time(), scene_.end_time) - head.trajectory.start_time());
    emitted_volume += kPi * head.inner_diameter * head.inner_diameter / 4 * head.exit_speed * duration;
  }
  const double particle_volume = std::pow(static_cast<double>(spacing), 3);
  solver_.reserve(initial_particles + static_cast<std::size_t>(1.1 * emitted_volume / particle_volume) + 1024);
  initial_fluid_mass_ = solver_.total_fluid_mass();
  update_print_heads();
}

void Simulation::update_print_heads() {
  for (std::size_t i = 0; i < scene_.print_heads.size(); ++i) {
    const auto& head = scene_.print_heads[i];
    const auto sample = head.trajectory.sample(solver_.time());
    Pose pose;
    pose.position = sample.position;
    pose.orientation = Quat::FromTwoVectors(Vec3(0, 0, -1), head.direction.normalized());
    // A G-code move asks for its own flow (E over time); other paths use the nozzle's nominal one.
    const Real nominal_flow = kPi * head.inner_diameter * head.inner_diameter / 4 * head.exit_speed;
    const Real flow_scale = sample.volume_rate > 0 && nominal_flow > 0 ? sample.volume_rate / nominal_flow : Real(1);
    solver_.set_nozzle(static_cast<Index>(i), pose, sample.velocity, sample.extruding, flow_scale);
  }
}

const sph::StepStats& Simulation::step() {
  update_print_heads();
  const sph::StepStats& stats = solver_.step();
  world_.step_to(solver_.time());
  return stats;
}

void Simulation::set_printed_mesh(const TriangleMesh& mesh) { world_.set_static_mesh("printed_material", mesh); }

}  // namespace m3dp::sim
