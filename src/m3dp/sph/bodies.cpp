// Stage "bodies": the boundary particles of moving bodies follow their poses, and the grids the
// neighbour search reads them from; the fluid's force and torque on each body, summed per chunk of particles in a fixed order.
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/kernels.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void move_bodies(const Model& model, State& state, Workspace& workspace) {
  auto& boundary = state.boundary;
  const Real support = model.support_radius;
  // A nozzle's bore moves with the nozzle.
  for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
    for (const std::int32_t index : {model.nozzle_geometry[n].bore_body, model.nozzle_geometry[n].piston_body}) {
      if (index < 0) continue;
      BoundaryBody& body = state.bodies[static_cast<std::size_t>(index)];
      body.pose = state.nozzles[n].pose;
      body.linear_velocity = state.nozzles[n].velocity;
      body.angular_velocity.setZero();
    }
  }
  const Real cell_size = workspace.search_cell_size;
  if (workspace.static_boundary_dirty) {
    ++workspace.fixed_grids_version;
    workspace.static_boundary_indices.clear();
    // Every static body's particles, a lazy wall's tiles too (appended after the other bodies').
    for (Index k = 0; k < boundary.size(); ++k)
      if (state.bodies[boundary.body[k]].is_static) workspace.static_boundary_indices.push_back(k);
    workspace.static_boundary_grid.build(boundary.position, workspace.static_boundary_indices, cell_size);
    workspace.static_boundary_dirty = false;
  }
  workspace.moving_boundary_indices.clear();
  const bool any_moving = std::any_of(state.bodies.begin(), state.bodies.end(), [](const BoundaryBody& body) { return !body.is_static; });
  if (!any_moving) {
    workspace.moving_boundary_grid.build(boundary.position, workspace.moving_boundary_indices, cell_size);
    return;
  }
  // Where fluid can be this step (make_walls_near_material): a moving body outside it cannot have
  // fluid neighbours, so its particles are neither moved nor sorted.
  const Aabb& region = workspace.material_region;
  // A body within a support radius of that region may have fluid neighbours; a nozzle's disc reaches
  // its radius further, and a particle moves less than a diameter in a step.
    const Vec3 reach = Vec3::Constant(support + model.widest_nozzle / 2 + model.particle_diameter);

  for (auto& body : state.bodies) {
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
        workspace.moving_boundary_indices.push_back(body.first_particle + k);
    }
  }
  workspace.moving_boundary_grid.build(boundary.position, workspace.moving_boundary_indices, cell_size);
}

void sum_boundary_volumes(const Model& model, State& state, std::size_t first, Index body_index, bool is_static) {
  auto& boundary = state.boundary;
  // Akinci 2012, eq. 4: V_b = 1 / Σ_k W_bk (times the model's boundary_volume_scale). Static bodies are summed together, so where walls meet or
  // overlap (a tank built from boxes) the shared region is not counted twice; a moving body on its own
  // (its volumes then do not change with its pose).
  // A static body changes only the sums of static particles within the support of its own: those are
  // summed again, over every static particle within the support of them (not all static particles at
  // each static body added, which made a world of many shapes quadratic in them).
  const Real support = model.support_radius;
  Aabb added;
  for (std::size_t k = first; k < boundary.size(); ++k) added.extend(boundary.position[k]);
  const auto within = [](const Aabb& box, const Vec3& point, Real margin) {
    return (point.array() >= box.min.array() - margin).all() && (point.array() <= box.max.array() + margin).all();
  };
  std::vector<Index> members;   // the particles whose volumes are summed again
  std::vector<Vec3> points;     // every particle of their sums: members first, then the others near them
  for (Index k = 0; k < boundary.size(); ++k) {
    const bool together = is_static ? state.bodies[boundary.body[k]].is_static : boundary.body[k] == body_index;
    if (together && (!is_static || k >= first || within(added, boundary.position[k], support))) members.push_back(k);
  }
  points.reserve(members.size());
  for (const Index k : members) points.push_back(boundary.position[k]);
  if (is_static)
    for (Index k = 0; k < first; ++k)
      if (state.bodies[boundary.body[k]].is_static && !within(added, boundary.position[k], support) &&
          within(added, boundary.position[k], 2 * support))
        points.push_back(boundary.position[k]);
  boundary.volume.resize(boundary.size());
  SpatialHashGrid grid;
  grid.build(points, support);
  // Each particle's own sum, in the grid's order: the same on any number of threads.
  with_kernel(model.settings.kernel, support, [&](const auto& kernel) {
    parallel_for_each_index(members.size(), [&](std::size_t m) {
      Real sum = 0;
      grid.for_each_candidate(points[m], [&](Index, const Vec3& other) { sum += kernel.W((points[m] - other).norm()); });
      boundary.volume[members[m]] = model.boundary_volume_scale / sum;
    }, 4096);
  });
}

void reset_body_wrenches(const Model& /*model*/, State& /*state*/, Workspace& workspace) { workspace.body_wrench_chunks_used = 0; }

void prepare_wrench_chunks(const State& state, Workspace& workspace, std::size_t chunks) {
  const std::size_t bodies = state.bodies.size();
  if (chunks <= workspace.body_wrench_chunks_used) return;
  if (workspace.body_wrench_chunks.size() < chunks * bodies) workspace.body_wrench_chunks.resize(chunks * bodies);
  std::fill(workspace.body_wrench_chunks.begin() + std::ptrdiff_t(workspace.body_wrench_chunks_used * bodies),
            workspace.body_wrench_chunks.begin() + std::ptrdiff_t(chunks * bodies), Wrench{});
  workspace.body_wrench_chunks_used = chunks;
}

void collect_body_wrenches(const Model& /*model*/, State& state, Workspace& workspace) {
  const std::size_t bodies = state.bodies.size();
  for (std::size_t b = 0; b < bodies; ++b) {
    state.bodies[b].fluid_force.setZero();
    state.bodies[b].fluid_torque.setZero();
    for (std::size_t chunk = 0; chunk < workspace.body_wrench_chunks_used; ++chunk) {
      state.bodies[b].fluid_force += workspace.body_wrench_chunks[chunk * bodies + b].force;
      state.bodies[b].fluid_torque += workspace.body_wrench_chunks[chunk * bodies + b].torque;
    }
  }
}

}  // namespace m3dp::sph::stages
