#pragma once
// The SPH particle engine: the compiled model (immutable), the state (what a checkpoint holds) and
// the workspace (what the stages rebuild), and one step as the list of stages in Solver::step.
#include <span>
#include <string>

#include "m3dp/core/types.hpp"
#include "m3dp/sph/model.hpp"
#include "m3dp/sph/stages.hpp"
#include "m3dp/sph/state.hpp"

namespace m3dp::sph {

class Solver {
 public:
  /// Compiles the model (throws ParameterError for parameters check_parameters does not accept).
  explicit Solver(Parameters parameters);

  // ---- set-up ----
  /// Adds a rigid body whose surface is sampled as `local_points` (body frame). Returns its index.
  Index add_body(const std::string& name, std::span<const Vec3> local_points, const Pose& pose, bool is_static);
  /// A static body whose `surface.now` points are in at once and whose `surface.later` faces get
  /// their particles tile by tile where material comes near (sample_shape_surface_tiled).
  Index add_static_surface(const std::string& name, const TiledSurface& surface, const Pose& pose);
  /// Adds fluid particles at rest spacing (positions in m); points closer than a radius to a boundary are skipped.
  std::size_t add_particles(std::span<const Vec3> positions, const Vec3& velocity, std::uint16_t phase);
  /// Pre-sizes every array for `capacity` fluid particles, so steps do not allocate.
  void reserve(std::size_t capacity);

  // ---- inputs set between steps ----
  void set_body_motion(Index body, const Pose& pose, const Vec3& linear_velocity, const Vec3& angular_velocity);
  /// `flow_scale` multiplies the nominal flow π D²/4 · U (and the exit speed): G-code sets it per move.
  /// `print_layer`: the layer of its path the nozzle prints (0 first), kept by each particle it emits.
  void set_nozzle(Index nozzle, const Pose& pose, const Vec3& nozzle_velocity, bool extruding, Real flow_scale = 1,
                  std::int32_t print_layer = -1);

  /// Replaces the state with a saved one (a checkpoint); the workspace's caches are rebuilt.
  void restore(const State& saved);
  /// The same with the workspace saved with it: the next step is the saved one's, bit for bit, caches
  /// included (benchmarks that time the same step).
  void restore(const State& saved, const Workspace& saved_workspace);

  /// Drops the workspace's caches (kept neighbour lists, fixed grids, the viscosity's coarse level) as
  /// a restore does: a run that writes a checkpoint calls it there, so that it goes on exactly as a
  /// run resumed from that checkpoint will.
  void drop_caches() { workspace_.invalidate(); }

  /// Advances by one adaptive (CFL) time step: the stages in order. Throws SimulationError on NaN or explosion.
  const StepStats& step();

  // ---- read-out ----
  [[nodiscard]] const Model& model() const { return model_; }
  [[nodiscard]] const Parameters& parameters() const { return model_; }
  [[nodiscard]] const State& state() const { return state_; }
  [[nodiscard]] const Workspace& workspace() const { return workspace_; }
  /// The settled resting particles: slots [begin, end) whose particles have not moved since the
  /// neighbour stage chose them (build number `build`), for what keeps its own structure of them
  /// (cameras). Empty when there are none or a slot has changed since.
  struct SettledParticles {
    std::size_t begin = 0, end = 0;
    std::uint64_t build = 0;
  };
  [[nodiscard]] SettledParticles settled_particles() const {
    const auto& fluid = state_.fluid;
    if (workspace_.resting_grid_dirty || fluid.watched_touched || workspace_.settled_begin < state_.active_count ||
        workspace_.settled_end > fluid.size() || workspace_.settled_begin >= workspace_.settled_end)
      return {};
    return {workspace_.settled_begin, workspace_.settled_end, workspace_.settled_builds};
  }
  [[nodiscard]] const FluidParticles& fluid() const { return state_.fluid; }
  [[nodiscard]] const BoundaryParticles& boundary() const { return state_.boundary; }
  [[nodiscard]] const std::vector<BoundaryBody>& bodies() const { return state_.bodies; }
  [[nodiscard]] const NozzleGeometry& nozzle_geometry(Index nozzle) const { return model_.nozzle_geometry[nozzle]; }
  [[nodiscard]] double time() const { return state_.time; }
  [[nodiscard]] Real particle_diameter() const { return model_.particle_diameter; }
  [[nodiscard]] Real support_radius() const { return model_.support_radius; }
  /// Mass of one particle of `phase` (kg): rest density × diameter³.
  [[nodiscard]] Real particle_mass(std::uint16_t phase) const { return model_.particle_mass[phase]; }
  /// Pressure of particle i (Pa) from the last step's κ values (Bender & Koschier: κ = ρ0 p / ρ²).
  [[nodiscard]] Real pressure(std::size_t particle) const;
  [[nodiscard]] double total_fluid_mass() const;
  [[nodiscard]] Real boundary_volume_scale() const { return model_.boundary_volume_scale; }
  [[nodiscard]] const ViscosityCalibration& viscosity_calibration() const { return model_.viscosity_calibration; }
  [[nodiscard]] const SurfaceTensionCalibration& surface_tension_calibration() const { return model_.surface_tension_calibration; }
  /// True when the materials are granular (discrete spheres with contacts, no fluid forces).
  [[nodiscard]] bool granular() const { return model_.granular; }
  /// Contact law of a granular phase: the material's stiffness (N/m) or the derived default, and ζ.
  [[nodiscard]] const GranularContact& granular_contact(std::uint16_t phase) const { return model_.granular_contacts[phase]; }

 private:
  /// Runs `functions` in order as the timed stage `stage`.
  void run(Stage stage, std::initializer_list<stages::StageFunction> functions);

  Model model_;
  State state_;
  Workspace workspace_;
};

}  // namespace m3dp::sph
