#include "m3dp/scene/scene.hpp"
#include "m3dp/scene/schema.hpp"
#include "m3dp/scene/urdf_check.hpp"
#include "m3dp/scene/xml_names.hpp"
#include "m3dp/sph/boundary_sampling.hpp"

#include <fmt/format.h>
#include <unistd.h>
#include <fmt/ranges.h>
#include <pugixml.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <map>
#include <sstream>
#include <span>
#include <string_view>
#include <utility>

#include "m3dp/core/text.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/sph/model.hpp"
#include "m3dp/toolpath/gcode.hpp"
#include "m3dp/toolpath/waypoints.hpp"

namespace m3dp::scene {

namespace {

// Memory a particle takes while the scene runs: 1.05 kB measured on the dam break (peak resident
// set of m3dp bench at 10⁶ fluid and 3.6·10⁵ wall particles, per particle), doubled for what the
// outputs hold (meshing grids, recording buffers). The default <max_particles> is what 80 % of the
// machine's memory holds at that.
constexpr std::size_t kBytesPerParticle = 2048;
// Memory a path point takes (the polyline's point and the trajectory piece made of it), rounded up.
constexpr std::size_t kBytesPerPathPoint = 128;

// Whether a path the user wrote names something: a name the file system refuses (too long, say)
// names nothing, rather than throwing filesystem_error past the reader's messages.
bool path_exists(const std::filesystem::path& path) {
  std::error_code error;
  return std::filesystem::exists(path, error) && !error;
}

double physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page_size = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page_size > 0 ? double(pages) * double(page_size) : 8e9;  // unknown: assume 8 GB
}

double default_max_particles() { return 0.8 * physical_memory_bytes() / double(kBytesPerParticle); }

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------
// Units: every numeric element may say `unit="..."`; values are stored in SI.
// ---------------------------------------------------------------------------------------------


/// Users often have viscosities from tables in kinematic units; these get a message saying how to convert.
bool is_kinematic_viscosity_unit(std::string_view symbol) {
  constexpr std::string_view kKinematic[] = {"m^2/s", "m2/s", "mm^2/s", "mm2/s", "cSt", "St"};
  return std::find(std::begin(kKinematic), std::end(kKinematic), symbol) != std::end(kKinematic);
}


// ---------------------------------------------------------------------------------------------
// Small text helpers
// ---------------------------------------------------------------------------------------------

std::string_view trim(std::string_view text) {
  constexpr std::string_view kBlank = " \t\r\n";
  const auto first = text.find_first_not_of(kBlank);
  if (first == std::string_view::npos) return {};
  const auto last = text.find_last_not_of(kBlank);
  return text.substr(first, last - first + 1);
}

/// A finite number, the whole word (from_chars does not take a leading '+', SDF files sometimes have one).
std::optional<double> parse_number(std::string_view word) {
  if (!word.empty() && word.front() == '+') word.remove_prefix(1);
  double value = 0;
  const auto [end, error] = std::from_chars(word.data(), word.data() + word.size(), value);
  if (error != std::errc() || end != word.data() + word.size() || !std::isfinite(value)) return std::nullopt;
  return value;
}

/// Levenshtein's edit distance: the fewest letters inserted, deleted or changed to turn a into b.
std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

std::optional<bool> parse_bool(std::string_view word) {
  if (word == "true" || word == "1") return true;
  if (word == "false" || word == "0") return false;
  return std::nullopt;
}

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

std::vector<pugi::xml_node> child_elements(const pugi::xml_node& parent, std::string_view name) {
  std::vector<pugi::xml_node> children;
  for (const auto& child : parent.children()) {
    if (child.type() == pugi::node_element && name == child.name()) children.push_back(child);
  }
  return children;
}


enum class Presence { required, optional };

// ---------------------------------------------------------------------------------------------
// The reader: walks the SDF world, fills a Scene, and collects every problem on the way.
// ---------------------------------------------------------------------------------------------

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

// ---- structure checks ----

namespace {
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
}  // namespace

void SceneReader::check_children(const pugi::xml_node& element, std::span<const std::string_view> allowed,
                                 std::span<const std::string_view> repeatable) {
  std::vector<std::pair<std::string_view, int>> first_line_of;
  for (const auto& child : element.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string_view name = child.name();
    if (!contains(allowed, name)) {
      if (allowed.size() == 0) {
        report(child, fmt::format("unknown element <{}> in <{}>; <{}> takes a value, not elements", name,
                                  element.name(), element.name()));
      } else if (const std::string_view closest = closest_name(name, allowed); !closest.empty()) {
        report(child, fmt::format("unknown element <{}> in <{}>; did you mean <{}>? (expected one of: {})", name, element.name(),
                                  closest, join(allowed)));
      } else {
        report(child,
               fmt::format("unknown element <{}> in <{}>; expected one of: {}", name, element.name(), join(allowed)));
      }
      continue;
    }
    if (contains(repeatable, name)) continue;
    const auto first = std::find_if(first_line_of.begin(), first_line_of.end(),
                                    [&](const auto& entry) { return entry.first == name; });
    if (first != first_line_of.end()) {
      report(child, fmt::format("<{}> appears more than once in {}; the first is at line {}", name,
                                describe(element), first->second));
    } else {
      first_line_of.emplace_back(name, where(child).line);
    }
  }
}

void SceneReader::read_block(const pugi::xml_node& element, std::string_view block, const SchemaTarget& target, FieldLocations* fields,
                             bool values_given) {
  check_block_children(element, block);
  for (const SchemaRow* row : schema_block(block)) read_row(element, *row, target, fields, values_given);
}

/// Unknown and repeated children of `element`, by its block's rows: errors at their lines.
void SceneReader::check_block_children(const pugi::xml_node& element, std::string_view block) {
  std::vector<std::string_view> names, repeated;
  for (const SchemaRow* row : schema_block(block)) {
    names.push_back(row->name);
    if (row->repeated) repeated.push_back(row->name);
  }
  check_children(element, names, repeated);
}

void SceneReader::read_row(const pugi::xml_node& element, const SchemaRow& row, const SchemaTarget& target, FieldLocations* fields,
                           bool values_given) {
  const std::string name(row.name);
  const Presence presence = row.required && !values_given ? Presence::required : Presence::optional;
  if (!row.set) {
    if (presence == Presence::required) (void)find_child(element, name.c_str(), presence);
    return;
  }
  std::optional<double> value;
  switch (row.kind) {
    case ValueKind::number: value = read_scalar(element, name.c_str(), row.quantity, row.limits, presence); break;
    case ValueKind::integer:
      if (presence == Presence::required) (void)find_child(element, name.c_str(), presence);
      if (const auto whole = read_int(element, name.c_str(), int(row.limits.at_least.value_or(-2147483648.0)))) {
        if (row.limits.admits(*whole)) value = *whole;
        else report(element.child(name.c_str()), fmt::format("<{}> must be a whole number {}, got {}", name, row.limits.describe(""), *whole));
      }
      break;
    case ValueKind::boolean:
      if (const auto flag = read_bool(element, name.c_str())) value = *flag ? 1 : 0;
      break;
    case ValueKind::keyword:
      if (const pugi::xml_node child = element.child(name.c_str())) {
        const std::string_view word = leaf_text(child, {});
        const auto found = std::find(row.words.begin(), row.words.end(), word);
        if (found != row.words.end())
          value = double(found - row.words.begin());
        else
          report(child, fmt::format("<{}> must be one of: {}; got '{}'", name, row.hint.empty() ? join(row.words) : std::string(row.hint), word));
      }
      break;
    case ValueKind::structure: break;
  }
  if (value) row.set(target, *value);
  if (fields) record_field(*fields, std::string(row.field.empty() ? row.name : row.field), element, name.c_str());
}

void SceneReader::check_attributes(const pugi::xml_node& element, std::initializer_list<std::string_view> allowed) {
  for (const auto& attribute : element.attributes()) {
    if (contains(allowed, attribute.name())) continue;
    if (allowed.size() == 0) {
      report(element, fmt::format("unknown attribute '{}' on <{}>; it takes none", attribute.name(), element.name()));
    } else if (const std::string_view closest = closest_name(attribute.name(), allowed); !closest.empty()) {
      report(element, fmt::format("unknown attribute '{}' on <{}>; did you mean '{}'? (expected one of: {})", attribute.name(),
                                  element.name(), closest, join(allowed)));
    } else {
      report(element, fmt::format("unknown attribute '{}' on <{}>; expected one of: {}", attribute.name(),
                                  element.name(), join(allowed)));
    }
  }
}

pugi::xml_node SceneReader::find_child(const pugi::xml_node& parent, const char* name, Presence presence) {
  const pugi::xml_node child = parent.child(name);
  if (!child && presence == Presence::required) {
    report(parent, fmt::format("missing required <{}> in {}", name, describe(parent)));
  }
  return child;
}

std::optional<std::string> SceneReader::read_attribute(const pugi::xml_node& element, const char* name,
                                                       Presence presence) {
  const auto attribute = element.attribute(name);
  const std::string_view value = trim(attribute.value());
  if (!attribute || value.empty()) {
    if (presence == Presence::required) {
      report(element, fmt::format("missing required attribute {}=\"...\" on {}", name, describe(element)));
    }
    return std::nullopt;
  }
  return std::string(value);
}

void SceneReader::check_unique_name(const pugi::xml_node& element, const std::string& name,
                                    std::vector<std::pair<std::string, int>>& seen) {
  const auto first = std::find_if(seen.begin(), seen.end(), [&](const auto& entry) { return entry.first == name; });
  if (first != seen.end()) {
    report(element, fmt::format("{} is defined twice; the first is at line {}", describe(element), first->second));
  } else {
    seen.emplace_back(name, where(element).line);
  }
}

// ---- values ----

/// The trimmed text of an element that holds a value, after checking it has no child elements.
std::string_view SceneReader::leaf_text(const pugi::xml_node& element,
                                        std::initializer_list<std::string_view> allowed_attributes) {
  check_children(element, {});
  check_attributes(element, allowed_attributes);
  return trim(element.child_value());
}

std::optional<double> SceneReader::unit_factor(const pugi::xml_node& element, Quantity quantity) {
  const auto unit_attribute = element.attribute("unit");
  if (!unit_attribute) return 1.0;
  const std::string_view symbol = trim(unit_attribute.value());
  const QuantityInfo info = quantity_info(quantity);
  if (quantity == Quantity::plain_number) {
    report(element, fmt::format("<{}> is a plain number and takes no unit, got unit=\"{}\"", element.name(), symbol));
    return std::nullopt;
  }
  for (const Unit& unit : info.units) {
    if (unit.symbol == symbol) return unit.to_si;
  }
  if (quantity == Quantity::dynamic_viscosity && is_kinematic_viscosity_unit(symbol)) {
    report(element, fmt::format("<{}> is dynamic viscosity in Pa*s; '{}' is a kinematic viscosity unit (multiply by "
                                "density to convert)",
                                element.name(), symbol));
    return std::nullopt;
  }
  std::string expected;
  for (const Unit& unit : info.units) expected += (expected.empty() ? "" : ", ") + std::string(unit.symbol);
  report(element, fmt::format("unit '{}' on <{}> is not a {} unit; expected one of: {}", symbol, element.name(),
                              info.name, expected));
  return std::nullopt;
}

std::optional<std::vector<double>> SceneReader::parse_numbers(const pugi::xml_node& element, std::string_view text,
                                                              std::size_t count, std::string_view format) {
  const auto words = split_words(text);
  std::vector<double> values;
  for (const auto word : words) {
    const auto value = parse_number(word);
    if (!value) break;
    values.push_back(*value);
  }
  if (values.size() != count || words.size() != count) {
    report(element, fmt::format("expected {} numbers ({}) in <{}>, got '{}'", count, format, element.name(), text));
    return std::nullopt;
  }
  return values;
}

std::optional<std::vector<double>> SceneReader::read_numbers(const pugi::xml_node& element, std::size_t count,
                                                             Quantity quantity, std::string_view format) {
  const auto text = leaf_text(element, {"unit"});
  const auto factor = unit_factor(element, quantity);
  auto values = parse_numbers(element, text, count, format);
  if (!values || !factor) return std::nullopt;
  for (double& value : *values) {
    value *= *factor;
    if (!check_magnitude(element, element.name(), value, quantity)) return std::nullopt;
  }
  return values;
}

bool SceneReader::check_magnitude(const pugi::xml_node& element, std::string_view name, double si_value, Quantity quantity) {
  const Magnitude bounds = magnitude(quantity);
  const QuantityInfo info = quantity_info(quantity);
  const double size = std::abs(si_value);
  const std::string unit = info.si_symbol.empty() ? "" : fmt::format(" {}", info.si_symbol);
  if (size > bounds.largest) {
    report(element, fmt::format("<{}> of {:g}{} is beyond any {} M3DP simulates (at most {:g}{})", name, si_value, unit,
                                info.name, bounds.largest, unit));
    return false;
  }
  if (size != 0 && size < bounds.smallest) {
    report(element, fmt::format("<{}> of {:g}{} is below the smallest {} M3DP resolves ({:g}{}); write 0 if it is none", name,
                                si_value, unit, info.name, bounds.smallest, unit));
    return false;
  }
  return true;
}

std::optional<double> SceneReader::read_scalar(const pugi::xml_node& parent, const char* name, Quantity quantity,
                                               const Limits& limits, Presence presence) {
  const pugi::xml_node element = find_child(parent, name, presence);
  if (!element) return std::nullopt;
  const auto text = leaf_text(element, {"unit"});
  const auto factor = unit_factor(element, quantity);
  const auto value = parse_number(text);
  if (!value) {
    report(element, fmt::format("expected a number in <{}>, got '{}'", name, text));
    return std::nullopt;
  }
  if (!factor) return std::nullopt;
  const double si_value = *value * *factor;
  if (!limits.admits(si_value)) {
    const auto unit = element.attribute("unit");
    const std::string as_written = unit ? fmt::format("{} {}", text, trim(unit.value())) : std::string(text);
    report(element, fmt::format("<{}> must be {}, got {}", name, limits.describe(quantity_info(quantity).si_symbol),
                                as_written));
    return std::nullopt;
  }
  if (!check_magnitude(element, name, si_value, quantity)) return std::nullopt;
  return si_value;
}

std::optional<Vec3> SceneReader::read_vector(const pugi::xml_node& parent, const char* name, Quantity quantity,
                                             Presence presence) {
  const pugi::xml_node element = find_child(parent, name, presence);
  if (!element) return std::nullopt;
  const auto values = read_numbers(element, 3, quantity, "x y z");
  if (!values) return std::nullopt;
  return Vec3(Real((*values)[0]), Real((*values)[1]), Real((*values)[2]));
}

std::optional<Vec3> SceneReader::read_direction(const pugi::xml_node& parent, const char* name, Presence presence) {
  const auto direction = read_vector(parent, name, Quantity::plain_number, presence);
  if (!direction) return std::nullopt;
  if (direction->norm() == 0) {
    report(parent.child(name), fmt::format("<{}> must not be the zero vector", name));
    return std::nullopt;
  }
  return direction->normalized();
}

std::optional<bool> SceneReader::read_bool(const pugi::xml_node& parent, const char* name) {
  const pugi::xml_node element = parent.child(name);
  if (!element) return std::nullopt;
  const auto text = leaf_text(element, {});
  const auto value = parse_bool(text);
  if (!value) report(element, fmt::format("<{}> must be true or false (or 1 or 0), got '{}'", name, text));
  return value;
}

std::optional<int> SceneReader::read_int(const pugi::xml_node& parent, const char* name, int minimum) {
  const pugi::xml_node element = parent.child(name);
  if (!element) return std::nullopt;
  const auto text = leaf_text(element, {});
  int value = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
  if (error != std::errc() || end != text.data() + text.size() || value < minimum) {
    report(element, fmt::format("<{}> must be a whole number >= {}, got '{}'", name, minimum, text));
    return std::nullopt;
  }
  return value;
}

std::optional<double> SceneReader::read_number_attribute(const pugi::xml_node& element, const char* name,
                                                         Quantity quantity, const Limits& limits) {
  const auto attribute = element.attribute(name);
  if (!attribute) return std::nullopt;
  const std::string_view text = trim(attribute.value());
  const auto value = parse_number(text);
  const QuantityInfo info = quantity_info(quantity);
  if (!value) {
    report(element, fmt::format("attribute {}=\"{}\" on <{}> must be a number ({} in {})", name, text,
                                element.name(), info.name, info.si_symbol));
    return std::nullopt;
  }
  if (!limits.admits(*value)) {
    report(element, fmt::format("attribute {} on <{}> must be {}, got {}", name, element.name(),
                                limits.describe(info.si_symbol), text));
    return std::nullopt;
  }
  if (!check_magnitude(element, fmt::format("{} {}", element.name(), name), *value, quantity)) return std::nullopt;
  return value;
}

std::optional<bool> SceneReader::read_bool_attribute(const pugi::xml_node& element, const char* name) {
  const auto attribute = element.attribute(name);
  if (!attribute) return std::nullopt;
  const std::string_view text = trim(attribute.value());
  const auto value = parse_bool(text);
  if (!value) {
    report(element, fmt::format("attribute {}=\"{}\" on <{}> must be true or false (or 1 or 0)", name, text,
                                element.name()));
  }
  return value;
}

Pose SceneReader::read_pose(const pugi::xml_node& parent) {
  const pugi::xml_node element = parent.child("pose");
  if (!element) return Pose{};
  // Pose values mix lengths and angles, so they take no unit attribute; SDF's own attributes say how to read them.
  const std::string_view text = leaf_text(element, {"relative_to", "degrees", "rotation_format"});
  // Frames named in relative_to need the SDF frame graph; only poses relative to the parent are supported.
  if (!trim(element.attribute("relative_to").value()).empty()) {
    report(element, "<pose relative_to=\"...\"> is not supported yet; give the pose relative to the parent element");
  }
  const bool degrees = read_bool_attribute(element, "degrees").value_or(false);
  const std::string_view rotation_format = trim(element.attribute("rotation_format").value());
  if (rotation_format == "quat_xyzw") {
    const auto values = parse_numbers(element, text, 7, "x y z qx qy qz qw");
    if (!values) return Pose{};
    const auto& v = *values;
    for (int k = 0; k < 7; ++k)
      if (!check_magnitude(element, "pose", v[k], k < 3 ? Quantity::length : Quantity::plain_number)) return Pose{};
    const Quat orientation{Real(v[6]), Real(v[3]), Real(v[4]), Real(v[5])};  // Eigen takes w first
    if (orientation.norm() == 0) {
      report(element, "<pose> quaternion must not be zero");
      return Pose{};
    }
    return Pose{Vec3(Real(v[0]), Real(v[1]), Real(v[2])), orientation.normalized()};
  }
  if (!rotation_format.empty() && rotation_format != "euler_rpy") {
    report(element, fmt::format("<pose rotation_format=\"{}\"> is not known; expected euler_rpy or quat_xyzw",
                                rotation_format));
    return Pose{};
  }
  const auto values = parse_numbers(element, text, 6, "x y z roll pitch yaw");
  if (!values) return Pose{};
  const auto& v = *values;
  for (int k = 0; k < 6; ++k)
    if (!check_magnitude(element, "pose", v[k], k < 3 ? Quantity::length : Quantity::angle)) return Pose{};
  const double to_radians = degrees ? kRadiansPerDegree : 1.0;
  return Pose::from_xyz_rpy(Real(v[0]), Real(v[1]), Real(v[2]), Real(v[3] * to_radians), Real(v[4] * to_radians),
                            Real(v[5] * to_radians));
}

/// <min> and <max> children: a box with min < max on every axis.
std::optional<Aabb> SceneReader::read_box(const pugi::xml_node& parent) {
  const auto min = read_vector(parent, "min", Quantity::length, Presence::required);
  const auto max = read_vector(parent, "max", Quantity::length, Presence::required);
  if (!min || !max) return std::nullopt;
  if (((*min).array() >= (*max).array()).any()) {
    report(parent, fmt::format("<min> must be below <max> on every axis in {}, got min ({} {} {}) and max ({} {} {})",
                               describe(parent), (*min).x(), (*min).y(), (*min).z(), (*max).x(), (*max).y(),
                               (*max).z()));
    return std::nullopt;
  }
  return Aabb{*min, *max};
}

// ---- SDF world ----

pugi::xml_node SceneReader::parse_root(pugi::xml_document& document, std::string_view expected_root) {
  const pugi::xml_parse_result parsed =
      document.load_buffer(text_.data(), text_.size(), pugi::parse_default, pugi::encoding_utf8);
  if (!parsed) {
    throw InputError(SourceLocation{file_.string(), lines_.line_at(parsed.offset)},
                     fmt::format("the file is not well-formed XML: {}", parsed.description()));
  }
  const pugi::xml_node root = document.document_element();
  if (std::string_view(root.name()) != expected_root) {
    throw InputError(where(root), fmt::format("expected the root element <{}>, got <{}>", expected_root, root.name()));
  }
  return root;
}

Scene SceneReader::read() {
  pugi::xml_document document;
  const pugi::xml_node sdf = parse_root(document, "sdf");
  scene_.file = file_;
  const auto worlds = child_elements(sdf, "world");
  if (worlds.empty()) {
    report(sdf, "missing <world> in <sdf>; a scene is an SDF world");
  } else {
    for (std::size_t extra = 1; extra < worlds.size(); ++extra) {
      report(worlds[extra], fmt::format("only one <world> per scene file; the first is at line {}",
                                        where(worlds.front()).line));
    }
    read_world(worlds.front());
  }

  if (!diagnostics_.empty()) {
    // The scene's own problems first, by line; then those of other files (presets) it uses.
    std::stable_sort(diagnostics_.begin(), diagnostics_.end(), [&](const Diagnostic& a, const Diagnostic& b) {
      const bool a_elsewhere = a.location.file != file_.string(), b_elsewhere = b.location.file != file_.string();
      return a_elsewhere != b_elsewhere ? b_elsewhere : a.location.line < b.location.line;
    });
    throw InputError(std::move(diagnostics_));
  }
  return std::move(scene_);
}

void SceneReader::warn_unknown_children(const pugi::xml_node& element, std::string_view block) {
  std::vector<std::string_view> known;
  for (const SchemaRow* row : schema_block(block)) known.push_back(row->name);
  for (const auto& child : element.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string_view name = child.name();
    if (std::find(known.begin(), known.end(), name) != known.end()) continue;
    const std::string_view closest = closest_name(name, known);
    scene_.warnings.push_back({where(child), closest.empty()
                                                 ? fmt::format("unknown element <{}> in <{}>, ignored: SDF has no such element there", name, element.name())
                                                 : fmt::format("unknown element <{}> in <{}>, ignored; did you mean <{}>?", name, element.name(), closest)});
  }
}

void SceneReader::read_world(const pugi::xml_node& world) {
  scene_.world_name = world.attribute("name").value();
  warn_unknown_children(world, "world");
  if (const auto gravity = read_vector(world, "gravity", Quantity::acceleration, Presence::optional)) {
    scene_.solver.gravity = *gravity;
  }

  std::vector<pugi::xml_node> m3dp_plugins;
  for (const auto& child : world.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string_view name = child.name();
    if (name == "model") {
      read_model(child);
    } else if (name == "include") {
      read_include(child);
    } else if (name == "plugin" && is_m3dp_plugin(child)) {
      m3dp_plugins.push_back(child);
    }
    // Other SDF world elements (physics, scene, light, other plugins, ...) are valid SDF that M3DP does not use.
  }

  if (m3dp_plugins.empty()) {
    report(world, fmt::format("missing <plugin name=\"m3dp\" filename=\"m3dp\"> in {}; it holds the solver, "
                              "materials and fluid",
                              describe(world)));
    return;
  }
  for (std::size_t extra = 1; extra < m3dp_plugins.size(); ++extra) {
    report(m3dp_plugins[extra], fmt::format("more than one m3dp <plugin> in the world; the first is at line {}",
                                            where(m3dp_plugins.front()).line));
  }
  read_plugin(m3dp_plugins.front());
}

void SceneReader::read_model(const pugi::xml_node& model) {
  StaticBody body;
  body.name = read_attribute(model, "name", Presence::required).value_or("");
  body.where = where(model);
  if (!body.name.empty()) check_unique_name(model, body.name, model_names_);
  warn_unknown_children(model, "model");
  if (!read_bool(model, "static").value_or(false)) {
    read_dynamic_model(model, body.name);
    return;
  }
  const Pose model_pose = read_pose(model);
  for (const auto& child : model.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string_view name = child.name();
    if (name == "link") {
      read_link(child, model_pose, body.name, body);
    } else if (name == "model") {
      report(child, "nested <model> is not supported yet; put each model directly in the <world>");
    } else if (name == "include") {
      report(child, "<include> is not supported yet; copy the model into the world");
    }
    // Joints, plugins and the like are valid SDF with no meaning for a static boundary.
  }
  scene_.bodies.push_back(std::move(body));
}

void SceneReader::read_dynamic_model(const pugi::xml_node& model, const std::string& name) {
  DynamicBody body;
  body.name = name;
  body.where = where(model);
  const auto links = child_elements(model, "link");
  if (links.size() != 1) {
    report(model, fmt::format("{}: a dynamic (not <static>) model needs exactly one <link>, found {}; M3DP has no "
                              "jointed SDF models yet (robots come from URDF through <include>)",
                              describe(model), links.size()));
    return;
  }
  for (const auto& child : model.children())
    if (child.type() == pugi::node_element && (std::string_view(child.name()) == "model" || std::string_view(child.name()) == "include"))
      report(child, fmt::format("<{}> inside a dynamic model is not supported", child.name()));
  const pugi::xml_node link = links.front();
  warn_unknown_children(link, "link");
  body.pose = read_pose(model) * read_pose(link);
  const pugi::xml_node inertial = link.child("inertial");
  if (!inertial) {
    report(link, fmt::format("{} of dynamic model '{}' needs <inertial><mass>...</mass></inertial> (kg)", describe(link), name));
  } else {
    if (const auto mass = read_scalar(inertial, "mass", Quantity::mass, Limits::positive(), Presence::required))
      body.mass = *mass;
    if (inertial.child("pose")) report(inertial.child("pose"), "an <inertial><pose> is not supported yet: the centre of mass is the link origin");
    if (const pugi::xml_node inertia = inertial.child("inertia")) {
      Mat3 tensor = Mat3::Zero();
      bool valid = true;
      const char* names[3][3] = {{"ixx", "ixy", "ixz"}, {"ixy", "iyy", "iyz"}, {"ixz", "iyz", "izz"}};
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
          const bool diagonal = r == c;
          const auto value = read_scalar(inertia, names[r][c], Quantity::plain_number,
                                         diagonal ? Limits::positive() : Limits::any(),
                                         diagonal ? Presence::required : Presence::optional);
          if (diagonal && !value) valid = false;
          tensor(r, c) = Real(value.value_or(0));
        }
      if (valid) body.inertia = tensor;
    }
  }
  for (const auto& collision : child_elements(link, "collision")) {
    warn_unknown_children(collision, "collision");
    const std::string collision_name = read_attribute(collision, "name", Presence::required).value_or("");
    const pugi::xml_node geometry = find_child(collision, "geometry", Presence::required);
    if (!geometry) continue;
    if (auto shape = read_geometry(geometry)) {
      if (std::holds_alternative<PlaneShape>(*shape)) {
        report(geometry, "a <plane> cannot move: put it in a <static> model");
        continue;
      }
      body.collisions.push_back(CollisionShape{fmt::format("{}/{}/{}", name, link.attribute("name").value(), collision_name),
                                               std::move(*shape), read_pose(collision), where(collision)});
    }
  }
  if (body.collisions.empty() && link.child("collision").empty() && inertial) {
    report(link, fmt::format("dynamic model '{}' has no <collision>: the world and the fluid would not see it", name));
  }
  scene_.dynamic_bodies.push_back(std::move(body));
}

