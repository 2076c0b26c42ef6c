#include "m3dp/sph/solver.hpp"

#include <fmt/format.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <numeric>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"

namespace m3dp::sph {

namespace {

using Clock = std::chrono::steady_clock;
double elapsed_ms(Clock::time_point since) {
  return std::chrono::duration<double, std::milli>(Clock::now() - since).count();
}

/// Fast particles that kept neighbour lists tolerate (SkinnedNeighborSearch): each searches the grids
/// itself and all of them pairwise, so a few hundred cost less than a new search of every particle.
std::size_t most_movers(std::size_t active_count) {
  return std::clamp<std::size_t>(active_count / 64, 32, 1024);
}

/// Disc samples on a square lattice of spacing `spacing` inside radius D/2 (at least the centre).
NozzleGeometry make_nozzle_geometry(const NozzleSettings& nozzle, Real spacing) {
  NozzleGeometry geometry;
  const Real radius = nozzle.inner_diameter / 2;
  const int half_count = static_cast<int>(std::ceil(radius / spacing)) + 1;
  // Offset the lattice by half a spacing when that packs more points (even counts across).
  for (const Real shift : {Real(0), Real(0.5)}) {
    std::vector<Vec3> offsets;
    for (int i = -half_count; i <= half_count; ++i)
      for (int j = -half_count; j <= half_count; ++j) {
        const Vec3 point((i + shift) * spacing, (j + shift) * spacing, 0);
        if (point.head<2>().norm() <= radius + Real(1e-6) * spacing) offsets.push_back(point);
      }
    if (offsets.size() > geometry.disc_offsets.size()) geometry.disc_offsets = std::move(offsets);
  }
  if (geometry.disc_offsets.empty()) geometry.disc_offsets.push_back(Vec3::Zero());
  const double particle_volume = std::pow(static_cast<double>(spacing), 3);
  const double flux = kPi * nozzle.inner_diameter * nozzle.inner_diameter / 4 * nozzle.exit_speed;  // m³/s
  geometry.layer_period = flux > 0 ? geometry.disc_offsets.size() * particle_volume / flux : 0;
  return geometry;
}

/// Akinci 2012 volumes (V_b = 1/Σ W) make a one-layer wall contribute more density than the fluid
/// it replaces: a particle resting one spacing in front of a flat wall would sit ~6 % over rest
/// density (cubic spline, h = 4r), so every fluid block starts compressed where it touches a wall and
/// the first pressure solves push violently. This factor scales the boundary volumes so that a
/// cubic-lattice fluid at one spacing from a square-lattice wall is exactly at rest density.
/// Computed once from the kernel, with the same sums the solver uses.
/// Σ_b V_b W over a flat square-lattice wall layer (spacing `wall_spacing`, Akinci volumes
/// V_b = 1 / Σ_in-plane W) at `distance` from the layer.
Real wall_share(KernelType type, Real support_radius, Real wall_spacing, Real distance) {
  return with_kernel(type, support_radius, [&](const auto& kernel) {
    const int reach = static_cast<int>(std::ceil(support_radius / wall_spacing)) + 1;
    double in_plane = 0, share = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j) {
        in_plane += kernel.W(Vec3(i * wall_spacing, j * wall_spacing, 0).norm());
        share += kernel.W(Vec3(i * wall_spacing, j * wall_spacing, distance).norm());
      }
    return static_cast<Real>(share / in_plane);
  });
}

/// Akinci 2012 volumes make a one-layer wall contribute more density than the fluid it replaces:
/// a particle resting one spacing in front of a flat wall would sit several per cent over rest
/// density, so every fluid block would start compressed where it touches a wall and the first
/// pressure solves push violently. This factor scales the boundary volumes so that a cubic-lattice
/// fluid (spacing d) one spacing from the wall layer is exactly at rest density.
Real calibrated_boundary_volume_scale(KernelType type, Real support_radius, Real fluid_spacing, Real wall_spacing) {
  const double fluid_share = with_kernel(type, support_radius, [&](const auto& kernel) {
    const int reach = static_cast<int>(std::ceil(support_radius / fluid_spacing)) + 1;
    double sum = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j)
        for (int k = 0; k <= reach; ++k) sum += kernel.W(Vec3(i * fluid_spacing, j * fluid_spacing, k * fluid_spacing).norm());
    return sum * std::pow(static_cast<double>(fluid_spacing), 3);  // the half-lattice on the particle's side
  });
  return static_cast<Real>((1.0 - fluid_share) / wall_share(type, support_radius, wall_spacing, fluid_spacing));
}

/// The Morris/Monaghan viscosity sum 2(d+2) Σ_j V_j (v_ij·x_ij)/(r² + 0.01h²) ∇W_ij is the Laplacian
/// only where a kernel has many neighbours: on the rest lattice of a cubic spline with a support of
/// two spacings (our default) it gives 0.70 ∇²v, so every viscosity would act 30 % too weak (the
/// Poiseuille test sees exactly that). `fluid` scales the sum so that it is exact on the rest lattice
/// for a shear flow u = (z², 0, 0). `boundary` scales the wall term so that a linear shear flow
/// u = γ̇ z over a wall is in equilibrium, i.e. the no-slip plane is the geometric surface (a radius in
/// front of the boundary layer), with the Akinci volumes the solver gives a flat wall. The velocity
/// gradient (the rheology's shear rate) gets the same treatment: exact for linear shear inside the
/// fluid and over a wall (with the wall's term alone, a first-layer particle sees 0.77 of its shear
/// rate, and a yield-stress material at the wall behaves too stiff).
ViscosityCalibration calibrated_viscosity(KernelType type, Real support_radius, Real fluid_spacing, Real wall_spacing,
                                          Real boundary_volume_scale) {
  return with_kernel(type, support_radius, [&](const auto& kernel) {
    const double d = fluid_spacing, regularisation = 0.01 * double(support_radius) * support_radius, volume = d * d * d;
    const int reach = static_cast<int>(std::ceil(support_radius / fluid_spacing)) + 1;
    auto pair_term = [&](double distance_squared) {
      return double(kernel.gradient_factor(Real(std::sqrt(distance_squared)))) / (distance_squared + regularisation);
    };
    // Laplacian of (z², 0, 0) at the origin: x-component of 2(d+2) Σ V (u_i − u_j)(x_i − x_j)² f / (r² + ε) = 2.
    double laplacian = 0, fluid_shear = 0, gradient = 0, fluid_gradient_near_wall = 0, coupling = 0;
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j)
        for (int k = -reach; k <= reach; ++k) {
          const double x = i * d, y = j * d, z = k * d, r2 = x * x + y * y + z * z;
          if (r2 == 0 || r2 >= double(support_radius) * support_radius) continue;
          laplacian += volume * (-z * z) * x * x * pair_term(r2);
          coupling += volume * std::abs(pair_term(r2)) * r2;
          // Linear shear over the wall: the fluid neighbours of a first-layer particle (k ≥ 0), u = z.
          if (k >= 0) fluid_shear += volume * (-z) * x * x * pair_term(r2);
          // Velocity gradient of u = (z, 0, 0): Σ V (u_j − u_i)(z_i − z_j) f = ∂u/∂z = 1; near the wall only k ≥ 0.
          const double gradient_term = volume * z * (-z) * double(kernel.gradient_factor(Real(std::sqrt(r2))));
          gradient += gradient_term;
          if (k >= 0) fluid_gradient_near_wall += gradient_term;
        }
    laplacian *= 2 * (3 + 2);
    const double fluid_scale = 2.0 / laplacian;
    // The wall layer one spacing below that particle (no-slip plane half a spacing below it), at rest.
    double in_plane = 0, wall_shear = 0, wall_gradient = 0;
    const int wall_reach = static_cast<int>(std::ceil(support_radius / wall_spacing)) + 1;
    for (int i = -wall_reach; i <= wall_reach; ++i)
      for (int j = -wall_reach; j <= wall_reach; ++j) in_plane += kernel.W(Vec3(i * wall_spacing, j * wall_spacing, 0).norm());
    const double wall_volume = boundary_volume_scale / in_plane;
    for (int i = -wall_reach; i <= wall_reach; ++i)
      for (int j = -wall_reach; j <= wall_reach; ++j) {
        const double x = i * wall_spacing, y = j * wall_spacing, r2 = x * x + y * y + d * d;
        if (r2 >= double(support_radius) * support_radius) continue;
        wall_shear += wall_volume * (d / 2) * x * x * pair_term(r2);
        wall_gradient += wall_volume * (-d / 2) * d * double(kernel.gradient_factor(Real(std::sqrt(r2))));
      }
    ViscosityCalibration calibration;
    calibration.fluid = static_cast<Real>(fluid_scale);
    calibration.boundary = static_cast<Real>(-fluid_scale * fluid_shear / wall_shear);
    calibration.fluid_gradient = static_cast<Real>(1 / gradient);
    calibration.boundary_gradient = static_cast<Real>((1 - fluid_gradient_near_wall / gradient) / (wall_gradient / gradient));
    calibration.coupling = static_cast<Real>(2 * (3 + 2) * fluid_scale * coupling);
    return calibration;
  });
}

}  // namespace

