#pragma once
// The SPH particle engine: parameters (immutable after construction) apart from state, and
// one step as a list of named, timed stages:
//   bodies → remove → emit → reorder → neighbours → density/α → divergence solve
//   → non-pressure forces → CFL time step → density solve → advect → check.
#include <tbb/enumerable_thread_specific.h>

#include <array>
#include <chrono>
#include <limits>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "m3dp/core/types.hpp"
#include "m3dp/material/material.hpp"
#include "m3dp/sph/kernels.hpp"
#include "m3dp/sph/neighbor_search.hpp"
#include "m3dp/sph/particles.hpp"

namespace m3dp::sph {

/// A fluid as the solver sees it: a material (density, rheology, ageing, boundary viscosity).
/// Phases may differ in rest density: every particle has the rest volume d³ (its mass is its phase's
/// rest density × d³), and the solver works with volumes (see dfsph_bender2017.cpp).
using FluidPhase = material::Material;

/// Rest volume of every fluid particle (m³): the particle diameter cubed.
inline Real particle_rest_volume(Real particle_radius) { return 8 * particle_radius * particle_radius * particle_radius; }

/// How surface tension is modelled.
enum class SurfaceTensionModel {
  // Akinci et al. 2013 cohesion, curvature and wall adhesion: robust down to single particles and
  // with any wetting, but σ sets only its scale (a droplet oscillates 2.6–3× too fast).
  akinci2013,
  // Continuum surface force (Brackbill et al. 1992) with curvature fitted to the surface: the physical
  // σ (Rayleigh's droplet within 3 %), for surfaces resolved by ~10 particles per radius of curvature;
  // walls are wetted at 90° (no adhesion setting).
  csf_brackbill1992,
};

/// How viscous forces are integrated.
enum class ViscositySolver {
  implicit_weiler2018,  // Weiler et al. 2018: stable at any viscosity and time step (conjugate gradients)
  explicit_morris1997,  // Morris et al. 1997: cheaper for water, but Δt ≤ 0.125 d²ρ/μ
};

struct SolverSettings {
  Real particle_radius = Real(0.01);          // m; rest spacing is 2 × radius
  KernelType kernel = KernelType::cubic_spline;
  Real support_radius_factor = 4;             // support radius = factor × particle radius
  Real boundary_spacing_factor = Real(1.0);   // boundary particle spacing = factor × diameter (volumes and
                                              // the wall calibration follow it; 0.5 gives smoother walls)
  Vec3 gravity = Vec3(0, 0, Real(-9.81));     // m/s²
  Real cfl_factor = Real(0.5);                // dt = cfl · 0.4 · diameter / v_max
  Real min_time_step = Real(1e-5);            // s
  Real max_time_step = Real(5e-3);            // s
  Real density_tolerance = Real(0.0005);      // mean relative density error of the density solve
  Real divergence_tolerance = Real(0.001);    // mean relative density change per step of the divergence solve
  int min_density_iterations = 2;
  int max_density_iterations = 100;
  int max_divergence_iterations = 100;
  // The divergence solve stops at once when its warm start already meets the tolerance (the usual case
  // for a settled flow; 1 forced iteration cost 6 of 12 ms a step in the 47k dam break).
  int min_divergence_iterations = 0;
  bool divergence_solver = true;
  bool warm_start = true;                     // the solves start from the last step's solution (false: cold, v* and κ = 0)
  Aabb bounds;                                // particles leaving it are removed (m)
  Real max_speed = 100;                       // m/s; faster means the state exploded
  int reorder_interval = 32;                  // steps between Z-order reorderings
  // Neighbour lists kept across steps (SkinnedNeighborSearch) with this skin, a fraction of the support
  // radius, while the material is slow: each step the solver predicts from the speeds whether they
  // would last, and returns to a search every step where they did not (a splash). 0: never.
  Real neighbor_skin = Real(0.1);
  ViscositySolver viscosity_solver = ViscositySolver::implicit_weiler2018;
  Real viscosity_tolerance = Real(1e-2);      // implicit viscosity: relative residual ‖b − Av‖/‖b‖ of the solve
  int max_viscosity_iterations = 300;
  Real xsph_factor = 0;                       // XSPH velocity smoothing ε (Monaghan 1989), 0 = none
  SurfaceTensionModel surface_tension_model = SurfaceTensionModel::akinci2013;
  // Material at rest costs nothing: a particle of a yield-stress material that has moved slower than
  // rest_speed, below its yield stress, for rest_duration leaves the solve and stays where it is as a
  // fixed neighbour of the material still moving. It wakes when a moving neighbour (fluid faster than
  // wake_speed, or a moving body's surface) comes within a support radius.
  bool rest_detection = true;
  // Buildability: resting material also wakes when the weight above it (checked every
  // rest_duration/2) has grown since it came to rest by a tenth of its yield stress and exceeds
  // Roussel's unconfined bound √3 τ0, and is then simulated for load_wake_duration. Off by default:
  // a print nearing its bound then costs what it costs without rest detection (the 20-layer clay
  // wall bench: 13× the cost at layer 2 instead of 1.2×).
  bool wake_on_load = false;
  // Air drag on the material's surface (Gissler et al. 2017), off by default: still air exerts
  // ½ ρ_air C_D A v² on each exposed particle; wind is air_velocity.
  bool air_drag = false;
  Real air_density = Real(1.204);             // kg/m³, dry air at 20 °C
  Real air_viscosity = Real(1.825e-5);        // Pa·s, dry air at 20 °C
  Vec3 air_velocity = Vec3::Zero();           // m/s
  Real rest_speed = Real(2e-3);               // m/s
  Real rest_duration = Real(0.05);            // s
  Real wake_speed = Real(5e-3);               // m/s
  Real load_wake_duration = 1;                // s: material woken by load is simulated at least this long
                                              // (a collapse starts slowly; measured: 0.25 s missed it)
};

/// A circular nozzle that emits whole disc layers of particles (Issue: volume flux π D²/4 · U).
struct NozzleSettings {
  std::string name;
  Real inner_diameter = Real(0.01);   // m
  Real exit_speed = Real(0.1);        // m/s, mean speed of material leaving the nozzle
  std::uint16_t phase = 0;
};

struct Parameters {
  SolverSettings settings;
  std::vector<FluidPhase> phases;
  std::vector<NozzleSettings> nozzles;
};

struct NozzleState {
  Pose pose;                          // emission axis = pose · (0, 0, −1): pointing down by default
  Vec3 velocity = Vec3::Zero();       // m/s of the nozzle itself (added to the exit velocity)
  bool extruding = false;
  Real flow_scale = 1;                // flow / nominal flow π D²/4 · U (a G-code move's E rate); 1 = nominal
  double pending_time = 0;            // s of nominal extrusion not yet emitted as a layer
  std::uint64_t layers_emitted = 0;
  std::uint64_t particles_emitted = 0;
  std::uint64_t blocked_layers = 0;   // steps in which a due layer was delayed: the space in front was occupied
};

/// Wall-clock time per stage of the last step (ms).
struct StageTimes {
  double bodies = 0, remove = 0, emit = 0, reorder = 0, neighbors = 0, density = 0, divergence = 0, forces = 0,
         viscosity = 0, pressure = 0, advect = 0;
  [[nodiscard]] double total() const {
    return bodies + remove + emit + reorder + neighbors + density + divergence + forces + viscosity + pressure + advect;
  }
};

struct StepStats {
  double time_step = 0;                 // s
  int density_iterations = 0;
  int divergence_iterations = 0;
  int viscosity_iterations = 0;         // conjugate-gradient iterations of the implicit viscosity solve
  Real density_error = 0;               // mean relative density error after the density solve
  Real max_density_error = 0;           // max over particles of (ρ/ρ0 − 1) at the start of the step
  std::size_t particles_emitted = 0;
  std::size_t particles_removed = 0;
  std::size_t particles_at_rest = 0;    // at the end of the step (not simulated)
  StageTimes stage_ms;
};

struct Wrench {
  Vec3 force = Vec3::Zero();
  Vec3 torque = Vec3::Zero();
};

namespace stages {
class CoarseViscosityLevel;  // the implicit viscosity's coarse level (viscosity_weiler2018.cpp)

/// Owns the coarse level between solves (its buffers, and the factorisation's analysis, reused while
/// A_c keeps its pattern). A copy (a State snapshot) starts with an empty one: every solve builds the
/// level again, and a restored state steps as the original would.
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

/// Everything that changes during a run.
struct State {
  FluidParticles fluid;
  // The first active_count particles are simulated; the rest have come to rest (rest_detection) and
  // only stand as fixed neighbours: zero velocity and κ, not in any solver sweep.
  std::size_t active_count = 0;
  int resting_woken = 0;             // 1 when update_rest_clocks woke a resting particle this step
  double next_load_check_time = 0;   // s, when the weight on resting material is checked next
  BoundaryParticles boundary;
  std::vector<BoundaryBody> bodies;
  std::vector<NozzleState> nozzles;