std::optional<fs::path> SceneReader::resolve_model_uri(const pugi::xml_node& uri_element) {
  const std::string uri(trim(uri_element.child_value()));
  constexpr std::string_view kModel = "model://", kFile = "file://";
  if (uri.starts_with(kModel)) {
    const std::string name = uri.substr(kModel.size());
    std::vector<std::string> looked;
    for (const fs::path& folder : model_search_path(file_)) {
      for (const fs::path& candidate : {folder / name / (name + ".urdf"), folder / name / "model.urdf"}) {
        if (path_exists(candidate)) {
          scene_.input_files.push_back(candidate);
          return candidate;
        }
        looked.push_back(candidate.string());
      }
    }
    report(uri_element, fmt::format("'{}' not found; looked for {}", uri, fmt::join(looked, ", ")));
    return std::nullopt;
  }
  fs::path path(uri.starts_with(kFile) ? uri.substr(kFile.size()) : uri);
  if (path.is_relative()) path = file_.parent_path() / path;
  if (!path_exists(path)) {
    report(uri_element, fmt::format("'{}' not found (looked for {})", uri, path.string()));
    return std::nullopt;
  }
  scene_.input_files.push_back(path);
  return path;
}

void SceneReader::read_include(const pugi::xml_node& include) {
  check_block_children(include, "include");
  const pugi::xml_node uri_element = find_child(include, "uri", Presence::required);
  if (!uri_element) return;
  const auto file = resolve_model_uri(uri_element);
  if (!file) return;
  if (file->extension() != ".urdf") {
    report(uri_element, fmt::format("'{}' is not a URDF file; <include> takes URDF robots for now (SDF models go "
                                    "directly into the world as <model>)",
                                    file->string()));
    return;
  }
  RobotInclude robot;
  robot.urdf_file = *file;
  robot.pose = read_pose(include);
  robot.where = where(include);
  // The URDF is read here too, so that `m3dp validate` reports its XML errors with its own lines
  // and the scene's checks (link and joint names) need no physics engine.
  const std::string text = read_text_file(*file, "URDF file");
  pugi::xml_document urdf;
  const pugi::xml_parse_result parsed = urdf.load_buffer(text.data(), text.size());
  if (!parsed) {
    report(SourceLocation{file->string(), LineIndex(text).line_at(parsed.offset)},
           fmt::format("the URDF is not well-formed XML: {}", parsed.description()));
    return;
  }
  const pugi::xml_node root = urdf.document_element();
  if (std::string_view(root.name()) != "robot") {
    report(SourceLocation{file->string(), LineIndex(text).line_at(root.offset_debug())},
           fmt::format("expected the root element <robot> in a URDF, got <{}>", root.name()));
    return;
  }
  const LineIndex urdf_lines(text);
  const auto urdf_problems = check_urdf(root, *file, [&](std::ptrdiff_t offset) { return urdf_lines.line_at(offset); });
  for (const Diagnostic& problem : urdf_problems) report(problem.location, problem.message);
  if (!urdf_problems.empty()) return;
  const std::string urdf_name = root.attribute("name").value();
  if (const pugi::xml_node name_element = include.child("name")) {
    robot.name = std::string(trim(name_element.child_value()));
  } else {
    robot.name = urdf_name;
  }
  if (robot.name.empty()) {
    report(include, "the robot has no name: give the <include> a <name> or the URDF's <robot> a name=\"...\"");
    return;
  }
  check_unique_name(include, robot.name, model_names_);
  for (const auto& link : root.children("link")) robot.link_names.emplace_back(link.attribute("name").value());
  // Colours for cameras: a link's first visual material, given there or by name at the robot's top level.
  std::map<std::string, std::string> named_colors;
  for (const auto& material : root.children("material"))
    if (const auto color = material.child("color")) named_colors[material.attribute("name").value()] = color.attribute("rgba").value();
  for (const auto& link : root.children("link")) {
    const pugi::xml_node material = link.child("visual").child("material");
    if (!material) continue;
    std::string rgba = material.child("color").attribute("rgba").value();
    if (rgba.empty() && named_colors.contains(material.attribute("name").value())) rgba = named_colors[material.attribute("name").value()];
    std::istringstream values(rgba);
    std::array<float, 3> color{};
    if (values >> color[0] >> color[1] >> color[2] && std::all_of(color.begin(), color.end(), [](float c) { return c >= 0 && c <= 1; }))
      robot.link_colors.emplace_back(link.attribute("name").value(), color);
  }
  for (const auto& joint : root.children("joint")) {
    const std::string_view type = joint.attribute("type").value();
    if (type == "revolute" || type == "continuous" || type == "prismatic") robot.joint_names.emplace_back(joint.attribute("name").value());
  }
  scene_.robots.push_back(std::move(robot));
}

