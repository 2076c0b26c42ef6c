#pragma once
// The engine's mutable data, in two parts (MuJoCo's mjData, Box2D's hot and cold data):
//  State      what a checkpoint needs to continue a run: particles, bodies, nozzles, clocks, warm
//             starts and the decisions that carry over from step to step.
//  Workspace  what every step rebuilds or only caches: grids, neighbour lists, per-pair arrays,
//             solver vectors and scratch. A state restored without its workspace steps on after
//             rebuilding the caches (see Workspace::invalidate).
#include <tbb/enumerable_thread_specific.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string_view>
#include <vector>

#include "m3dp/core/types.hpp"
#include "m3dp/sph/boundary_sampling.hpp"
#include "m3dp/sph/neighbors/neighbor_search.hpp"
#include "m3dp/sph/particles.hpp"

namespace m3dp {
class StateWriter;
class StateReader;
}  // namespace m3dp

namespace m3dp::sph {

struct NozzleState {
  Pose pose;                          // emission axis = pose · (0, 0, −1): pointing down by default
  Vec3 velocity = Vec3::Zero();       // m/s of the nozzle itself (added to the exit velocity)
  bool extruding = false;
  Real flow_scale = 1;                // flow / nominal flow π D²/4 · U (a G-code move's E rate); 1 = nominal
  std::int32_t print_layer = -1;      // the layer of its path it prints now (0 first), given to what it emits
  double pending_time = 0;            // s of nominal extrusion not yet emitted as a layer
  std::uint64_t layers_emitted = 0;
  std::uint64_t particles_emitted = 0;
  std::uint64_t blocked_layers = 0;   // steps in which a due layer was delayed: the space in front was occupied
  double volume_commanded = 0;        // m³: the flow asked for, π D²/4 · U · flow scale over the extruding time
  // Flow a blocked nozzle could not emit is lost (a nozzle keeps at most one layer pending): its
  // volume, and when and where the nozzle was blocked.
  double volume_lost = 0;             // m³
  double blocked_time = 0;            // s in all
  double blocked_since = -1;          // s: when the present blockage began; < 0 while it flows
  Vec3 blocked_at = Vec3::Zero();     // m: where its exit was then
  struct Blockage {
    double start = 0, duration = 0;   // s
    Vec3 position = Vec3::Zero();     // m, the nozzle's exit when it began
  } longest_blockage;
  // A nozzle with a bore: filled at its first extrusion (a primed pump), and the pump's push on the
  // material (the piston's force along the axis, and that over the bore's section, smoothed over 0.05 s).
  bool primed = false;
  double volume_primed = 0;           // m³ put in the bore to fill it (emitted, but not commanded)
  Real extrusion_force = 0;           // N, this step
  Real extrusion_pressure = 0;        // Pa
  Real extrusion_pressure_max = 0;    // Pa, the largest so far
  bool pump_stalled = false;          // the material ahead of the piston was compressed: it did not push
  // The bore's outflow (particles/s, smoothed), from its particle count and the particles emitted
  // when it was last taken (at the end of a step's solves).
  Real bore_outflow = 0;
  std::uint64_t bore_particles = 0, bore_emitted = 0;
  /// Ends the present blockage at `now` (s), keeping it if it is the longest; nothing if it flows.
  void end_blockage(double now);
};

/// The timed stages of a step, in the order they run (Solver::step). One table: the stage times,
/// the timing.csv columns and the benchmarks' rows all come from it.
enum class Stage : std::uint8_t { bodies, remove, emit, reorder, neighbors, density, divergence, forces, pressure, viscosity, advect };
inline constexpr std::array<std::string_view, 11> kStageNames{"bodies",  "remove",     "emit",   "reorder",  "neighbors", "density",
                                                              "divergence", "forces", "pressure", "viscosity", "advect"};
inline constexpr std::size_t kStageCount = kStageNames.size();

/// Wall-clock time per stage of a step (ms).
struct StageTimes {
  std::array<double, kStageCount> ms{};
  [[nodiscard]] double& operator[](Stage stage) { return ms[static_cast<std::size_t>(stage)]; }
  [[nodiscard]] double operator[](Stage stage) const { return ms[static_cast<std::size_t>(stage)]; }
  [[nodiscard]] double total() const;
  StageTimes& operator+=(const StageTimes& other);
};

/// Which limit of the time-step rule (time_step.cpp) set a step: the settings' largest or smallest
/// step, the CFL condition, the explicit viscosity's, the capillary waves' or gravity's limit.
enum class TimeStepBound : std::uint8_t { largest, courant, viscosity, capillary, gravity, smallest };
inline constexpr std::array<std::string_view, 6> kTimeStepBoundNames{"largest", "cfl", "viscosity", "capillary", "gravity", "smallest"};

struct StepStats {
  double time_step = 0;                 // s
  TimeStepBound time_step_bound = TimeStepBound::largest;
  int density_iterations = 0;
  int divergence_iterations = 0;
  int viscosity_iterations = 0;         // conjugate-gradient iterations of the implicit viscosity solve
  bool viscosity_solved = false;        // the implicit viscosity solve ran (a viscous material moved)
  Real density_error = 0;               // mean relative density error after the density solve
  Real max_density_error = 0;           // max over particles of (ρ/ρ0 − 1) at the start of the step
  Real volume_error = 0;                // mean predicted ρ/ρ0 − 1 after the viscosity solve, before the volume correction
  int volume_iterations = 0;            // iterations of the volume correction (correct_volume)
  int tension_iterations = 0;           // conjugate-gradient iterations of the tension projection
  Real tension_error = 0;               // its mean |∇·v| Δt after the solve
  std::size_t particles_emitted = 0;
  std::size_t particles_removed = 0;
  std::size_t particles_at_rest = 0;    // at the end of the step (not simulated)
  StageTimes stage_ms;
};

struct Wrench {
  Vec3 force = Vec3::Zero();
  Vec3 torque = Vec3::Zero();
};

inline constexpr int kLazyTilePoints = 32;

/// A static body's wide flat face whose boundary particles are made tile by tile where material comes
/// near (lazy_walls.cpp): a wall costs memory and time for the area the material reaches, not its whole.
struct LazyWallFace {
  Index body = 0;                       // the static body whose particles they become
  RectangleLattice lattice;             // its points, in the body's frame
  int tiles_a = 0, tiles_b = 0;         // tiles of kLazyTilePoints × kLazyTilePoints lattice points
  std::vector<std::uint8_t> made;       // (tiles_a × tiles_b) 1: the tile's particles are in