Solver::Solver(Parameters parameters) : parameters_(std::move(parameters)) {
  const auto& settings = parameters_.settings;
  if (!(settings.particle_radius > 0)) throw Error("sph::Solver: particle_radius must be > 0");
  if (parameters_.phases.empty()) throw Error("sph::Solver: at least one fluid phase is needed");
  for (const auto& phase : parameters_.phases)
    if (!(phase.density > 0)) throw Error(fmt::format("sph::Solver: phase '{}' needs a rest density > 0 kg/m³", phase.name));
  for (const auto& nozzle : parameters_.nozzles) {
    if (nozzle.phase >= parameters_.phases.size()) throw Error("sph::Solver: nozzle '" + nozzle.name + "' has no phase");
    nozzle_geometry_.push_back(make_nozzle_geometry(nozzle, particle_diameter()));
  }
  state_.nozzles.resize(parameters_.nozzles.size());
  const Real wall_spacing = settings.boundary_spacing_factor * particle_diameter();
  boundary_volume_scale_ = calibrated_boundary_volume_scale(settings.kernel, support_radius(), particle_diameter(), wall_spacing);
  // A centre on the geometric surface is a radius from the layer; the limit sits a tenth of a radius
  // in front of it, so that rounding never leaves a centre on the wrong side.
  viscosity_calibration_ = calibrated_viscosity(settings.kernel, support_radius(), particle_diameter(), wall_spacing,
                                                boundary_volume_scale_);
  surface_tension_calibration_ =
      calibrated_surface_tension(settings.kernel, support_radius(), particle_diameter(), wall_spacing, boundary_volume_scale_);
  surface_tension_calibration_.layer_kernel_sum = csf_layer_kernel_sum(settings.kernel, support_radius(), particle_diameter());
  boundary_share_at_surface_ =
      boundary_volume_scale_ * wall_share(settings.kernel, support_radius(), wall_spacing, Real(1.1) * settings.particle_radius);
  derive_material_data();
  state_.time_step = settings.max_time_step;
  if (!(settings.neighbor_skin >= 0)) throw Error(fmt::format("sph::Solver: neighbor_skin must be >= 0, got {}", settings.neighbor_skin));
  state_.search_cell_size = support_radius();
}

void Solver::derive_material_data() {
  // Per-phase data of the optional models, and the checks that need the solver's settings.
  for (const auto& phase : parameters_.phases) {
    largest_surface_tension_ = std::max(largest_surface_tension_, phase.surface_tension);
    lightest_rest_density_ = std::min(lightest_rest_density_, phase.density);
    // Akinci's adhesion pulls against Akinci's cohesion; without it (measured on sessile drops, 0.5σ to
    // 2σ) the contact line sprayed apart.
    if (phase.adhesion > 0 && parameters_.settings.surface_tension_model == SurfaceTensionModel::csf_brackbill1992)
      throw Error(fmt::format("sph::Solver: material '{}' sets an adhesion, which the brackbill1992 surface tension "
                              "model does not have (it wets walls at 90°); use the akinci2013 model",
                              phase.name));
  }
  full_neighbourhood_ = full_neighbourhood_count(support_radius(), particle_diameter());
  for (const auto& phase : parameters_.phases) {
    if (!phase.elasticity.enabled) continue;
    any_elastic_ = true;
    if (parameters_.settings.viscosity_solver != ViscositySolver::implicit_weiler2018)
      throw Error(fmt::format("sph::Solver: material '{}' is elastic, which needs the implicit viscosity solver", phase.name));
    if (!(phase.elasticity.shear_modulus > 0))
      throw Error(fmt::format("sph::Solver: material '{}': shear modulus must be > 0 Pa", phase.name));
    if (!(phase.elasticity.poisson_ratio >= 0 && phase.elasticity.poisson_ratio <= Real(0.49)))
      throw Error(fmt::format("sph::Solver: material '{}': Poisson's ratio must be in [0, 0.49], got {}", phase.name,
                              phase.elasticity.poisson_ratio));
  }
  for (const auto& phase : parameters_.phases) {
    // Micropolar: Θ of the sphere of one particle's volume unless the material gives one.
    const Real sphere_radius = particle_diameter() * std::cbrt(Real(3) / (4 * kPi));
    microinertia_.push_back(phase.micropolar.microinertia > 0 ? phase.micropolar.microinertia
                                                              : Real(0.4) * sphere_radius * sphere_radius);
  }
  if (parameters_.settings.air_drag && !(parameters_.settings.air_density > 0 && parameters_.settings.air_viscosity > 0))
    throw Error("sph::Solver: air drag needs a positive air density and viscosity");
  // Granular mode: every phase or none (a fluid and discrete spheres do not interact yet).
  granular_ = parameters_.phases.front().granular.enabled;
  for (const auto& phase : parameters_.phases)
    if (phase.granular.enabled != granular_)
      throw Error(fmt::format("sph::Solver: material '{}' is {} but '{}' is {}; one scene's materials are all fluids or "
                              "all granular for now",
                              phase.name, phase.granular.enabled ? "granular" : "a fluid", parameters_.phases.front().name,
                              granular_ ? "granular" : "a fluid"));
  if (granular_) {
    // The default spring: a column of ten particles under gravity compresses each contact by 1 % of
    // a diameter (stiff enough to keep the particle size, soft enough for ~1e-4 s steps at d = 2 mm).
    const Real gravity = parameters_.settings.gravity.norm() > 0 ? parameters_.settings.gravity.norm() : Real(9.81);
    for (std::uint16_t p = 0; p < parameters_.phases.size(); ++p) {
      const auto& granular = parameters_.phases[p].granular;
      if (!(granular.restitution > 0 && granular.restitution <= 1))
        throw Error(fmt::format("sph::Solver: material '{}': restitution must be in (0, 1], got {}", parameters_.phases[p].name,
                                granular.restitution));
      const Real stiffness = granular.stiffness > 0 ? granular.stiffness : 1000 * particle_mass(p) * gravity / particle_diameter();
      granular_contacts_.push_back(GranularContact{stiffness, granular.damping_ratio(), granular.friction});
      // Contact duration π√(m*/k), m* = m/2 between two particles; ten steps per contact.
      const Real contact_time = kPi * std::sqrt(particle_mass(p) / 2 / stiffness);
      granular_time_step_ = granular_time_step_ > 0 ? std::min(granular_time_step_, contact_time / 10) : contact_time / 10;
    }
  }
}