void SceneReader::read_robot_settings(const pugi::xml_node& element) {
  check_attributes(element, {"name"});
  read_block(element, "robot", &scene_);
  // The mobile base's own values are checked whether or not the robot is found: every error at once.
  const pugi::xml_node base = element.child("mobile_base");
  MobileBase mobile;
  const std::size_t problems_before = diagnostics_.size();
  if (base) {
    check_attributes(base, {});
    read_block(base, "mobile_base", &mobile);
    mobile.where = where(base);
  }
  bool base_valid = diagnostics_.size() == problems_before;
  const auto name = read_attribute(element, "name", Presence::required);
  if (!name) return;
  check_unique_name(element, *name, robot_setting_names_);
  auto robot = std::find_if(scene_.robots.begin(), scene_.robots.end(), [&](const RobotInclude& r) { return r.name == *name; });
  if (robot == scene_.robots.end()) {
    std::vector<std::string> names;
    for (const auto& r : scene_.robots) names.push_back(r.name);
    report(element, fmt::format("<robot name=\"{}\">: no robot of that name is included in the world{}", *name,
                                names.empty() ? std::string("; add <include><uri>model://...</uri></include>")
                                              : fmt::format(" (robots: {})", fmt::join(names, ", "))));
    return;
  }
  auto is_joint = [&](const std::string& joint) {
    return std::find(robot->joint_names.begin(), robot->joint_names.end(), joint) != robot->joint_names.end();
  };
  for (const auto& joint : child_elements(element, "joint")) {
    const auto joint_name = read_attribute(joint, "name", Presence::required);
    if (!joint_name) continue;
    if (!is_joint(*joint_name)) {
      report(joint, fmt::format("robot '{}' has no movable joint '{}'; its joints: {}", robot->name, *joint_name,
                                fmt::join(robot->joint_names, ", ")));
      continue;
    }
    const auto text = leaf_text(joint, {"name", "unit"});
    const auto factor = unit_factor(joint, Quantity::angle);
    const auto value = parse_numbers(joint, text, 1, "an initial joint position (rad, or unit=\"deg\")");
    if (value && factor) robot->initial_joint_positions.emplace_back(*joint_name, value->front() * *factor);
  }
  if (!base) return;
  for (const auto& [tag, target] : {std::pair{"left_wheel", &mobile.left_wheel_joint}, std::pair{"right_wheel", &mobile.right_wheel_joint}}) {
    const pugi::xml_node wheel = base.child(tag);
    if (!wheel) continue;
    *target = std::string(leaf_text(wheel, {}));
    if (!is_joint(*target)) {
      report(wheel, fmt::format("robot '{}' has no movable joint '{}' for a wheel; its joints: {}", robot->name, *target,
                                fmt::join(robot->joint_names, ", ")));
      base_valid = false;
    }
  }
  if (const pugi::xml_node path = base.child("path")) {
    mobile.path = read_path(path);
    if (!mobile.path) base_valid = false;
  }
  if (base_valid) robot->mobile_base = std::move(mobile);
}

