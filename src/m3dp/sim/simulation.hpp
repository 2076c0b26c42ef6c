#pragma once
// Simulation: owns one of each module for a scene and runs the step of the architecture. The run
// around it (its observers and summary) is run.hpp's.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "m3dp/coupling/fluid_body_coupling.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/coordination_erdmann1987.hpp"
#include "m3dp/sim/robots.hpp"
#include "m3dp/sph/measure.hpp"
#include "m3dp/sph/solver.hpp"
#include "m3dp/world/world.hpp"

namespace m3dp::sim {

class CameraRig;
class PrintedBody;

class Simulation {
 public:
  explicit Simulation(const scene::Scene& scene);
  ~Simulation();
  Simulation(const Simulation&) = delete;
  Simulation& operator=(const Simulation&) = delete;

  /// One step: the coordinator (if on) decides the robots' speeds along their paths, print heads follow their paths (robots through their controllers), the links' motion
  /// goes to the fluid, the fluid advances (adaptive dt), its forces go back to the links, and the
  /// world is stepped to the fluid's clock. Throws SimulationError when the state blows up: a particle
  /// past the speed limit, or most of the material gone out of the bounds (kLostFractionBlowUp).
  const sph::StepStats& step();

  /// Where a print head's nozzle is and what it does now: its exit frame (material leaves along the
  /// pose's −z), velocity (m/s), whether it extrudes, and the flow it is asked for (m³/s).
  struct NozzleState {
    Pose pose;
    Vec3 velocity = Vec3::Zero();
    bool extruding = false;
    Real volume_rate = 0;
    Real flow_scale = 1;  // volume_rate over the nozzle's nominal π D²/4 · U
    std::int32_t print_layer = -1;  // the layer of its path it prints now (0 first)
  };
  [[nodiscard]] NozzleState nozzle_state(std::size_t head) const;

  /// Who moves a print head: its path; commands from outside (its robot under external control, or a
  /// target given to a gantry head); or, after them, its way back to where its path is now, which it
  /// travels without extruding.
  enum class HeadControl : std::uint8_t { path, external, rejoining };
  [[nodiscard]] HeadControl head_control(std::size_t head) const { return head_control_.at(head); }
  [[nodiscard]] static std::string_view to_string(HeadControl control);

  /// A print head commanded from outside (the Python API): whether it extrudes and its flow as a
  /// fraction of its nominal π D²/4 · U; none: as its path says while the path moves it, and off (at
  /// the nominal flow) under external control. Held until the next command. Where the head goes is
  /// command_head_target's, or its robot's (World::command_tool_target).
  struct HeadCommand {
    std::optional<bool> extruding;
    std::optional<Real> flow_scale;
  };
  void command_head(std::size_t head, const HeadCommand& command);
  /// Where a print head's nozzle exit should go (m, world) and the direction material should leave
  /// along: the robot carrying it goes there through its IK, a head on an ideal gantry directly,
  /// along a straight line within `limits`; held until the next command. Throws Error for a target
  /// out of the robot's reach, or outside the scene's bounds on a gantry.
  void command_head_target(std::size_t head, const world::ToolTarget& target, const world::MotionLimits& limits);
  /// Ends external control of a head (and its robot): it goes back to its path, travelling there
  /// within the default limits on a gantry, without extruding on the way.
  void release_head(std::size_t head);
  /// The way a head under a target (or on its way back to its path) goes now; null when its path moves it.
  [[nodiscard]] const world::TargetFollower* head_target(std::size_t head) const;
  /// How close (m) a head must come to where its path is before it extrudes again after external control.
  [[nodiscard]] Real rejoin_tolerance(std::size_t head) const;
  /// The path a print head follows now (the scene's, or one given at run time), on path_time's clock.
  [[nodiscard]] const toolpath::Trajectory& head_path(std::size_t head) const { return head_paths_.at(head); }
  /// The path a scene robot's mobile base follows now; none: it has none (or no base).
  [[nodiscard]] const std::optional<toolpath::Trajectory>& base_path(std::size_t robot) const { return base_paths_.at(robot); }
  /// A new path for a print head, given while it runs: it replaces the head's path from now on (the
  /// head first travels from where its path has it now to the new path's first point), or with
  /// `append` follows the path's end. `delay` (s) waits that long first. The robot that carries
  /// the head goes back to following its path. The scene keeps the path the run started with, which
  /// outputs that draw paths keep drawing; checkpoints hold the paths as they are.
  void set_head_path(std::size_t head, std::vector<toolpath::PathSegment> segments, double delay, bool append);
  /// The same for a mobile base's path (z ignored): the scene's robot `robot` (scene order) follows it.
  void set_base_path(std::size_t robot, std::vector<toolpath::PathSegment> segments, double delay, bool append);
  [[nodiscard]] const HeadCommand& head_command(std::size_t head) const { return head_commands_.at(head); }