  /// The lattice indices of tile `tile` (= tile_a · tiles_b + tile_b), inclusive.
  struct Range {
    int first_a, last_a, first_b, last_b;
    [[nodiscard]] std::size_t points() const { return std::size_t(last_a - first_a + 1) * std::size_t(last_b - first_b + 1); }
  };
  [[nodiscard]] Range tile_range(std::size_t tile) const;
};

/// Everything a checkpoint needs.
struct State {
  FluidParticles fluid;
  // The first active_count particles are simulated; the rest have come to rest (rest_detection) and
  // only stand as fixed neighbours: zero velocity and κ, not in any solver sweep.
  std::size_t active_count = 0;
  int resting_woken = 0;             // 1 when update_rest_clocks woke a resting particle this step
  double next_load_check_time = 0;   // s, when the weight on resting material is checked next
  BoundaryParticles boundary;
  std::vector<BoundaryBody> bodies;
  std::vector<LazyWallFace> lazy_walls;
  std::vector<std::uint64_t> made_tiles;  // face << 32 | tile, in the order their particles were appended
  std::vector<NozzleState> nozzles;

  double time = 0;                   // s
  std::int64_t step = 0;
  Real time_step = 0;                // s, the last step's (the next step's divergence solve and emission use it)
  std::uint64_t next_particle_id = 0;
  std::uint64_t particles_removed_total = 0;
  double mass_removed_total = 0;     // kg
  double mass_emitted_total = 0;     // kg
  StepStats last_step;               // the step in progress, then the last one