std::optional<NozzleMount> SceneReader::read_mount(const pugi::xml_node& element) {
  check_attributes(element, {"robot", "link"});
  NozzleMount mount;
  read_block(element, "mount", &mount);
  mount.where = where(element);
  const auto robot_name = read_attribute(element, "robot", Presence::required);
  const auto link = read_attribute(element, "link", Presence::required);
  mount.offset = read_pose(element);
  if (!robot_name || !link || !check_robot_link(element, *robot_name, *link)) return std::nullopt;
  mount.robot = *robot_name;
  mount.link = *link;
  return mount;
}

bool SceneReader::check_robot_link(const pugi::xml_node& element, const std::string& robot_name, const std::string& link) {
  const RobotInclude* robot = scene_.find_robot(robot_name);
  if (!robot) {
    report(element, fmt::format("<mount robot=\"{}\">: no robot of that name is included in the world", robot_name));
    return false;
  }
  if (std::find(robot->link_names.begin(), robot->link_names.end(), link) == robot->link_names.end()) {
    report(element, fmt::format("robot '{}' has no link '{}'; its links: {}", robot->name, link, fmt::join(robot->link_names, ", ")));
    return false;
  }
  return true;
}

// ---- cameras ----

bool SceneReader::read_camera_settings(const pugi::xml_node& named, const pugi::xml_node& intrinsics,
                                       sensors::CameraSettings& settings) {
  bool valid = true;
  if (const auto name = read_attribute(named, "name", Presence::required)) {
    settings.name = *name;
    const auto earlier = std::find_if(scene_.cameras.begin(), scene_.cameras.end(),
                                      [&](const CameraEntry& camera) { return camera.settings.name == *name; });
    if (earlier != scene_.cameras.end()) {
      report(named, fmt::format("a camera '{}' is already defined at line {}", *name, earlier->where.line));
      valid = false;
    }
  } else {
    valid = false;
  }
  const auto type = read_attribute(named, "type", Presence::required).value_or("");
  if (type == "camera") settings.type = sensors::CameraType::camera;
  else if (type == "depth_camera" || type == "depth") settings.type = sensors::CameraType::depth_camera;
  else if (type == "rgbd_camera" || type == "rgbd") settings.type = sensors::CameraType::rgbd_camera;
  else {
    if (!type.empty()) report(named, fmt::format("camera type '{}' is not one M3DP renders; expected camera, depth_camera or rgbd_camera", type));
    valid = false;
  }
  // The table's values (schema.cpp). The plugin's <camera> has had its own rows read (read_block);
  // SDF keeps <update_rate> on the <sensor> and <horizontal_fov> in its <camera>.
  const std::size_t problems_before = diagnostics_.size();
  if (named != intrinsics) read_row(named, schema_row("camera", "update_rate"), &settings);
  if (intrinsics) {
    if (named != intrinsics) read_row(intrinsics, schema_row("camera", "horizontal_fov"), &settings);
    if (const pugi::xml_node image = intrinsics.child("image")) read_block(image, "image", &settings);
    if (const pugi::xml_node clip = intrinsics.child("clip")) {
      read_block(clip, "clip", &settings);
      if (diagnostics_.size() == problems_before && settings.far <= settings.near)
        report(clip, fmt::format("<far> ({} m) must be beyond <near> ({} m)", settings.far, settings.near));
    }
    if (const pugi::xml_node noise = intrinsics.child("noise")) {
      check_attributes(noise, {"type"});
      const std::string kind = noise.attribute("type") ? noise.attribute("type").value() : std::string(trim(noise.child_value("type")));
      if (kind != "gaussian" && kind != "none") report(noise, fmt::format("camera noise '{}' is not simulated; expected gaussian (or none)", kind));
      sensors::CameraSettings read = settings;
      read_block(noise, "noise", &read);
      if (kind == "gaussian") settings.noise = read.noise;
    }
  }
  return valid && diagnostics_.size() == problems_before;
}

void SceneReader::read_sensor(const pugi::xml_node& sensor, const Pose& link_pose, const std::string& link_name) {
  const std::string type = sensor.attribute("type").value();
  if (type != "camera" && type != "depth_camera" && type != "depth" && type != "rgbd_camera" && type != "rgbd") {
    scene_.warnings.push_back({where(sensor), fmt::format("<sensor type=\"{}\"> in link '{}' is not simulated (M3DP renders "
                                                          "camera, depth_camera and rgbd_camera); ignored", type, link_name)});
    return;
  }
  check_attributes(sensor, {"name", "type"});
  // SDF's children of a sensor M3DP reads, and those it accepts with no effect on the images.
  check_children(sensor, {"pose", "update_rate", "camera", "always_on", "visualize", "topic", "enable_metrics", "frame", "plugin"},
                 {"plugin"});
  const pugi::xml_node camera = sensor.child("camera");
  if (camera)
    check_children(camera, {"horizontal_fov", "image", "clip", "noise", "save", "depth_camera", "distortion", "lens",
                            "visibility_mask", "optical_frame_id", "camera_info_topic", "trigger_topic", "triggered", "pose"});
  CameraEntry entry;
  entry.where = where(sensor);
  if (!read_camera_settings(sensor, camera, entry.settings)) return;
  entry.settings.pose = link_pose * read_pose(sensor) * (camera ? read_pose(camera) : Pose{});
  scene_.cameras.push_back(std::move(entry));
}

void SceneReader::read_plugin_camera(const pugi::xml_node& element) {
  check_attributes(element, {"name", "type"});
  CameraEntry entry;
  entry.where = where(element);
  // The table checks the children and reads <shadows>; read_camera_settings reads the rest.
  const std::size_t problems_before = diagnostics_.size();
  read_block(element, "camera", &entry.settings);
  bool valid = read_camera_settings(element, element, entry.settings) && diagnostics_.size() == problems_before;
  if (const pugi::xml_node cloud = element.child("point_cloud")) {
    // <point_cloud frame="optical|world">true</point_cloud>
    const std::string_view text = leaf_text(cloud, {"frame"});
    const auto enabled = parse_bool(text);
    const std::string frame = cloud.attribute("frame").as_string("optical");
    if (!enabled) {
      report(cloud, fmt::format("<point_cloud> must be true or false (or 1 or 0), got '{}'", text));
      valid = false;
    } else if (frame != "optical" && frame != "world") {
      report(cloud, fmt::format("<point_cloud frame=\"{}\">: expected optical or world", frame));
      valid = false;
    } else if (*enabled) {
      if (!sensors::has_depth(entry.settings.type)) {
        report(cloud, "a point cloud needs depth: the camera's type must be depth_camera or rgbd_camera");
        valid = false;
      }
      entry.settings.point_cloud = frame == "world" ? sensors::CameraSettings::PointCloud::world : sensors::CameraSettings::PointCloud::optical;
    }
  }
  if (const pugi::xml_node mount = element.child("mount")) {
    check_attributes(mount, {"robot", "link"});
    check_children(mount, {"pose"});  // the camera's mount: only its pose (a print head's <mount> has a barrel too)
    if (element.child("pose")) {
      report(element.child("pose"), "a mounted camera's <pose> goes inside its <mount> (in the link's frame)");
      valid = false;
    }
    const auto robot = read_attribute(mount, "robot", Presence::required);
    const auto link = read_attribute(mount, "link", Presence::required);
    if (!robot || !link || !check_robot_link(mount, *robot, *link)) return;
    entry.settings.robot = *robot;
    entry.settings.link = *link;
    entry.settings.pose = read_pose(mount);
  } else {
    entry.settings.pose = read_pose(element);
  }
  entry.in_plugin = true;
  if (valid) scene_.cameras.push_back(std::move(entry));
}

std::optional<std::array<float, 3>> SceneReader::read_color(const pugi::xml_node& parent) {
  const pugi::xml_node element = parent.child("color");
  if (!element) return std::nullopt;
  const auto values = parse_numbers(element, leaf_text(element, {}), 3, "r g b");
  if (!values) return std::nullopt;
  std::array<float, 3> color{};
  for (std::size_t c = 0; c < 3; ++c) {
    if (!((*values)[c] >= 0 && (*values)[c] <= 1)) {
      report(element, fmt::format("<color> is red, green and blue in [0, 1], got '{}'", leaf_text(element, {})));
      return std::nullopt;
    }
    color[c] = static_cast<float>((*values)[c]);
  }
  return color;
}

void SceneReader::read_link(const pugi::xml_node& link, const Pose& model_pose, const std::string& model_name,
                            StaticBody& body) {
  const std::string link_name = read_attribute(link, "name", Presence::required).value_or("");
  const Pose link_pose = model_pose * read_pose(link);
  warn_unknown_children(link, "link");
  for (const auto& collision : child_elements(link, "collision")) {
    warn_unknown_children(collision, "collision");
    const std::string collision_name = read_attribute(collision, "name", Presence::required).value_or("");
    const Pose collision_pose = link_pose * read_pose(collision);
    const pugi::xml_node geometry = find_child(collision, "geometry", Presence::required);
    if (!geometry) continue;
    if (auto shape = read_geometry(geometry)) {
      body.collisions.push_back(CollisionShape{fmt::format("{}/{}/{}", model_name, link_name, collision_name),
                                               std::move(*shape), collision_pose, where(collision)});
    }
  }
  for (const auto& sensor : child_elements(link, "sensor")) read_sensor(sensor, link_pose, fmt::format("{}/{}", model_name, link_name));
  // <visual>, <inertial> ... are valid SDF that the fluid does not see.
}

