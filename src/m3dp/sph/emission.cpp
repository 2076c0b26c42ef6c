// Stage "emit" and the extruder's push in "advect": nozzles lay disc layers of particles where there
// is room in front of them, and the material in a nozzle's exit leaves at least at the exit speed.
// append_particle is the one place a particle's fields are initialised (emission and set-up).
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
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
    // A bore's whole length (a pump's check valve): the piston zone is not moved at all.
    const NozzleGeometry& geometry = model.nozzle_geometry[n];
    const Real upstream = geometry.has_bore() ? model.nozzles[n].bore_length + model.particle_diameter : model.particle_diameter;
    if (axial < -upstream || axial > 2 * model.particle_diameter || (offset - axial * axis).squaredNorm() > radius * radius)
      continue;
    if (geometry.has_bore() && axial < geometry.piston_depth - model.nozzles[n].bore_length) return Vec3::Zero();
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
    // Layers come in at the exit, or at the top of a bore.
    const Vec3 inlet = nozzle.pose.position - (geometry.has_bore() ? settings.bore_length : Real(0)) * axis;
    Vec3 centre = inlet;
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
    auto emit_disc = [&] {
      const std::size_t first = fluid.size();
      for (const Vec3& offset : geometry.disc_offsets)
        fluid.print_layer[append_particle(model, state, centre + nozzle.pose.rotate(offset), exit_velocity, settings.phase)] =
            nozzle.print_layer;
      state.mass_emitted_total += static_cast<double>(geometry.disc_offsets.size()) * model.particle_mass[settings.phase];
      activate_appended(state, first);
      nozzle.particles_emitted += geometry.disc_offsets.size();
      state.last_step.particles_emitted += geometry.disc_offsets.size();
    };
    if (geometry.has_bore() && !nozzle.primed) {
      // A primed pump: the bore is filled at the first extrusion, disc by disc down to the tip, where
      // nothing is in the way (a nozzle started in material keeps what is there), from a spacing below
      // the inlet. The first disc the pump brings comes to the inlet a layer period later, when the
      // column has moved a spacing down: two spacings above it, at the kernel's edge. A column that
      // pulls (tension) hangs from the pump and fell off it there, so with tension the bore is filled
      // from the inlet itself; a push-only one is pushed, and one disc more in a bore whose exit is
      // closed pressed material through the bed.
      nozzle.primed = true;
      const double disc_volume = static_cast<double>(geometry.disc_offsets.size()) * model.particle_volume;
      const Real first_depth = model.settings.tension ? Real(0) : diameter;
      for (Real depth = first_depth; depth <= settings.bore_length - diameter / 2; depth += diameter) {
        centre = inlet + depth * axis;
        if (blocked_by(fluid.position, fluid_clearance_squared)) continue;
        emit_disc();
        nozzle.volume_primed += disc_volume;
      }
    }
    while (nozzle.pending_time >= geometry.layer_period) {
      // The layer was due (pending − period) seconds ago: place it that far along the axis.
      // pending_time counts nominal seconds: at the nominal speed that is the distance travelled.
      const Real travelled = static_cast<Real>((nozzle.pending_time - geometry.layer_period) * settings.exit_speed);
      centre = inlet + travelled * axis;
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
      emit_disc();
      nozzle.pending_time -= geometry.layer_period;
      ++nozzle.layers_emitted;
    }
  }
}

