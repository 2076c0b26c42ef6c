#pragma once
// The scene reader: walks an SDF world (or a material library, or a lone <path>), fills a Scene, and
// collects every problem on the way with its file and line. Internal to the scene library; its
// methods live in files by the elements they read:
//   read_values.cpp     structure checks, units, numbers, vectors, poses
//   read_world.cpp      the SDF world, models, links, geometry, meshes, includes
//   read_robots.cpp     the plugin's <robot> settings, mobile bases, mounts
//   read_cameras.cpp    SDF camera sensors and the plugin's <camera>
//   read_plugin.cpp     M3DP's <plugin> blocks and the checks over all of them
//   read_materials.cpp  materials, their rheology, the preset library
//   read_paths.cpp      print paths, curves, G-code and waypoint files
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <pugixml.hpp>

#include <algorithm>
#include <array>
#include <cstddef>
#include <filesystem>
#include <initializer_list>
#include <map>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "m3dp/core/text.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/scene/schema.hpp"
#include "m3dp/scene/xml_names.hpp"
#include "m3dp/sph/model.hpp"

namespace m3dp::scene::detail {

namespace fs = std::filesystem;

// Memory a particle takes while the scene runs: 1.05 kB measured on the dam break (peak resident
// set of m3dp bench at 10⁶ fluid and 3.6·10⁵ wall particles, per particle), doubled for what the
// outputs hold (meshing grids, recording buffers). The default <max_particles> is what 80 % of the
// machine's memory holds at that.
constexpr std::size_t kBytesPerParticle = 2048;
// Memory a path point takes (the polyline's point and the trajectory piece made of it), rounded up.
constexpr std::size_t kBytesPerPathPoint = 128;

// Whether a path the user wrote names something: a name the file system refuses (too long, say)
// names nothing, rather than throwing filesystem_error past the reader's messages.
bool path_exists(const std::filesystem::path& path);
/// This machine's memory in bytes (8 GB when the system does not say).
double physical_memory_bytes();
/// The default <max_particles>: what 80 % of the machine's memory holds.
double default_max_particles();

std::string_view trim(std::string_view text);
/// A finite number, the whole word (from_chars does not take a leading '+', SDF files sometimes have one).
std::optional<double> parse_number(std::string_view word);
/// Levenshtein's edit distance: the fewest letters inserted, deleted or changed to turn a into b.
std::size_t edit_distance(std::string_view a, std::string_view b);
std::optional<bool> parse_bool(std::string_view word);
std::vector<pugi::xml_node> child_elements(const pugi::xml_node& parent, std::string_view name);

template <typename Words>
std::string join(const Words& words) {
  std::string text;
  for (const auto word : words) {
    if (!text.empty()) text += ", ";
    text += word;
  }
  return text;
}

template <typename Words>
bool contains(const Words& words, std::string_view word) {
  return std::find(words.begin(), words.end(), word) != words.end();
}

/// The name among `candidates` at most two letters off `name` (the nearest), or empty: a misspelling's fix.
template <typename Names>
std::string_view closest_name(std::string_view name, const Names& candidates) {
  std::string_view closest;
  std::size_t best = 3;
  for (const std::string_view candidate : candidates)
    if (const std::size_t distance = edit_distance(name, candidate); distance < best) {
      best = distance;
      closest = candidate;
    }
  return closest;
}

enum class Presence { required, optional };

class SceneReader {
 public:
  SceneReader(const std::string& text, fs::path file) : text_(text), file_(std::move(file)), lines_(text) {}

  Scene read();
  /// The text is a <path> element on its own.
  PathSegments read_path_text();
  /// Parses the text into `document` and returns its root element, which must be <expected_root>
  /// (InputError at the file's line otherwise).
  pugi::xml_node parse_root(pugi::xml_document& document, std::string_view expected_root);
  /// Reads a <materials> file of <material> definitions (the presets). Throws InputError listing every problem.
  std::vector<MaterialEntry> read_material_library();

 private:
  // A <material> as defined, for the checks that need all of them.
  struct DefinedMaterial {
    std::string name;
    SourceLocation where;
    bool used = false;
  };
  struct MaterialUse {
    std::string material;
    std::string user;  // "<fluid_block name="column">"
    SourceLocation where;
  };

  // ---- where and what went wrong ----
  [[nodiscard]] SourceLocation where(const pugi::xml_node& node) const {
    return SourceLocation{file_.string(), lines_.line_at(node.offset_debug())};
  }
  void report(const SourceLocation& location, std::string message) {
    diagnostics_.push_back(Diagnostic{location, std::move(message)});
  }
  void report(const pugi::xml_node& node, std::string message) { report(where(node), std::move(message)); }

