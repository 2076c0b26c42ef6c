// Stage "emit" and the extruder's push in "advect": nozzles lay disc layers of particles where there
// is room in front of them, and the material in a nozzle's exit leaves at least at the exit speed.
// append_particle is the one place a particle's fields are initialised (emission and set-up).
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <functional>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

std::size_t append_particle(const Model& model, State& state, const Vec3& position, const Vec3& velocity, std::uint16_t phase) {
  auto& fluid = state.fluid;
  const std::size_t i = fluid.size();
  fluid.resize(i + 1);  // numbers are zero, Eigen vectors uninitialised: each is set below
  fluid.position[i] = position;
  fluid.velocity[i] = velocity;
  fluid.acceleration[i] = Vec3::Zero();
  fluid.viscous_change[i] = Vec3::Zero();
  fluid.angular_velocity[i] = Vec3::Zero();
  fluid.mass[i] = model.particle_mass[phase];
  fluid.density[i] = model.phases[phase].density;
  fluid.density_advected[i] = 1;
  fluid.phase[i] = phase;
  fluid.id[i] = state.next_particle_id++;
  fluid.birth_time[i] = static_cast<Real>(state.time);
  fluid.print_layer[i] = -1;
  fluid.viscosity[i] = model.phases[phase].rheology.viscosity;
  fluid.viscous_velocity[i] = velocity;
  fluid.rest_load[i] = -1;
  fluid.reference_position[i] = position;
  return i;
}

void activate_appended(State& state, std::size_t first) {
  auto& fluid = state.fluid;
  // Each new particle takes the first resting one's slot; that one moves to the end.
  for (std::size_t i = first; i < fluid.size(); ++i) {
    if (i != state.active_count) fluid.swap(i, state.active_count);
    ++state.active_count;
  }
}

Vec3 without_push_into_nozzles(const Model& model, const State& state, const Vec3& position, Vec3 displacement) {
  for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
    const NozzleState& nozzle = state.nozzles[n];
    if (!nozzle.extruding) continue;
    const Vec3 axis = nozzle.pose.rotate(Vec3(0, 0, -1));
    const Vec3 offset = position - nozzle.pose.position;
    const Real axial = offset.dot(axis);
    const Real radius = model.nozzles[n].inner_diameter / 2 + model.particle_diameter;
    if (axial < -model.particle_diameter || axial > 2 * model.particle_diameter ||
        (offset - axial * axis).squaredNorm() > radius * radius)
      continue;
    const Real backwards = displacement.dot(axis);
    if (backwards < 0) displacement -= backwards * axis;
  }
  return displacement;
}

void emit_layers(const Model& model, State& state, Workspace& workspace) {
  auto& fluid = state.fluid;
  const Real diameter = model.particle_diameter;
  // A new particle keeps half a spacing from other particles and its boundary clearance from walls.
  const Real fluid_clearance_squared = Real(0.25) * diameter * diameter;
  const Real boundary_clearance_squared = boundary_clearance(model) * boundary_clearance(model);
  const double step = state.time_step;
  for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
    NozzleState& nozzle = state.nozzles[n];
    const NozzleSettings& settings = model.nozzles[n];
    const NozzleGeometry& geometry = model.nozzle_geometry[n];
    if (!nozzle.extruding || geometry.layer_period <= 0) {
      nozzle.end_blockage(state.time);
      continue;
    }
    // Layers come at the nominal period scaled by the flow; they also leave faster or slower.
    nozzle.pending_time += step * nozzle.flow_scale;
    nozzle.volume_commanded += step * nozzle.flow_scale * geometry.flux;
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
          for (const SpatialHashGrid* grid : {&workspace.static_boundary_grid, &workspace.moving_boundary_grid})
            grid->for_each_candidate(point, [&](Index, const Vec3& b) {
              blocked |= (b - point).squaredNorm() < boundary_clearance_squared;
            });
          if (blocked) return true;
        }
        return false;
      };
      if (blocked_by(fluid.position, fluid_clearance_squared) || blocked_by_boundary()) {
        ++nozzle.blocked_layers;
        nozzle.blocked_time += step;
        if (nozzle.blocked_since < 0) {
          nozzle.blocked_since = state.time;
          nozzle.blocked_at = nozzle.pose.position;
        }
        // At most one layer stays pending, so a blocked nozzle does not burst when it clears; the
        // rest of the flow asked for is lost.
        const double excess = nozzle.pending_time - geometry.layer_period;
        if (excess > 0) nozzle.volume_lost += excess * geometry.flux;
        nozzle.pending_time = std::min(nozzle.pending_time, geometry.layer_period);
        break;
      }
      nozzle.end_blockage(state.time);
      const std::size_t first = fluid.size();
      for (const Vec3& offset : geometry.disc_offsets)
        fluid.print_layer[append_particle(model, state, centre + nozzle.pose.rotate(offset), exit_velocity, settings.phase)] =
            nozzle.print_layer;
      state.mass_emitted_total += static_cast<double>(geometry.disc_offsets.size()) * model.particle_mass[settings.phase];
      activate_appended(state, first);
      nozzle.pending_time -= geometry.layer_period;
      ++nozzle.layers_emitted;
      nozzle.particles_emitted += geometry.disc_offsets.size();
      state.last_step.particles_emitted += geometry.disc_offsets.size();
    }
  }
}

void push_out_of_nozzles(const Model& model, State& state, Workspace& /*workspace*/) {
  // The extruder pushes: material in a nozzle's exit cross-section, up to one spacing in front of
  // it, leaves at least at the exit speed (a velocity inlet). Where the bead below fills the gap
  // (slow printing, small gaps) this squeezes it sideways; without it the new layers would find no
  // room and the flow would be lost. Applied last, after the solvers, so that nothing softens it.
  auto& fluid = state.fluid;
  const Real diameter = model.particle_diameter;
  for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
    const NozzleState& nozzle = state.nozzles[n];
    const NozzleSettings& settings = model.nozzles[n];
    if (!nozzle.extruding || nozzle.flow_scale <= 0) continue;
    const Vec3 axis = nozzle.pose.rotate(Vec3(0, 0, -1));
    const Real target_speed = settings.exit_speed * nozzle.flow_scale + nozzle.velocity.dot(axis);
    const Real radius_squared = settings.inner_diameter * settings.inner_diameter / 4;
    parallel_for_each_index(state.active_count, [&](std::size_t i) {
      const Vec3 offset = fluid.position[i] - nozzle.pose.position;
      const Real axial = offset.dot(axis);
      if (axial < 0 || axial > diameter || (offset - axial * axis).squaredNorm() > radius_squared) return;
      const Real speed = fluid.velocity[i].dot(axis);
      if (speed < target_speed) fluid.velocity[i] += (target_speed - speed) * axis;
    }, 2048);
  }
}

}  // namespace m3dp::sph::stages