std::optional<Shape> SceneReader::read_geometry(const pugi::xml_node& geometry) {
  constexpr std::string_view kSupported = "box, sphere, cylinder, plane, mesh";
  const auto shapes = [&] {
    std::vector<pugi::xml_node> elements;
    for (const auto& child : geometry.children()) {
      if (child.type() == pugi::node_element) elements.push_back(child);
    }
    return elements;
  }();
  if (shapes.empty()) {
    report(geometry, fmt::format("<geometry> has no shape; expected one of: {}", kSupported));
    return std::nullopt;
  }
  if (shapes.size() > 1) {
    report(shapes[1], fmt::format("<geometry> must hold exactly one shape; found <{}> and <{}>", shapes[0].name(),
                                  shapes[1].name()));
    return std::nullopt;
  }
  const pugi::xml_node shape = shapes.front();
  const std::string_view kind = shape.name();
  if (kind == "box") {
    const pugi::xml_node size_element = find_child(shape, "size", Presence::required);
    if (!size_element) return std::nullopt;
    const auto size = read_numbers(size_element, 3, Quantity::length, "x y z");
    if (!size) return std::nullopt;
    if (std::any_of(size->begin(), size->end(), [](double edge) { return edge <= 0; })) {
      report(size_element, fmt::format("<size> of a <box> must be > 0 m on every axis, got '{}'",
                                       trim(size_element.child_value())));
      return std::nullopt;
    }
    return BoxShape{Vec3(Real((*size)[0]), Real((*size)[1]), Real((*size)[2]))};
  }
  if (kind == "sphere") {
    const auto radius = read_scalar(shape, "radius", Quantity::length, Limits::positive(), Presence::required);
    if (!radius) return std::nullopt;
    return SphereShape{Real(*radius)};
  }
  if (kind == "cylinder") {
    const auto radius = read_scalar(shape, "radius", Quantity::length, Limits::positive(), Presence::required);
    const auto length = read_scalar(shape, "length", Quantity::length, Limits::positive(), Presence::required);
    if (!radius || !length) return std::nullopt;
    return CylinderShape{Real(*radius), Real(*length)};
  }
  if (kind == "plane") {
    const auto normal = shape.child("normal") ? read_direction(shape, "normal", Presence::optional)
                                              : std::optional<Vec3>(Vec3::UnitZ());
    // SDF planes are infinite; boundary particles need a finite patch.
    const pugi::xml_node size_element = shape.child("size");
    if (!size_element) {
      report(shape, "missing required <size> in <plane>; M3DP samples a finite patch, e.g. <size>2 2</size>");
      return std::nullopt;
    }
    const auto size = read_numbers(size_element, 2, Quantity::length, "x y");
    if (!normal || !size) return std::nullopt;
    if ((*size)[0] <= 0 || (*size)[1] <= 0) {
      report(size_element,
             fmt::format("<size> of a <plane> must be > 0 m on both axes, got '{}'", trim(size_element.child_value())));
      return std::nullopt;
    }
    return PlaneShape{*normal, Real((*size)[0]), Real((*size)[1])};
  }
  if (kind == "mesh") {
    auto mesh = read_mesh(shape);
    if (!mesh) return std::nullopt;
    return std::move(*mesh);
  }
  report(shape, fmt::format("<{}> geometry is not supported yet; expected one of: {}", kind, kSupported));
  return std::nullopt;
}

std::optional<MeshShape> SceneReader::read_mesh(const pugi::xml_node& mesh) {
  const pugi::xml_node uri_element = find_child(mesh, "uri", Presence::required);
  if (!uri_element) return std::nullopt;
  const std::string_view uri = leaf_text(uri_element, {});

  constexpr std::string_view kFileScheme = "file://";
  fs::path mesh_path;
  if (uri.starts_with("model://")) {
    report(uri_element, fmt::format("'{}': model:// URIs need a Gazebo model path, which M3DP does not search; use a "
                                    "path relative to the scene file's folder (e.g. meshes/part.stl)",
                                    uri));
    return std::nullopt;
  }
  if (uri.starts_with(kFileScheme)) {
    mesh_path = fs::path(std::string(uri.substr(kFileScheme.size())));
  } else if (uri.find("://") != std::string_view::npos) {
    report(uri_element, fmt::format("'{}': unsupported URI scheme; use a path relative to the scene file's folder or "
                                    "file:///absolute/path",
                                    uri));
    return std::nullopt;
  } else if (uri.empty()) {
    report(uri_element, "<uri> is empty; expected the path of an .obj or .stl file");
    return std::nullopt;
  } else {
    mesh_path = fs::path(std::string(uri));
  }
  if (mesh_path.is_relative()) mesh_path = file_.parent_path() / mesh_path;
  scene_.input_files.push_back(mesh_path);

  Vec3 scale = Vec3::Ones();
  if (const pugi::xml_node scale_element = mesh.child("scale")) {
    const auto values = read_numbers(scale_element, 3, Quantity::plain_number, "x y z");
    if (!values) return std::nullopt;
    scale = Vec3(Real((*values)[0]), Real((*values)[1]), Real((*values)[2]));
    if ((scale.array() == 0).any()) {
      report(scale_element, "<scale> must not be 0 on any axis (it would flatten the mesh)");
      return std::nullopt;
    }
  }

  MeshShape shape;
  shape.file = mesh_path.string();
  try {
    shape.mesh = io::read_triangle_mesh(mesh_path);
  } catch (const InputError& error) {
    std::string details;
    for (const auto& diagnostic : error.diagnostics()) {
      details += (details.empty() ? "" : "; ") + diagnostic.str();
    }
    report(uri_element, fmt::format("cannot load mesh '{}': {}", shape.file, details));
    return std::nullopt;
  }
  for (Vec3& vertex : shape.mesh.vertices) vertex = vertex.cwiseProduct(scale);
  // A mirroring scale turns the triangles inside out; swap two corners to keep them counter-clockwise.
  if (scale.prod() < 0) {
    for (auto& triangle : shape.mesh.triangles) std::swap(triangle[1], triangle[2]);
  }
  return shape;
}

// ---- the m3dp plugin ----

void SceneReader::read_plugin(const pugi::xml_node& plugin) {
  read_block(plugin, "plugin", &scene_);
  // The solver comes first: other checks need the particle radius and the bounds.
  if (const pugi::xml_node solver = plugin.child("solver")) read_solver(solver);
  if (const pugi::xml_node air = plugin.child("air")) read_air(air);
  for (const auto& material : child_elements(plugin, "material")) read_material(material);
  for (const auto& block : child_elements(plugin, "fluid_block")) read_fluid_block(block);
  for (const auto& robot : child_elements(plugin, "robot")) read_robot_settings(robot);
  for (const auto& head : child_elements(plugin, "print_head")) read_print_head(head);
  if (const pugi::xml_node output = plugin.child("output")) read_output(output);
  if (const pugi::xml_node meshing = plugin.child("meshing")) read_meshing(meshing);
  for (const auto& camera : child_elements(plugin, "camera")) read_plugin_camera(camera);
  if (const pugi::xml_node coordinator = plugin.child("coordinator")) read_coordinator(coordinator);

  if (!plugin.child("fluid_block") && !plugin.child("print_head")) {
    report(plugin, "the scene has no fluid: add a <fluid_block> or a <print_head>");
  }
  check_materials();
  check_engine_parameters();
  check_sizes();
}

void SceneReader::check_sizes() {
  // The particles the scene asks for, estimated before anything is sampled or allocated: a tiny
  // radius, a kilometre nozzle or box would otherwise end in std::bad_alloc with no line named.
  if (!particle_radius_) return;
  const double spacing = 2.0 * *particle_radius_;
  const double wall_spacing = spacing * scene_.solver.boundary_spacing_factor;
  struct Part {
    SourceLocation where;
    std::string what;
    double particles;
  };
  std::vector<Part> parts;
  for (const FluidBlock& block : scene_.fluid_blocks) {
    const Vec3 size = block.box.max - block.box.min;
    const double volume = block.cylinder_radius ? kPi * double(*block.cylinder_radius) * *block.cylinder_radius * size.z()
                                                : double(size.x()) * size.y() * size.z();
    parts.push_back({block.where, fmt::format("<fluid_block name=\"{}\"> ({:.3g} m³)", block.name, volume),
                     volume / (spacing * spacing * spacing)});
  }
  for (const PrintHead& head : scene_.print_heads) {
    const double duration = std::max(0.0, std::min(head.trajectory.end_time(), scene_.end_time) - head.trajectory.start_time());
    const double volume = kPi * double(head.inner_diameter) * head.inner_diameter / 4 * head.exit_speed * duration;
    parts.push_back({head.where, fmt::format("<print_head name=\"{}\"> ({:.3g} m³ extruded in {:.3g} s)", head.name, volume, duration),
                     volume / (spacing * spacing * spacing)});
  }
  for (const auto* bodies : {&scene_.bodies})
    for (const StaticBody& body : *bodies)
      for (const CollisionShape& collision : body.collisions) {
        const double area = sph::shape_surface_area(collision.shape);
        parts.push_back({collision.where, fmt::format("the wall particles of <collision> '{}' ({:.3g} m²)", collision.name, area),
                         area / (wall_spacing * wall_spacing)});
      }
  for (const DynamicBody& body : scene_.dynamic_bodies)
    for (const CollisionShape& collision : body.collisions) {
      const double area = sph::shape_surface_area(collision.shape);
      parts.push_back({collision.where, fmt::format("the wall particles of <collision> '{}' ({:.3g} m²)", collision.name, area),
                       area / (wall_spacing * wall_spacing)});
    }
  double total = 0;
  const Part* largest = nullptr;
  for (const Part& part : parts) {
    total += part.particles;
    if (!largest || part.particles > largest->particles) largest = &part;
  }
  const double limit = max_particles_.value_or(default_max_particles());
  if (!largest || !(total > limit)) return;
  report(largest->where,
         fmt::format("the scene would hold about {:.3g} particles at a particle radius of {:.3g} m, {:.3g} of them from {}; at most "
                     "{:.3g} fit ({}): use a larger <particle_radius> or a smaller part, or set <solver><max_particles>",
                     total, *particle_radius_, largest->particles, largest->what, limit,
                     max_particles_ ? "<max_particles>"
                                    : fmt::format("this machine's {:.3g} GB of memory at about {} bytes a particle",
                                                  physical_memory_bytes() / 1e9, kBytesPerParticle)));
}

void SceneReader::read_air(const pugi::xml_node& air) {
  // The air around the print: its drag on the material's surface (Gissler et al. 2017) is on when
  // the block is there, unless <drag>false</drag>.
  check_attributes(air, {});
  scene_.solver.air_drag = true;
  read_block(air, "air", &scene_, &scene_.solver_fields);
  if (const auto velocity = read_vector(air, "velocity", Quantity::speed, Presence::optional)) scene_.solver.air_velocity = *velocity;
}