  // ---- structure checks ----
  void check_children(const pugi::xml_node& element, std::initializer_list<std::string_view> allowed,
                      std::initializer_list<std::string_view> repeatable = {}) {
    check_children(element, std::span<const std::string_view>(allowed.begin(), allowed.size()),
                   std::span<const std::string_view>(repeatable.begin(), repeatable.size()));
  }
  void check_children(const pugi::xml_node& element, std::span<const std::string_view> allowed,
                      std::span<const std::string_view> repeatable);
  /// The schema's block `block` (schema.hpp) in `element`: its children checked against the rows,
  /// and every row with a setter read into `target`, its line recorded in `fields` under its field.
  /// `values_given`: the target holds every value already (a preset's), so none is required.
  void read_block(const pugi::xml_node& element, std::string_view block, const SchemaTarget& target, FieldLocations* fields = nullptr,
                  bool values_given = false);
  /// One row of the table, read from `element` into `target` (a row outside its block's element, as a
  /// <sensor>'s <update_rate> is).
  void read_row(const pugi::xml_node& element, const SchemaRow& row, const SchemaTarget& target, FieldLocations* fields = nullptr,
                bool values_given = false);
  /// Outside the plugin, an element SDF does not have where M3DP reads is a warning (not an error:
  /// the file may be for a newer SDF), naming the known element it is closest to: a typo such as
  /// <modle> would otherwise delete a model without a word.
  void warn_unknown_children(const pugi::xml_node& element, std::string_view block);
  void check_block_children(const pugi::xml_node& element, std::string_view block);
  void check_attributes(const pugi::xml_node& element, std::initializer_list<std::string_view> allowed);
  pugi::xml_node find_child(const pugi::xml_node& parent, const char* name, Presence presence);
  std::optional<std::string> read_attribute(const pugi::xml_node& element, const char* name, Presence presence);
  void check_unique_name(const pugi::xml_node& element, const std::string& name,
                         std::vector<std::pair<std::string, int>>& seen);

  // ---- values of leaf elements (each returns nothing, having reported why, when the value is wrong) ----
  std::string_view leaf_text(const pugi::xml_node& element, std::initializer_list<std::string_view> allowed_attributes);
  std::optional<double> unit_factor(const pugi::xml_node& element, Quantity quantity);
  std::optional<std::vector<double>> parse_numbers(const pugi::xml_node& element, std::string_view text,
                                                   std::size_t count, std::string_view format);
  std::optional<std::vector<double>> read_numbers(const pugi::xml_node& element, std::size_t count,
                                                  Quantity quantity, std::string_view format);
  std::optional<double> read_scalar(const pugi::xml_node& parent, const char* name, Quantity quantity,
                                    const Limits& limits, Presence presence);
  std::optional<Vec3> read_vector(const pugi::xml_node& parent, const char* name, Quantity quantity,
                                  Presence presence);
  std::optional<Vec3> read_direction(const pugi::xml_node& parent, const char* name, Presence presence);
  std::optional<bool> read_bool(const pugi::xml_node& parent, const char* name);
  /// The value of a keyword element (`<kernel>wendland_c2</kernel>`) from its allowed words; a word not
  /// among them is reported with the list (and `hint`, which explains them, if given).
  template <class Value>
  std::optional<Value> read_keyword(const pugi::xml_node& parent, const char* name,
                                    std::initializer_list<std::pair<std::string_view, Value>> choices,
                                    std::string_view hint = {}) {
    const pugi::xml_node element = parent.child(name);
    if (!element) return std::nullopt;
    const std::string_view word = leaf_text(element, {});
    for (const auto& [choice, value] : choices)
      if (choice == word) return value;
    std::string words;
    for (const auto& choice : choices) words += (words.empty() ? "" : ", ") + std::string(choice.first);
    report(element, fmt::format("<{}> must be one of: {}; got '{}'", name, hint.empty() ? words : std::string(hint), word));
    return std::nullopt;
  }
  std::optional<int> read_int(const pugi::xml_node& parent, const char* name, int minimum);
  /// Whether `si_value` (of <name> at `element`) is a magnitude the quantity may have; reported if not.
  bool check_magnitude(const pugi::xml_node& element, std::string_view name, double si_value, Quantity quantity);
  std::optional<double> read_number_attribute(const pugi::xml_node& element, const char* name, Quantity quantity,
                                              const Limits& limits);
  std::optional<bool> read_bool_attribute(const pugi::xml_node& element, const char* name);
  Pose read_pose(const pugi::xml_node& parent);
  std::optional<Aabb> read_box(const pugi::xml_node& parent);

  // ---- SDF world ----
  void read_world(const pugi::xml_node& world);
  void read_model(const pugi::xml_node& model);
  void read_dynamic_model(const pugi::xml_node& model, const std::string& name);
  void read_include(const pugi::xml_node& include);
  std::optional<fs::path> resolve_model_uri(const pugi::xml_node& uri_element);
  void read_robot_settings(const pugi::xml_node& element);
  std::optional<NozzleMount> read_mount(const pugi::xml_node& element);
  /// Whether the world includes robot `robot_name` with link `link`; reported at `element` if not.
  bool check_robot_link(const pugi::xml_node& element, const std::string& robot_name, const std::string& link);
  /// An SDF <sensor> in a static link at `link_pose`: a camera, or a warning that it is not simulated.
  void read_sensor(const pugi::xml_node& sensor, const Pose& link_pose, const std::string& link_name);
  /// The plugin's <camera name=… type=…>: on a robot link (<mount>) or in the world (<pose>).
  void read_plugin_camera(const pugi::xml_node& element);
  /// A camera's name and type attributes, and its intrinsics from `intrinsics` (SDF <camera>'s
  /// children: horizontal_fov, image, clip, noise) into `settings`.
  bool read_camera_settings(const pugi::xml_node& named, const pugi::xml_node& intrinsics, sensors::CameraSettings& settings);
  std::optional<std::array<float, 3>> read_color(const pugi::xml_node& parent);
  void read_link(const pugi::xml_node& link, const Pose& model_pose, const std::string& model_name,
                 StaticBody& body);
  std::optional<Shape> read_geometry(const pugi::xml_node& geometry);
  std::optional<MeshShape> read_mesh(const pugi::xml_node& mesh);