  /// The multi-robot coordinator (coordination_erdmann1987.hpp): on from the scene's <coordinator>,
  /// switched on (with the scene's settings, or the defaults) or off here. Off, every robot's paths
  /// run at full speed from where they are. Null when off.
  void set_coordination(bool on);
  [[nodiscard]] const PrioritizedCoordination* coordination() const { return coordination_.get(); }
  /// The scene robot (scene order) that carries a print head; none on an ideal gantry.
  [[nodiscard]] std::optional<std::size_t> robot_of_head(std::size_t head) const { return head_robots_.at(head); }
  /// When a print head's path (as it is now) begins each layer: s, on its path's clock.
  [[nodiscard]] const std::vector<double>& layer_start_times(std::size_t head) const { return head_layer_starts_.at(head); }
  /// The clock the scene's robot `robot` (scene order) samples its paths at.
  [[nodiscard]] const PlanClock& plan_clock(std::size_t robot) const { return plan_clocks_.at(robot); }
  /// The time a print head's path is sampled at now: its robot's plan clock, or the simulation's.
  [[nodiscard]] double path_time(std::size_t head) const;

  /// Puts `mesh` (e.g. the newest surface of the printed material) into the world as the static
  /// collision body "printed_material", replacing the previous one.
  void set_printed_mesh(std::shared_ptr<const TriangleMesh> mesh);
  /// The printed material's surface, remade at the scene's <meshing> period and put into the world
  /// after the step it was asked at (printed_body.hpp), whether or not a run writes it; null when
  /// the scene does not mesh. Outputs tell it where to write its meshes.
  [[nodiscard]] PrintedBody* printed_body() const { return printed_body_.get(); }
  /// Before a checkpoint: the mesh in progress joins the world and the kept meshing field is dropped,
  /// so that the run goes on as one resumed from the checkpoint will.
  void prepare_checkpoint();

  /// The scene's cameras (camera_rig.hpp), made on first use: each renders the simulation as it is,
  /// once a step, when asked. Observers share it, as they share the measured density.
  [[nodiscard]] CameraRig& cameras() const;

  /// A checkpoint of everything that evolves: the fluid's state, the world's, the printed mesh in
  /// it and the cameras' frame counts; and back into a simulation made from the same scene. Caches
  /// are not saved: a run that writes a checkpoint drops them there (drop_caches), so that it goes on
  /// bit for bit as a run resumed from it.
  void save_state(StateWriter& out) const;
  void load_state(StateReader& in);
  void drop_caches();
  /// The printed material's mesh in the world now (null before the first), and how many were set.
  [[nodiscard]] const std::shared_ptr<const TriangleMesh>& printed_mesh() const { return printed_mesh_; }
  [[nodiscard]] std::size_t printed_mesh_version() const { return printed_mesh_version_; }

  /// Every fluid particle's density measured where the particles are now (sph::measure_density), with
  /// its statistics: what the particle frames write and the run reports. Measured at most once a step.
  struct DensityMeasurement {
    std::int64_t step = -1;
    double time = 0;                 // s
    std::vector<Real> density;       // kg/m³, in the solver's particle order
    sph::DensityStatistics statistics;
  };
  [[nodiscard]] const DensityMeasurement& measured_density() const;
  /// The latest measurement, or null before the first.
  [[nodiscard]] const DensityMeasurement* latest_density_measurement() const {
    return density_measurement_.step >= 0 ? &density_measurement_ : nullptr;
  }

