#include "m3dp/io/vtk_writer.hpp"

#include <fmt/format.h>

#include <numeric>

#include "m3dp/core/error.hpp"
#include "m3dp/io/atomic_file.hpp"

namespace m3dp::io {

namespace {
constexpr const char* kRealType = sizeof(Real) == 4 ? "Float32" : "Float64";
}

PointArray PointArray::of(std::string name, std::span<const Real> values) {
  return {std::move(name), kRealType, 1, values.data(), sizeof(Real)};
}
PointArray PointArray::of(std::string name, std::span<const Vec3> values) {
  static_assert(sizeof(Vec3) == 3 * sizeof(Real), "Vec3 must be tightly packed");
  return {std::move(name), kRealType, 3, values.data(), sizeof(Real)};
}
PointArray PointArray::of(std::string name, std::span<const std::uint16_t> values) {
  return {std::move(name), "UInt16", 1, values.data(), sizeof(std::uint16_t)};
}
PointArray PointArray::of(std::string name, std::span<const std::uint64_t> values) {
  return {std::move(name), "UInt64", 1, values.data(), sizeof(std::uint64_t)};
}

void write_vtu(const std::filesystem::path& file, std::span<const Vec3> points, const std::vector<PointArray>& arrays,
               const std::vector<FieldValue>& field_data) {
  const std::uint64_t count = points.size();
  // Appended blocks: each is a UInt64 byte count followed by the bytes.
  struct Block {
    const void* data;
    std::uint64_t bytes;
  };
  std::vector<Block> blocks;
  std::string header;
  std::uint64_t offset = 0;
  auto add_block = [&](const void* data, std::uint64_t bytes) {
    blocks.push_back({data, bytes});
    const std::uint64_t this_offset = offset;
    offset += sizeof(std::uint64_t) + bytes;
    return this_offset;
  };

  // Cells: one VTK_VERTEX per particle, so ParaView shows points without a filter.
  std::vector<std::int64_t> connectivity(count);
  std::iota(connectivity.begin(), connectivity.end(), std::int64_t(0));
  std::vector<std::int64_t> cell_offsets(count);
  std::iota(cell_offsets.begin(), cell_offsets.end(), std::int64_t(1));
  const std::vector<std::uint8_t> cell_types(count, 1);

  header += "<?xml version=\"1.0\"?>\n";
  header += "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n";
  header += "  <UnstructuredGrid>\n";
  if (!field_data.empty()) {
    header += "    <FieldData>\n";
    for (const auto& field : field_data)
      header += fmt::format("      <DataArray type=\"Float64\" Name=\"{}\" NumberOfTuples=\"1\" format=\"ascii\">{:.17g}</DataArray>\n",
                            field.name, field.value);
    header += "    </FieldData>\n";
  }
  header += fmt::format("    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n", count, count);
  header += "      <PointData>\n";
  for (const auto& array : arrays) {
    const std::uint64_t bytes = count * array.components * array.element_bytes;
    header += fmt::format(
        "        <DataArray type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\" format=\"appended\" offset=\"{}\"/>\n",
        array.vtk_type, array.name, array.components, add_block(array.data, bytes));
  }
  header += "      </PointData>\n      <Points>\n";
  header += fmt::format("        <DataArray type=\"{}\" NumberOfComponents=\"3\" format=\"appended\" offset=\"{}\"/>\n",
                        kRealType, add_block(points.data(), count * sizeof(Vec3)));
  header += "      </Points>\n      <Cells>\n";
  header += fmt::format("        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"appended\" offset=\"{}\"/>\n",
                        add_block(connectivity.data(), count * sizeof(std::int64_t)));
  header += fmt::format("        <DataArray type=\"Int64\" Name=\"offsets\" format=\"appended\" offset=\"{}\"/>\n",
                        add_block(cell_offsets.data(), count * sizeof(std::int64_t)));
  header += fmt::format("        <DataArray type=\"UInt8\" Name=\"types\" format=\"appended\" offset=\"{}\"/>\n",
                        add_block(cell_types.data(), count * sizeof(std::uint8_t)));
  header += "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _";

  write_file_atomically(
      file,
      [&](std::ostream& stream) {
        stream.write(header.data(), static_cast<std::streamsize>(header.size()));
        for (const Block& block : blocks) {
          stream.write(reinterpret_cast<const char*>(&block.bytes), sizeof(block.bytes));
          if (block.bytes > 0) stream.write(static_cast<const char*>(block.data), static_cast<std::streamsize>(block.bytes));
        }
        stream << "\n  </AppendedData>\n</VTKFile>\n";
      },
      true);
}

void PvdCollection::add(double time, const std::filesystem::path& dataset_file) {
  entries_.push_back({time, std::filesystem::relative(dataset_file, file_.parent_path()).generic_string()});
  std::string text = "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n";
  for (const auto& entry : entries_)
    text += fmt::format("    <DataSet timestep=\"{:.9g}\" group=\"\" part=\"0\" file=\"{}\"/>\n", entry.time, entry.relative_file);
  text += "  </Collection>\n</VTKFile>\n";
  write_text_atomically(file_, text);
}

}  // namespace m3dp::io