  // Decisions carried from step to step: whether neighbour lists are kept across steps
  // (SolverSettings::neighbor_skin) and whether the viscosity solve uses its coarse level.
  bool skin_in_use = false;
  int calm_steps = 0;                 // consecutive steps the speeds predicted kept lists to last
  int skin_cooldown = 0;              // steps before kept lists may be tried again
  int skin_backoff = 64;              // the next cooldown: doubles each time kept lists fail soon
  std::int64_t skin_since_step = 0;   // the step the last switch happened
  std::uint32_t recent_searches = 0;  // bit k: the kept lists were searched anew k steps ago
  std::uint64_t neighbor_searches = 0;  // steps that searched the grids for every particle
  int previous_viscosity_iterations = 0;  // CG iterations of the last implicit viscosity solve
};

/// The state as a checkpoint's bytes, and back into a state made by the same scene (the same bodies
/// and nozzles; a damaged or foreign checkpoint is an InputError).
void save_state(const State& state, StateWriter& out);
void load_state(StateReader& in, State& state);

namespace stages {
class CoarseViscosityLevel;  // the implicit viscosity's coarse level (viscosity/coarse_level.hpp)

/// Owns the coarse level between solves (its buffers, and the factorisation's analysis, reused while
/// A_c keeps its pattern). A copy starts with an empty one: every solve builds the level again.
class CoarseViscosityLevelHolder {
 public:
  CoarseViscosityLevelHolder();
  CoarseViscosityLevelHolder(const CoarseViscosityLevelHolder& other);
  CoarseViscosityLevelHolder(CoarseViscosityLevelHolder&& other) noexcept;
  CoarseViscosityLevelHolder& operator=(const CoarseViscosityLevelHolder& other);
  CoarseViscosityLevelHolder& operator=(CoarseViscosityLevelHolder&& other) noexcept;
  ~CoarseViscosityLevelHolder();
  CoarseViscosityLevel& get();  // made on first use

 private:
  std::unique_ptr<CoarseViscosityLevel> level_;
};
}  // namespace stages

/// What the stages rebuild or cache; nothing here is needed to continue a run.
struct Workspace {
  SpatialHashGrid fluid_grid;    // the active particles, at each neighbour search without a skin
  // The resting particles (neighbours too, but fixed), in two grids: the settled ones, slots
  // [settled_begin, settled_end) when built, watched by the fluid (FluidParticles::watch_slots) and
  // built again only when one of them changed slot or the recent ones grew too many; and the recent
  // ones (come to rest or moved to the end by an emission since: slots [active_count, settled_begin)
  // and [settled_end, n)), built again whenever they changed (ids and positions as built).
  SpatialHashGrid resting_grid;
  SpatialHashGrid recent_resting_grid;
  bool resting_grid_dirty = true;                // built from another state, or never
  // (n) 1: a running pump sets this active particle's velocity (its piston zone, stages::hold_pumps);
  // the viscosity solve and the tension projection hold it fixed. 2 + k: nozzle k's exit holds its
  // speed along the nozzle's axis, held_axes[k] (stages::hold_drawn_exits); the viscosity solve
  // moves it across the axis only, the projection not at all. Whether any is, this step.
  std::vector<std::uint8_t> piston_driven;
  bool any_piston_driven = false;
  std::vector<Vec3> held_axes;  // per nozzle: its axis, for the marks 2 + k
  /// The part of a change `value` to particle i's velocity that its mark leaves free.
  Vec3 free_part(std::size_t i, const Vec3& value) const {
    const std::uint8_t mark = piston_driven[i];
    if (mark == 0) return value;
    if (mark == 1) return Vec3::Zero();
    const Vec3& axis = held_axes[mark - 2];
    return value - value.dot(axis) * axis;
  }
  std::vector<double> piston_impulse;  // per nozzle: Σ m Δv the pump gave its piston zone this step (N·s)
  std::size_t settled_begin = 0, settled_end = 0;
  std::vector<Index> settled_holes;  // settled slots changed since the build (sorted): out of resting_grid, in the recent one
  std::uint64_t settled_builds = 0;               // how many times the settled slots were chosen (cameras keep their BVH until then)
  std::vector<Index> resting_grid_subset;
  std::vector<Index> recent_resting_slots;        // the recent grid's particles as built: slots,
  std::vector<std::uint64_t> recent_resting_ids;  // ids
  std::vector<Vec3> recent_resting_positions;     // and positions
  // Boundary particles in two grids: static bodies' sorted once (a large floor costs nothing per
  // step), moving bodies' every step, and only those bodies near the fluid or a nozzle (a robot
  // arm's upper links usually are not).
  SpatialHashGrid static_boundary_grid;
  SpatialHashGrid moving_boundary_grid;
  bool static_boundary_dirty = true;
  Aabb material_region;  // this step's fluid and extruding nozzles (stage "bodies"); empty: none
  std::vector<std::vector<std::uint8_t>> lazy_wall_wanted;  // (faces × tiles) tiles this step's material reaches
  std::vector<Index> static_boundary_indices;
  std::vector<Index> moving_boundary_indices;  // this step's: particles of the moving bodies near the fluid
  // Every grid's cell: the support radius, or support + skin while lists are kept across steps.
  Real search_cell_size = 0;
  std::uint64_t fixed_grids_version = 0;  // counts rebuilds of the resting and static boundary grids
  SkinnedNeighborSearch skinned_search;   // lists kept across steps for slow material
  NeighborLists fluid_neighbors;     // fluid → fluid
  NeighborLists boundary_neighbors;  // fluid → boundary
  // Per neighbour pair (same slots as the lists), filled with the densities each step:
  // V_j · (dW/dr)/r, so that V_j ∇W_ij = factor · (x_i − x_j). Positions do not move between the
  // density pass and advection, so every solver sweep rebuilds V_j ∇W_ij from these without a
  // square root or a branch. V_j = m_j/ρ0 for fluid, the Akinci volume for boundary particles.
  std::vector<Real> fluid_pair_gradient;
  std::vector<Real> boundary_pair_gradient;

