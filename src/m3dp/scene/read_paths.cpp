// Print paths: <path> segments and curves, G-code and waypoint files, with the memory check of their points.
#include "m3dp/scene/scene_reader.hpp"

#include "m3dp/toolpath/gcode.hpp"
#include "m3dp/toolpath/waypoints.hpp"

namespace m3dp::scene::detail {

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

}  // namespace m3dp::scene::detail
