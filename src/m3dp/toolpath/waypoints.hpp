#pragma once
// Hand-made toolpaths: the rectangle wall of N layers that construction printing starts with, and
// waypoint files (CSV) that any script or CAD tool can write.
#include <filesystem>
#include <string_view>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/toolpath/parametric.hpp"

namespace m3dp::toolpath {

/// A rectangular wall: `layers` closed loops around the rectangle [corner, corner + (size_x, size_y)]
/// at heights corner.z + k · layer_height, counter-clockwise seen from above, each starting and
/// ending at `corner`, joined by straight rises at that corner. All in m.
PolylineCurve rectangle_wall(const Vec3& corner, Real size_x, Real size_y, int layers, Real layer_height);

/// Reads a waypoint file: one waypoint per line, `x, y, z, speed, extrude` (m, m, m, m/s, 0/1 or
/// true/false), commas or whitespace between fields; '#' starts a comment; a first line of words
/// (a header such as "x,y,z,speed,extrude") is skipped. The nozzle starts at the first waypoint
/// and moves to each next one in a straight line at that waypoint's speed, extruding if that
/// waypoint says so. `placement` maps the file's frame into the world.
/// Throws InputError naming file:line for a line that cannot be read, or fewer than two waypoints.
std::vector<PathSegment> read_waypoints(const std::filesystem::path& file, const Pose& placement = {});
std::vector<PathSegment> parse_waypoints(std::string_view text, const std::filesystem::path& file, const Pose& placement = {});

}  // namespace m3dp::toolpath
