#include "m3dp/toolpath/waypoints.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <optional>

#include "m3dp/core/text.hpp"

namespace m3dp::toolpath {

PolylineCurve rectangle_wall(const Vec3& corner, Real size_x, Real size_y, int layers, Real layer_height) {
  if (!(size_x > 0) || !(size_y > 0) || layers < 1 || !(layer_height > 0))
    throw Error("rectangle_wall: the sizes and layer height must be > 0 m and there must be at least one layer");
  PolylineCurve wall;
  for (int layer = 0; layer < layers; ++layer) {
    const Vec3 start = corner + Vec3(0, 0, Real(layer) * layer_height);
    for (const Vec3& offset : {Vec3(0, 0, 0), Vec3(size_x, 0, 0), Vec3(size_x, size_y, 0), Vec3(0, size_y, 0), Vec3(0, 0, 0)})
      wall.points.push_back(start + offset);
  }
  return wall;
}

namespace {
// The largest coordinate (m) and speed (m/s) a waypoint may hold: far beyond any printer, far inside
// float (a millimetre file read as metres stays inside, nan and inf do not).
constexpr double kLargestCoordinate = 1e4;
constexpr double kLargestSpeed = 100;

std::optional<double> number_of(std::string_view field) {
  double value = 0;
  const auto [end, error] = std::from_chars(field.data(), field.data() + field.size(), value);
  if (error != std::errc() || end != field.data() + field.size()) return std::nullopt;
  return value;
}
}  // namespace

std::vector<PathSegment> parse_waypoints(std::string_view text, const std::filesystem::path& file, const Pose& placement) {
  struct Waypoint {
    Vec3 position;
    Real speed;
    bool extrude;
  };
  std::vector<Waypoint> waypoints;
  std::vector<Diagnostic> problems;
  bool seen_data = false;
  for_each_line(text, [&](std::string_view line, int line_number) {
    if (const auto hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    const auto fields = split_words(line, " \t\r,;");
    if (fields.empty()) return;
    auto problem = [&](std::string message) { problems.push_back(Diagnostic{SourceLocation{file.string(), line_number}, std::move(message)}); };
    // A header of words before the first waypoint: no field of it a number (a first waypoint with a
    // typo is an error at its line, not a header).
    if (!seen_data && std::none_of(fields.begin(), fields.end(), [](std::string_view field) { return number_of(field).has_value(); })) {
      seen_data = true;
      return;
    }
    seen_data = true;
    if (fields.size() != 5) {
      problem(fmt::format("expected 5 fields 'x, y, z, speed, extrude' (m, m, m, m/s, 0/1), got {}", fields.size()));
      return;
    }
    double values[4];
    for (int k = 0; k < 4; ++k) {
      const auto value = number_of(fields[std::size_t(k)]);
      if (!value) {
        problem(fmt::format("field {} ('{}') is not a number", k + 1, fields[std::size_t(k)]));
        return;
      }
      values[k] = *value;
      // from_chars reads "nan" and "inf": numbers, but not places.
      if (k < 3 && !(std::abs(*value) <= kLargestCoordinate)) {
        problem(fmt::format("field {} ('{}') must be a finite coordinate within ±{:g} m", k + 1, fields[std::size_t(k)], kLargestCoordinate));
        return;
      }
    }
    if (!(values[3] > 0) || !(values[3] <= kLargestSpeed)) {
      problem(fmt::format("the speed must be > 0 m/s and at most {:g} m/s, got {}", kLargestSpeed, fields[3]));
      return;
    }
    const std::string_view flag = fields[4];
    bool extrude = false;
    if (flag == "1" || flag == "true" || flag == "yes") {
      extrude = true;
    } else if (!(flag == "0" || flag == "false" || flag == "no")) {
      problem(fmt::format("extrude must be 0/1 or true/false, got '{}'", flag));
      return;
    }
    waypoints.push_back(Waypoint{placement.apply(Vec3(Real(values[0]), Real(values[1]), Real(values[2]))), Real(values[3]), extrude});
  });
  if (!problems.empty()) throw InputError(std::move(problems));
  if (waypoints.size() < 2)
    throw InputError(SourceLocation{file.string(), 0}, fmt::format("a waypoint file needs at least two waypoints, found {}", waypoints.size()));
  std::vector<PathSegment> segments;
  for (std::size_t k = 1; k < waypoints.size(); ++k)
    segments.push_back(PathSegment{LineCurve{waypoints[k - 1].position, waypoints[k].position}, waypoints[k].speed, waypoints[k].extrude});
  return segments;
}

std::vector<PathSegment> read_waypoints(const std::filesystem::path& file, const Pose& placement) {
  return parse_waypoints(read_text_file(file, "waypoint file"), file, placement);
}

}  // namespace m3dp::toolpath