  SpatialHashGrid fluid_grid;    // the active particles, every step
  // The resting particles (neighbours too, but fixed): rebuilt only when the resting range, its
  // particles or their positions changed (first index, ids and positions as built).
  SpatialHashGrid resting_grid;
  std::size_t resting_grid_first = 0;            // the first resting index when it was built
  std::vector<Index> resting_grid_subset;
  std::vector<std::uint64_t> resting_grid_ids;
  std::vector<Vec3> resting_grid_positions;
  // Boundary particles in two grids: static bodies' sorted once (a large floor costs nothing per
  // step), moving bodies' every step, and only those bodies near the fluid or a nozzle (a robot
  // arm's upper links usually are not).
  SpatialHashGrid static_boundary_grid;
  SpatialHashGrid moving_boundary_grid;
  bool static_boundary_dirty = true;
  std::vector<Index> static_boundary_indices;
  std::vector<Index> moving_boundary_indices;  // this step's: particles of the moving bodies near the fluid
  // Every grid's cell: the support radius, or support + skin while lists are kept across steps.
  Real search_cell_size = 0;
  std::uint64_t fixed_grids_version = 0;  // counts rebuilds of the resting and static boundary grids
  // Lists kept across steps for slow material (SolverSettings::neighbor_skin) and when to use them.
  SkinnedNeighborSearch skinned_search;
  bool skin_in_use = false;
  int calm_steps = 0;                 // consecutive steps the speeds predicted kept lists to last
  int skin_cooldown = 0;              // steps before kept lists may be tried again
  int skin_backoff = 64;              // the next cooldown: doubles each time kept lists fail soon
  std::int64_t skin_since_step = 0;   // the step the last switch happened
  std::uint32_t recent_searches = 0;  // bit k: the kept lists were searched anew k steps ago
  std::uint64_t neighbor_searches = 0;  // steps that searched the grids for every particle (all, without kept lists)
  NeighborLists fluid_neighbors;     // fluid → fluid
  NeighborLists boundary_neighbors;  // fluid → boundary
  // Per neighbour pair (same slots as the lists), filled with the densities each step:
  // V_j · (dW/dr)/r, so that V_j ∇W_ij = factor · (x_i − x_j). Positions do not move between the
  // density pass and advection, so every solver sweep rebuilds V_j ∇W_ij from these without a
  // square root or a branch. V_j = m_j/ρ0 for fluid, the Akinci volume for boundary particles.
  std::vector<Real> fluid_pair_gradient;
  std::vector<Real> boundary_pair_gradient;