void SceneReader::read_solver(const pugi::xml_node& solver) {
  check_attributes(solver, {});
  sph::SolverSettings& settings = scene_.solver;
  scene_.solver_fields.emplace_back("", where(solver));  // for settings the file does not name
  // The table's values (schema.cpp), then what ties them together or is not a plain value.
  read_block(solver, "solver", &scene_, &scene_.solver_fields);
  if (solver.child("particle_radius") && settings.particle_radius > 0) particle_radius_ = settings.particle_radius;
  if (const auto limit = read_scalar(solver, "max_particles", Quantity::plain_number, Limits::positive(), Presence::optional))
    max_particles_ = *limit;
  if ((solver.child("min_time_step") || solver.child("max_time_step")) && settings.max_time_step < settings.min_time_step) {
    const pugi::xml_node culprit = solver.child("max_time_step") ? solver.child("max_time_step") : solver.child("min_time_step");
    report(culprit, fmt::format("<max_time_step> ({} s) must be >= <min_time_step> ({} s)", settings.max_time_step,
                                settings.min_time_step));
  }
  if (const pugi::xml_node bounds = solver.child("bounds")) {
    check_attributes(bounds, {});
    check_children(bounds, {"min", "max"});
    if (const auto box = read_box(bounds)) {
      settings.bounds = *box;
      bounds_ = *box;
    }
  }
}

void SceneReader::read_material(const pugi::xml_node& element) {
  check_attributes(element, {"name", "preset"});
  const auto name = read_attribute(element, "name", Presence::required);
  const auto preset_name = read_attribute(element, "preset", Presence::optional);
  const MaterialEntry* preset = nullptr;
  if (preset_name) {
    const auto& presets = material_presets();
    const auto found = std::find_if(presets.begin(), presets.end(),
                                    [&](const MaterialEntry& entry) { return entry.material.name == *preset_name; });
    if (found == presets.end()) {
      std::string known;
      for (const auto& entry : presets) known += (known.empty() ? "" : ", ") + entry.material.name;
      report(element, fmt::format("unknown material preset '{}'; the presets ({}) are: {}", *preset_name,
                                  material_presets_file().string(), known.empty() ? "none" : known));
      if (name) defined_materials_.push_back(DefinedMaterial{*name, where(element)});
      return;
    }
    preset = &*found;
  }
  // A preset's fields where the material does not set them again (its own are found first).
  FieldLocations fields;
  auto material = read_material_values(element, preset ? &preset->material : nullptr, fields);
  if (preset) fields.insert(fields.end(), preset->fields.begin(), preset->fields.end());
  if (!name) return;

  const auto earlier = std::find_if(defined_materials_.begin(), defined_materials_.end(),
                                    [&](const DefinedMaterial& defined) { return defined.name == *name; });
  if (earlier != defined_materials_.end()) {
    report(element, fmt::format("material '{}' is defined twice; the first is at line {}", *name, earlier->where.line));
    return;
  }
  defined_materials_.push_back(DefinedMaterial{*name, where(element)});
  if (!material) return;
  material->name = *name;
  if (preset) material->preset = preset->material.name;
  auto color = read_color(element);
  if (!color && preset) color = preset->color;
  scene_.materials.push_back(MaterialEntry{std::move(*material), where(element), std::move(fields), color});
}

std::optional<material::Material> SceneReader::read_material_values(const pugi::xml_node& element,
                                                                   const material::Material* base, FieldLocations& fields) {
  material::Material material = base ? *base : material::Material{};
  bool valid = true;
  // The table's values (schema.cpp: density, nozzle_wall, surface_tension, adhesion), then what is special.
  read_block(element, "material", &material, &fields);
  if (!base && !find_child(element, "density", Presence::required)) valid = false;
  const pugi::xml_node viscosity = element.child("viscosity");
  const pugi::xml_node rheology = element.child("rheology");
  if (viscosity && rheology) {
    report(viscosity, fmt::format("{} has both <viscosity> (a Newtonian fluid) and <rheology> (line {}); give one",
                                  describe(element), where(rheology).line));
    valid = false;
  } else if (viscosity) {
    if (const auto value = read_scalar(element, "viscosity", Quantity::dynamic_viscosity, Limits::non_negative(),
                                       Presence::required)) {
      material.rheology = material::Rheology{};
      material.rheology.viscosity = Real(*value);
    } else {
      valid = false;
    }
  } else if (rheology) {
    if (auto read = read_rheology(rheology, base ? &base->rheology : nullptr)) material.rheology = *read;
    else valid = false;
  } else if (!base) {
    report(element, fmt::format("missing <viscosity> (Pa*s, a Newtonian fluid) or <rheology model=\"...\"> in {}",
                                describe(element)));
    valid = false;
  }
  if (const pugi::xml_node ageing = element.child("ageing")) read_ageing(ageing, material);
  // A viscosity in Pa·s (Navier slip: the wall carries μ_b × slip rate), or no_slip: the material sticks.
  if (const pugi::xml_node wall = element.child("boundary_viscosity")) {
    if (trim(wall.child_value()) == "no_slip") {
      leaf_text(wall, {});
      material.sticks_to_walls = true;
    } else if (const auto value = read_scalar(element, "boundary_viscosity", Quantity::dynamic_viscosity,
                                              Limits::non_negative(), Presence::optional)) {
      material.boundary_viscosity = Real(*value);
      material.sticks_to_walls = false;
    }
  }
  if (const pugi::xml_node granular = element.child("granular")) read_granular(granular, material, fields);
  if (const pugi::xml_node micropolar = element.child("micropolar")) read_micropolar(micropolar, material);
  if (const pugi::xml_node elasticity = element.child("elasticity")) read_elasticity(elasticity, material, fields);
  if (const pugi::xml_node source = element.child("source")) leaf_text(source, {});
  if (!valid) return std::nullopt;
  return material;
}

std::optional<material::Rheology> SceneReader::read_rheology(const pugi::xml_node& element,
                                                             const material::Rheology* base) {
  using material::RheologyModel;
  check_attributes(element, {"model"});
  constexpr RheologyModel kModels[] = {RheologyModel::newtonian, RheologyModel::power_law, RheologyModel::cross,
                                       RheologyModel::carreau,   RheologyModel::bingham,   RheologyModel::herschel_bulkley};
  // The model: as written, or the preset's when the scene only changes some of its values.
  std::optional<RheologyModel> model;
  if (const auto written = read_attribute(element, "model", base ? Presence::optional : Presence::required)) {
    for (const RheologyModel candidate : kModels)
      if (material::to_string(candidate) == *written) model = candidate;
    if (!model) {
      report(element, fmt::format("unknown rheology model '{}'; expected one of: newtonian, power_law, cross, carreau, "
                                  "bingham, herschel_bulkley",
                                  *written));
      return std::nullopt;
    }
  } else if (base) {
    model = base->model;
  } else {
    return std::nullopt;
  }
  // Over the preset's values when the model is the same; a different model starts from scratch.
  const bool over_base = base && base->model == *model;
  material::Rheology rheology = over_base ? *base : material::Rheology{};
  rheology.model = *model;
  // The model's parameters from its rows (schema.cpp), then what ties them together.
  const std::size_t problems_before = diagnostics_.size();
  read_block(element, fmt::format("rheology {}", material::to_string(*model)), &rheology, nullptr, over_base);
  bool valid = diagnostics_.size() == problems_before;
  if (valid && rheology.infinite_shear_viscosity > rheology.viscosity) {
    report(element.child("infinite_shear_viscosity"),
           fmt::format("<infinite_shear_viscosity> ({} Pa*s) must not exceed <zero_shear_viscosity> ({} Pa*s)",
                       rheology.infinite_shear_viscosity, rheology.viscosity));
    valid = false;
  }
  if (!valid) return std::nullopt;
  return rheology;
}

void SceneReader::read_ageing(const pugi::xml_node& element, material::Material& material) {
  check_attributes(element, {});
  read_block(element, "ageing", &material);
}

void SceneReader::read_granular(const pugi::xml_node& element, material::Material& material, FieldLocations& fields) {
  // <granular/> on its own switches the material to discrete spheres with the default contact law.
  check_attributes(element, {});
  material.granular.enabled = true;
  fields.emplace_back("granular", where(element));
  read_block(element, "granular", &material, &fields);
}

void SceneReader::read_micropolar(const pugi::xml_node& element, material::Material& material) {
  // <micropolar/> on its own turns the model on with its defaults.
  check_attributes(element, {});
  material.micropolar.enabled = true;
  read_block(element, "micropolar", &material);
}

void SceneReader::read_elasticity(const pugi::xml_node& element, material::Material& material, FieldLocations& fields) {
  check_attributes(element, {});
  material.elasticity.enabled = true;
  fields.emplace_back("elasticity", where(element));
  read_block(element, "elasticity", &material, &fields);
}

const std::vector<MaterialEntry>& SceneReader::material_presets() {
  if (!material_presets_) {
    const fs::path file = material_presets_file();
    try {
      material_presets_ = SceneReader(read_text_file(file, "material presets"), file).read_material_library();
    } catch (const InputError& error) {
      for (const auto& diagnostic : error.diagnostics()) diagnostics_.push_back(diagnostic);
      material_presets_.emplace();
    }
  }
  return *material_presets_;
}

std::vector<MaterialEntry> SceneReader::read_material_library() {
  pugi::xml_document document;
  const pugi::xml_node root = parse_root(document, "materials");
  check_children(root, {"material"}, {"material"});
  std::vector<MaterialEntry> entries;
  for (const auto& element : child_elements(root, "material")) {
    check_attributes(element, {"name"});
    const auto name = read_attribute(element, "name", Presence::required);
    FieldLocations fields;
    auto material = read_material_values(element, nullptr, fields);
    if (!name || !material) continue;
    material->name = *name;
    entries.push_back(MaterialEntry{std::move(*material), where(element), std::move(fields), read_color(element)});
  }
  // Each preset as the one material of default settings: what the engine would refuse in any scene.
  for (const MaterialEntry& entry : entries) {
    sph::Parameters parameters;
    parameters.phases.push_back(entry.material);
    report_parameter_problems(sph::check_parameters(parameters), parameters, std::span(&entry, 1));
  }
  if (!diagnostics_.empty()) throw InputError(std::move(diagnostics_));
  return entries;
}

void SceneReader::read_fluid_block(const pugi::xml_node& element) {
  check_attributes(element, {"name", "material"});
  FluidBlock block;
  read_block(element, "fluid_block", &block);
  block.name = read_attribute(element, "name", Presence::required).value_or("");
  block.material = read_attribute(element, "material", Presence::required).value_or("");
  block.where = where(element);
  if (!block.name.empty()) check_unique_name(element, block.name, fluid_block_names_);
  if (!block.material.empty()) material_uses_.push_back(MaterialUse{block.material, describe(element), block.where});

  std::optional<Aabb> box;
  if (const pugi::xml_node cylinder = element.child("cylinder")) {
    // A vertical cylinder: the slump test's mould.
    if (element.child("min") || element.child("max")) {
      report(cylinder, fmt::format("{} has both <cylinder> and <min>/<max>; give one shape", describe(element)));
    }
    check_attributes(cylinder, {});
    const std::size_t problems_before = diagnostics_.size();
    read_block(cylinder, "cylinder", &block);
    const auto base = read_vector(cylinder, "base", Quantity::length, Presence::optional);
    if (base && diagnostics_.size() == problems_before) {
      const Real radius = *block.cylinder_radius;
      box = Aabb{*base - Vec3(radius, radius, 0), *base + Vec3(radius, radius, block.cylinder_height)};
    }
  } else {
    box = read_box(element);
  }
  if (box) block.box = *box;
  // Particles outside the solver bounds are removed at once, so a block reaching out of them is a mistake.
  if (box && bounds_ && !(bounds_->contains(box->min) && bounds_->contains(box->max))) {
    report(element, fmt::format("{} reaches outside the solver <bounds>; particles there would be removed at once",
                                describe(element)));
  }
  if (const auto velocity = read_vector(element, "velocity", Quantity::speed, Presence::optional)) {
    block.initial_velocity = *velocity;
  }
  scene_.fluid_blocks.push_back(std::move(block));
}

