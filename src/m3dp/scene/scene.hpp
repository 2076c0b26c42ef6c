#pragma once
// A scene as loaded from an SDF world file: validated, immutable parameters and nothing else.
// Every entry remembers where in the file it came from, for later messages.
#include <array>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/core/geometry.hpp"
#include "m3dp/material/material.hpp"
#include "m3dp/sensors/camera.hpp"
#include "m3dp/sph/settings.hpp"
#include "m3dp/surface/surface.hpp"
#include "m3dp/toolpath/parametric.hpp"

namespace m3dp::scene {

/// One collision shape of a static SDF model, placed in the world.
struct CollisionShape {
  std::string name;  // "model/link/collision"
  Shape shape;
  Pose pose;  // world pose of the shape frame (model ∘ link ∘ collision)
  SourceLocation where;
};

/// A static SDF <model>: the fluid sees each of its collision shapes as boundary particles.
struct StaticBody {
  std::string name;
  std::vector<CollisionShape> collisions;
  SourceLocation where;
};

/// A free rigid SDF <model> (not static, one <link>): it falls, floats and is pushed by the fluid.
struct DynamicBody {
  std::string name;
  std::vector<CollisionShape> collisions;  // poses in the body (link) frame
  Pose pose;                               // world pose of the link frame (m)
  double mass = 1;                         // kg, <inertial><mass>
  std::optional<Mat3> inertia;             // kg·m² about the link origin; none: from the first shape
  SourceLocation where;
};

/// A differential-drive base (the plugin's <robot><mobile_base>): wheel joints and geometry, and
/// optionally a path for the base to follow (z ignored).
struct MobileBase {
  std::string left_wheel_joint;
  std::string right_wheel_joint;
  Real wheel_radius = Real(0.033);      // m
  Real wheel_separation = Real(0.287);  // m
  std::optional<toolpath::Trajectory> path;
  SourceLocation where;
};

/// A robot: an SDF <include> of a URDF file, placed by the include's <pose>.
struct RobotInclude {
  std::string name;
  std::filesystem::path urdf_file;                 // resolved, absolute or relative to the working directory
  Pose pose;                                       // of the URDF root in the world
  std::vector<std::string> joint_names;            // the URDF's movable joints, in file order
  std::vector<std::string> link_names;
  /// Links whose URDF <visual> gives a <material><color rgba>: linear RGB in [0, 1] (cameras draw them so).
  std::vector<std::pair<std::string, std::array<float, 3>>> link_colors;
  std::vector<std::pair<std::string, double>> initial_joint_positions;  // rad or m, from the plugin's <robot>
  std::optional<MobileBase> mobile_base;
  SourceLocation where;
};

/// A print head carried by a robot: the nozzle's exit frame on a link (z = the way material leaves).
struct NozzleMount {
  std::string robot;
  std::string link;
  Pose offset;                 // exit frame in the link frame (m)
  Real barrel_radius = 0;      // m: a cylinder from the link to the exit that collides and displaces fluid; 0 = none
  SourceLocation where;
};

/// Where each engine field of an entry was written, by the names sph::ParameterProblem uses
/// ("density", "elasticity.poisson_ratio"): a problem the engine finds is reported at that line.
using FieldLocations = std::vector<std::pair<std::string, SourceLocation>>;

struct MaterialEntry {
  material::Material material;
  SourceLocation where;
  FieldLocations fields = {};  // the material's own elements, or its preset's
  std::optional<std::array<float, 3>> color = {};  // linear RGB in [0, 1] (<color>, or its preset's): how cameras draw it
};

/// A camera: an SDF <sensor type="camera|depth_camera|rgbd_camera"> in a static model's link (fixed
/// in the world), or the plugin's <camera> on a robot link (<mount>) or in the world (<pose>).
struct CameraEntry {
  sensors::CameraSettings settings;
  SourceLocation where;
  bool in_plugin = false;  // a <camera> of M3DP's plugin (its values have paths: camera[NAME]...), not an SDF <sensor>
};

/// Particles on a lattice of spacing 2·particle_radius filling a box [min, max] or, when `cylinder_radius`
/// is set, the vertical cylinder inscribed in that box (a slump-test mould: base centre, radius, height).
struct FluidBlock {
  std::string name;
  std::string material;
  Aabb box;                            // m
  std::optional<Real> cylinder_radius; // m; the cylinder's axis is the box's vertical centre line
  Real cylinder_height = 0;            // m, as read (the box holds it too)
  Vec3 initial_velocity = Vec3::Zero();  // m/s
  SourceLocation where;
};

/// A print head: a nozzle moved along a path, extruding where the path says so.
struct PrintHead {
  std::string name;
  std::string material;
  Real inner_diameter = Real(0.01);  // m
  Real exit_speed = Real(0.1);       // m/s
  Vec3 direction = Vec3(0, 0, -1);   // unit vector the material leaves along
  Real bore_length = 0;              // m of bore above the exit, as walls (0: none, the exit is the inlet)
  Real outer_diameter = 0;           // m, the tip's lip (0: a wall one particle thick)
  FieldLocations nozzle_fields = {};  // where its nozzle's elements are (for the engine's checks)
  toolpath::Trajectory trajectory;
  std::optional<NozzleMount> mount;  // none: an ideal gantry moves the nozzle exactly along the path
  SourceLocation where;
};

struct OutputSettings {
  /// s of simulated time between particle frames (and world.pvd's, and run.mcap's); 0 = none; unset:
  /// chosen for the run's length (particle_frame_period).
  std::optional<Real> particles_period;
  bool write_particles = true;
  bool mcap = false;                   // run.mcap: the run in Foxglove's messages (also `m3dp run --record`)
  std::optional<std::uint16_t> serve_port;  // a live Foxglove WebSocket stream on this port (0: any free one)
  double checkpoint_period = 0;        // s of simulated time between checkpoints (m3dp run --resume); 0 = none
  /// s of simulated time between the in-run quality report's looks at the printed height (quality.json,
  /// written at the end of a run with an output folder and print heads); 0 = no in-run quality report.
  double quality_period = 0.1;
};

/// The frames of particles a run writes, at most this many by default: a 15-minute print at one every
/// 0.02 s would be 45,000 files.
constexpr double kDefaultMostParticleFrames = 500;
/// The period (s) between particle frames of a run to `end_time` (s): the scene's <particles_period>
/// if it gives one, else 0.02 s, or for a run longer than 10 s the next 1, 2 or 5 × 10^k s that keeps
/// it to kDefaultMostParticleFrames frames.
[[nodiscard]] double particle_frame_period(const OutputSettings& output, double end_time);

/// Surface meshes made during the run (issue 4): every `period` seconds of simulated time the fluid
/// is meshed on a worker thread and written to meshes/ (the solver does not wait for it).
struct MeshingSettings {
  bool enabled = false;
  Real period = Real(0.5);                // s of simulated time between meshes
  std::string format = "ply";            // a name of io::mesh_formats()
  std::string material;                  // mesh only this material; empty = all
  std::optional<Aabb> region;            // mesh only particles inside this box (m); none = everywhere
  surface::SurfaceSettings surface;       // particle_radius filled from the solver
  SourceLocation where;
};

/// The multi-robot coordinator (the plugin's <coordinator>; sim/coordination_erdmann1987.hpp): every
/// `period` it looks `horizon` ahead along each robot's paths and slows or stops, in priority order,
/// a robot whose predicted shapes would come within `robot_clearance` of another robot's or within
/// `print_clearance` of the printed material.
struct CoordinatorSettings {
  bool enabled = false;
  double period = 0.1;                // s of simulated time between decisions
  double horizon = 1.5;               // s looked ahead
  int samples = 6;                    // predicted configurations over the horizon
  Real robot_clearance = Real(0.03);  // m
  Real print_clearance = Real(0.01);  // m
  std::vector<std::string> priority;  // robot names, highest first; those not named follow in scene order
  SourceLocation where;
};

struct Scene {
  std::filesystem::path file;   // the scene file as given
  std::string world_name;
  double end_time = 1;          // s of simulated time
  sph::SolverSettings solver;   // includes gravity (from the world's <gravity>) and bounds
  FieldLocations solver_fields; // where <particle_radius>, <air><density>… were written
  std::vector<MaterialEntry> materials;
  std::vector<StaticBody> bodies;
  std::vector<DynamicBody> dynamic_bodies;
  std::vector<RobotInclude> robots;
  std::vector<FluidBlock> fluid_blocks;
  std::vector<PrintHead> print_heads;
  OutputSettings output;
  MeshingSettings meshing;
  CoordinatorSettings coordinator;
  std::vector<CameraEntry> cameras;
  std::vector<Diagnostic> warnings;  // not errors: e.g. G-code commands that were skipped (file:line)
  std::vector<std::filesystem::path> input_files;  // the files it reads beside itself: URDF, G-code, waypoints, meshes