  double time = 0;                   // s
  std::int64_t step = 0;
  Real time_step;                    // s, last step's
  std::uint64_t next_particle_id = 0;
  std::uint64_t particles_removed_total = 0;
  double mass_removed_total = 0;     // kg
  double mass_emitted_total = 0;     // kg
  StepStats last_step;

  // Scratch reused every step (no allocation in the step once sized).
  std::vector<Real> kappa;           // (n) m κ of the current solver iteration
  // Positions and velocities padded to Vec4 (w = 0) for the solvers' sweeps: one aligned load and one
  // SIMD operation per neighbour (1.4–1.5× faster sweeps than with Vec3). The positions are packed once
  // a step, in the density pass, and read until advection by the pressure solves, the shear rates and
  // the implicit viscosity; the velocities are packed by each user and go back after each solve. (n) each.
  std::vector<Vec4> solver_position, solver_velocity;
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
  tbb::enumerable_thread_specific<std::vector<Wrench>> body_wrench_per_thread;
  std::vector<std::uint64_t> sort_keys;
  std::vector<Index> permutation;
  std::vector<Vec3> scratch_vec3;
  std::vector<Real> scratch_real;
  std::vector<std::uint16_t> scratch_u16;
  std::vector<std::uint64_t> scratch_u64;
  std::vector<Real> height;          // (n) m, against gravity (load check)
  // Implicit viscosity (Weiler et al. 2018): the system's coefficients and the CG vectors.
  struct ViscositySystem {
    std::vector<Real> fluid_pair_coefficient;     // per fluid neighbour slot: −Δt × the pair's viscous factor (kg/m²)
    std::vector<Real> boundary_pair_coefficient;  // per boundary neighbour slot, the same
    std::vector<Mat3> inverse_diagonal;           // (n) block-Jacobi preconditioner
    std::vector<Mat3> own_block;                  // (n) m_i I + the walls' Σ_b c_ib r rᵀ: A's part that acts on x_i alone (kg)
    std::vector<Vec3> rhs, residual, preconditioned, product, start_velocity;  // (n) each
    // The vector that A multiplies (the start velocity, then each CG direction), padded to Vec4 for the
    // product's sweep as the pressure solves' copies (State::solver_position holds the positions). The
    // CG direction lives only here.
    std::vector<Vec4> padded_operand;
    // The preconditioner's coarse level: aggregates of particles (cells of a coarse grid) that move
    // as one (see viscosity_weiler2018.cpp).
    std::vector<std::uint64_t> aggregate_key;     // (n) coarse cell of each active particle
    std::vector<Index> aggregate_order;           // (n) active particles grouped by aggregate
    std::vector<Index> aggregate_start;           // (aggregates + 1) into aggregate_order
    std::vector<Index> aggregate_of;              // (n) aggregate of each active particle
    std::vector<Vec3> aggregate_offset;           // (n) x_i − its aggregate's centroid (m)
    std::vector<double> coarse_residual, coarse_correction;  // (6 × aggregates: translation, rotation)
    std::vector<Real> coarse_motion;              // coarse_correction in single precision, for the per-particle sweep
    int previous_iterations = 0;                  // CG iterations of the last solve (whether to build the coarse level)
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
};

/// Factors on the viscosity sums that make them exact on the rest lattice (see calibrated_viscosity()).
struct ViscosityCalibration {
  Real fluid = 1;     // on fluid–fluid pairs
  Real boundary = 1;  // on fluid–boundary pairs: no slip at the geometric surface
  Real fluid_gradient = 1;     // on the velocity gradient's fluid sum
  Real boundary_gradient = 1;  // on its wall sum
  // 1/m²: on the rest lattice, Σ_j |c_ij| r_ij² = Δt μ/ρ0 × coupling (c_ij the implicit solve's pair
  // coefficients): how strongly the viscous term couples a particle to its neighbours in a step.
  Real coupling = 0;
};

/// Surface tension (Akinci et al. 2013) coefficients per unit of the material's physical values:
/// γ = cohesion_per_tension × σ / (ρ0_i ρ0_j), β = adhesion_per_work × W_a / ρ0_i² (σ, W_a in N/m); see
/// surface_tension_akinci2013.cpp.
struct SurfaceTensionCalibration {
  Real cohesion_per_tension = 0;
  Real adhesion_per_work = 0;
  Real layer_kernel_sum = 0;  // CSF: d² Σ_j W_fit over a flat layer of the rest lattice (m² · kernel units)
};
/// The mean-field surface energy of Akinci's cohesion and adhesion forces on the rest lattice.
SurfaceTensionCalibration calibrated_surface_tension(KernelType kernel_type, Real support_radius, Real fluid_spacing,
                                                     Real wall_spacing, Real boundary_volume_scale);
/// The CSF's area scale: d² Σ_j W over a flat layer of the rest lattice with the curvature fit's kernel, so
/// that a layer particle's area is this over its kernel sum. See surface_tension_brackbill1992.cpp.
Real csf_layer_kernel_sum(KernelType kernel_type, Real support_radius, Real spacing);

/// A granular phase's contact law as the solver uses it (derived once from the material).
struct GranularContact {
  Real stiffness = 0;      // N/m, normal spring
  Real damping_ratio = 0;  // ζ of the normal dashpot, from the restitution
  Real friction = 0;       // Coulomb μ
};

/// Drag coefficient of a sphere at Reynolds number Re (Schiller & Naumann 1933; 0.44 from Re = 1000).
Real sphere_drag_coefficient(Real reynolds_number);
/// Neighbours (excluding itself) of a particle on the rest lattice of spacing `spacing`.
int full_neighbourhood_count(Real support_radius, Real spacing);

/// Derived, immutable data of a nozzle: disc sample offsets and layer period.
struct NozzleGeometry {
  std::vector<Vec3> disc_offsets;  // in the nozzle frame, z = 0
  double layer_period = 0;         // s between layers at the set exit speed
};

class Solver {
 public:
  explicit Solver(Parameters parameters);

