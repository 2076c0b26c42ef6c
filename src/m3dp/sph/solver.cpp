#include "m3dp/sph/solver.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <stdexcept>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"

namespace m3dp::sph {

Solver::Solver(Parameters parameters) : model_(compile_model(std::move(parameters))) {
  state_.nozzles.resize(model_.nozzles.size());
  state_.time_step = model_.settings.max_time_step;
  workspace_.search_cell_size = model_.support_radius;
  // Each nozzle with a bore carries its walls as a moving body, posed by move_bodies from the nozzle.
  for (std::size_t n = 0; n < model_.nozzles.size(); ++n) {
    NozzleGeometry& geometry = model_.nozzle_geometry[n];
    if (!geometry.has_bore()) continue;
    geometry.bore_body = static_cast<std::int32_t>(add_body("nozzle/" + model_.nozzles[n].name, geometry.bore_points, Pose{}, false));
    geometry.piston_body =
        static_cast<std::int32_t>(add_body("nozzle/" + model_.nozzles[n].name + "/piston", geometry.piston_points, Pose{}, false));
    for (const std::int32_t index : {geometry.bore_body, geometry.piston_body}) {
      const BoundaryBody& body = state_.bodies[static_cast<std::size_t>(index)];
      for (Index k = 0; k < body.particle_count; ++k) state_.boundary.wall_kind[body.first_particle + k] = material::Wall::nozzle_bore;
    }
  }
}

const StepStats& Solver::step() {
  using namespace stages;
  state_.last_step = StepStats{};
  run(Stage::bodies, {choose_neighbor_search, make_walls_near_material, move_bodies});
  run(Stage::remove, {remove_out_of_bounds});
  run(Stage::emit, {emit_layers});
  run(Stage::reorder, {update_rest_partition, reorder_particles});
  run(Stage::neighbors, {search_neighbors});
  if (model_.granular) {  // discrete spheres: contacts instead of the fluid stages
    run(Stage::forces, {reset_body_wrenches, compute_granular_contacts});
    run(Stage::advect, {choose_granular_time_step, integrate_granular, keep_out_of_boundaries, collect_body_wrenches, finish_step});
    return state_.last_step;
  }
  run(Stage::density, {reset_body_wrenches, compute_density_and_factor});
  run(Stage::divergence, {solve_divergence});
  run(Stage::forces, {update_effective_viscosity, add_gravity_and_explicit_viscosity, add_surface_tension, add_air_drag,
                      add_elastic_forces, choose_time_step, apply_micropolar, integrate_accelerations, drive_pumps});
  run(Stage::pressure, {solve_density});
  // Viscosity after the pressure solve, right before the velocities move the particles: see
  // viscosity/weiler2018.cpp.
  run(Stage::viscosity, {add_elastic_stiffness, hold_pumps, hold_drawn_exits, apply_tension_pressure, solve_implicit_viscosity, project_tension, apply_xsph, shift_particles, correct_volume});
  run(Stage::advect, {push_out_of_nozzles, advect_positions, relax_reference_shape, update_rest_clocks, wake_loaded_rest,
                      wake_compressed_rest, keep_out_of_boundaries, collect_body_wrenches, finish_step});
  return state_.last_step;
}

void Solver::run(Stage stage, std::initializer_list<stages::StageFunction> functions) {
  const auto start = std::chrono::steady_clock::now();
  for (const stages::StageFunction function : functions) function(model_, state_, workspace_);
  state_.last_step.stage_ms[stage] = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

Index Solver::add_body(const std::string& name, std::span<const Vec3> local_points, const Pose& pose, bool is_static) {
  const Index body_index = static_cast<Index>(state_.bodies.size());
  BoundaryBody body;
  body.name = name;
  body.is_static = is_static;
  body.first_particle = static_cast<Index>(state_.boundary.size());
  body.particle_count = static_cast<Index>(local_points.size());
  body.pose = pose;
  for (const Vec3& local : local_points) body.local_bounds.extend(local);
  state_.bodies.push_back(body);

  auto& boundary = state_.boundary;
  const std::size_t total = boundary.size() + local_points.size();
  // Room for this body at least, doubling: an exact reserve per body copied every array at each of a
  // world's many shapes.
  const auto grow = [total](auto& array) {
    if (array.capacity() < total) array.reserve(std::max(total, 2 * array.capacity()));
  };
  grow(boundary.local_position), grow(boundary.position), grow(boundary.velocity), grow(boundary.body), grow(boundary.wall_kind);
  for (const Vec3& local : local_points) {
    boundary.local_position.push_back(local);
    boundary.position.push_back(pose.apply(local));
    boundary.velocity.push_back(Vec3::Zero());
    boundary.body.push_back(body_index);
    boundary.wall_kind.push_back(is_static ? material::Wall::static_wall : material::Wall::moving_body);
  }
  stages::sum_boundary_volumes(model_, state_, body.first_particle, body_index, is_static);
  workspace_.static_boundary_dirty = true;
  workspace_.static_boundary_indices.reserve(boundary.size());
  workspace_.moving_boundary_indices.reserve(boundary.size());
  return body_index;
}

Index Solver::add_static_surface(const std::string& name, const TiledSurface& surface, const Pose& pose) {
  const Index body = add_body(name, surface.now.points, pose, true);
  for (const RectangleLattice& lattice : surface.later) {
    LazyWallFace face;
    face.body = body;
    face.lattice = lattice;
    face.tiles_a = (lattice.last_a - lattice.first_a) / kLazyTilePoints + 1;
    face.tiles_b = (lattice.last_b - lattice.first_b) / kLazyTilePoints + 1;
    face.made.assign(std::size_t(face.tiles_a) * std::size_t(face.tiles_b), 0);
    state_.lazy_walls.push_back(std::move(face));
  }
  return body;
}

std::size_t Solver::add_particles(std::span<const Vec3> positions, const Vec3& velocity, std::uint16_t phase) {
  // The lazy walls' tiles around the new particles first: they are the material's region from now on.
  Aabb around;
  for (const Vec3& point : positions) around.extend(point);
  if (!around.empty()) {
    const Vec3 reach = Vec3::Constant(stages::lazy_wall_reach(model_));
    Aabb within;
    within.extend(around.min - reach);
    within.extend(around.max + reach);
    stages::make_walls_within(model_, state_, workspace_, within);
  }
  // Points within the boundary clearance of a wall's particles are skipped.
  const Real clearance = stages::boundary_clearance(model_);
  SpatialHashGrid grid;
  grid.build(state_.boundary.position, model_.support_radius);
  const std::size_t first_new = state_.fluid.size();
  for (const Vec3& point : positions) {
    bool blocked = false;
    grid.for_each_candidate(point, [&](Index, const Vec3& b) { blocked |= (point - b).squaredNorm() < clearance * clearance; });
    if (!blocked) stages::append_particle(model_, state_, point, velocity, phase);
  }
  stages::activate_appended(state_, first_new);
  return state_.fluid.size() - first_new;
}

void Solver::reserve(std::size_t capacity) {
  state_.fluid.reserve(capacity);
  workspace_.reserve(capacity);
}

void Solver::set_body_motion(Index body, const Pose& pose, const Vec3& linear_velocity, const Vec3& angular_velocity) {
  auto& target = state_.bodies.at(body);
  for (const LazyWallFace& face : state_.lazy_walls)
    if (face.body == body) throw std::logic_error("body '" + target.name + "' has walls made where material comes: it cannot move");
  target.pose = pose;
  target.linear_velocity = linear_velocity;
  target.angular_velocity = angular_velocity;
  if (target.is_static) workspace_.static_boundary_dirty = true;  // it leaves the static grid
  target.is_static = false;
}

void Solver::set_nozzle(Index nozzle, const Pose& pose, const Vec3& nozzle_velocity, bool extruding, Real flow_scale,
                        std::int32_t print_layer) {
  if (!(flow_scale >= 0)) throw Error(fmt::format("sph::Solver::set_nozzle: flow_scale must be >= 0, got {}", flow_scale));
  auto& target = state_.nozzles.at(nozzle);
  target.flow_scale = flow_scale;
  target.pose = pose;
  target.velocity = nozzle_velocity;
  target.extruding = extruding;
  target.print_layer = print_layer;
}

void Solver::restore(const State& saved) {
  state_ = saved;
  workspace_.invalidate();
}

void Solver::restore(const State& saved, const Workspace& saved_workspace) {
  state_ = saved;
  workspace_ = saved_workspace;
}

Real Solver::pressure(std::size_t i) const {
  const auto& fluid = state_.fluid;
  const Real rest_density = fluid.mass[i] / particle_rest_volume(model_.settings.particle_radius);  // its phase's
  // κ = ρ0 p / ρ² summed over both solvers' updates of the last step.
  return (fluid.kappa_density[i] + fluid.kappa_divergence[i] + fluid.kappa_tension[i]) * fluid.density[i] * fluid.density[i] / rest_density;
}

double Solver::total_fluid_mass() const {
  double total = 0;
  for (const Real mass : state_.fluid.mass) total += mass;
  return total;
}

}  // namespace m3dp::sph
