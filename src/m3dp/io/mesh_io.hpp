#pragma once
// Triangle mesh files: reading OBJ and STL (ASCII and binary) for collision geometry.
#include <filesystem>

#include "m3dp/core/geometry.hpp"

namespace m3dp::io {

/// Reads an .obj or .stl (ASCII or binary) file. Throws InputError naming file:line on bad content,
/// and an InputError naming the file when it cannot be opened or has an unknown extension.
TriangleMesh read_triangle_mesh(const std::filesystem::path& file);

}  // namespace m3dp::io
