#pragma once
// Collision shapes as triangles, for what draws them (world.pvd, recordings, the viewer): boxes,
// spheres, cylinders and planes are tessellated in the shape's frame; meshes are their own.
#include "m3dp/core/geometry.hpp"

namespace m3dp {

/// The shape's surface, counter-clockwise seen from outside; round shapes in `segments` around
/// (at least 3). A plane is its finite patch, facing along its normal.
TriangleMesh tessellate(const Shape& shape, int segments = 24);

/// `mesh`'s vertices moved by `pose`, appended to `out` (its triangles renumbered after out's).
void append_transformed(const TriangleMesh& mesh, const Pose& pose, TriangleMesh& out);

}  // namespace m3dp