  std::vector<Real> kappa;           // (n) m κ of the current solver iteration
  // (n) ρ/ρ0 − 1 the density solves leave a particle embedded in resting material: the compression
  // rest detection lets material keep (SolverSettings::rest_compression), by how far its neighbourhood
  // rests beyond a half-space (0 on a layer laid on resting material, the whole deep inside it).
  std::vector<Real> rest_allowance;
  // The resting particles that moving ones touch, as the density solves see them: fixed (they do not
  // move), but pushing the moving ones back where these would compress them past the density they
  // rested with, so a bead laid on resting material cannot press it together (which woke it, and the
  // woken particles woke the next: issue 57). Built in the density pass; m κ in `kappa` only while a
  // density solve runs (pressure/dfsph_bender2017.cpp).
  struct RestingInterface {
    std::vector<Index> particles;       // resting slots, in the order the moving particles first reach them
    std::vector<std::size_t> first;     // (particles + 1) each one's moving neighbours in `neighbor`, `pair_slot`
    std::vector<Index> neighbor;        // moving neighbour i
    std::vector<std::size_t> pair_slot; // the pair's slot in i's list (fluid_pair_gradient)
    std::vector<Real> density;          // ρ/ρ0 now, over every neighbour and wall
    std::vector<Real> limit;            // ρ/ρ0 it may reach: as it rested, at least 1
    std::vector<Real> factor;           // 1 / Σ_i (m_j/m_i) |V ∇W_ji|² over its moving neighbours (their motion is all that moves it)
    std::vector<Real> predicted;        // ρ*/ρ0 of the current iteration
    std::vector<Real> kappa_total;      // Σ κ of this step's density solve (m²/s²): the pressure it held the moving ones back with
    std::vector<Index> slot_of;         // (n) its place in `particles`, kNone otherwise (reset after each build)
    // (n) per resting slot: Σ W over its resting neighbours (itself included), Σ |V ∇W|² over them and
    // Σ V_b W over the static walls, as taken while fixed_grids_version was `fixed_part_version`:
    // they change only with the resting set or the static walls, which bump that version.
    std::vector<Vec3> fixed_part;
    std::vector<std::uint64_t> fixed_part_version;
    static constexpr Index kNone = ~Index(0);
  } resting_interface;
  // Positions and velocities padded to Vec4 (w = 0) for the solvers' sweeps: one aligned load and one
  // SIMD operation per neighbour. The positions are packed once a step, in the density pass, and read
  // until advection by the pressure solves, the shear rates and the implicit viscosity; the velocities
  // are packed by each user and go back after each solve. (n) each.
  std::vector<Vec4> solver_position, solver_velocity;
  // What a padded copy holds of the resting particles (from active_count on): they neither move nor
  // change slot while the resting grids' version stands (update_resting_grids), and rest with zero
  // velocity, so their part is copied again only when it changed: a 20-layer wall rests 4·10⁵
  // particles against ~10³ moving ones (pack_padded, make_walls_near_material).
  struct RestingCopy {
    std::uint64_t version = ~std::uint64_t(0);
    std::size_t size = 0, active = 0;
    std::uint64_t settled_builds = ~std::uint64_t(0);  // the settled grid's build it was copied under (pack_padded)
    /// Records the resting set now (the resting grids' `version`, the particles, the active ones);
    /// true when it differs from the one recorded before.
    bool take(std::uint64_t now_version, std::size_t now_size, std::size_t now_active) {
      const bool changed = version != now_version || size != now_size || active != now_active;
      version = now_version, size = now_size, active = now_active;
      return changed;
    }
  };
  RestingCopy position_copy, velocity_copy;
  // The resting particles' box, and the resting set it was taken of (make_walls_near_material).
  Aabb resting_box;
  RestingCopy resting_box_of;
  Aabb settled_box;                                // the settled slots' box when their grid was built
  std::uint64_t settled_box_builds = ~std::uint64_t(0);  // which build
  // Each particle's sums over its wall neighbours, taken in the density pass: they do not change until
  // advection (the walls' positions and velocities are fixed for the step), so the solves' sweeps
  // need no wall loop. With g_b = V_b (dW/dr)/r and r_b = x_i − x_b,
  struct WallSums {
    Vec4 gradient;        // Σ_b g_b r_b (1/m), w = 0
    Vec3 torque;          // Σ_b (x_b − c) × g_b r_b about the body's origin c (1), if one body
    Real velocity_flux;   // Σ_b g_b v_b·r_b (1/s)
    Index body;           // the one body of all its wall neighbours, or kSeveralBodies
  };
  static constexpr Index kSeveralBodies = ~Index(0);
  std::vector<WallSums> solver_wall_sums;  // (n)
  std::vector<Wrench> body_wrench_chunks;  // (chunks × bodies) the particle chunks' shares of the body wrenches
  std::size_t body_wrench_chunks_used = 0;  // chunks zeroed and in use this step
  Real largest_kinematic_viscosity = 0;  // m²/s, this step's largest μ/ρ (the explicit viscosity's time-step limit)
  std::vector<std::uint64_t> sort_keys;
  std::vector<Index> permutation;
  std::vector<Vec3> scratch_vec3;
  std::vector<Real> scratch_real;
  std::vector<std::uint16_t> scratch_u16;
  std::vector<std::int32_t> scratch_i32;
  std::vector<std::uint64_t> scratch_u64;
  std::vector<Real> height;          // (n) m, against gravity (load check)
  SpatialHashGrid moved_grid;             // the active particles where the step left them (wake_compressed_rest)
  std::vector<std::uint8_t> woken_in_block;  // (resting / 4096) 1: a block of resting slots holds a woken particle (update_rest_partition)
  // The tension projection's conjugate gradients (pressure/projection_cummins_rudman1999.cpp), (n) each:
  // its right-hand side and residual (1/s²), the iterate and the direction (m κ, kg m²/s²), the
  // preconditioned residual, the product, the inverse diagonal, and the velocity change of the
  // direction (M⁻¹ Bᵀ p, padded; zero for the resting particles).
  struct TensionSystem {
    std::vector<Real> residual, solution, direction, preconditioned, product, inverse_diagonal;
    std::vector<Vec4> velocity_change;
    std::vector<std::uint8_t> at_surface;  // (n) 1: its neighbourhood is lopsided (a free surface or a wall)
  } tension_system;
  // Implicit viscosity (Weiler et al. 2018): the system's coefficients and the CG vectors.
  struct ViscositySystem {
    std::vector<Real> fluid_pair_coefficient;     // per fluid neighbour slot: −Δt × the pair's viscous factor (kg/m²)
    std::vector<Real> boundary_pair_coefficient;  // per boundary neighbour slot, the same
    std::vector<Mat3> inverse_diagonal;           // (n) block-Jacobi preconditioner
    std::vector<Mat3> own_block;                  // (n) m_i I + the walls' Σ_b c_ib r rᵀ: A's part that acts on x_i alone (kg)
    std::vector<Vec3> rhs, residual, preconditioned, product, start_velocity;  // (n) each
    // The vector that A multiplies (the start velocity, then each CG direction), padded to Vec4 for the
    // product's sweep as the pressure solves' copies (solver_position holds the positions). The CG
    // direction lives only here.
    std::vector<Vec4> padded_operand;
    RestingCopy operand_copy;  // the resting set its zeros were written for
    // The stress form's part (SolverSettings::stress_form_viscosity), (n) each: the operand's stress
    // μ(G + Gᵀ) times M_iᵀ (zero at resting particles), and its share of A times the operand; empty when unused.
    std::vector<Mat3> stress;
    std::vector<Vec3> stress_product;
    std::vector<Mat3> gradient_correction;  // (n) M_i = B_i⁻¹, B_i = Σ_j (x_j − x_i) ⊗ V∇W_ij: exact gradients of linear fields
    std::vector<Vec3> no_slip_wall_sum;     // (n) Σ_b V_b ∇W_ib over the walls the particle does not slip on
    // The preconditioner's coarse level: aggregates of particles (cells of a coarse grid) that move
    // as one (see viscosity/coarse_level.hpp).
    std::vector<std::uint64_t> aggregate_key;     // (n) coarse cell of each active particle
    std::vector<Index> aggregate_order;           // (n) active particles grouped by aggregate
    std::vector<Index> aggregate_start;           // (aggregates + 1) into aggregate_order
    std::vector<Index> aggregate_of;              // (n) aggregate of each active particle
    std::vector<Vec3> aggregate_offset;           // (n) x_i − its aggregate's centroid (m)
    std::vector<double> coarse_residual, coarse_correction;  // (6 × aggregates: translation, rotation)
    std::vector<Real> coarse_motion;              // coarse_correction in single precision, for the per-particle sweep
    stages::CoarseViscosityLevelHolder coarse_level;
  } viscosity_system;
  std::vector<Mat3> elastic_stress;  // (n) R σ L of elastic particles this step (Peer et al. 2018)
  std::vector<Vec3> surface_normal;  // (n) Akinci 2013 normals h Σ V_j ∇W_ij, or the colour gradient ∇c of the CSF
  std::vector<std::uint8_t> surface_flag;  // (n) CSF: 1 on the outermost layer of the material
  std::vector<Real> surface_curvature;     // (n) CSF: κ (1/m) of the surface at or above the particle
  struct SurfaceLayer {                    // CSF: the outermost layer and its neighbours within the fit radius
    std::vector<Index> indices;            // fluid indices of the layer's particles
    std::vector<Vec3> positions;           // their positions, in the same order
    std::vector<Real> area;                // m², the surface each carries
    std::vector<Vec3> outward;             // unit outward normal of the surface fitted around each
    std::vector<Vec3> wall_normal;         // (n) towards the wall next to a layer particle, zero if none
    std::vector<Vec3> wall_point;          // (n) a point of that wall's geometric surface
    SpatialHashGrid grid;
    NeighborLists neighbors;               // per layer particle, fluid indices of layer particles
  } surface_layer;