  // ---- the m3dp plugin ----
  void read_plugin(const pugi::xml_node& plugin);
  void read_solver(const pugi::xml_node& solver);
  void read_material(const pugi::xml_node& material);
  /// A material's values over `base` (a preset) or, without one, from scratch (then density and a
  /// viscosity or rheology are required).
  std::optional<material::Material> read_material_values(const pugi::xml_node& element, const material::Material* base,
                                                         FieldLocations& fields);
  std::optional<material::Rheology> read_rheology(const pugi::xml_node& element, const material::Rheology* base);
  void read_ageing(const pugi::xml_node& element, material::Material& material);
  void read_granular(const pugi::xml_node& element, material::Material& material, FieldLocations& fields);
  void read_air(const pugi::xml_node& air);
  void read_micropolar(const pugi::xml_node& element, material::Material& material);
  void read_elasticity(const pugi::xml_node& element, material::Material& material, FieldLocations& fields);
  /// The presets of data/materials.xml, read on first use (their problems reported at that file's lines).
  const std::vector<MaterialEntry>& material_presets();
  void read_fluid_block(const pugi::xml_node& block);
  void read_print_head(const pugi::xml_node& head);
  std::optional<toolpath::Trajectory> read_path(const pugi::xml_node& path);
  std::optional<PathSegments> read_path_segments(const pugi::xml_node& path);
  std::optional<toolpath::PathSegment> read_path_segment(const pugi::xml_node& element, Real path_speed);
  std::optional<std::vector<toolpath::PathSegment>> read_gcode_segments(const pugi::xml_node& element);
  std::optional<std::vector<toolpath::PathSegment>> read_waypoint_segments(const pugi::xml_node& element);
  /// A file named in the scene (relative paths from the scene's folder); reported at `element` if missing.
  std::optional<fs::path> find_input_file(const pugi::xml_node& element, const std::string& file, std::string_view what);
  std::optional<toolpath::Curve> read_curve(const pugi::xml_node& element);
  pugi::xml_node find_centre(const pugi::xml_node& curve);
  void read_output(const pugi::xml_node& output);
  void read_meshing(const pugi::xml_node& meshing);
  void read_coordinator(const pugi::xml_node& coordinator);
  void check_materials();
  /// The engine's own check of what was read (sph::check_parameters), each problem at its field's line.
  void check_engine_parameters();
  /// Refuses a scene whose particles (fluid blocks, what the print heads extrude, wall samples)
  /// would not fit in memory, at the line of the largest part, before anything is allocated.
  void check_sizes();
  /// Records where `parent`'s child `name` was written as `field` (nothing if it is not there).
  void record_field(FieldLocations& fields, std::string field, const pugi::xml_node& parent, const char* name) {
    const pugi::xml_node child = parent.child(name);
    if (!child) return;
    // The engine's name for it may differ (<max_volume_error> fills volume_tolerance): messages name what was written.
    const std::size_t dot = field.rfind('.');
    if (field.substr(dot == std::string::npos ? 0 : dot + 1) != name) written_as_[field] = name;
    fields.emplace_back(std::move(field), where(child));
  }
  /// Reports `problems` of `parameters`: `phase_entries` (one per phase) and the scene's solver fields say where.
  void report_parameter_problems(const std::vector<sph::ParameterProblem>& problems, const sph::Parameters& parameters,
                                 std::span<const MaterialEntry> phase_entries);

  const std::string& text_;
  fs::path file_;
  LineIndex lines_;
  std::optional<double> max_particles_;  // <solver><max_particles>; none: from the machine's memory
  std::map<std::string, std::string> written_as_;  // an engine field → the element that filled it, where they differ
  Scene scene_;
  std::vector<Diagnostic> diagnostics_;

  std::optional<Real> particle_radius_;  // set when <particle_radius> was valid
  std::optional<Aabb> bounds_;           // set when <bounds> was valid
  std::vector<DefinedMaterial> defined_materials_;
  std::vector<MaterialUse> material_uses_;
  std::optional<std::vector<MaterialEntry>> material_presets_;
  std::vector<std::pair<std::string, int>> model_names_, fluid_block_names_, print_head_names_, robot_setting_names_;
};

}  // namespace m3dp::scene::detail