Real Solver::particle_mass(std::uint16_t phase) const {
  const Real diameter = particle_diameter();
  return parameters_.phases[phase].density * diameter * diameter * diameter;
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
  for (const Vec3& local : local_points) {
    boundary.local_position.push_back(local);
    boundary.position.push_back(pose.apply(local));
    boundary.velocity.push_back(Vec3::Zero());
    boundary.body.push_back(body_index);
  }
  // Akinci 2012, eq. 4: V_b = 1 / Σ_k W_bk (times the calibration above). Static bodies are summed together, so where walls meet or
  // overlap (a tank built from boxes) the shared region is not counted twice; a moving body on its own
  // (its volumes then do not change with its pose).
  const Real support = support_radius();
  std::vector<Index> members;
  for (Index k = 0; k < boundary.size(); ++k)
    if (is_static ? state_.bodies[boundary.body[k]].is_static : boundary.body[k] == body_index) members.push_back(k);
  std::vector<Vec3> points;
  points.reserve(members.size());
  for (const Index k : members) points.push_back(boundary.position[k]);
  boundary.volume.resize(boundary.size());
  SpatialHashGrid grid;
  grid.build(points, support);
  with_kernel(parameters_.settings.kernel, support, [&](const auto& kernel) {
    for (std::size_t m = 0; m < members.size(); ++m) {
      Real sum = 0;
      grid.for_each_candidate(points[m], [&](Index, const Vec3& other) { sum += kernel.W((points[m] - other).norm()); });
      boundary.volume[members[m]] = boundary_volume_scale_ / sum;
    }
  });
  state_.static_boundary_dirty = true;
  state_.static_boundary_indices.reserve(boundary.size());
  state_.moving_boundary_indices.reserve(boundary.size());
  return body_index;
}

std::size_t Solver::add_particles(std::span<const Vec3> positions, const Vec3& velocity, std::uint16_t phase) {
  // Skip points closer than one spacing to the boundary layer, i.e. less than a radius in front of a
  // surface (the layer lies a radius behind it; see boundary_sampling.hpp).
  const Real min_distance = particle_diameter() * Real(0.999);
  SpatialHashGrid grid;
  grid.build(state_.boundary.position, support_radius());
  auto& fluid = state_.fluid;
  const std::size_t first_new = fluid.size();
  std::size_t added = 0;
  for (const Vec3& point : positions) {
    bool blocked = false;
    grid.for_each_candidate(point, [&](Index, const Vec3& b) { blocked |= (point - b).squaredNorm() < min_distance * min_distance; });
    if (blocked) continue;
    const std::size_t i = fluid.size();
    fluid.resize(i + 1);
    fluid.position[i] = point;
    fluid.velocity[i] = velocity;
    fluid.acceleration[i] = Vec3::Zero();
    fluid.mass[i] = particle_mass(phase);
    fluid.density[i] = parameters_.phases[phase].density;
    fluid.phase[i] = phase;
    fluid.id[i] = state_.next_particle_id++;
    fluid.birth_time[i] = static_cast<Real>(state_.time);
    fluid.viscosity[i] = parameters_.phases[phase].rheology.viscosity;
    fluid.shear_rate[i] = 0;
    fluid.viscous_change[i] = Vec3::Zero();
    fluid.viscous_velocity[i] = velocity;
    fluid.rest_time[i] = 0;
    fluid.rest_load[i] = -1;
    fluid.angular_velocity[i] = Vec3::Zero();
    fluid.reference_position[i] = point;
    ++added;
  }
  activate_appended(first_new);
  return added;
}

void Solver::activate_appended(std::size_t first) {
  auto& fluid = state_.fluid;
  // Each new particle takes the first resting one's slot; that one moves to the end.
  for (std::size_t i = first; i < fluid.size(); ++i) {
    if (i != state_.active_count) fluid.swap(i, state_.active_count);
    ++state_.active_count;
  }
}

void Solver::update_rest_partition() {
  auto& fluid = state_.fluid;
  const Real duration = parameters_.settings.rest_duration;
  // Resting: from the top of the active range down, so a swap never moves an unvisited candidate.
  for (std::size_t i = state_.active_count; i-- > 0;) {
    if (fluid.rest_time[i] < duration) continue;
    const std::size_t last = --state_.active_count;
    if (i != last) fluid.swap(i, last);
    fluid.velocity[last] = Vec3::Zero();
    fluid.viscous_change[last] = Vec3::Zero();
    fluid.viscous_velocity[last] = Vec3::Zero();
    fluid.angular_velocity[last] = Vec3::Zero();
    fluid.kappa_density[last] = 0;
    fluid.kappa_divergence[last] = 0;
    fluid.rest_load[last] = -1;  // measured at the next load check
  }
  // Waking: a resting particle whose clock was reset by motion nearby (update_rest_clocks).
  if (!state_.resting_woken) return;
  state_.resting_woken = 0;
  for (std::size_t j = state_.active_count; j < fluid.size(); ++j) {
    if (fluid.rest_time[j] >= duration) continue;
    if (j != state_.active_count) fluid.swap(j, state_.active_count);
    ++state_.active_count;
  }
}

void Solver::update_rest_clocks(Real time_step) {
  const auto& settings = parameters_.settings;
  auto& fluid = state_.fluid;
  const std::size_t active = state_.active_count;
  const Real rest_speed_squared = settings.rest_speed * settings.rest_speed;
  const Real wake_speed_squared = settings.wake_speed * settings.wake_speed;
  const Real time = static_cast<Real>(state_.time);
  auto wake = [&](std::size_t j) {
    std::atomic_ref<Real>(fluid.rest_time[j]).store(0, std::memory_order_relaxed);
    std::atomic_ref<int>(state_.resting_woken).store(1, std::memory_order_relaxed);
  };
  // With none resting there is nothing to wake: no pass over the fast particles' lists (in the 47k
  // dam break, most of them: 0.5 ms a step).
  const bool any_resting = active < fluid.size();
  parallel_for_each_index(active, [&](std::size_t i) {
    const FluidPhase& phase = parameters_.phases[fluid.phase[i]];
    const Real speed_squared = fluid.velocity[i].squaredNorm();
    // Only a yield-stress material can stop for good (any other creeps on); it rests while slow and
    // while its shear stress μ γ̇ stays below its (aged) yield stress.
    bool resting = false;
    // An elastic material never rests: its stress depends on where its neighbours are.
    if (material::has_yield_stress(phase.rheology.model) && !phase.elasticity.enabled && speed_squared < rest_speed_squared) {
      const Real age = time - fluid.birth_time[i];
      resting = fluid.viscosity[i] * fluid.shear_rate[i] < phase.ageing.yield_stress(phase.rheology.yield_stress, age);
    }
    // A negative clock (woken by load) keeps counting from where it is; motion cannot shorten the hold.
    fluid.rest_time[i] = resting ? fluid.rest_time[i] + time_step : std::min(fluid.rest_time[i], Real(0));
    if (any_resting && speed_squared > wake_speed_squared)
      for (const Index j : state_.fluid_neighbors.of(i))
        if (j >= active) wake(j);
  }, 512);
  // A moving body's surface wakes the resting material it reaches (a robot, a dropped box).
  if (active == fluid.size() || state_.moving_boundary_indices.empty()) return;
  const Real support_squared = support_radius() * support_radius();
  parallel_for_each_index(state_.moving_boundary_indices.size(), [&](std::size_t k) {
    const Index b = state_.moving_boundary_indices[k];
    const Vec3 velocity = state_.boundary.velocity[b];
    if (velocity.squaredNorm() <= wake_speed_squared) return;
    // Where the surface is now and where it will be in two steps: a fast body must not reach resting
    // material before it has woken (it would land inside particles that do not push back).
    for (const Vec3& position : {state_.boundary.position[b], Vec3(state_.boundary.position[b] + 2 * time_step * velocity)})
      state_.resting_grid.for_each_candidate(position, [&](Index j, const Vec3& p) {
        if (j >= active && (p - position).squaredNorm() < support_squared) wake(j);
      });
  }, 64);
}