  /// Where the printed volume went so far (m³; a particle is d³, at its rest density): what the
  /// paths or commands asked of the nozzles, what they emitted (the bores' priming included), what
  /// fills their bores now and what primed them, what left their exits (laid = emitted − in_bores),
  /// what they could not emit (blocked), what left the bounds, and what the particles hold now.
  /// commanded = laid + lost_at_nozzles + (in_bores − primed), within a disc of particles a nozzle.
  struct VolumeBalance {
    double commanded = 0, emitted = 0, primed = 0, in_bores = 0, laid = 0, lost_at_nozzles = 0, removed = 0, in_particles = 0;
  };
  [[nodiscard]] VolumeBalance volume_balance() const;
  /// One nozzle's share of it (m³): lost_at_nozzles is its lost volume; removed and in_particles are not kept per nozzle (0).
  [[nodiscard]] VolumeBalance nozzle_volumes(std::size_t nozzle) const;
  /// More than this fraction of the material ever present (initial and emitted, by mass) has left
  /// the bounds: the state blew up (or the bounds are wrong), and step() throws SimulationError.
  static constexpr double kLostFractionBlowUp = 0.5;

  [[nodiscard]] const scene::Scene& scene() const { return scene_; }
  [[nodiscard]] sph::Solver& solver() { return solver_; }
  [[nodiscard]] const sph::Solver& solver() const { return solver_; }
  [[nodiscard]] double time() const { return solver_.time(); }
  [[nodiscard]] double initial_fluid_mass() const { return initial_fluid_mass_; }
  /// The rigid world: the scene's static shapes, bodies added by the caller, printed meshes.
  [[nodiscard]] world::World& world() { return world_; }
  [[nodiscard]] const world::World& world() const { return world_; }
  /// The world's robot for each of the scene's robots, in scene order.
  [[nodiscard]] const std::vector<world::RobotIndex>& robots() const { return robots_; }
  /// The tool a print head is mounted as, if a robot carries it.
  [[nodiscard]] std::optional<world::ToolIndex> print_head_tool(std::size_t head) const { return head_tools_.at(head); }
  /// The world's body for each of the scene's dynamic bodies, in scene order.
  [[nodiscard]] const std::vector<world::BodyIndex>& dynamic_bodies() const { return dynamic_bodies_; }
  [[nodiscard]] const coupling::FluidBodyCoupling& coupling() const { return *coupling_; }
  /// Wall-clock ms of the last step's coupling (both ways) and world steps.
  [[nodiscard]] double last_coupling_ms() const { return last_coupling_ms_; }
  [[nodiscard]] double last_world_ms() const { return last_world_ms_; }

 private:
  void add_robots();
  void update_print_heads();
  void update_head_control(std::size_t head);
  void check_material_kept() const;

  const scene::Scene scene_;  // as read: the plans it started with
  sph::Solver solver_;
  world::World world_;
  std::vector<world::RobotIndex> robots_;
  std::vector<world::BodyIndex> dynamic_bodies_;
  std::vector<std::optional<world::ToolIndex>> head_tools_;
  std::vector<HeadCommand> head_commands_;  // per print head
  std::vector<HeadControl> head_control_;   // per print head
  struct GantryTarget {                     // a print head without a robot, commanded from outside
    bool external = false;
    world::TargetFollower follower;         // where it is asked to be (also on its way back to its path)
    Vec3 axis = Vec3(0, 0, -1);             // the direction material leaves along
  };
  std::vector<std::optional<GantryTarget>> gantry_targets_;  // per print head
  std::vector<PlanClock> plan_clocks_;      // per scene robot; sized once (the world's paths point into it)
  // The paths followed now, per print head and per scene robot's base: the scene's, changed at run
  // time. Sized once and changed in place: the world's controllers point into them.
  std::vector<toolpath::Trajectory> head_paths_;
  std::vector<std::optional<toolpath::Trajectory>> base_paths_;
  std::vector<std::optional<std::size_t>> head_robots_;  // per print head: the scene robot carrying it
  std::vector<std::vector<double>> head_layer_starts_;  // per print head: when its path begins each layer (s, its clock)
  std::unique_ptr<PrioritizedCoordination> coordination_;
  std::unique_ptr<coupling::FluidBodyCoupling> coupling_;
  double initial_fluid_mass_ = 0;
  std::shared_ptr<const TriangleMesh> printed_mesh_;
  std::size_t printed_mesh_version_ = 0;
  double last_coupling_ms_ = 0, last_world_ms_ = 0;
  mutable DensityMeasurement density_measurement_;
  std::unique_ptr<PrintedBody> printed_body_;
  mutable std::unique_ptr<CameraRig> cameras_;  // a cache of what the state is: observers share it
};

}  // namespace m3dp::sim