  // ---- set-up ----
  /// Adds a rigid body whose surface is sampled as `local_points` (body frame). Returns its index.
  Index add_body(const std::string& name, std::span<const Vec3> local_points, const Pose& pose, bool is_static);
  /// Adds fluid particles at rest spacing (positions in m); points closer than a radius to a boundary are skipped.
  std::size_t add_particles(std::span<const Vec3> positions, const Vec3& velocity, std::uint16_t phase);
  /// Pre-sizes every array for `capacity` fluid particles, so steps do not allocate.
  void reserve(std::size_t capacity);

  // ---- inputs set between steps ----
  void set_body_motion(Index body, const Pose& pose, const Vec3& linear_velocity, const Vec3& angular_velocity);
  /// `flow_scale` multiplies the nominal flow π D²/4 · U (and the exit speed): G-code sets it per move.
  void set_nozzle(Index nozzle, const Pose& pose, const Vec3& nozzle_velocity, bool extruding, Real flow_scale = 1);

  /// Replaces the whole mutable state with a saved copy (checkpoints; benchmarks that time the same step).
  void restore(const State& saved) { state_ = saved; }

  /// Advances by one adaptive (CFL) time step. Throws SimulationError on NaN or explosion.
  const StepStats& step();

  // ---- read-out ----
  [[nodiscard]] const Parameters& parameters() const { return parameters_; }
  [[nodiscard]] const State& state() const { return state_; }
  [[nodiscard]] const FluidParticles& fluid() const { return state_.fluid; }
  [[nodiscard]] const BoundaryParticles& boundary() const { return state_.boundary; }
  [[nodiscard]] const std::vector<BoundaryBody>& bodies() const { return state_.bodies; }
  [[nodiscard]] const NozzleGeometry& nozzle_geometry(Index nozzle) const { return nozzle_geometry_[nozzle]; }
  [[nodiscard]] double time() const { return state_.time; }
  [[nodiscard]] Real particle_diameter() const { return 2 * parameters_.settings.particle_radius; }
  [[nodiscard]] Real support_radius() const {
    return parameters_.settings.support_radius_factor * parameters_.settings.particle_radius;
  }
  /// Mass of one particle of `phase` (kg): rest density × diameter³.
  [[nodiscard]] Real particle_mass(std::uint16_t phase) const;
  /// Pressure of particle i (Pa) from the last step's κ values (Bender & Koschier: κ = ρ0 p / ρ²).
  [[nodiscard]] Real pressure(std::size_t particle) const;
  [[nodiscard]] double total_fluid_mass() const;
  [[nodiscard]] Real boundary_volume_scale() const { return boundary_volume_scale_; }
  [[nodiscard]] const ViscosityCalibration& viscosity_calibration() const { return viscosity_calibration_; }
  [[nodiscard]] const SurfaceTensionCalibration& surface_tension_calibration() const { return surface_tension_calibration_; }
  /// True when the materials are granular (discrete spheres with contacts, no fluid forces).
  [[nodiscard]] bool granular() const { return granular_; }
  /// Contact law of a granular phase: the material's stiffness (N/m) or the derived default, and ζ.
  [[nodiscard]] const GranularContact& granular_contact(std::uint16_t phase) const { return granular_contacts_[phase]; }