void Solver::wake_loaded_rest() {
  const auto& settings = parameters_.settings;
  auto& fluid = state_.fluid;
  const std::size_t count = fluid.size();
  const Real g = settings.gravity.norm();
  if (state_.active_count == count || !(g > 0)) return;
  // Columns two particle diameters across, along gravity: the weight per area above each particle,
  // σ_v = g Σ m / w², from the top of its column down. One diameter is too noisy: the particles are
  // not on a lattice, and a d-wide column over a print's seam held twice its share.
  const Vec3 down = settings.gravity / g;
  const Vec3 across_u = down.unitOrthogonal();
  const Vec3 across_v = down.cross(across_u);
  const Real column_width = 2 * particle_diameter();
  const Real inverse_width = 1 / column_width;
  state_.sort_keys.resize(count);
  state_.permutation.resize(count);
  state_.height.resize(count);
  parallel_for_each_index(count, [&](std::size_t i) {
    const Vec3& p = fluid.position[i];
    const auto column_u = static_cast<std::int64_t>(std::floor(p.dot(across_u) * inverse_width)) + (std::int64_t(1) << 31);
    const auto column_v = static_cast<std::int64_t>(std::floor(p.dot(across_v) * inverse_width)) + (std::int64_t(1) << 31);
    state_.sort_keys[i] = (static_cast<std::uint64_t>(column_u) << 32) | (static_cast<std::uint64_t>(column_v) & 0xffffffffu);
    state_.height[i] = -p.dot(down);
    state_.permutation[i] = static_cast<Index>(i);
  }, 2048);
  const auto& key = state_.sort_keys;
  const auto& height = state_.height;
  tbb::parallel_sort(state_.permutation.begin(), state_.permutation.end(), [&](Index a, Index b) {
    return key[a] != key[b] ? key[a] < key[b] : (height[a] != height[b] ? height[a] > height[b] : a < b);
  });
  const Real load_per_mass = g * inverse_width * inverse_width;
  const Real time = static_cast<Real>(state_.time);
  const std::size_t active = state_.active_count;
  // Roussel 2018: a layer under a height H of material yields once ρ g H > √3 τ0 (unconfined).
  const Real unconfined = std::sqrt(Real(3));
  bool woken = false;
  std::size_t run_begin = 0;
  while (run_begin < count) {
    std::size_t run_end = run_begin + 1;
    while (run_end < count && key[state_.permutation[run_end]] == key[state_.permutation[run_begin]]) ++run_end;
    Real mass_above = 0;
    std::size_t deepest_loaded = run_begin;  // one past the deepest particle to wake in this column
    for (std::size_t n = run_begin; n < run_end; ++n) {
      const Index i = state_.permutation[n];
      const Real load = load_per_mass * mass_above;
      mass_above += fluid.mass[i];
      if (i < active) continue;
      if (fluid.rest_load[i] < 0) {
        fluid.rest_load[i] = load;  // came to rest since the last check
        continue;
      }
      const FluidPhase& phase = parameters_.phases[fluid.phase[i]];
      const Real yield_stress = phase.ageing.yield_stress(phase.rheology.yield_stress, time - fluid.birth_time[i]);
      if (load - fluid.rest_load[i] > Real(0.1) * yield_stress && load > unconfined * yield_stress) deepest_loaded = n + 1;
    }
    // The material above a loaded particle is what loads it: it must move too, or it hangs as a fixed block.
    for (std::size_t n = run_begin; n < deepest_loaded; ++n) {
      const Index i = state_.permutation[n];
      if (i < active) continue;
      // A collapse starts slowly: the clock starts well below zero so that the particle is simulated
      // long enough for the flow to develop before slowness can put it to rest again.
      fluid.rest_time[i] = -settings.load_wake_duration;
      woken = true;
    }
    run_begin = run_end;
  }
  if (woken) state_.resting_woken = 1;
}

void Solver::reserve(std::size_t capacity) {
  state_.fluid.reserve(capacity);
  state_.kappa.reserve(capacity);
  state_.solver_position.reserve(capacity);
  state_.solver_velocity.reserve(capacity);
  state_.solver_wall_sums.reserve(capacity);
  state_.resting_grid_subset.reserve(capacity);
  state_.resting_grid_ids.reserve(capacity);
  state_.resting_grid_positions.reserve(capacity);
  state_.sort_keys.reserve(capacity);
  state_.permutation.reserve(capacity);
  state_.scratch_vec3.reserve(capacity);
  state_.scratch_real.reserve(capacity);
  state_.scratch_u16.reserve(capacity);
  state_.scratch_u64.reserve(capacity);
  state_.fluid_neighbors.counts.reserve(capacity);
  state_.fluid_neighbors.firsts.reserve(capacity);
  state_.fluid_neighbors.indices.reserve(capacity * state_.fluid_neighbors.stride);
  state_.fluid_neighbors.staging.reserve(capacity * state_.fluid_neighbors.stride);
  state_.boundary_neighbors.counts.reserve(capacity);
  state_.boundary_neighbors.firsts.reserve(capacity);
  state_.boundary_neighbors.indices.reserve(capacity * state_.boundary_neighbors.stride);
  state_.boundary_neighbors.staging.reserve(capacity * state_.boundary_neighbors.stride);
  auto& system = state_.viscosity_system;
  system.fluid_pair_coefficient.reserve(capacity * state_.fluid_neighbors.stride);
  system.boundary_pair_coefficient.reserve(capacity * state_.boundary_neighbors.stride);
  system.inverse_diagonal.reserve(capacity);
  system.own_block.reserve(capacity);
  system.padded_operand.reserve(capacity);
  state_.surface_normal.reserve(capacity);
  state_.surface_flag.reserve(capacity);
  state_.surface_curvature.reserve(capacity);
  state_.elastic_stress.reserve(capacity);
  for (auto* vector : {&system.rhs, &system.residual, &system.preconditioned, &system.product, &system.start_velocity,
                       &system.aggregate_offset})
    vector->reserve(capacity);
}

void Solver::set_body_motion(Index body, const Pose& pose, const Vec3& linear_velocity, const Vec3& angular_velocity) {
  auto& target = state_.bodies.at(body);
  target.pose = pose;
  target.linear_velocity = linear_velocity;
  target.angular_velocity = angular_velocity;
  if (target.is_static) state_.static_boundary_dirty = true;  // it leaves the static grid
  target.is_static = false;
}

void Solver::set_nozzle(Index nozzle, const Pose& pose, const Vec3& nozzle_velocity, bool extruding, Real flow_scale) {
  if (!(flow_scale >= 0)) throw Error(fmt::format("sph::Solver::set_nozzle: flow_scale must be >= 0, got {}", flow_scale));
  auto& target = state_.nozzles.at(nozzle);
  target.flow_scale = flow_scale;
  target.pose = pose;
  target.velocity = nozzle_velocity;
  target.extruding = extruding;
}