namespace {

/// The pump stalls (the exit is blocked) when the material ahead of a bore's piston is compressed by
/// kPumpStallCompression of ρ0 while less than half the commanded flow leaves the bore, or by
/// kPumpStallCompressionAlways whatever leaves. The volume correction keeps moving material within
/// 1 %, but a stiff paste pushed through a pressed lip runs several % over it in the bore while it
/// flows (a 10⁴ Pa·s paste at g = D/2 stalled on compression alone at 3 % one step in four, 9 % of
/// its flow lost); a bore closed by the bed and pressed to 8-10 % pushed material through the bed's
/// one layer of particles. The outflow is the bore's particle count balance, smoothed over two layer periods.
constexpr Real kPumpStallCompression = Real(0.03);
constexpr Real kPumpStallCompressionAlways = Real(0.1);
/// The time over which the reported extrusion pressure is smoothed (s).
constexpr double kPressureSmoothing = 0.05;

/// The pump of each nozzle with a bore: material in the piston zone (the bore's top, where discs come
/// in) moves with the nozzle at the commanded flow along the axis, unless the material ahead of it is
/// compressed (a blocked exit). After the solves, the force the step's drives took (Σ m Δv / Δt along
/// the axis, from the drive before the viscosity solve on) is the nozzle's extrusion force, and over
/// the bore's section its extrusion pressure.
enum class PistonDrive {
  before_pressure,   // drive_pumps: the impulses of this step start here
  before_viscosity,  // hold_pumps: what the pressure solve did to the piston zones is added, and they
                     // are marked in Workspace::piston_driven for the solves that hold them
  after_solves,      // push_out_of_nozzles: added, and the force and the outflow measured
};
void drive_pistons(const Model& model, State& state, Workspace& workspace, PistonDrive call) {
  const bool measure = call == PistonDrive::after_solves, mark = call == PistonDrive::before_viscosity;
  if (call == PistonDrive::before_pressure || workspace.piston_impulse.size() != state.nozzles.size())
    workspace.piston_impulse.assign(state.nozzles.size(), 0.0);
  if (mark) workspace.piston_driven.assign(state.fluid.size(), 0);
  workspace.any_piston_driven = false;
  auto& fluid = state.fluid;
  const Real diameter = model.particle_diameter;
  for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
    NozzleState& nozzle = state.nozzles[n];
    const NozzleSettings& settings = model.nozzles[n];
    const NozzleGeometry& geometry = model.nozzle_geometry[n];
    if (!geometry.has_bore()) continue;
    const bool driving = nozzle.extruding && nozzle.flow_scale > 0;
    const BoreRegion bore(model, nozzle, n);
    const Vec3& axis = bore.axis;
    // The discs advance a spacing each layer period (their section is π D²/4 within rounding).
    const Real disc_speed = static_cast<Real>(diameter / geometry.layer_period);
    const Vec3 piston_velocity = nozzle.velocity + disc_speed * nozzle.flow_scale * axis;
    const Real time_step = state.time_step;
    // The material ahead of the piston (count and Σ ρ/ρ0) and in the whole bore (count).
    struct Sums {
      double density_ratio = 0;
      std::size_t ahead = 0, in_bore = 0;
    };
    const std::size_t count = state.active_count;
    auto in_bore = [&](std::size_t i, Real& depth) { return bore.contains(fluid.position[i], depth); };
    if (driving) {
      const Sums ahead = tbb::parallel_deterministic_reduce(
          tbb::blocked_range<std::size_t>(0, count, 2048), Sums{},
          [&](const tbb::blocked_range<std::size_t>& range, Sums sums) {
            for (std::size_t i = range.begin(); i != range.end(); ++i) {
              Real depth = 0;
              if (!in_bore(i, depth)) continue;
              ++sums.in_bore;
              if (depth < geometry.piston_depth || depth > geometry.piston_depth + 3 * diameter) continue;
              sums.density_ratio += fluid.density[i] / model.phases[fluid.phase[i]].density;
              ++sums.ahead;
            }
            return sums;
          },
          [](Sums a, const Sums& b) {
            a.density_ratio += b.density_ratio;
            a.ahead += b.ahead;
            a.in_bore += b.in_bore;
            return a;
          });
      const double compression = ahead.ahead > 0 ? ahead.density_ratio / static_cast<double>(ahead.ahead) - 1 : 0;
      if (measure && time_step > 0) {
        // Particles that left the bore this step: those that came in less the bore's gain.
        const double left = static_cast<double>(nozzle.particles_emitted - nozzle.bore_emitted) -
                            (static_cast<double>(ahead.in_bore) - static_cast<double>(nozzle.bore_particles));
        const double blend = std::min(1.0, time_step / (2 * geometry.layer_period));
        nozzle.bore_outflow += static_cast<Real>(blend * (left / time_step - nozzle.bore_outflow));
        nozzle.bore_particles = ahead.in_bore;
        nozzle.bore_emitted = nozzle.particles_emitted;
      }
      const double commanded = static_cast<double>(geometry.disc_offsets.size()) / geometry.layer_period * nozzle.flow_scale;  // particles/s
      nozzle.pump_stalled = compression > kPumpStallCompressionAlways ||
                            (compression > kPumpStallCompression && nozzle.bore_outflow < 0.5 * commanded);
    }
    if (!driving || nozzle.pump_stalled) {
      if (measure) {
        nozzle.extrusion_force = 0;
        nozzle.extrusion_pressure = 0;
      }
      continue;
    }
    // The particles of the piston zone, in a fixed order: their impulse summed per chunk.
    const double impulse = tbb::parallel_deterministic_reduce(
        tbb::blocked_range<std::size_t>(0, count, 2048), 0.0,
        [&](const tbb::blocked_range<std::size_t>& range, double sum) {
          for (std::size_t i = range.begin(); i != range.end(); ++i) {
            Real depth = 0;
            if (!in_bore(i, depth) || depth > geometry.piston_depth) continue;
            sum += static_cast<double>(fluid.mass[i] * (piston_velocity - fluid.velocity[i]).dot(axis));
            fluid.velocity[i] = piston_velocity;
            if (mark) workspace.piston_driven[i] = 1;
          }
          return sum;
        },
        std::plus<double>());
    if (mark) workspace.any_piston_driven = true;
    if (call != PistonDrive::before_pressure) workspace.piston_impulse[n] += impulse;
    if (measure && time_step > 0) {
      // The pump's push: what moving the piston zone took, and the material's push on the lid (last step's).
      const Vec3& lid_force = state.bodies[static_cast<std::size_t>(geometry.piston_body)].fluid_force;
      nozzle.extrusion_force = static_cast<Real>(workspace.piston_impulse[n] / time_step) - lid_force.dot(axis);
      const double area = kPi * settings.inner_diameter * settings.inner_diameter / 4;
      const double blend = std::min(1.0, time_step / kPressureSmoothing);
      nozzle.extrusion_pressure += static_cast<Real>(blend * (nozzle.extrusion_force / area - nozzle.extrusion_pressure));
      nozzle.extrusion_pressure_max = std::max(nozzle.extrusion_pressure_max, nozzle.extrusion_pressure);
    }
  }
}

}  // namespace

