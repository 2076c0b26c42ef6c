#include "m3dp/sim/simulation.hpp"

#include "m3dp/core/state_io.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "m3dp/sim/camera_rig.hpp"
#include "m3dp/sim/printed_body.hpp"
#include "m3dp/sim/robots.hpp"
#include "m3dp/sph/boundary_sampling.hpp"

namespace m3dp::sim {

namespace {
/// When a print head's path begins each layer (s, on its clock): a layer is a height more than a
/// quarter of the nozzle's bore from the last.
std::vector<double> path_layer_starts(const toolpath::Trajectory& path, const scene::PrintHead& head) {
  return toolpath::layer_start_times(path.polyline(head.inner_diameter), Real(0.25) * head.inner_diameter);
}
}  // namespace

Simulation::Simulation(const scene::Scene& scene)
    : scene_(scene), solver_(scene::solver_parameters(scene)), world_(world::WorldSettings{scene.solver.gravity}) {
  const Real spacing = solver_.particle_diameter();
  const Real wall_spacing = scene_.solver.boundary_spacing_factor * spacing;
  for (const auto& body : scene_.bodies) {
    for (const auto& collision : body.collisions) {
      // Wide flat faces (a floor, a wall) get their particles where the material comes, not all at once:
      // faces of 4,096 lattice points and more (16 × 16 cm at a 2.5 mm radius).
      const sph::TiledSurface surface =
          sph::sample_shape_surface_tiled(collision.shape, wall_spacing, -scene_.solver.particle_radius, 4096);
      solver_.add_static_surface(collision.name, surface, collision.pose);
      world_.add_static_shape(collision.name, collision.shape, collision.pose);
    }
  }
  for (const auto& body : scene_.dynamic_bodies) {
    std::vector<Shape> shapes;
    std::vector<Pose> poses;
    for (const auto& collision : body.collisions) {
      shapes.push_back(collision.shape);
      poses.push_back(collision.pose);
    }
    if (!shapes.empty()) dynamic_bodies_.push_back(world_.add_rigid_body(body.name, shapes, poses, body.mass, body.pose, body.inertia));
  }
  add_robots();
  // Every movable link (dynamic bodies, robot links, nozzle barrels) becomes a moving boundary.
  coupling_ = std::make_unique<coupling::FluidBodyCoupling>(world_, solver_);
  std::size_t initial_particles = 0;
  for (const auto& block : scene_.fluid_blocks) {
    auto points = sph::lattice_in_box(block.box, spacing);
    if (block.cylinder_radius) {
      const Vec3 axis_point = (block.box.min + block.box.max) / 2;
      const Real radius = *block.cylinder_radius;
      std::erase_if(points, [&](const Vec3& p) { return (p - axis_point).head<2>().norm() > radius; });
    }
    initial_particles += solver_.add_particles(points, block.initial_velocity, scene_.material_index(block.material));
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
  if (scene_.meshing.enabled) printed_body_ = std::make_unique<PrintedBody>(*this);
  update_print_heads();
}

void Simulation::add_robots() {
  head_paths_ = scene_head_paths(scene_);
  base_paths_ = scene_base_paths(scene_);
  head_commands_.resize(scene_.print_heads.size());
  head_control_.assign(scene_.print_heads.size(), HeadControl::path);
  gantry_targets_.resize(scene_.print_heads.size());
  plan_clocks_.resize(scene_.robots.size());
  for (std::size_t head = 0; head < scene_.print_heads.size(); ++head) {
    head_robots_.push_back(robot_of_print_head(scene_, head));
    head_layer_starts_.push_back(path_layer_starts(head_paths_[head], scene_.print_heads[head]));
  }
  robots_ = add_scene_robots(scene_, world_, plan_clocks_, base_paths_);
  head_tools_ = add_print_head_tools(scene_, world_, robots_, solver_.particle_diameter(), plan_clocks_, head_paths_);
  if (scene_.coordinator.enabled) coordination_ = std::make_unique<PrioritizedCoordination>(scene_.coordinator, scene_);
}

void Simulation::set_coordination(bool on) {
  if (on == (coordination_ != nullptr)) return;
  if (on) {
    coordination_ = std::make_unique<PrioritizedCoordination>(scene_.coordinator, scene_);
    return;
  }
  coordination_.reset();
  for (PlanClock& clock : plan_clocks_) clock.set_rate(solver_.time(), 1);
}

double Simulation::path_time(std::size_t head) const {
  const auto& robot = head_robots_.at(head);
  return robot ? plan_clocks_[*robot].at(solver_.time()) : solver_.time();
}

Simulation::NozzleState Simulation::nozzle_state(std::size_t head_index) const {
  const auto& head = scene_.print_heads.at(head_index);
  const auto sample = head_paths_[head_index].sample(path_time(head_index));
  NozzleState state;
  state.pose.position = sample.position;
  state.pose.orientation = Quat::FromTwoVectors(Vec3(0, 0, -1), head.direction.normalized());
  state.velocity = sample.velocity;
  const HeadControl control = head_control_[head_index];
  if (const auto& gantry = gantry_targets_[head_index]; gantry && control != HeadControl::path) {
    state.pose.position = gantry->follower.position().cast<Real>();
    state.pose.orientation = Quat::FromTwoVectors(Vec3(0, 0, -1), gantry->axis);
    state.velocity = gantry->follower.velocity().cast<Real>();
  }
  if (head_tools_[head_index]) {
    // A robot carries it: material leaves where the nozzle really is, along the tool's z axis
    // (the solver emits along its pose's −z: turn the tool frame over its x axis).
    state.pose = world_.tool_pose(*head_tools_[head_index]) * Pose{Vec3::Zero(), Quat(Eigen::AngleAxis<Real>(Real(kPi), Vec3::UnitX()))};
    state.velocity = world_.tool_linear_velocity(*head_tools_[head_index]);
  }
  // A G-code move asks for its own flow (E over time); other paths use the nozzle's nominal one.
  const Real nominal_flow = kPi * head.inner_diameter * head.inner_diameter / 4 * head.exit_speed;
  state.flow_scale = sample.volume_rate > 0 && nominal_flow > 0 ? sample.volume_rate / nominal_flow : Real(1);
  state.extruding = sample.extruding;
  // A robot the coordinator slows extrudes in proportion (the bead keeps its section); stopped, none.
  if (const auto& robot = head_robots_[head_index]) {
    const double rate = plan_clocks_[*robot].rate;
    state.flow_scale *= Real(rate);
    state.extruding = state.extruding && rate > 0;
  }
  const auto& starts = head_layer_starts_[head_index];
  state.print_layer = static_cast<std::int32_t>(std::upper_bound(starts.begin(), starts.end(), path_time(head_index)) - starts.begin()) - 1;
  // Under external control the abandoned path's clock says nothing: off and nominal unless told.
  if (control != HeadControl::path) {
    state.extruding = false;
    state.flow_scale = 1;
    state.print_layer = -1;
  }
  const HeadCommand& command = head_commands_[head_index];
  if (command.flow_scale) state.flow_scale = *command.flow_scale;
  if (command.extruding) state.extruding = *command.extruding;
  if (control == HeadControl::rejoining) state.extruding = false;  // travelling back to its path
  state.volume_rate = state.extruding ? nominal_flow * state.flow_scale : Real(0);
  return state;
}

void Simulation::command_head(std::size_t head, const HeadCommand& command) {
  if (command.flow_scale && !(*command.flow_scale >= 0 && *command.flow_scale <= 100))
    throw Error(fmt::format("print head '{}': a flow scale of {} (expected 0 to 100 times the nominal flow)",
                            scene_.print_heads.at(head).name, *command.flow_scale));
  head_commands_.at(head) = command;
}

namespace {
/// `path` given a new part at `now` (s): appended after its end, or replacing it from `here` (where
/// it has its follower now: a pause of `delay` there, then the travel to the new first point).
void change_path(toolpath::Trajectory& path, const Vec3& here, std::vector<toolpath::PathSegment> segments, double now,
                 double delay, bool append, const std::string& whose) {
  if (segments.empty()) throw Error(fmt::format("{}: a new path without segments", whose));
  if (!(delay >= 0) || !std::isfinite(delay)) throw Error(fmt::format("{}: a path's delay must be ≥ 0 s", whose));
  if (append) {
    path.append(std::move(segments), now + delay);
    return;
  }
  toolpath::PathSegment pause;
  pause.curve = toolpath::LineCurve{here, here};
  pause.speed = segments.front().speed;
  pause.extrude = false;
  toolpath::Trajectory changed({pause}, now);
  changed.append(std::move(segments), now + delay);
  path = std::move(changed);  // in place: the controllers read it where it is
}
}  // namespace

void Simulation::set_head_path(std::size_t head_index, std::vector<toolpath::PathSegment> segments, double delay, bool append) {
  const auto& head = scene_.print_heads.at(head_index);
  auto& path = head_paths_.at(head_index);
  const double now = path_time(head_index);
  change_path(path, path.sample(now).position, std::move(segments), now, delay, append, fmt::format("print head '{}'", head.name));
  head_layer_starts_[head_index] = path_layer_starts(path, head);
  release_head(head_index);
}

void Simulation::set_base_path(std::size_t robot, std::vector<toolpath::PathSegment> segments, double delay, bool append) {
  const auto& description = scene_.robots.at(robot);
  if (!description.mobile_base) throw Error(fmt::format("robot '{}' has no mobile base", description.name));
  auto& path = base_paths_.at(robot);
  const double now = plan_clocks_[robot].at(solver_.time());
  const bool had_path = path.has_value();
  // A base without a path starts its new one where it stands.
  Vec3 here = world_.base_pose(robots_[robot]).position;
  if (!had_path) path = toolpath::Trajectory({}, now);
  else here = path->sample(now).position;
  change_path(*path, here, std::move(segments), now, delay, append && had_path, fmt::format("robot '{}'", description.name));
  if (!had_path) world_.set_base_trajectory(robots_[robot], clocked_base_path(*path, plan_clocks_[robot]));
  world_.set_external_control(robots_[robot], false);
}

void Simulation::update_print_heads() {
  for (std::size_t i = 0; i < scene_.print_heads.size(); ++i) {
    update_head_control(i);
    const NozzleState state = nozzle_state(i);
    solver_.set_nozzle(static_cast<Index>(i), state.pose, state.velocity, state.extruding, state.flow_scale, state.print_layer);
  }
}

std::string_view Simulation::to_string(HeadControl control) {
  switch (control) {
    case HeadControl::path: return "path";
    case HeadControl::external: return "external";
    case HeadControl::rejoining: return "rejoining";
  }
  return "?";
}

Real Simulation::rejoin_tolerance(std::size_t head) const {
  return std::max(Real(5e-4), Real(0.1) * scene_.print_heads.at(head).inner_diameter);
}

void Simulation::command_head_target(std::size_t head, const world::ToolTarget& target, const world::MotionLimits& limits) {
  const auto& description = scene_.print_heads.at(head);
  if (!target.position.allFinite() || !target.axis.allFinite() || target.axis.norm() < Real(1e-6))
    throw Error(fmt::format("print head '{}': a target needs a finite position (m) and a non-zero axis", description.name));
  const Vec3& at = target.position;
  if (const auto& tool = head_tools_[head]) {
    // An unreachable target is an error now, not a robot straining at its joint limits for ever.
    const double miss = world_.tool_target_miss(*tool, target);
    if (miss > 2e-3)
      throw Error(fmt::format("print head '{}': the target ({:.4g}, {:.4g}, {:.4g}) m is out of reach of robot '{}': its "
                              "inverse kinematics gets the nozzle no closer than {:.3f} m",
                              description.name, at.x(), at.y(), at.z(), scene_.robots.at(*head_robots_[head]).name, miss));
    world_.command_tool_target(*tool, target, limits);
    head_control_[head] = HeadControl::external;
    return;
  }
  const Aabb& bounds = scene_.solver.bounds;
  if ((at.array() < bounds.min.array()).any() || (at.array() > bounds.max.array()).any())
    throw Error(fmt::format("print head '{}': the target ({:.4g}, {:.4g}, {:.4g}) m is outside the scene's <bounds>", description.name,
                            at.x(), at.y(), at.z()));
  auto& gantry = gantry_targets_[head];
  if (!gantry) {
    gantry.emplace();
    gantry->follower.reset(nozzle_state(head).pose.position.cast<double>(), solver_.time());
  }
  gantry->follower.set_target(at.cast<double>(), limits);
  gantry->axis = target.axis.normalized();
  gantry->external = true;
  head_control_[head] = HeadControl::external;
}

void Simulation::release_head(std::size_t head) {
  if (const auto robot = head_robots_.at(head); robot && head_tools_[head]) world_.set_external_control(robots_[*robot], false);
  if (auto& gantry = gantry_targets_[head]) gantry->external = false;
}

const world::TargetFollower* Simulation::head_target(std::size_t head) const {
  if (head_control_.at(head) == HeadControl::path) return nullptr;
  if (const auto& gantry = gantry_targets_[head]) return &gantry->follower;
  return head_tools_[head] ? world_.tool_target_follower(*head_tools_[head]) : nullptr;
}

void Simulation::update_head_control(std::size_t head) {
  HeadControl& control = head_control_[head];
  auto& gantry = gantry_targets_[head];
  const auto& tool = head_tools_[head];
  const bool external = tool ? world_.external_control(robots_[*head_robots_[head]]) : gantry && gantry->external;
  if (external) {
    control = HeadControl::external;
    if (gantry) gantry->follower.advance(solver_.time());
    return;
  }
  if (control == HeadControl::external) control = HeadControl::rejoining;
  if (control != HeadControl::rejoining) return;
  const auto path_now = head_paths_[head].sample(path_time(head));
  const Vec3 on_path = path_now.position;
  Vec3 at = Vec3::Zero();
  if (gantry) {
    // A gantry travels back within the default limits, catching up with where its path is now.
    gantry->follower.set_target(on_path.cast<double>(), world::MotionLimits{}, path_now.velocity.cast<double>());
    at = gantry->follower.advance(solver_.time()).cast<Real>();
  } else {
    at = nozzle_state(head).pose.position;
  }
  if ((at - on_path).norm() <= rejoin_tolerance(head)) {
    control = HeadControl::path;
    gantry.reset();
  }
}



const sph::StepStats& Simulation::step() {
  using Clock = std::chrono::steady_clock;
  auto milliseconds_since = [](Clock::time_point start) {
    return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  };
  if (coordination_) coordination_->update(*this, plan_clocks_);
  update_print_heads();
  auto start = Clock::now();
  coupling_->push_link_motion();
  last_coupling_ms_ = milliseconds_since(start);
  const sph::StepStats& stats = solver_.step();
  start = Clock::now();
  coupling_->pull_fluid_wrenches();
  last_coupling_ms_ += milliseconds_since(start);
  start = Clock::now();
  world_.step_to(solver_.time());
  last_world_ms_ = milliseconds_since(start);
  if (printed_body_)
    if (auto mesh = printed_body_->after_step(*this)) set_printed_mesh(std::move(mesh));
  check_material_kept();
  return stats;
}

void Simulation::check_material_kept() const {
  // A few particles thrown out is a splash; most of the material is a blow-up (a run where 7,978 of
  // 7,992 particles left ended "completed" before this check).
  const auto& state = solver_.state();
  const double ever = initial_fluid_mass_ + state.mass_emitted_total;
  if (state.particles_removed_total < 100 || !(state.mass_removed_total > kLostFractionBlowUp * ever)) return;
  throw SimulationError(fmt::format(
      "simulation blew up at t = {:.6f} s (step {}): {} particles, {:.0f} % of the material, left the bounds ({} remain). "
      "If the material should stay, the time step may be too large (max_time_step, cfl_factor); if it leaves the scene "
      "on purpose, make the <bounds> larger",
      state.time, state.step, state.particles_removed_total, 100 * state.mass_removed_total / ever, solver_.fluid().size()));
}

Simulation::VolumeBalance Simulation::nozzle_volumes(std::size_t n) const {
  const auto& nozzle = solver_.state().nozzles[n];
  const double particle_volume = solver_.model().particle_volume;
  VolumeBalance volumes;
  volumes.commanded = nozzle.volume_commanded;
  volumes.emitted = double(nozzle.particles_emitted) * particle_volume;
  volumes.primed = nozzle.volume_primed;
  volumes.in_bores = double(sph::particles_in_bore(solver_, n)) * particle_volume;
  volumes.laid = volumes.emitted - volumes.in_bores;
  volumes.lost_at_nozzles = nozzle.volume_lost;
  return volumes;
}

Simulation::VolumeBalance Simulation::volume_balance() const {
  const auto& state = solver_.state();
  const double particle_volume = solver_.model().particle_volume;
  VolumeBalance balance;
  for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
    const VolumeBalance nozzle = nozzle_volumes(n);
    balance.commanded += nozzle.commanded;
    balance.emitted += nozzle.emitted;
    balance.primed += nozzle.primed;
    balance.in_bores += nozzle.in_bores;
    balance.laid += nozzle.laid;
    balance.lost_at_nozzles += nozzle.lost_at_nozzles;
  }
  balance.removed = double(state.particles_removed_total) * particle_volume;
  balance.in_particles = double(solver_.fluid().size()) * particle_volume;
  return balance;
}

const Simulation::DensityMeasurement& Simulation::measured_density() const {
  if (density_measurement_.step != solver_.state().step) {
    sph::measure_density(solver_, density_measurement_.density);
    density_measurement_.statistics = sph::density_statistics(solver_, density_measurement_.density);
    density_measurement_.step = solver_.state().step;
    density_measurement_.time = solver_.time();
  }
  return density_measurement_;
}

Simulation::~Simulation() = default;

CameraRig& Simulation::cameras() const {
  if (!cameras_) cameras_ = std::make_unique<CameraRig>(*this);
  return *cameras_;
}

void Simulation::save_state(StateWriter& out) const {
  out.section("simulation");
  sph::save_state(solver_.state(), out);
  world_.save_state(out);
  out.put(static_cast<std::uint64_t>(printed_mesh_version_));
  out.put(printed_mesh_ != nullptr);
  if (printed_mesh_) {
    out.put(printed_mesh_->vertices);
    out.put(printed_mesh_->triangles);
  }
  if (printed_body_) printed_body_->save(out);
  out.put(cameras_ != nullptr);
  if (cameras_) cameras_->save_totals(out);
  out.put(plan_clocks_);
  out.put(coordination_ != nullptr);
  if (coordination_) coordination_->save(out);
  // The paths as they are now (given at run time included), what was commanded from outside and who
  // moves each head.
  for (const auto& path : head_paths_) path.save(out);
  for (const auto& path : base_paths_) {
    out.put(path.has_value());
    if (path) path->save(out);
  }
  for (std::size_t head = 0; head < head_commands_.size(); ++head) {
    const HeadCommand& command = head_commands_[head];
    out.put(command.extruding.has_value());
    out.put(command.extruding.value_or(false));
    out.put(command.flow_scale.has_value());
    out.put(command.flow_scale.value_or(Real(1)));
    out.put(static_cast<std::uint8_t>(head_control_[head]));
    const auto& gantry = gantry_targets_[head];
    out.put(gantry.has_value());
    if (gantry) {
      out.put(gantry->external);
      gantry->follower.save(out);
      out.put(gantry->axis);
    }
  }
}

void Simulation::load_state(StateReader& in) {
  in.section("simulation");
  sph::State state = solver_.state();
  sph::load_state(in, state);
  solver_.restore(state);
  world_.load_state(in);
  const auto mesh_version = in.get<std::uint64_t>();
  if (in.get<bool>()) {
    auto mesh = std::make_shared<TriangleMesh>();
    in.get(mesh->vertices);
    in.get(mesh->triangles);
    for (const auto& triangle : mesh->triangles)
      for (const Index vertex : triangle)
        if (vertex >= mesh->vertices.size()) in.fail("a printed-mesh triangle with a vertex it does not have");
    set_printed_mesh(std::move(mesh));
  }
  printed_mesh_version_ = mesh_version;
  if (printed_body_) printed_body_->load(in, printed_mesh_);
  if (in.get<bool>()) cameras().load_totals(in);
  std::vector<PlanClock> clocks;
  in.get(clocks);
  if (clocks.size() != plan_clocks_.size()) in.fail("a checkpoint for another number of robots");
  set_coordination(in.get<bool>());
  if (coordination_) coordination_->load(in);
  std::copy(clocks.begin(), clocks.end(), plan_clocks_.begin());  // in place: the world's paths point into it
  // In place: the world's controllers point into them.
  for (std::size_t head = 0; head < head_paths_.size(); ++head) {
    head_paths_[head].load(in);
    head_layer_starts_[head] = path_layer_starts(head_paths_[head], scene_.print_heads[head]);
  }
  for (std::size_t robot = 0; robot < base_paths_.size(); ++robot) {
    auto& path = base_paths_[robot];
    const bool had_path = path.has_value();
    if (!in.get<bool>()) {
      if (had_path) in.fail("a checkpoint without a base path the scene has");
      continue;
    }
    if (!path) path.emplace();
    path->load(in);
    if (!had_path) world_.set_base_trajectory(robots_[robot], clocked_base_path(*path, plan_clocks_[robot]));
  }
  for (std::size_t head = 0; head < head_commands_.size(); ++head) {
    HeadCommand& command = head_commands_[head];
    const bool has_extruding = in.get<bool>();
    const bool extruding = in.get<bool>();
    command.extruding = has_extruding ? std::optional<bool>(extruding) : std::nullopt;
    const bool has_flow_scale = in.get<bool>();
    const Real flow_scale = in.get<Real>();
    command.flow_scale = has_flow_scale ? std::optional<Real>(flow_scale) : std::nullopt;
    const auto control = in.get<std::uint8_t>();
    if (control > static_cast<std::uint8_t>(HeadControl::rejoining)) in.fail("a print head's control that does not exist");
    head_control_[head] = static_cast<HeadControl>(control);
    auto& gantry = gantry_targets_[head];
    gantry.reset();
    if (in.get<bool>()) {
      gantry.emplace();
      in.get(gantry->external);
      gantry->follower.load(in);
      in.get(gantry->axis);
    }
  }
  density_measurement_.step = -1;
}

void Simulation::drop_caches() { solver_.drop_caches(); }

void Simulation::prepare_checkpoint() {
  if (!printed_body_) return;
  if (auto mesh = printed_body_->settle()) set_printed_mesh(std::move(mesh));
}

void Simulation::set_printed_mesh(std::shared_ptr<const TriangleMesh> mesh) {
  world_.set_static_mesh("printed_material", *mesh);
  printed_mesh_ = std::move(mesh);
  ++printed_mesh_version_;
}

}  // namespace m3dp::sim
