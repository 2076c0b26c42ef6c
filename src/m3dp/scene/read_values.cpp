// The reader's checks of structure (unknown, repeated and missing elements and attributes) and its
// values of leaf elements: numbers with their units, vectors, poses, booleans and keywords.
#include "m3dp/scene/scene_reader.hpp"

#include <charconv>
#include <cmath>
#include <iterator>

namespace m3dp::scene::detail {

// ---- files, units and words ----

bool path_exists(const std::filesystem::path& path) {
  std::error_code error;
  return std::filesystem::exists(path, error) && !error;
}

namespace {
/// Users often have viscosities from tables in kinematic units; these get a message saying how to convert.
bool is_kinematic_viscosity_unit(std::string_view symbol) {
  constexpr std::string_view kKinematic[] = {"m^2/s", "m2/s", "mm^2/s", "mm2/s", "cSt", "St"};
  return std::find(std::begin(kKinematic), std::end(kKinematic), symbol) != std::end(kKinematic);
}
}  // namespace

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

std::vector<pugi::xml_node> child_elements(const pugi::xml_node& parent, std::string_view name) {
  std::vector<pugi::xml_node> children;
  for (const auto& child : parent.children()) {
    if (child.type() == pugi::node_element && name == child.name()) children.push_back(child);
  }
  return children;
}

// ---- structure checks ----

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

}  // namespace m3dp::scene::detail
