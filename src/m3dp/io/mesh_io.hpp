#pragma once
// Triangle mesh files: reading OBJ and STL (ASCII and binary) for collision geometry; writing
// OBJ, binary PLY and binary STL, and Gazebo model folders, for reconstructed surfaces.
#include <filesystem>
#include <string>

#include "m3dp/core/geometry.hpp"

namespace m3dp::io {

/// Reads an .obj or .stl (ASCII or binary) file. Throws InputError naming file:line on bad content,
/// and an InputError naming the file when it cannot be opened or has an unknown extension.
TriangleMesh read_triangle_mesh(const std::filesystem::path& file);

/// True for the extensions write_triangle_mesh knows: .obj, .ply, .stl.
bool is_writable_mesh_extension(const std::filesystem::path& file);

/// Writes `mesh` as .obj (text), .ply (binary little-endian) or .stl (binary), chosen by the
/// extension, to a temporary name and renames it. Coordinates in metres; no paths inside.
void write_triangle_mesh(const std::filesystem::path& file, const TriangleMesh& mesh);

/// A Gazebo model folder a world can <include>: model.config, model.sdf (one static link whose
/// visual and collision are the mesh) and meshes/<model_name>.stl, referenced as
/// model://<model_name>/meshes/<model_name>.stl (no absolute path).
void write_sdf_model(const std::filesystem::path& folder, const std::string& model_name, const TriangleMesh& mesh);

}  // namespace m3dp::io
