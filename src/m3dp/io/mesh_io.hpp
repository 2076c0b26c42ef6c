#pragma once
// Triangle mesh files: reading OBJ and STL (ASCII and binary) for collision geometry; writing
// OBJ, binary PLY and binary STL, and Gazebo model folders, for reconstructed surfaces.
#include <filesystem>
#include <ostream>
#include <span>
#include <string>
#include <string_view>

#include "m3dp/core/geometry.hpp"

namespace m3dp::io {

/// A triangle mesh file format. The one table of them (mesh_formats()) is where the scene's
/// <meshing><format>, the CLI's --format and the readers and writers here take theirs from: a new
/// format is its writer (and reader) and one row.
struct MeshFormat {
  std::string_view name;          // as scenes and --format say it: "ply"
  std::string_view extension;     // ".ply"
  std::string_view description;   // "binary PLY"
  bool binary = true;
  void (*write)(std::ostream& stream, const TriangleMesh& mesh) = nullptr;
  TriangleMesh (*read)(const std::filesystem::path& file) = nullptr;  // null where M3DP does not read it
};
[[nodiscard]] std::span<const MeshFormat> mesh_formats();
/// The format called `name`, or null.
[[nodiscard]] const MeshFormat* find_mesh_format(std::string_view name);
/// The format of a file by its extension (any case), or null.
[[nodiscard]] const MeshFormat* mesh_format_of(const std::filesystem::path& file);
/// "obj, ply, stl" (the readable ones only, if asked), for messages and --help.
[[nodiscard]] std::string mesh_format_names(bool readable_only = false);

/// Reads an .obj or .stl (ASCII or binary) file. Throws InputError naming file:line on bad content,
/// and an InputError naming the file when it cannot be opened or has an unknown extension.
TriangleMesh read_triangle_mesh(const std::filesystem::path& file);

/// Writes `mesh` as .obj (text), .ply (binary little-endian) or .stl (binary), chosen by the
/// extension, to a temporary name and renames it. Coordinates in metres; no paths inside.
void write_triangle_mesh(const std::filesystem::path& file, const TriangleMesh& mesh);

/// A binary PLY with a float per-vertex property "quality" (MeshLab colours by it: Render → Color
/// → Per Vertex Quality), atomically; `comment` (one line) says what it is.
void write_ply_with_quality(const std::filesystem::path& file, const TriangleMesh& mesh, std::span<const float> quality,
                            std::string_view comment);

/// A Gazebo model folder a world can <include>: model.config, model.sdf (one static link whose
/// visual and collision are the mesh) and meshes/<model_name>.stl, referenced as
/// model://<model_name>/meshes/<model_name>.stl (no absolute path).
void write_sdf_model(const std::filesystem::path& folder, const std::string& model_name, const TriangleMesh& mesh);

}  // namespace m3dp::io