  [[nodiscard]] const MaterialEntry* find_material(const std::string& name) const;
  /// Whether a material sticks to static walls for want of a wall friction of its own: a print head
  /// lays it, and neither the scene, its preset nor the code that made it sets one (a bed holds what
  /// is laid on it; Material::sticks_to_static_walls).
  [[nodiscard]] bool holds_on_beds(const MaterialEntry& entry) const;
  /// The material's index (the engine's phase); 0 for a name the loader did not accept.
  [[nodiscard]] std::uint16_t material_index(const std::string& name) const;
  [[nodiscard]] const RobotInclude* find_robot(const std::string& name) const;
};

/// The engine's parameters: the solver settings, the materials as phases (in scene order) and the
/// print heads as nozzles.
sph::Parameters solver_parameters(const Scene& scene);

/// Where `model://NAME` URIs are looked for, in order: models/ beside the scene file and one level
/// up, each folder of the M3DP_MODEL_PATH environment variable (':'-separated), and the project's
/// own models/ folder. NAME/NAME.urdf or NAME/model.urdf inside it is the robot.
std::vector<std::filesystem::path> model_search_path(const std::filesystem::path& scene_file);

/// A scene value replaced by its path: `material[mortar].rheology.yield_stress` is the <yield_stress>
/// of the <rheology> of the <material name="mortar"> in M3DP's plugin; a first step the <world> has
/// (model[floor], include[arm], gravity) starts at the world. A step's [key] picks its element by
/// name="..." (or, all digits, by its index among its namesakes); a last step that is no child but an
/// attribute the element has sets the attribute (print_head[head].path.speed: <path speed="...">).
/// The value is text as written in the scene, SI (a unit attribute there is dropped).
struct SceneOverride {
  std::string path;
  std::string value;
};

/// Loads and validates a scene. Throws InputError listing every problem found, each with file:line.
Scene load_scene(const std::filesystem::path& file);
/// Same, with values replaced (studies): each checked as if written in the file.
Scene load_scene(const std::filesystem::path& file, std::span<const SceneOverride> overrides);
/// The scene file's text with the overrides applied: what load_scene(file, overrides) reads.
std::string read_scene_text(const std::filesystem::path& file, std::span<const SceneOverride> overrides = {});
/// The scene text with the overrides applied (an element not written is added where its path says;
/// the reader then checks it belongs there). Throws InputError naming the path where it leads nowhere.
std::string apply_overrides(const std::string& text, const std::filesystem::path& file_name, std::span<const SceneOverride> overrides);
/// The material presets file: $M3DP_MATERIALS if set, else the project's data/materials.xml.
std::filesystem::path material_presets_file();
/// Every preset of that file, with its line (InputError naming the file and line if it is wrong).
std::vector<MaterialEntry> load_material_presets();
/// Same, from text in memory; `file_name` is used in messages and to resolve relative mesh paths.
Scene load_scene_from_string(const std::string& text, const std::filesystem::path& file_name);

/// A print head's <path> element on its own (paths given at run time, the Python API): its segments
/// and its start_time attribute (s; 0 if absent). `file_name` names it in errors (file:line) and
/// is what the <gcode> and <waypoints> files it refers to are relative to.
struct PathSegments {
  std::vector<toolpath::PathSegment> segments;
  double start_time = 0;
};
PathSegments load_path_from_string(const std::string& text, const std::filesystem::path& file_name);

}  // namespace m3dp::scene