const StepStats& Solver::step() {
  StepStats stats;
  const auto& settings = parameters_.settings;
  auto start = Clock::now();

  choose_neighbor_search();
  update_bodies();
  stats.stage_ms.bodies = elapsed_ms(start);

  start = Clock::now();
  remove_out_of_bounds(stats);
  stats.stage_ms.remove = elapsed_ms(start);

  start = Clock::now();
  emit(stats);
  stats.stage_ms.emit = elapsed_ms(start);

  start = Clock::now();
  if (settings.rest_detection) update_rest_partition();
  if (settings.reorder_interval > 0 && state_.step % settings.reorder_interval == 0) reorder();
  stats.stage_ms.reorder = elapsed_ms(start);

  // Only the active particles are simulated; the resting ones keep κ = 0 (solver sweeps read it for
  // every neighbour).
  const std::size_t count = state_.active_count;
  state_.kappa.resize(state_.fluid.size());
  std::fill(state_.kappa.begin() + static_cast<std::ptrdiff_t>(count), state_.kappa.end(), Real(0));

  start = Clock::now();
  search_neighbors();
  stats.stage_ms.neighbors = elapsed_ms(start);

  if (granular_) {
    step_granular(stats);
    return state_.last_step;
  }

  start = Clock::now();
  stages::reset_body_wrenches(state_);
  stats.max_density_error = stages::compute_density_and_factor(parameters_, state_);
  stats.stage_ms.density = elapsed_ms(start);

  start = Clock::now();
  if (settings.divergence_solver) {
    stats.divergence_iterations = stages::solve_divergence(parameters_, state_, state_.time_step);
  }
  stats.stage_ms.divergence = elapsed_ms(start);

  start = Clock::now();
  // Each particle's viscosity from its rheology and age, then gravity (and explicit viscosity).
  const Real largest_kinematic_viscosity = stages::update_effective_viscosity(parameters_, state_, viscosity_calibration_);
  stages::compute_non_pressure_accelerations(parameters_, state_, viscosity_calibration_);
  stages::add_surface_tension(parameters_, state_, surface_tension_calibration_);
  stages::add_air_drag(parameters_, state_, full_neighbourhood_);
  stages::add_elastic_forces(parameters_, state_);
  // CFL (Courant) condition on the velocity after the non-pressure forces.
  const Real previous_step = state_.time_step;
  const Real max_speed_squared = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, count, 1024), Real(0),
      [&](const tbb::blocked_range<std::size_t>& range, Real value) {
        for (std::size_t i = range.begin(); i != range.end(); ++i)
          value = std::max(value, (state_.fluid.velocity[i] + previous_step * state_.fluid.acceleration[i]).squaredNorm());
        return value;
      },
      [](Real a, Real b) { return std::max(a, b); });
  const Real diameter = particle_diameter();
  Real time_step = settings.max_time_step;
  if (max_speed_squared > Real(1e-18))
    time_step = std::min(time_step, settings.cfl_factor * Real(0.4) * diameter / std::sqrt(max_speed_squared));
  // Explicit viscosity: Morris et al. 1997's limit Δt ≤ 0.125 h²/ν, with the smoothing length h =
  // half the support radius = one particle diameter for our kernels. The implicit solver has none.
  const bool explicit_viscosity = settings.viscosity_solver == ViscositySolver::explicit_morris1997;
  // The calibration strengthens the sums (most at walls), so the limit tightens by the same factor.
  if (explicit_viscosity && largest_kinematic_viscosity > 0)
    time_step = std::min(time_step, Real(0.125) * diameter * diameter /
                                        (largest_kinematic_viscosity *
                                         std::max(viscosity_calibration_.fluid, viscosity_calibration_.boundary)));
  // Capillary waves (Brackbill et al. 1992): Δt ≤ √(ρ d³ / (2π σ)).
  if (largest_surface_tension_ > 0)
    time_step = std::min(time_step, std::sqrt(lightest_rest_density_ * diameter * diameter * diameter /
                                              (2 * kPi * largest_surface_tension_)));
  // Body-force limit: from rest, gravity moves a particle at most 1 % of a spacing per step
  // (g Δt²/2 ≤ d/100). Larger steps leave a settling column more compression than the clamped,
  // push-only pressure solve removes cleanly, and deep columns start to ring (seen from ~5 %).
  const Real gravity_norm = settings.gravity.norm();
  if (gravity_norm > 0) time_step = std::min(time_step, std::sqrt(diameter / (50 * gravity_norm)));
  time_step = std::max(time_step, settings.min_time_step);
  state_.time_step = time_step;
  // Micro-rotation (its relaxation is integrated implicitly, so it sets no limit of its own).
  stages::apply_micropolar(parameters_, state_, time_step, microinertia_);
  parallel_for_each_index(count, [&](std::size_t i) { state_.fluid.velocity[i] += time_step * state_.fluid.acceleration[i]; }, 1024);
  stats.stage_ms.forces = elapsed_ms(start);

  start = Clock::now();
  stats.density_iterations = stages::solve_density(parameters_, state_, time_step, stats.density_error);
  stats.stage_ms.pressure = elapsed_ms(start);

  // Implicit viscosity after the pressure solve, right before the velocities move the particles.
  // Before it (the usual DFSPH order), every step's pressure correction would move a stiff material
  // as if it were water, by about g Δt² per step: an unyielded column on a floor then creeps at
  // g Δt (2 cm/s at 2 ms steps) and never stands. The next step's divergence solve corrects what the
  // viscous smoothing changes in the divergence.
  start = Clock::now();
  // Elastic materials: their shear stiffness enters the implicit velocity solve as a viscosity G·Δt
  // (elasticity_peer2018.cpp); the stress of the current shape was added with the other forces.
  if (any_elastic_)
    parallel_for_each_index(count, [&](std::size_t i) {
      const auto& elasticity = parameters_.phases[state_.fluid.phase[i]].elasticity;
      if (elasticity.enabled) state_.fluid.viscosity[i] += elasticity.shear_modulus * time_step;
    }, 1024);
  if (!explicit_viscosity) stats.viscosity_iterations = stages::solve_implicit_viscosity(parameters_, state_, time_step, viscosity_calibration_);
  stages::apply_xsph(parameters_, state_);
  stats.stage_ms.viscosity = elapsed_ms(start);

  start = Clock::now();
  push_out_of_nozzles();
  parallel_for_each_index(count, [&](std::size_t i) { state_.fluid.position[i] += time_step * state_.fluid.velocity[i]; }, 1024);
  if (any_elastic_) stages::relax_reference_shape(parameters_, state_, time_step);
  if (settings.rest_detection) {
    update_rest_clocks(time_step);
    if (settings.wake_on_load && state_.time >= state_.next_load_check_time) {
      wake_loaded_rest();
      state_.next_load_check_time = state_.time + 0.5 * settings.rest_duration;
    }
  }
  stats.particles_at_rest = state_.fluid.size() - state_.active_count;
  finish_step(stats, time_step, start);
  return state_.last_step;
}

void Solver::finish_step(StepStats& stats, Real time_step, std::chrono::steady_clock::time_point advect_start) {
  keep_out_of_boundaries();
  stages::collect_body_wrenches(state_);
  // Impulses were summed as forces of velocity updates applied over one step each; see the update.
  state_.time += time_step;
  ++state_.step;
  check_state();
  stats.stage_ms.advect = elapsed_ms(advect_start);
  stats.time_step = time_step;
  state_.last_step = stats;
}

Real Solver::step_granular(StepStats& stats) {
  const auto& settings = parameters_.settings;
  const std::size_t count = state_.active_count;
  auto start = Clock::now();
  stages::reset_body_wrenches(state_);
  stages::compute_granular_contacts(parameters_, state_, granular_contacts_);
  stats.stage_ms.forces = elapsed_ms(start);
  start = Clock::now();
  // Contacts set the step; the CFL limit keeps a fast particle from passing through another.
  const Real max_speed_squared = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, count, 1024), Real(0),
      [&](const tbb::blocked_range<std::size_t>& range, Real value) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) value = std::max(value, state_.fluid.velocity[i].squaredNorm());
        return value;
      },
      [](Real a, Real b) { return std::max(a, b); });
  Real time_step = std::min(settings.max_time_step, granular_time_step_);
  if (max_speed_squared > Real(1e-18))
    time_step = std::min(time_step, settings.cfl_factor * Real(0.4) * particle_diameter() / std::sqrt(max_speed_squared));
  time_step = std::max(time_step, settings.min_time_step);
  state_.time_step = time_step;
  auto& fluid = state_.fluid;
  parallel_for_each_index(count, [&](std::size_t i) {
    fluid.velocity[i] += time_step * fluid.acceleration[i];
    fluid.position[i] += time_step * fluid.velocity[i];
  }, 1024);
  finish_step(stats, time_step, start);
  return time_step;
}