void SceneReader::read_print_head(const pugi::xml_node& element) {
  check_attributes(element, {"name", "material"});
  PrintHead head;
  read_block(element, "print_head", &head);
  head.name = read_attribute(element, "name", Presence::required).value_or("");
  head.material = read_attribute(element, "material", Presence::required).value_or("");
  head.where = where(element);
  if (!head.name.empty()) check_unique_name(element, head.name, print_head_names_);
  if (!head.material.empty()) material_uses_.push_back(MaterialUse{head.material, describe(element), head.where});

  if (const pugi::xml_node nozzle = element.child("nozzle")) {
    check_attributes(nozzle, {});
    // The table's values (schema.cpp), then the checks against the particles and each other.
    read_block(nozzle, "nozzle", &head, &head.nozzle_fields);
    if (nozzle.child("inner_diameter") && particle_radius_ && head.inner_diameter < 2 * *particle_radius_) {
      report(nozzle.child("inner_diameter"),
             fmt::format("the nozzle is narrower than one particle: <inner_diameter> {} m is below the particle "
                         "diameter 2*<particle_radius> = {} m; widen the nozzle or use smaller particles",
                         head.inner_diameter, 2 * *particle_radius_));
    }
    if (const auto direction = read_direction(nozzle, "direction", Presence::optional)) head.direction = *direction;
    // A nozzle with walls: the bore above the exit and the tip's lip (sph::NozzleSettings); the engine
    // checks the bore against the particles (sph::check_parameters) at these elements' lines.
    if (nozzle.child("outer_diameter") && head.outer_diameter > 0) {
      if (head.outer_diameter <= head.inner_diameter)
        report(nozzle.child("outer_diameter"), fmt::format("<outer_diameter> {} m must be larger than <inner_diameter> {} m",
                                                           head.outer_diameter, head.inner_diameter));
    }
  }
  if (const pugi::xml_node path = element.child("path")) {
    if (auto trajectory = read_path(path)) head.trajectory = std::move(*trajectory);
  }
  if (const pugi::xml_node mount = element.child("mount")) head.mount = read_mount(mount);
  scene_.print_heads.push_back(std::move(head));
}

std::optional<toolpath::Trajectory> SceneReader::read_path(const pugi::xml_node& path) {
  auto read = read_path_segments(path);
  if (!read) return std::nullopt;
  return toolpath::Trajectory(std::move(read->segments), read->start_time);
}

PathSegments SceneReader::read_path_text() {
  pugi::xml_document document;
  const pugi::xml_node path = parse_root(document, "path");
  auto read = read_path_segments(path);
  if (!diagnostics_.empty()) throw InputError(std::move(diagnostics_));
  return std::move(*read);
}

std::optional<PathSegments> SceneReader::read_path_segments(const pugi::xml_node& path) {
  check_attributes(path, {"start_time", "speed"});
  check_children(path, {"line", "polyline", "circle", "helix", "wall", "gcode", "waypoints"},
                 {"line", "polyline", "circle", "helix", "wall", "gcode", "waypoints"});
  const auto start_time = read_number_attribute(path, "start_time", Quantity::time, Limits::non_negative());
  const auto speed = read_number_attribute(path, "speed", Quantity::speed, Limits::positive());
  const bool attributes_valid = (start_time || !path.attribute("start_time")) && (speed || !path.attribute("speed"));

  std::vector<toolpath::PathSegment> segments;
  bool segments_valid = true;
  for (const auto& child : path.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string_view kind = child.name();
    if (kind == "waypoints" || kind == "gcode") {
      // Files that hold a whole path.
      if (auto read = kind == "gcode" ? read_gcode_segments(child) : read_waypoint_segments(child)) {
        segments.insert(segments.end(), std::make_move_iterator(read->begin()), std::make_move_iterator(read->end()));
      } else {
        segments_valid = false;
      }
      continue;
    }
    if (kind != "line" && kind != "polyline" && kind != "circle" && kind != "helix" && kind != "wall") continue;  // reported above
    if (auto segment = read_path_segment(child, Real(speed.value_or(toolpath::PathSegment{}.speed)))) {
      segments.push_back(std::move(*segment));
    } else {
      segments_valid = false;
    }
  }
  if (segments.empty() && segments_valid) {
    report(path, "<path> has no segments; expected one or more of: line, polyline, circle, helix, wall, gcode, waypoints");
    return std::nullopt;
  }
  if (!segments_valid || !attributes_valid) return std::nullopt;
  return PathSegments{std::move(segments), start_time.value_or(0)};
}

std::optional<std::vector<toolpath::PathSegment>> SceneReader::read_gcode_segments(const pugi::xml_node& element) {
  check_attributes(element, {"file"});
  check_children(element, {"pose", "scale", "filament_diameter", "volumetric_extrusion", "speed_scale", "flow_scale"});
  const auto file = read_attribute(element, "file", Presence::required);
  if (!file) return std::nullopt;
  toolpath::GcodeSettings settings;
  settings.placement = read_pose(element);
  if (const auto diameter =
          read_scalar(element, "filament_diameter", Quantity::length, Limits::positive(), Presence::optional))
    settings.filament_diameter = Real(*diameter);
  if (const auto volumetric = read_bool(element, "volumetric_extrusion")) settings.volumetric_extrusion = *volumetric;
  if (const auto scale = read_scalar(element, "scale", Quantity::plain_number, Limits::positive(), Presence::optional))
    settings.geometry_scale = Real(*scale);
  // A printer's speed and flow overrides (M220, M221), as a study varies them.
  if (const auto scale = read_scalar(element, "speed_scale", Quantity::plain_number, Limits::positive(), Presence::optional))
    settings.speed_scale = Real(*scale);
  if (const auto scale = read_scalar(element, "flow_scale", Quantity::plain_number, Limits::positive(), Presence::optional))
    settings.flow_scale = Real(*scale);
  const auto gcode_path = find_input_file(element, *file, "G-code file");
  if (!gcode_path) return std::nullopt;
  try {
    toolpath::GcodeProgram program = toolpath::read_gcode(*gcode_path, settings);
    for (auto& warning : program.warnings) scene_.warnings.push_back(std::move(warning));
    if (program.moves.empty()) {
      report(element, fmt::format("G-code file '{}' has no moves", *file));
      return std::nullopt;
    }
    return program.path_segments();
  } catch (const InputError& error) {
    for (const auto& diagnostic : error.diagnostics()) report(diagnostic.location, diagnostic.message);
    return std::nullopt;
  }
}

std::optional<fs::path> SceneReader::find_input_file(const pugi::xml_node& element, const std::string& file,
                                                     std::string_view what) {
  fs::path path(file);
  if (path.is_relative()) path = file_.parent_path() / path;  // relative to the scene file
  if (!path_exists(path)) {
    report(element, fmt::format("{} '{}' not found (looked for {})", what, file, path.string()));
    return std::nullopt;
  }
  scene_.input_files.push_back(path);
  return path;
}

std::optional<std::vector<toolpath::PathSegment>> SceneReader::read_waypoint_segments(const pugi::xml_node& element) {
  check_attributes(element, {"file"});
  check_children(element, {"pose"});
  const auto file = read_attribute(element, "file", Presence::required);
  if (!file) return std::nullopt;
  const auto waypoint_path = find_input_file(element, *file, "waypoint file");
  if (!waypoint_path) return std::nullopt;
  try {
    return toolpath::read_waypoints(*waypoint_path, read_pose(element));
  } catch (const InputError& error) {
    for (const auto& diagnostic : error.diagnostics()) report(diagnostic.location, diagnostic.message);
    return std::nullopt;
  }
}

std::optional<toolpath::PathSegment> SceneReader::read_path_segment(const pugi::xml_node& element, Real path_speed) {
  check_attributes(element, {"speed", "extrude"});
  const auto speed = read_number_attribute(element, "speed", Quantity::speed, Limits::positive());
  const auto extrude = read_bool_attribute(element, "extrude");
  auto curve = read_curve(element);
  if (!curve || (element.attribute("speed") && !speed) || (element.attribute("extrude") && !extrude)) {
    return std::nullopt;
  }
  return toolpath::PathSegment{std::move(*curve), speed ? Real(*speed) : path_speed, extrude.value_or(true)};
}

/// <centre> or its American spelling <center>: exactly one of them.
pugi::xml_node SceneReader::find_centre(const pugi::xml_node& curve) {
  const pugi::xml_node centre = curve.child("centre");
  const pugi::xml_node center = curve.child("center");
  if (centre && center) {
    report(center, fmt::format("<{}> has both <centre> and <center>; give one", curve.name()));
    return {};
  }
  if (!centre && !center) report(curve, fmt::format("missing required <centre> in <{}>", curve.name()));
  return centre ? centre : center;
}

std::optional<toolpath::Curve> SceneReader::read_curve(const pugi::xml_node& element) {
  const std::string_view kind = element.name();
  if (kind == "line") {
    check_children(element, {"start", "end"});
    const auto start = read_vector(element, "start", Quantity::length, Presence::required);
    const auto end = read_vector(element, "end", Quantity::length, Presence::required);
    if (!start || !end) return std::nullopt;
    return toolpath::LineCurve{*start, *end};
  }
  if (kind == "wall") {
    check_children(element, {"corner", "size", "layers", "layer_height"});
    const auto corner = read_vector(element, "corner", Quantity::length, Presence::required);
    std::optional<std::vector<double>> size;
    if (const pugi::xml_node size_element = find_child(element, "size", Presence::required)) {
      size = read_numbers(size_element, 2, Quantity::length, "x y");
      if (size && ((*size)[0] <= 0 || (*size)[1] <= 0)) {
        report(size_element, fmt::format("<size> of a <wall> must be > 0 m on both axes, got '{}'", trim(size_element.child_value())));
        size.reset();
      }
    }
    const auto layers = read_int(element, "layers", 1);
    const auto layer_height = read_scalar(element, "layer_height", Quantity::length, Limits::positive(), Presence::required);
    if (!element.child("layers")) report(element, "missing required <layers> in <wall>");
    if (!corner || !size || !layers || !layer_height) return std::nullopt;
    if (const double points = 5.0 * *layers; points * kBytesPerPathPoint > 0.8 * physical_memory_bytes()) {
      report(element.child("layers"), fmt::format("a wall of {} layers is a path of {:.3g} points, more than this machine's {:.3g} GB "
                                                  "of memory holds",
                                                  *layers, points, physical_memory_bytes() / 1e9));
      return std::nullopt;
    }
    return toolpath::rectangle_wall(*corner, Real((*size)[0]), Real((*size)[1]), *layers, Real(*layer_height));
  }
  if (kind == "polyline") {
    check_children(element, {"point"}, {"point"});
    toolpath::PolylineCurve polyline;
    bool points_valid = true;
    for (const auto& point_element : child_elements(element, "point")) {
      const auto point = read_numbers(point_element, 3, Quantity::length, "x y z");
      if (point) {
        polyline.points.emplace_back(Real((*point)[0]), Real((*point)[1]), Real((*point)[2]));
      } else {
        points_valid = false;
      }
    }
    if (!points_valid) return std::nullopt;
    if (polyline.points.size() < 2) {
      report(element, fmt::format("<polyline> needs at least 2 <point>s, got {}", polyline.points.size()));
      return std::nullopt;
    }
    return polyline;
  }

  // Circles and helices share centre, radius, turns and start angle; a helix also rises.
  const bool is_helix = kind == "helix";
  if (is_helix) {
    check_children(element, {"centre", "center", "radius", "turns", "rise_per_turn", "start_angle"});
  } else {
    check_children(element, {"centre", "center", "radius", "turns", "start_angle"});
  }
  std::optional<Vec3> centre;
  if (const pugi::xml_node centre_element = find_centre(element)) {
    if (const auto values = read_numbers(centre_element, 3, Quantity::length, "x y z")) {
      centre = Vec3(Real((*values)[0]), Real((*values)[1]), Real((*values)[2]));
    }
  }
  const auto radius = read_scalar(element, "radius", Quantity::length, Limits::positive(), Presence::required);
  double turns = 1;  // a plain value, not an optional: GCC 12 warns of one copied about here
  bool turns_valid = !element.child("turns");
  if (const auto read = read_scalar(element, "turns", Quantity::plain_number, Limits::any(), Presence::optional)) {
    turns = *read;
    turns_valid = turns != 0;
    if (!turns_valid) report(element.child("turns"), "<turns> must not be 0 (negative turns go clockwise)");
  }
  const auto start_angle =
      read_scalar(element, "start_angle", Quantity::angle, Limits::any(), Presence::optional);
  const bool start_angle_valid = start_angle || !element.child("start_angle");
  const auto rise = is_helix ? read_scalar(element, "rise_per_turn", Quantity::length, Limits::any(),
                                           Presence::required)
                             : std::optional<double>(0.0);
  if (!centre || !radius || !turns_valid || !start_angle_valid || !rise) return std::nullopt;

  const Real turn_count = Real(turns);
  const Real angle = Real(start_angle.value_or(0));
  if (is_helix) return toolpath::HelixCurve{*centre, Real(*radius), angle, turn_count, Real(*rise)};
  return toolpath::CircleCurve{*centre, Real(*radius), angle, turn_count};
}