 private:
  void update_bodies();
  void remove_out_of_bounds(StepStats& stats);
  void emit(StepStats& stats);
  void push_out_of_nozzles();
  /// Moves the particles appended from `first` on into the active range (before the resting ones).
  void activate_appended(std::size_t first);
  /// Particles that have rested long enough leave the active range; woken ones re-enter it.
  void update_rest_partition();
  /// After advection: rest clocks of the active particles, and wake-up marks on resting ones near motion.
  void update_rest_clocks(Real time_step);
  /// Wakes resting material whose load has grown towards its yield stress (and the column above it).
  void wake_loaded_rest();
  void reorder();
  /// Whether this step keeps neighbour lists from earlier steps (slow material) or searches anew,
  /// and every grid's cell size for it.
  void choose_neighbor_search();
  void search_neighbors();
  void keep_out_of_boundaries();
  void check_state() const;
  /// Checks the materials' optional models and derives their per-phase data (constructor).
  void derive_material_data();
  /// Granular mode's step after the neighbour search: contacts, time step, integration.
  Real step_granular(StepStats& stats);
  /// The end of every step once the particles have moved: walls, body wrenches, clock, state check, stats.
  void finish_step(StepStats& stats, Real time_step, std::chrono::steady_clock::time_point advect_start);

  Parameters parameters_;
  Real boundary_volume_scale_ = 1;      // see calibrated_boundary_volume_scale() in solver.cpp
  Real boundary_share_at_surface_ = 1;
  ViscosityCalibration viscosity_calibration_;  // Σ V_b W on a geometric surface; see keep_out_of_boundaries()
  SurfaceTensionCalibration surface_tension_calibration_;
  Real largest_surface_tension_ = 0;    // N/m, over the phases (capillary time-step limit)
  Real lightest_rest_density_ = std::numeric_limits<Real>::max();  // kg/m³, over the phases
  std::vector<Real> microinertia_;      // m² per phase (micropolar)
  bool any_elastic_ = false;
  int full_neighbourhood_ = 1;           // neighbours of an interior particle on the rest lattice
  bool granular_ = false;
  std::vector<GranularContact> granular_contacts_;  // per phase
  Real granular_time_step_ = 0;          // s, a tenth of the shortest contact duration
  std::vector<NozzleGeometry> nozzle_geometry_;
  State state_;
};

// ---- stages over (parameters, state), in dfsph_bender2017.cpp and viscosity_morris1997.cpp ----
namespace stages {
/// ρ_i and the DFSPH factor α_i (Bender & Koschier 2017, eq. 11); returns max relative density error.
Real compute_density_and_factor(const Parameters& parameters, State& state);
/// Divergence-free solver (Bender & Koschier 2017, Algorithm 2). Returns iterations.
int solve_divergence(const Parameters& parameters, State& state, Real time_step);
/// Constant-density solver (Bender & Koschier 2017, Algorithm 3). Returns iterations; sets mean error.
int solve_density(const Parameters& parameters, State& state, Real time_step, Real& mean_density_error);
/// Gravity, plus laminar viscosity (Morris et al. 1997 form, as in Monaghan 2005) when the viscosity
/// solver is the explicit one, into state.fluid.acceleration.
void compute_non_pressure_accelerations(const Parameters& parameters, State& state, const ViscosityCalibration& calibration);
/// Each particle's shear rate (1/s) and effective dynamic viscosity (Pa·s) from its phase's rheology
/// and its age (viscosity_weiler2018.cpp). Returns the largest μ/ρ (m²/s).
Real update_effective_viscosity(const Parameters& parameters, State& state, const ViscosityCalibration& calibration);
/// Implicit viscosity (Weiler et al. 2018) on state.fluid.velocity over `time_step`; adds the
/// boundary friction to the body wrenches. Returns conjugate-gradient iterations.
int solve_implicit_viscosity(const Parameters& parameters, State& state, Real time_step,
                             const ViscosityCalibration& calibration);
/// Granular mode (Cundall & Strack 1979): gravity plus each particle's contact forces over its mass into
/// state.fluid.acceleration; the walls' share goes to the body wrenches. One GranularContact per phase.
void compute_granular_contacts(const Parameters& parameters, State& state, std::span<const GranularContact> phases);
/// Elastic materials (Peer et al. 2018): the corotated deviatoric stress of each particle's deformation
/// against its reference shape, as accelerations into state.fluid.acceleration.
void add_elastic_forces(const Parameters& parameters, State& state);
/// Elastic materials with a relaxation time: the reference shape creeps towards the current one.
void relax_reference_shape(const Parameters& parameters, State& state, Real time_step);
/// Micropolar materials (Bender et al. 2017): adds μ_t ∇×ω / ρ to state.fluid.acceleration and advances
/// each particle's micro-rotation over `time_step` (the −2ω relaxation implicitly). `microinertia`: Θ
/// (m²) per phase.
void apply_micropolar(const Parameters& parameters, State& state, Real time_step, std::span<const Real> microinertia);
/// Air drag (Gissler et al. 2017) on the exposed particles, added to state.fluid.acceleration.
/// `full_neighbourhood`: the neighbour count of a particle inside the material.
void add_air_drag(const Parameters& parameters, State& state, int full_neighbourhood);
/// Surface tension (the settings' model) and wall adhesion (Akinci et al. 2013), added to
/// state.fluid.acceleration; the adhesion's reaction goes to the body wrenches.
void add_surface_tension(const Parameters& parameters, State& state, const SurfaceTensionCalibration& calibration);
/// The colour gradient ∇c_i = Σ_j V_j ∇W_ij + Σ_b V_b ∇W_ib of particle i (pointing into the material;
/// walls count as material), from this step's pair gradients, which hold the rest volume. With
/// `rest_volume` (m³) > 0 each neighbour counts with its current volume m_j/ρ_j instead.
Vec3 colour_gradient(const State& state, std::size_t i, Real rest_volume = 0);
/// The continuum surface force (Brackbill et al. 1992) of surface_tension_brackbill1992.cpp.
void add_csf_surface_tension(const Parameters& parameters, State& state, Real layer_kernel_sum);
/// XSPH (Monaghan 1989): v_i += ε Σ_j V_j (v_j − v_i) W_ij.
void apply_xsph(const Parameters& parameters, State& state);
/// Viscosity of a particle pair (Pa·s): the harmonic mean, as for fluxes across layers in series. Where a
/// yielded particle meets an unyielded one (10³× more viscous) the arithmetic mean would make the pair as
/// stiff as the plug and drag the sheared layer along (Bingham Poiseuille flow then runs 40 % slow).
inline Real pair_viscosity(Real mu_i, Real mu_j) {
  const Real sum = mu_i + mu_j;
  return sum > 0 ? 2 * mu_i * mu_j / sum : Real(0);
}
/// Clears the per-thread wrench accumulators (sized to the bodies).
void reset_body_wrenches(State& state);
/// This thread's wrench accumulator, one entry per body (sized on a thread's first use only).
inline std::vector<Wrench>& thread_body_wrenches(State& state) {
  std::vector<Wrench>& wrenches = state.body_wrench_per_thread.local();
  if (wrenches.size() != state.bodies.size()) wrenches.assign(state.bodies.size(), Wrench{});
  return wrenches;
}
/// Sums the per-thread wrenches into each body's fluid_force / fluid_torque.
void collect_body_wrenches(State& state);
}  // namespace stages

}  // namespace m3dp::sph