void Solver::update_bodies() {
  auto& boundary = state_.boundary;
  const Real support = support_radius();
  const Real cell_size = state_.search_cell_size;
  if (state_.static_boundary_dirty) {
    ++state_.fixed_grids_version;
    state_.static_boundary_indices.clear();
    for (const auto& body : state_.bodies)
      if (body.is_static)
        for (Index k = 0; k < body.particle_count; ++k) state_.static_boundary_indices.push_back(body.first_particle + k);
    state_.static_boundary_grid.build(boundary.position, state_.static_boundary_indices, cell_size);
    state_.static_boundary_dirty = false;
  }
  state_.moving_boundary_indices.clear();
  const bool any_moving = std::any_of(state_.bodies.begin(), state_.bodies.end(), [](const BoundaryBody& body) { return !body.is_static; });
  if (!any_moving) {
    state_.moving_boundary_grid.build(boundary.position, state_.moving_boundary_indices, cell_size);
    return;
  }
  // Where fluid can be this step: around the particles and every nozzle that is extruding. A
  // moving body outside it cannot have fluid neighbours, so its particles are neither moved nor sorted.
  Aabb region = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, state_.fluid.size(), 4096), Aabb{},
      [&](const tbb::blocked_range<std::size_t>& range, Aabb box) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) box.extend(state_.fluid.position[i]);
        return box;
      },
      [](Aabb a, const Aabb& b) {
        if (!b.empty()) {
          a.extend(b.min);
          a.extend(b.max);
        }
        return a;
      });
  for (std::size_t n = 0; n < state_.nozzles.size(); ++n)
    if (state_.nozzles[n].extruding) region.extend(state_.nozzles[n].pose.position);
  // A body within a support radius of that region may have fluid neighbours; a nozzle's disc reaches
  // its radius further, and a particle moves less than a diameter in a step.
  Real widest_nozzle = 0;
  for (const auto& nozzle : parameters_.nozzles) widest_nozzle = std::max(widest_nozzle, nozzle.inner_diameter);
  const Vec3 reach = Vec3::Constant(support + widest_nozzle / 2 + particle_diameter());

  for (auto& body : state_.bodies) {
    if (body.is_static) continue;
    Aabb box;
    for (int corner = 0; corner < 8; ++corner) {
      const Vec3 local((corner & 1) ? body.local_bounds.max.x() : body.local_bounds.min.x(),
                       (corner & 2) ? body.local_bounds.max.y() : body.local_bounds.min.y(),
                       (corner & 4) ? body.local_bounds.max.z() : body.local_bounds.min.z());
      box.extend(body.pose.apply(local));
    }
    body.near_fluid = !region.empty() && (box.min.array() <= (region.max + reach).array()).all() &&
                      (box.max.array() >= (region.min - reach).array()).all();
    if (!body.near_fluid) continue;
    parallel_for_each_index(body.particle_count, [&](std::size_t k) {
      const Index b = body.first_particle + static_cast<Index>(k);
      boundary.position[b] = body.pose.apply(boundary.local_position[b]);
      boundary.velocity[b] = body.linear_velocity + body.angular_velocity.cross(boundary.position[b] - body.pose.position);
    }, 1024);
    // Only its particles within reach join the grid: a robot's base beside a strand is mostly far from it.
    const Vec3 low = region.min - reach, high = region.max + reach;
    for (Index k = 0; k < body.particle_count; ++k) {
      const Vec3& position = boundary.position[body.first_particle + k];
      if ((position.array() >= low.array()).all() && (position.array() <= high.array()).all())
        state_.moving_boundary_indices.push_back(body.first_particle + k);
    }
  }
  state_.moving_boundary_grid.build(boundary.position, state_.moving_boundary_indices, cell_size);
}

void Solver::remove_out_of_bounds(StepStats& stats) {
  const Aabb& bounds = parameters_.settings.bounds;
  if (bounds.empty()) return;
  auto& fluid = state_.fluid;
  // Resting particles do not move, so only active ones can have left.
  const std::size_t outside = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, state_.active_count, 2048), std::size_t(0),
      [&](const tbb::blocked_range<std::size_t>& range, std::size_t found) {
        for (std::size_t i = range.begin(); i != range.end(); ++i) found += bounds.contains(fluid.position[i]) ? 0 : 1;
        return found;
      },
      std::plus<std::size_t>());
  if (outside == 0) return;
  // Swap-removal that keeps the active particles first: an active slot is refilled from the end of the
  // active range, whose slot is refilled from the end of the array.
  std::size_t count = fluid.size();
  for (std::size_t i = 0; i < state_.active_count;) {
    if (bounds.contains(fluid.position[i])) {
      ++i;
      continue;
    }
    state_.mass_removed_total += fluid.mass[i];
    const std::size_t last_active = --state_.active_count;
    if (i != last_active) fluid.move(last_active, i);
    if (last_active != count - 1) fluid.move(count - 1, last_active);
    --count;
  }
  fluid.resize(count);
  state_.particles_removed_total += outside;
  stats.particles_removed = outside;
}

void Solver::emit(StepStats& stats) {
  auto& fluid = state_.fluid;
  const Real diameter = particle_diameter();
  // A new particle keeps half a spacing from other particles and a full spacing from the boundary
  // layer (its centre at least a radius in front of the surface).
  const Real fluid_clearance_squared = Real(0.25) * diameter * diameter;
  const Real boundary_clearance_squared = Real(0.998) * diameter * diameter;
  const double step = state_.time_step;
  for (std::size_t n = 0; n < state_.nozzles.size(); ++n) {
    NozzleState& nozzle = state_.nozzles[n];
    const NozzleSettings& settings = parameters_.nozzles[n];
    const NozzleGeometry& geometry = nozzle_geometry_[n];
    if (!nozzle.extruding || geometry.layer_period <= 0) continue;
    // Layers come at the nominal period scaled by the flow; they also leave faster or slower.
    nozzle.pending_time += step * nozzle.flow_scale;
    const Real exit_speed = settings.exit_speed * nozzle.flow_scale;
    const Vec3 axis = nozzle.pose.rotate(Vec3(0, 0, -1));
    const Vec3 exit_velocity = exit_speed * axis + nozzle.velocity;
    while (nozzle.pending_time >= geometry.layer_period) {
      // The layer was due (pending − period) seconds ago: place it that far along the axis.
      // pending_time counts nominal seconds: at the nominal speed that is the distance travelled.
      const Real travelled = static_cast<Real>((nozzle.pending_time - geometry.layer_period) * settings.exit_speed);
      const Vec3 centre = nozzle.pose.position + travelled * axis;
      const Real reach = settings.inner_diameter / 2 + diameter;
      auto blocked_by = [&](const std::vector<Vec3>& points, Real clearance_squared) {
        return tbb::parallel_reduce(
            tbb::blocked_range<std::size_t>(0, points.size(), 4096), false,
            [&](const tbb::blocked_range<std::size_t>& range, bool blocked) {
              for (std::size_t i = range.begin(); i != range.end() && !blocked; ++i) {
                if ((points[i] - centre).squaredNorm() > reach * reach) continue;
                for (const Vec3& offset : geometry.disc_offsets)
                  if ((points[i] - (centre + nozzle.pose.rotate(offset))).squaredNorm() < clearance_squared) {
                    blocked = true;
                    break;
                  }
              }
              return blocked;
            },
            std::logical_or<bool>());
      };
      auto blocked_by_boundary = [&] {
        bool blocked = false;
        for (const Vec3& offset : geometry.disc_offsets) {
          const Vec3 point = centre + nozzle.pose.rotate(offset);
          for (const SpatialHashGrid* grid : {&state_.static_boundary_grid, &state_.moving_boundary_grid})
            grid->for_each_candidate(point, [&](Index, const Vec3& b) {
              blocked |= (b - point).squaredNorm() < boundary_clearance_squared;
            });
          if (blocked) return true;
        }
        return false;
      };
      if (blocked_by(fluid.position, fluid_clearance_squared) || blocked_by_boundary()) {
        ++nozzle.blocked_layers;
        // Keep at most one layer pending so a blocked nozzle does not burst when it clears.
        nozzle.pending_time = std::min(nozzle.pending_time, geometry.layer_period);
        break;
      }
      const std::size_t first = fluid.size();
      fluid.resize(first + geometry.disc_offsets.size());
      const Real mass = particle_mass(settings.phase);
      for (std::size_t k = 0; k < geometry.disc_offsets.size(); ++k) {
        const std::size_t i = first + k;
        fluid.position[i] = centre + nozzle.pose.rotate(geometry.disc_offsets[k]);
        fluid.velocity[i] = exit_velocity;
        fluid.acceleration[i] = Vec3::Zero();
        fluid.mass[i] = mass;
        fluid.density[i] = parameters_.phases[settings.phase].density;
        fluid.dfsph_factor[i] = 0;
        fluid.density_advected[i] = 1;
        fluid.kappa_density[i] = 0;
        fluid.kappa_divergence[i] = 0;
        fluid.phase[i] = settings.phase;
        fluid.neighbor_count[i] = 0;
        fluid.id[i] = state_.next_particle_id++;
        fluid.birth_time[i] = static_cast<Real>(state_.time);
        fluid.viscosity[i] = parameters_.phases[settings.phase].rheology.viscosity;
        fluid.shear_rate[i] = 0;
        fluid.viscous_change[i] = Vec3::Zero();
        fluid.viscous_velocity[i] = fluid.velocity[i];
        fluid.rest_time[i] = 0;
        fluid.rest_load[i] = -1;
        fluid.angular_velocity[i] = Vec3::Zero();
        fluid.reference_position[i] = fluid.position[i];
        state_.mass_emitted_total += mass;
      }
      activate_appended(first);
      nozzle.pending_time -= geometry.layer_period;
      ++nozzle.layers_emitted;
      nozzle.particles_emitted += geometry.disc_offsets.size();
      stats.particles_emitted += geometry.disc_offsets.size();
    }
  }
}