void SceneReader::read_output(const pugi::xml_node& output) {
  check_attributes(output, {});
  read_block(output, "output", &scene_);
}

void SceneReader::read_meshing(const pugi::xml_node& meshing) {
  check_attributes(meshing, {});
  read_block(meshing, "meshing", &scene_);
  MeshingSettings& settings = scene_.meshing;
  settings.enabled = true;
  settings.where = where(meshing);
  if (const pugi::xml_node method = meshing.child("method")) {
    const std::string_view name = leaf_text(method, {});
    if (const auto parsed = surface::parse_method(name)) {
      settings.surface.method = *parsed;
    } else {
      report(method, fmt::format("<method> must be one of: {}; got '{}'", surface::method_names(), name));
    }
  }
  if (const pugi::xml_node format = meshing.child("format")) {
    const std::string_view name = leaf_text(format, {});
    if (io::find_mesh_format(name))
      settings.format = std::string(name);
    else
      report(format, fmt::format("<format> must be one of: {}; got '{}'", io::mesh_format_names(), name));
  }
  if (const pugi::xml_node material = meshing.child("material")) {
    settings.material = std::string(leaf_text(material, {}));
    material_uses_.push_back(MaterialUse{settings.material, "<meshing>", where(material)});
  }
  if (const pugi::xml_node region = meshing.child("region")) {
    check_attributes(region, {});
    check_children(region, {"min", "max"});
    settings.region = read_box(region);
  }
}

void SceneReader::read_coordinator(const pugi::xml_node& coordinator) {
  check_attributes(coordinator, {"enabled"});
  read_block(coordinator, "coordinator", &scene_);
  CoordinatorSettings& settings = scene_.coordinator;
  settings.enabled = read_bool_attribute(coordinator, "enabled").value_or(true);
  settings.where = where(coordinator);
  if (const pugi::xml_node priority = coordinator.child("priority")) {
    for (const auto& name : split_words(leaf_text(priority, {}))) {
      const std::string robot(name);
      if (!scene_.find_robot(robot)) {
        std::vector<std::string> names;
        for (const auto& included : scene_.robots) names.push_back(included.name);
        report(priority, fmt::format("<priority>: no robot '{}' is included in the world; its robots: {}", robot,
                                     names.empty() ? "none" : fmt::format("{}", fmt::join(names, ", "))));
      } else if (std::find(settings.priority.begin(), settings.priority.end(), robot) != settings.priority.end()) {
        report(priority, fmt::format("<priority>: robot '{}' is named twice", robot));
      } else {
        settings.priority.push_back(robot);
      }
    }
  }
  if (scene_.robots.size() < 2) report(coordinator, "<coordinator> coordinates robots: the world needs at least two");
}

void SceneReader::check_materials() {
  std::string defined_names;
  for (const auto& defined : defined_materials_) defined_names += (defined_names.empty() ? "" : ", ") + defined.name;
  if (defined_names.empty()) defined_names = "none (add a <material name=\"...\">)";

  for (const MaterialUse& use : material_uses_) {
    const auto defined = std::find_if(defined_materials_.begin(), defined_materials_.end(),
                                      [&](const DefinedMaterial& material) { return material.name == use.material; });
    if (defined == defined_materials_.end()) {
      report(use.where, fmt::format("material '{}' used by {} is not defined; defined: {}", use.material, use.user,
                                    defined_names));
    } else {
      defined->used = true;
    }
  }
  for (const DefinedMaterial& defined : defined_materials_) {
    if (!defined.used) {
      report(defined.where, fmt::format("material '{}' is not used by any <fluid_block> or <print_head>; remove it "
                                        "or use it",
                                        defined.name));
    }
  }
}

void SceneReader::check_engine_parameters() {
  if (scene_.materials.empty()) return;  // already reported: no material, or none that could be read
  const sph::Parameters parameters = solver_parameters(scene_);
  report_parameter_problems(sph::check_parameters(parameters), parameters, scene_.materials);
}

void SceneReader::report_parameter_problems(const std::vector<sph::ParameterProblem>& problems, const sph::Parameters& parameters,
                                            std::span<const MaterialEntry> phase_entries) {
  auto location_of = [](const FieldLocations& fields, const std::string& field, const SourceLocation& fallback) {
    for (const auto& [name, location] : fields)
      if (name == field) return location;
    return fallback;
  };
  for (const sph::ParameterProblem& problem : problems) {
    SourceLocation location{file_.string(), 0};
    std::string owner;
    switch (problem.subject) {
      case sph::ParameterProblem::Subject::settings:
        location = location_of(scene_.solver_fields, problem.field, location_of(scene_.solver_fields, "", location));
        break;
      case sph::ParameterProblem::Subject::phase: {
        const MaterialEntry& entry = phase_entries[problem.index];
        location = location_of(entry.fields, problem.field, entry.where);
        owner = fmt::format("material '{}'", entry.material.name);
        break;
      }
      case sph::ParameterProblem::Subject::nozzle:
        if (problem.index < scene_.print_heads.size())
          location = location_of(scene_.print_heads[problem.index].nozzle_fields, problem.field, scene_.print_heads[problem.index].where);
        owner = fmt::format("print head '{}'", parameters.nozzles[problem.index].name);
        break;
    }
    // "<poisson_ratio> must be in [0, 0.49], got 0.5"; a whole material's problem names the material.
    const std::size_t dot = problem.field.rfind('.');
    const auto written = written_as_.find(problem.field);
    const std::string element = written != written_as_.end() ? written->second : problem.field.substr(dot == std::string::npos ? 0 : dot + 1);
    report(location, problem.field.empty() ? fmt::format("{} {}", owner, problem.message)
                                           : fmt::format("<{}> {}", element, problem.message));
  }
}

}  // namespace

const RobotInclude* Scene::find_robot(const std::string& name) const {
  for (const auto& robot : robots)
    if (robot.name == name) return &robot;
  return nullptr;
}

std::vector<fs::path> model_search_path(const fs::path& scene_file) {
  std::vector<fs::path> folders;
  const fs::path scene_folder = scene_file.parent_path().empty() ? fs::path(".") : scene_file.parent_path();
  folders.push_back(scene_folder / "models");
  folders.push_back(scene_folder / ".." / "models");
  if (const char* variable = std::getenv("M3DP_MODEL_PATH")) {
    std::string_view rest(variable);
    while (!rest.empty()) {
      const auto colon = rest.find(':');
      if (const auto folder = rest.substr(0, colon); !folder.empty()) folders.emplace_back(folder);
      rest = colon == std::string_view::npos ? std::string_view{} : rest.substr(colon + 1);
    }
  }
  folders.emplace_back(M3DP_PROJECT_MODELS);
  return folders;
}

std::uint16_t Scene::material_index(const std::string& name) const {
  for (std::size_t i = 0; i < materials.size(); ++i)
    if (materials[i].material.name == name) return static_cast<std::uint16_t>(i);
  return 0;
}

sph::Parameters solver_parameters(const Scene& scene) {
  sph::Parameters parameters;
  parameters.settings = scene.solver;
  for (const auto& entry : scene.materials) parameters.phases.push_back(entry.material);
  for (const auto& head : scene.print_heads)
    parameters.nozzles.push_back(
        sph::NozzleSettings{head.name, head.inner_diameter, head.exit_speed, scene.material_index(head.material), head.bore_length,
                            head.outer_diameter});
  return parameters;
}

const MaterialEntry* Scene::find_material(const std::string& name) const {
  const auto entry = std::find_if(materials.begin(), materials.end(),
                                  [&](const MaterialEntry& candidate) { return candidate.material.name == name; });
  return entry == materials.end() ? nullptr : &*entry;
}

std::filesystem::path material_presets_file() {
  if (const char* variable = std::getenv("M3DP_MATERIALS"); variable && *variable) return variable;
  return fs::path(M3DP_PROJECT_DATA) / "materials.xml";
}

std::vector<MaterialEntry> load_material_presets() {
  const fs::path file = material_presets_file();
  return SceneReader(read_text_file(file, "material presets"), file).read_material_library();
}

std::string read_scene_text(const std::filesystem::path& file, std::span<const SceneOverride> overrides) {
  return apply_overrides(read_text_file(file, "scene (expected an SDF world file, e.g. scenes/dam_break.sdf)"), file, overrides);
}

Scene load_scene(const std::filesystem::path& file) { return load_scene_from_string(read_scene_text(file), file); }

Scene load_scene(const std::filesystem::path& file, std::span<const SceneOverride> overrides) {
  return load_scene_from_string(read_scene_text(file, overrides), file);
}

Scene load_scene_from_string(const std::string& text, const std::filesystem::path& file_name) {
  return SceneReader(text, file_name).read();
}

PathSegments load_path_from_string(const std::string& text, const std::filesystem::path& file_name) {
  return SceneReader(text, file_name).read_path_text();
}

double particle_frame_period(const OutputSettings& output, double end_time) {
  if (output.particles_period) return double(*output.particles_period);
  constexpr double kShortest = 0.02;  // s: smooth playback of a short run
  const double wanted = end_time / kDefaultMostParticleFrames;
  if (!(wanted > kShortest)) return kShortest;
  const double decade = std::pow(10.0, std::floor(std::log10(wanted)));
  for (const double step : {1.0, 2.0, 5.0, 10.0})
    if (step * decade >= wanted * (1 - 1e-9)) return step * decade;
  return 10 * decade;
}

}  // namespace m3dp::scene
