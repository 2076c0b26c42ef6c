#pragma once
// Reading particle frames back for offline work (m3dp mesh): VTK XML UnstructuredGrid / PolyData
// (.vtu/.vtp: ascii, inline binary, appended raw or base64, uncompressed or zlib-compressed, as
// m3dp, ParaView and VTK write them), PLY point sets (ASCII or binary little-endian)
// and ParaView collections (.pvd) of such files.
#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "m3dp/core/types.hpp"

namespace m3dp::io {

struct ParticleFrame {
  std::vector<Vec3> positions;          // m
  std::optional<Real> particle_radius;  // m, from the file's FieldData "particle_radius" when present
  std::vector<std::uint64_t> ids;       // stable particle ids, from a point array "id" (.vtu/.vtp); empty if none
  std::vector<std::uint16_t> material;  // each particle's material index, from "material" (m3dp run writes it); empty if none
  std::vector<Real> birth_time;         // s, from "birth_time"; empty if none
  std::vector<std::int32_t> layer;      // print layer (0 first, -1 none), from "layer"; empty if none
};

/// Reads positions from a .vtu, .vtp or .ply file. Throws InputError naming the file (and line
/// where there is one) for anything it cannot read, saying what it expected.
ParticleFrame read_particle_frame(const std::filesystem::path& file);

struct CollectionEntry {
  double time = 0;                  // s
  std::filesystem::path file;       // resolved against the .pvd's folder
};
/// The datasets of a ParaView .pvd collection in file order.
std::vector<CollectionEntry> read_pvd(const std::filesystem::path& file);

/// The blocks of a VTK multiblock file (.vtm, as world.pvd's frames): each name and its file,
/// resolved against the .vtm's folder.
struct NamedBlock {
  std::string name;
  std::filesystem::path file;
};
std::vector<NamedBlock> read_vtm(const std::filesystem::path& file);
/// A VTK XML file's FieldData arrays written as ascii (e.g. a world block's position and
/// orientation_wxyz), by name.
std::map<std::string, std::vector<double>> read_field_data(const std::filesystem::path& file);

}  // namespace m3dp::io
