#pragma once
// Collision shapes as the scene describes them (SDF geometry), in the shape's own frame.
// Shared by the particle engine (boundary sampling) and later the world and cameras.
#include <array>
#include <string>
#include <variant>
#include <vector>

#include "m3dp/core/types.hpp"

namespace m3dp {

struct TriangleMesh {
  std::vector<Vec3> vertices;                  // m
  std::vector<std::array<Index, 3>> triangles;  // counter-clockwise seen from outside
};

struct BoxShape {
  Vec3 size = Vec3::Ones();  // full edge lengths (m), centred on the origin
};
struct SphereShape {
  Real radius = 1;  // m
};
struct CylinderShape {
  Real radius = 1;  // m
  Real length = 1;  // m, along the local z axis, centred on the origin
};
/// A finite plane patch through the origin (SDF <plane>): normal and edge lengths along two in-plane axes.
struct PlaneShape {
  Vec3 normal = Vec3::UnitZ();
  Real size_x = 1;  // m
  Real size_y = 1;  // m
};
struct MeshShape {
  std::string file;  // path as resolved when loading
  TriangleMesh mesh;  // already scaled
};

using Shape = std::variant<BoxShape, SphereShape, CylinderShape, PlaneShape, MeshShape>;

}  // namespace m3dp