void Solver::push_out_of_nozzles() {
  // The extruder pushes: material in a nozzle's exit cross-section, up to one spacing in front of
  // it, leaves at least at the exit speed (a velocity inlet). Where the bead below fills the gap
  // (slow printing, small gaps) this squeezes it sideways; without it the new layers would find no
  // room and the flow would be lost. Applied last, after the solvers, so that nothing softens it.
  auto& fluid = state_.fluid;
  const Real diameter = particle_diameter();
  for (std::size_t n = 0; n < state_.nozzles.size(); ++n) {
    const NozzleState& nozzle = state_.nozzles[n];
    const NozzleSettings& settings = parameters_.nozzles[n];
    if (!nozzle.extruding || nozzle.flow_scale <= 0) continue;
    const Vec3 axis = nozzle.pose.rotate(Vec3(0, 0, -1));
    const Real target_speed = settings.exit_speed * nozzle.flow_scale + nozzle.velocity.dot(axis);
    const Real radius_squared = settings.inner_diameter * settings.inner_diameter / 4;
    parallel_for_each_index(state_.active_count, [&](std::size_t i) {
      const Vec3 offset = fluid.position[i] - nozzle.pose.position;
      const Real axial = offset.dot(axis);
      if (axial < 0 || axial > diameter || (offset - axial * axis).squaredNorm() > radius_squared) return;
      const Real speed = fluid.velocity[i].dot(axis);
      if (speed < target_speed) fluid.velocity[i] += (target_speed - speed) * axis;
    }, 2048);
  }
}

void Solver::reorder() {
  // Only the active particles: resting ones do not move, so their order stays good.
  auto& fluid = state_.fluid;
  const std::size_t count = state_.active_count;
  if (count < 2) return;
  sort_by_cell(fluid.position, count, support_radius(), state_.sort_keys, state_.permutation);
  auto gather = [&](auto& field, auto& scratch) {
    scratch.resize(count);
    parallel_for_each_index(count, [&](std::size_t i) { scratch[i] = field[state_.permutation[i]]; }, 2048);
    std::copy(scratch.begin(), scratch.begin() + static_cast<std::ptrdiff_t>(count), field.begin());
  };
  fluid.for_each_field([&](auto& field) {
    using Element = typename std::decay_t<decltype(field)>::value_type;
    if constexpr (std::is_same_v<Element, Vec3>) gather(field, state_.scratch_vec3);
    else if constexpr (std::is_same_v<Element, Real>) gather(field, state_.scratch_real);
    else if constexpr (std::is_same_v<Element, std::uint16_t>) gather(field, state_.scratch_u16);
    else if constexpr (std::is_same_v<Element, std::uint64_t>) gather(field, state_.scratch_u64);
    else static_assert(sizeof(Element) == 0, "add a scratch buffer for this field type");
  });
}

void Solver::choose_neighbor_search() {
  const auto& settings = parameters_.settings;
  const Real support = support_radius();
  const Real skin = settings.neighbor_skin * support;
  const std::size_t active = state_.active_count;
  bool use_skin = state_.skin_in_use;
  if (!(skin > 0)) {
    use_skin = false;
  } else if (use_skin) {
    // Kept lists searched anew in half of the last eight steps cost more than a search every step.
    if (std::popcount(state_.recent_searches & 0xffu) >= 4) {
      use_skin = false;
      // Each switch rebuilds the fixed grids for the other cell size: where kept lists keep failing
      // soon (a print whose resting set changes every few steps), they are tried ever more rarely.
      const bool failed_soon = state_.step - state_.skin_since_step < 64;
      state_.skin_backoff = failed_soon ? std::min(2 * state_.skin_backoff, 4096) : 64;
      state_.skin_cooldown = state_.skin_backoff;
    }
  } else if (state_.skin_cooldown > 0) {
    --state_.skin_cooldown;
  } else {
    // Would kept lists last? A particle that moves more than skin/8 a step leaves its skin/2 within
    // four steps; a few of them (a falling strand) search for themselves, many force new searches.
    const Real step_limit = skin / 8 / state_.time_step;
    const Real speed_limit_squared = step_limit * step_limit;
    const std::size_t fast = tbb::parallel_reduce(
        tbb::blocked_range<std::size_t>(0, active, 4096), std::size_t(0),
        [&](const tbb::blocked_range<std::size_t>& range, std::size_t found) {
          for (std::size_t i = range.begin(); i != range.end(); ++i) found += state_.fluid.velocity[i].squaredNorm() > speed_limit_squared;
          return found;
        },
        std::plus<std::size_t>());
    state_.calm_steps = fast <= most_movers(active) ? state_.calm_steps + 1 : 0;
    if (state_.calm_steps >= 8) use_skin = true;
  }
  if (use_skin != state_.skin_in_use) {
    state_.skin_in_use = use_skin;
    state_.skin_since_step = state_.step;
    state_.calm_steps = 0;
    state_.recent_searches = 0;
    state_.skinned_search.invalidate();
  }
  // Lists of radius support + skin need cells as large in every grid.
  const Real cell_size = use_skin ? support + skin : support;
  if (cell_size != state_.search_cell_size) {
    state_.search_cell_size = cell_size;
    state_.static_boundary_dirty = true;
  }
}

