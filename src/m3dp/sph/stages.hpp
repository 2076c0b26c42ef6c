#pragma once
// Every stage of a step: a free function over (model, state, workspace), run in the order of
// Solver::step. Each lives in a file named after its stage or its method's paper.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <span>

#include "m3dp/sph/model.hpp"
#include "m3dp/sph/state.hpp"

namespace m3dp::sph::stages {

/// One stage: reads the model, advances the state, uses the workspace.
using StageFunction = void (*)(const Model& model, State& state, Workspace& workspace);

// ---- bodies (bodies.cpp, neighbors/search_stage.cpp) ----
/// Kept neighbour lists or a search every step (slow or fast material), and the grids' cell size.
void choose_neighbor_search(const Model& model, State& state, Workspace& workspace);
/// Moving bodies' boundary particles to their poses; the static and moving boundary grids.
void move_bodies(const Model& model, State& state, Workspace& workspace);
/// This step's material region (the fluid and the extruding nozzles), and the particles of the lazy
/// walls' tiles within reach of it (lazy_walls.cpp).
void make_walls_near_material(const Model& model, State& state, Workspace& workspace);
/// The particles of every lazy wall tile that `box` (world) touches, appended with their volumes.
void make_walls_within(const Model& model, State& state, Workspace& workspace, const Aabb& box);
/// How far from the material region wall particles must be in: their volumes need their neighbours.
Real lazy_wall_reach(const Model& model);
/// Akinci volumes (eq. 4) of the boundary particles from `first` on, all of body `body`; when static,
/// summed over every static particle, and those of the static particles near them summed again.
void sum_boundary_volumes(const Model& model, State& state, std::size_t first, Index body, bool is_static);

// ---- remove (removal.cpp) ----
/// Deletes the particles outside SolverSettings::bounds.
void remove_out_of_bounds(const Model& model, State& state, Workspace& workspace);

// ---- emit (emission.cpp) ----
/// Nozzle disc layers, where there is room in front of the nozzle.
void emit_layers(const Model& model, State& state, Workspace& workspace);
/// Nozzle `n`'s bore where the nozzle is now: from a spacing above its top (where discs come in)
/// down to its exit plane, within its radius. What the pump drives and the volume balance counts.
struct BoreRegion {
  Vec3 axis, top;  // the axis points out of the exit; m
  Real length = 0, radius_squared = 0, margin = 0;
  BoreRegion(const Model& model, const NozzleState& nozzle, std::size_t n)
      : axis(nozzle.pose.rotate(Vec3(0, 0, -1))),
        top(nozzle.pose.position - model.nozzles[n].bore_length * axis),
        length(model.nozzles[n].bore_length),
        radius_squared(model.nozzles[n].inner_diameter * model.nozzles[n].inner_diameter / 4),
        margin(model.particle_diameter) {}
  /// Whether `position` is inside; `depth` (m below the top) is set either way.
  [[nodiscard]] bool contains(const Vec3& position, Real& depth) const {
    const Vec3 offset = position - top;
    depth = offset.dot(axis);
    return depth >= -margin && depth <= length && (offset - depth * axis).squaredNorm() <= radius_squared;
  }
};

// ---- reorder (rest_detection.cpp, reorder.cpp) ----
/// Particles that rested long enough leave the active range; woken ones re-enter it.
void update_rest_partition(const Model& model, State& state, Workspace& workspace);
/// Every SolverSettings::reorder_interval steps, the active particles in Z-order (Morton) of their cells.
void reorder_particles(const Model& model, State& state, Workspace& workspace);

// ---- neighbors (neighbors/search_stage.cpp) ----
/// Fluid and boundary neighbour lists of the active particles (kept or searched).
void search_neighbors(const Model& model, State& state, Workspace& workspace);

// ---- density, divergence, pressure (pressure/dfsph_bender2017.cpp) ----
/// ρ_i and the DFSPH factor α_i (Bender & Koschier 2017, eq. 11); the wall sums and pair gradients.
void compute_density_and_factor(const Model& model, State& state, Workspace& workspace);
/// Divergence-free solver (Bender & Koschier 2017, Algorithm 2), over the last step's time step.
void solve_divergence(const Model& model, State& state, Workspace& workspace);
/// Constant-density solver (Bender & Koschier 2017, Algorithm 3), over this step's time step.
void solve_density(const Model& model, State& state, Workspace& workspace);

// ---- tension (pressure/projection_cummins_rudman1999.cpp) ----
/// The kept tension pressure (FluidParticles::kappa_tension) applied to the velocities, before the solves.
void apply_tension_pressure(const Model& model, State& state, Workspace& workspace);
/// After the implicit viscosity: the velocities' divergence taken out with both signs (the air beyond
/// a free surface at p = 0), its pressure added to the kept one.
void project_tension(const Model& model, State& state, Workspace& workspace);

// ---- forces ----
/// Each particle's shear rate (1/s) and effective viscosity (Pa·s) from its rheology and age
/// (viscosity/effective_viscosity.cpp).
void update_effective_viscosity(const Model& model, State& state, Workspace& workspace);
/// Gravity, plus the Morris et al. 1997 viscosity when it is the chosen solver (viscosity/morris1997.cpp).
void add_gravity_and_explicit_viscosity(const Model& model, State& state, Workspace& workspace);
/// Surface tension (the settings' model) and Akinci's wall adhesion (surface_tension/akinci2013.cpp).
void add_surface_tension(const Model& model, State& state, Workspace& workspace);
/// The continuum surface force of surface_tension/brackbill1992.cpp (add_surface_tension's other model).
void add_csf_surface_tension(const Model& model, State& state, Workspace& workspace);
/// Air drag on the exposed particles (forces/drag_gissler2017.cpp).
void add_air_drag(const Model& model, State& state, Workspace& workspace);
/// Elastic stress of each particle's deformation (forces/elasticity_peer2018.cpp).
void add_elastic_forces(const Model& model, State& state, Workspace& workspace);
/// This step's time step: CFL, explicit viscosity, capillary waves and body force (time_step.cpp).
void choose_time_step(const Model& model, State& state, Workspace& workspace);
/// Micro-rotation and its vortex force (forces/micropolar_bender2017.cpp).
void apply_micropolar(const Model& model, State& state, Workspace& workspace);
/// v += Δt a: the non-pressure forces act (time_step.cpp).
void integrate_accelerations(const Model& model, State& state, Workspace& workspace);

// ---- viscosity ----
/// Elastic materials' shear stiffness as a viscosity G·Δt for the implicit solve (forces/elasticity_peer2018.cpp).
void add_elastic_stiffness(const Model& model, State& state, Workspace& workspace);
/// Implicit viscosity (Weiler et al. 2018), with the wall friction's reaction on the bodies (viscosity/weiler2018.cpp).
void solve_implicit_viscosity(const Model& model, State& state, Workspace& workspace);
/// The volume correction: the compression the viscous velocities would leave, solved again with the
/// density solve and taken out of the positions, not the velocities (pressure/dfsph_bender2017.cpp).
void correct_volume(const Model& model, State& state, Workspace& workspace);
/// Particle shifting (Lind et al. 2012, speed-scaled as Skillen et al. 2013) of the moving particles
/// of viscous materials, where SolverSettings::shifting_factor > 0 (shifting/lind2012.cpp).
void shift_particles(const Model& model, State& state, Workspace& workspace);
/// XSPH velocity smoothing (Monaghan 1989) where SolverSettings::xsph_factor > 0 (forces/xsph_monaghan1989.cpp).
void apply_xsph(const Model& model, State& state, Workspace& workspace);

// ---- advect (emission.cpp, advection.cpp, rest_detection.cpp, boundary_push_out.cpp) ----
/// The extruder pushes: material in a nozzle's exit leaves at the exit speed.
void push_out_of_nozzles(const Model& model, State& state, Workspace& workspace);
/// The pumps of nozzles with a bore drive their piston zones (before the density solve, so that it
/// sees the flow; push_out_of_nozzles drives them again after the solves and measures the force).
void drive_pumps(const Model& model, State& state, Workspace& workspace);
/// With the tension projection (material that pulls), the pumps drive their piston zones again before
/// the viscosity solve and mark them in Workspace::piston_driven: the viscosity solve and the
/// projection hold them at the piston's velocity, as material of fixed velocity, so that the material
/// below hangs from them. (Moved by the solves and set back after, they let a 300 Pa·s rope drawn at
/// twice its speed slide off in free-falling slugs.)
void hold_pumps(const Model& model, State& state, Workspace& workspace);
/// With the tension projection, material in an exit-plane inlet's exit that the stream below draws out
/// faster than the exit speed is held at the exit speed along the nozzle's axis through the viscosity
/// solve and the projection (Workspace::piston_driven): a viscous stream hangs from its nozzle instead
/// of falling away in slugs.
void hold_drawn_exits(const Model& model, State& state, Workspace& workspace);
/// x += Δt v.
void advect_positions(const Model& model, State& state, Workspace& workspace);
/// Elastic materials with a relaxation time: the reference shape creeps towards the current one.
void relax_reference_shape(const Model& model, State& state, Workspace& workspace);
/// Rest clocks of the active particles, and wake-up marks on resting ones near motion.
void update_rest_clocks(const Model& model, State& state, Workspace& workspace);
/// With wake_on_load: resting material whose load has grown towards its yield stress wakes.
void wake_loaded_rest(const Model& model, State& state, Workspace& workspace);
/// Resting material that moving material nearby has compressed (settings.rest_compression) wakes.
void wake_compressed_rest(const Model& model, State& state, Workspace& workspace);
/// Particles whose centre crossed a wall's geometric surface go back onto it.
void keep_out_of_boundaries(const Model& model, State& state, Workspace& workspace);
/// The clock, the step count and the step's statistics; then the state check (throws SimulationError).
void finish_step(const Model& model, State& state, Workspace& workspace);

// ---- granular mode (granular/cundall_strack1979.cpp, time_step.cpp, advection.cpp) ----
/// Gravity and the contact forces (Cundall & Strack 1979); the walls' share to the body wrenches.
void compute_granular_contacts(const Model& model, State& state, Workspace& workspace);
/// The contacts' time step, within the CFL limit.
void choose_granular_time_step(const Model& model, State& state, Workspace& workspace);
/// v += Δt a, x += Δt v.
void integrate_granular(const Model& model, State& state, Workspace& workspace);

// ---- body wrenches (bodies.cpp) ----
/// Starts the step's wrench accumulators (see for_each_wrench_chunk).
void reset_body_wrenches(const Model& model, State& state, Workspace& workspace);
/// Sums the chunks' wrenches, in order, into each body's fluid_force / fluid_torque.
void collect_body_wrenches(const Model& model, State& state, Workspace& workspace);

// ---- helpers the stages share ----
/// Particles per wrench chunk. Each chunk of consecutive particles sums its share of the body
/// wrenches apart, in index order, and collect_body_wrenches adds the chunks in order: the bodies
/// feel the same force, bit for bit, on any number of threads (per-thread sums depended on which
/// thread took which range, so a robot touching the print moved differently on 1 and 2 threads).
inline constexpr std::size_t kWrenchChunk = 512;
/// Makes room for `chunks` wrench accumulators (zeroed) beyond those this step already uses.
void prepare_wrench_chunks(const State& state, Workspace& workspace, std::size_t chunks);
/// Runs body(range, wrenches) over the particles [0, count) in parallel, in whole chunks of
/// kWrenchChunk, `wrenches` being that chunk's accumulator (one entry per body).
template <class Body>
void for_each_wrench_chunk(const State& state, Workspace& workspace, std::size_t count, Body&& body) {
  const std::size_t bodies = state.bodies.size();
  const std::size_t chunks = (count + kWrenchChunk - 1) / kWrenchChunk;
  prepare_wrench_chunks(state, workspace, chunks);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks, 1), [&](const tbb::blocked_range<std::size_t>& chunk_range) {
    for (std::size_t chunk = chunk_range.begin(); chunk != chunk_range.end(); ++chunk) {
      const tbb::blocked_range<std::size_t> range(chunk * kWrenchChunk, std::min(count, (chunk + 1) * kWrenchChunk));
      body(range, std::span<Wrench>(workspace.body_wrench_chunks.data() + chunk * bodies, bodies));
    }
  });
}
/// Whether particle i of a yield-stress material is unyielded at `time` (s): its shear stress μ γ̇
/// below its yield stress, aged since its birth. False for materials without a yield stress.
inline bool unyielded(const FluidPhase& phase, const FluidParticles& fluid, std::size_t i, Real time) {
  return material::has_yield_stress(phase.rheology.model) &&
         fluid.viscosity[i] * fluid.shear_rate[i] < phase.ageing.yield_stress(phase.rheology.yield_stress, time - fluid.birth_time[i]);
}
/// Appends one particle of `phase` at rest density with every field initialised (emission.cpp), after
/// the resting particles: call activate_appended once a batch is placed. Returns its index.
std::size_t append_particle(const Model& model, State& state, const Vec3& position, const Vec3& velocity, std::uint16_t phase);
/// `displacement` (m) of a particle at `position` without its part back into an extruding nozzle's
/// exit (a diameter up it to two below it, a diameter wider): position corrections leave the pump's
/// flow alone (emission.cpp).
Vec3 without_push_into_nozzles(const Model& model, const State& state, const Vec3& position, Vec3 displacement);
/// Moves the particles appended from `first` on into the active range (before the resting ones).
void activate_appended(State& state, std::size_t first);
/// A new particle's least distance to the boundary layer (m): its centre at least a radius in front
/// of a surface, the layer being a radius behind it (boundary_sampling.hpp).
inline Real boundary_clearance(const Model& model) { return Real(0.999) * model.particle_diameter; }
/// The largest |v + Δt a|² of the active particles (m²/s²; Δt = 0: |v|²).
Real max_speed_squared(const State& state, Real time_step);
/// The colour gradient ∇c_i = Σ_j V_j ∇W_ij + Σ_b V_b ∇W_ib of particle i (pointing into the material;
/// walls count as material), from this step's pair gradients, which hold the rest volume. With
/// `rest_volume` (m³) > 0 each neighbour counts with its current volume m_j/ρ_j instead.
Vec3 colour_gradient(const State& state, const Workspace& workspace, std::size_t i, Real rest_volume = 0);
/// Viscosity of a particle pair (Pa·s): the harmonic mean, as for fluxes across layers in series. Where a
/// yielded particle meets an unyielded one (10³× more viscous) the arithmetic mean would make the pair as
/// stiff as the plug and drag the sheared layer along (Bingham Poiseuille flow then runs 40 % slow).
inline Real pair_viscosity(Real mu_i, Real mu_j) {
  const Real sum = mu_i + mu_j;
  return sum > 0 ? 2 * mu_i * mu_j / sum : Real(0);
}

}  // namespace m3dp::sph::stages