  /// Calls visit(begin, end) over the resting slots that can differ from a copy taken of slots
  /// [0, copied_size) under settled build `copied_builds`: while that build stands (and the copy
  /// holds its slots), the settled slots change only at its holes, so [active, settled_begin), the
  /// holes and [settled_end, n); otherwise [active, n). A 20-layer wall rests 4·10⁵ particles, and
  /// its resting set changes in half the steps.
  template <class Visit>
  void for_each_unsettled_range(std::size_t active, std::size_t n, std::uint64_t copied_builds, std::size_t copied_size,
                                Visit&& visit) const {
    const bool held = copied_builds == settled_builds && active <= settled_begin && settled_begin <= settled_end &&
                      settled_end <= std::min(n, copied_size);
    if (!held) {
      visit(active, n);
      return;
    }
    visit(active, settled_begin);
    for (const Index hole : settled_holes) visit(std::size_t(hole), std::size_t(hole) + 1);
    visit(settled_end, n);
  }
  /// Drops what was cached from another state: the fixed grids are rebuilt and lists searched anew.
  void invalidate();
  /// Pre-sizes the per-particle arrays for `capacity` fluid particles, so steps do not allocate.
  void reserve(std::size_t capacity);
};

/// `to` = `from` padded to Vec4: the first `active` always, the resting ones only when the resting set
/// may have changed since `copy` was taken (Workspace::RestingCopy), and then, while the settled grid's
/// build stands, only its slots that can have changed (Workspace::for_each_unsettled_range). True when
/// resting slots were copied too.
bool pack_padded(std::span<const Vec3> from, std::vector<Vec4>& to, std::size_t active, const Workspace& workspace,
                 Workspace::RestingCopy& copy);

}  // namespace m3dp::sph