void Solver::search_neighbors() {
  const Real support = support_radius();
  const Real cell_size = state_.search_cell_size;
  const auto& fluid = state_.fluid;
  const std::size_t active_count = state_.active_count;
  // The active particles in one grid, every step; the resting ones (neighbours too) in another, built
  // again only when they changed (in a 20-layer wall print, 24.6k resting particles against 185
  // active ones, their grid had been most of the neighbour stage). Only the active ones query.
  // Lists stay in grid order, which is as deterministic: sorting them by index cost 12 of 43 ms per
  // step in the 47k dam break and made the solver's sweeps no faster.
  const std::span<const Vec3> active(fluid.position.data(), active_count);
  const std::size_t resting_count = fluid.size() - active_count;
  // With none resting, the (empty) grid stays as it is when the active range grows (an emitted layer).
  const bool resting_changed =
      state_.resting_grid_ids.size() != resting_count || state_.resting_grid.cell_size() != cell_size ||
      (resting_count > 0 && state_.resting_grid_first != active_count) ||
      !std::equal(state_.resting_grid_ids.begin(), state_.resting_grid_ids.end(), fluid.id.begin() + std::ptrdiff_t(active_count)) ||
      !std::equal(state_.resting_grid_positions.begin(), state_.resting_grid_positions.end(),
                  fluid.position.begin() + std::ptrdiff_t(active_count));
  if (resting_changed) {
    ++state_.fixed_grids_version;
    state_.resting_grid_first = active_count;  // the grid holds indices, not ids
    state_.resting_grid_ids.assign(fluid.id.begin() + std::ptrdiff_t(active_count), fluid.id.end());
    state_.resting_grid_positions.assign(fluid.position.begin() + std::ptrdiff_t(active_count), fluid.position.end());
    state_.resting_grid_subset.resize(resting_count);
    std::iota(state_.resting_grid_subset.begin(), state_.resting_grid_subset.end(), static_cast<Index>(active_count));
    state_.resting_grid.build(fluid.position, state_.resting_grid_subset, cell_size);
  }
  if (state_.skin_in_use) {
    SkinnedNeighborSearch::Inputs inputs;
    inputs.fluid_positions = fluid.position;
    inputs.fluid_ids = fluid.id;
    inputs.active_count = active_count;
    inputs.resting_grid = &state_.resting_grid;
    inputs.static_boundary_grid = &state_.static_boundary_grid;
    inputs.moving_boundary_grid = &state_.moving_boundary_grid;
    inputs.boundary_positions = state_.boundary.position;
    inputs.moving_boundary_indices = state_.moving_boundary_indices;
    inputs.fixed_grids_version = state_.fixed_grids_version;
    const bool searched = state_.skinned_search.update(inputs, support, cell_size - support, most_movers(active_count),
                                                       state_.fluid_neighbors, state_.boundary_neighbors);
    state_.recent_searches = (state_.recent_searches << 1) | (searched ? 1u : 0u);
    state_.neighbor_searches += searched;
    return;
  }
  ++state_.neighbor_searches;
  state_.fluid_grid.build(active, cell_size);
  // Queries in the active grid's order: a cell's particles come together and share one candidate
  // gather (in index order they drift apart between reorderings).
  const std::span<const Index> query_order = state_.fluid_grid.points_in_grid_order();
  const SpatialHashGrid* fluid_grids[] = {&state_.fluid_grid, &state_.resting_grid};
  find_neighbors(fluid_grids, active, support, true, state_.fluid_neighbors, false, query_order);
  const SpatialHashGrid* boundary_grids[] = {&state_.static_boundary_grid, &state_.moving_boundary_grid};
  find_neighbors(boundary_grids, active, support, false, state_.boundary_neighbors, false, query_order);
}

void Solver::keep_out_of_boundaries() {
  // Pressure alone does not stop a lone, fast particle (a splash has too few fluid neighbours to
  // be over-dense at a wall), so a particle whose centre has crossed a geometric surface is moved
  // back onto it and loses its velocity into the wall. The crossing is read from the boundary share
  // Σ_b V_b W, which grows monotonically towards a wall: Newton steps along its gradient, which
  // work the same for any shape, edge or corner.
  auto& fluid = state_.fluid;
  const auto& boundary = state_.boundary;
  const Real surface_share = boundary_share_at_surface_;
  with_kernel(parameters_.settings.kernel, support_radius(), [&](const auto& kernel) {
    const Real inverse_time_step = Real(1) / state_.time_step;
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, state_.active_count, 256), [&](const tbb::blocked_range<std::size_t>& range) {
      std::vector<Wrench>& wrenches = stages::thread_body_wrenches(state_);
      for (std::size_t i = range.begin(); i != range.end(); ++i) {
      // A few Newton steps: one lands short where the share is curved (edges, corners).
      for (int iteration = 0; iteration < 3; ++iteration) {
        const Vec3 position = fluid.position[i];
        Real share = 0, nearest_weight = 0;
        Index nearest = 0;
        Vec3 gradient = Vec3::Zero(), wall_velocity = Vec3::Zero();
        for (const Index b : state_.boundary_neighbors.of(i)) {
          const Vec3 r = position - boundary.position[b];
          const auto [value, gradient_factor] = kernel.value_and_gradient_factor(r.norm());  // one square root
          const Real weight = boundary.volume[b] * value;
          // Selects, not a branch: which wall particle is nearest follows no order.
          nearest = weight > nearest_weight ? b : nearest;
          nearest_weight = std::max(weight, nearest_weight);
          share += weight;
          gradient += (boundary.volume[b] * gradient_factor) * r;
          wall_velocity += weight * boundary.velocity[b];
        }
        const Real gradient_squared = gradient.squaredNorm();
        if (share <= surface_share || gradient_squared <= 0) break;
        fluid.position[i] = position - ((share - surface_share) / gradient_squared) * gradient;
        const Vec3 away = -gradient / std::sqrt(gradient_squared);
        const Vec3 relative = fluid.velocity[i] - wall_velocity / share;  // share-weighted wall velocity
        const Real into_wall = relative.dot(away);
        if (into_wall < 0) {
          fluid.velocity[i] -= into_wall * away;
          // The wall took that momentum: count it in the body's force like the pressure forces.
          const Vec3 force = fluid.mass[i] * into_wall * away * inverse_time_step;
          Wrench& wrench = wrenches[boundary.body[nearest]];
          wrench.force += force;
          wrench.torque += (boundary.position[nearest] - state_.bodies[boundary.body[nearest]].pose.position).cross(force);
        }
      }
      }
    });
  });
}

void Solver::check_state() const {
  const auto& fluid = state_.fluid;
  const Real max_speed_squared = parameters_.settings.max_speed * parameters_.settings.max_speed;
  // Lowest index of a bad particle, or size() if none.
  // Active particles only: resting ones have not moved since they were checked.
  const std::size_t bad = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, state_.active_count, 2048), fluid.size(),
      [&](const tbb::blocked_range<std::size_t>& range, std::size_t found) {
        for (std::size_t i = range.begin(); i != range.end() && i < found; ++i) {
          const Real speed_squared = fluid.velocity[i].squaredNorm();
          if (!fluid.position[i].allFinite() || !std::isfinite(speed_squared) || speed_squared > max_speed_squared) return i;
        }
        return found;
      },
      [](std::size_t a, std::size_t b) { return std::min(a, b); });
  if (bad == fluid.size()) return;
  const Vec3& p = fluid.position[bad];
  const Vec3& v = fluid.velocity[bad];
  throw SimulationError(fmt::format(
      "simulation became unstable at t = {:.6f} s (step {}, dt = {:.3g} s): particle {} at ({:.4g}, {:.4g}, {:.4g}) m "
      "has velocity ({:.4g}, {:.4g}, {:.4g}) m/s (limit {} m/s). Try a smaller max_time_step or cfl_factor.",
      state_.time, state_.step, static_cast<double>(state_.time_step), fluid.id[bad], p.x(), p.y(), p.z(), v.x(), v.y(),
      v.z(), parameters_.settings.max_speed));
}

Real Solver::pressure(std::size_t i) const {
  const auto& fluid = state_.fluid;
  const Real rest_density = fluid.mass[i] / particle_rest_volume(parameters_.settings.particle_radius);  // its phase's
  // κ = ρ0 p / ρ² summed over both solvers' updates of the last step.
  return (fluid.kappa_density[i] + fluid.kappa_divergence[i]) * fluid.density[i] * fluid.density[i] / rest_density;
}

double Solver::total_fluid_mass() const {
  double total = 0;
  for (const Real mass : state_.fluid.mass) total += mass;
  return total;
}

}  // namespace m3dp::sph