void drive_pumps(const Model& model, State& state, Workspace& workspace) {
  drive_pistons(model, state, workspace, PistonDrive::before_pressure);
}

void hold_pumps(const Model& model, State& state, Workspace& workspace) {
  if (!model.settings.tension) return;  // drive_pumps left nothing marked
  drive_pistons(model, state, workspace, PistonDrive::before_viscosity);
}

void hold_drawn_exits(const Model& model, State& state, Workspace& workspace) {
  // Material an exit-plane inlet's exit holds, up to one spacing in front of it, that the stream
  // below draws out faster than the exit speed is held at the exit speed along the axis through the
  // viscosity solve (free across it) and the projection: the stream hangs from the nozzle by its
  // viscosity, as from an extruder (SPlisHSPlasH's emitter animates what it emitted alike), instead
  // of falling away. Pushed material is left to the solves: a bead pressed under the nozzle spreads.
  // With the tension projection only, as the pumps' hold: without a pull a drawn strand held at its
  // exit dilates (docs/decisions.md).
  if (!model.settings.tension) return;
  auto& fluid = state.fluid;
  const Real diameter = model.particle_diameter;
  for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
    const NozzleState& nozzle = state.nozzles[n];
    const NozzleSettings& settings = model.nozzles[n];
    if (n > 253) break;  // a mark is one byte (more nozzles than that let their streams fall)
    if (!nozzle.extruding || nozzle.flow_scale <= 0 || model.nozzle_geometry[n].has_bore()) continue;
    const Vec3 axis = nozzle.pose.rotate(Vec3(0, 0, -1));
    const Real target_speed = settings.exit_speed * nozzle.flow_scale + nozzle.velocity.dot(axis);
    const Real radius_squared = settings.inner_diameter * settings.inner_diameter / 4;
    if (!workspace.any_piston_driven) workspace.piston_driven.assign(fluid.size(), 0);
    workspace.any_piston_driven = true;
    if (workspace.held_axes.size() != state.nozzles.size()) workspace.held_axes.resize(state.nozzles.size());
    workspace.held_axes[n] = axis;
    const auto mark = static_cast<std::uint8_t>(2 + n);
    parallel_for_each_index(state.active_count, [&](std::size_t i) {
      const Vec3 offset = fluid.position[i] - nozzle.pose.position;
      const Real axial = offset.dot(axis);
      if (axial < 0 || axial > diameter || (offset - axial * axis).squaredNorm() > radius_squared) return;
      const Real speed = fluid.velocity[i].dot(axis);
      if (speed <= target_speed) return;
      fluid.velocity[i] += (target_speed - speed) * axis;
      workspace.piston_driven[i] = mark;
    }, 2048);
  }
}

void push_out_of_nozzles(const Model& model, State& state, Workspace& workspace) {
  drive_pistons(model, state, workspace, PistonDrive::after_solves);
  // The extruder pushes: material in a nozzle's exit cross-section, up to one spacing in front of
  // it, leaves at least at the exit speed (a velocity inlet). Where the bead below fills the gap
  // (slow printing, small gaps) this squeezes it sideways; without it the new layers would find no
  // room and the flow would be lost. Applied last, after the solvers, so that nothing softens it.
  auto& fluid = state.fluid;
  const Real diameter = model.particle_diameter;
  for (std::size_t n = 0; n < state.nozzles.size(); ++n) {
    const NozzleState& nozzle = state.nozzles[n];
    const NozzleSettings& settings = model.nozzles[n];
    if (!nozzle.extruding || nozzle.flow_scale <= 0 || model.nozzle_geometry[n].has_bore()) continue;
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
