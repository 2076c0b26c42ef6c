#pragma once
// What DART's URDF loader (urdfdom) would refuse or silently drop, found before it runs and reported
// at the URDF's own lines: `m3dp validate` needs no physics engine, and urdfdom's messages name
// neither the file nor the line.
#include <pugixml.hpp>

#include <cstddef>
#include <filesystem>
#include <functional>
#include <vector>

#include "m3dp/core/error.hpp"

namespace m3dp::scene {

/// Checks a URDF's <robot> element: link and joint names (unique, present), joint types, parents
/// and children (one tree, one root), numbers (finite; masses and sizes > 0), geometry and mesh
/// files (found, relative to the URDF). `line_of` maps a node's byte offset to its line.
std::vector<Diagnostic> check_urdf(const pugi::xml_node& robot, const std::filesystem::path& file,
                                   const std::function<int(std::ptrdiff_t)>& line_of);

}  // namespace m3dp::scene
