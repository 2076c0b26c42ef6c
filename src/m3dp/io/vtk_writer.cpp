#include "m3dp/io/vtk_writer.hpp"

#include <fmt/format.h>

#include <numeric>

#include "m3dp/core/error.hpp"
#include "m3dp/io/atomic_file.hpp"
#include "m3dp/io/vtk_binary.hpp"

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
PointArray PointArray::of(std::string name, std::span<const std::uint8_t> values) {
  return {std::move(name), "UInt8", 1, values.data(), sizeof(std::uint8_t)};
}
PointArray PointArray::of(std::string name, std::span<const std::int32_t> values) {
  return {std::move(name), "Int32", 1, values.data(), sizeof(std::int32_t)};
}

void write_vtu(const std::filesystem::path& file, std::span<const Vec3> points, const std::vector<PointArray>& arrays,
               const std::vector<FieldValue>& field_data, const VtuEncoding& encoding) {
  const std::uint64_t count = points.size();
  // Every array inline (format="binary"): the file is XML from start to end, which every expat
  // parses; appended data is not (see docs/architecture.md). The arrays are encoded together.
  std::vector<std::string> attributes;
  std::vector<std::string_view> payloads;
  auto add_array = [&](std::string attribute, const void* data, std::uint64_t bytes) {
    attributes.push_back(std::move(attribute));
    payloads.emplace_back(static_cast<const char*>(data), bytes);
  };
  std::size_t next_array = 0;
  std::vector<std::string> encoded;
  std::string text;
  auto write_array = [&] {
    text += fmt::format("        <DataArray {} format=\"binary\">\n", attributes[next_array]);
    text += encoded[next_array++];
    text += "\n        </DataArray>\n";
  };

  // Cells: one VTK_VERTEX per particle, so ParaView shows points without a filter.
  std::vector<std::int64_t> connectivity(count);
  std::iota(connectivity.begin(), connectivity.end(), std::int64_t(0));
  std::vector<std::int64_t> cell_offsets(count);
  std::iota(cell_offsets.begin(), cell_offsets.end(), std::int64_t(1));
  const std::vector<std::uint8_t> cell_types(count, 1);

  for (const auto& array : arrays)
    add_array(fmt::format("type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\"", array.vtk_type, array.name, array.components),
              array.data, count * array.components * array.element_bytes);
  add_array(fmt::format("type=\"{}\" NumberOfComponents=\"3\"", kRealType), points.data(), count * sizeof(Vec3));
  add_array("type=\"Int64\" Name=\"connectivity\"", connectivity.data(), count * sizeof(std::int64_t));
  add_array("type=\"Int64\" Name=\"offsets\"", cell_offsets.data(), count * sizeof(std::int64_t));
  add_array("type=\"UInt8\" Name=\"types\"", cell_types.data(), count * sizeof(std::uint8_t));
  encoded = encode_vtk_arrays(payloads, encoding.zlib_level);

  text += "<?xml version=\"1.0\"?>\n";
  text += fmt::format("<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\"{}>\n",
                      encoding.zlib_level >= 0 ? " compressor=\"vtkZLibDataCompressor\"" : "");
  text += "  <UnstructuredGrid>\n";
  if (!field_data.empty()) {
    text += "    <FieldData>\n";
    for (const auto& field : field_data)
      text += fmt::format("      <DataArray type=\"Float64\" Name=\"{}\" NumberOfTuples=\"1\" format=\"ascii\">{:.17g}</DataArray>\n",
                          field.name, field.value);
    text += "    </FieldData>\n";
  }
  text += fmt::format("    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">\n", count, count);
  text += "      <PointData>\n";
  for (std::size_t a = 0; a < arrays.size(); ++a) write_array();
  text += "      </PointData>\n      <Points>\n";
  write_array();
  text += "      </Points>\n      <Cells>\n";
  for (int cell_array = 0; cell_array < 3; ++cell_array) write_array();
  text += "      </Cells>\n    </Piece>\n  </UnstructuredGrid>\n</VTKFile>\n";
  write_text_atomically(file, text);
}

void write_vtp(const std::filesystem::path& file, const PolyData& poly_data, const VtuEncoding& encoding) {
  const std::size_t point_count = poly_data.points.size();
  // VTK's cells: connectivity and end offsets, as Int64.
  std::vector<std::int64_t> triangle_points, triangle_ends, line_points, line_ends;
  triangle_points.reserve(3 * poly_data.triangles.size());
  for (const auto& triangle : poly_data.triangles) {
    for (const Index vertex : triangle) {
      if (vertex >= point_count) throw Error(fmt::format("{}: triangle vertex {} of {} points", file.string(), vertex, point_count));
      triangle_points.push_back(vertex);
    }
    triangle_ends.push_back(static_cast<std::int64_t>(triangle_points.size()));
  }
  for (const Index vertex : poly_data.line_points) {
    if (vertex >= point_count) throw Error(fmt::format("{}: line vertex {} of {} points", file.string(), vertex, point_count));
    line_points.push_back(vertex);
  }
  for (const Index end : poly_data.line_ends) line_ends.push_back(end);

  std::vector<std::string> attributes;
  std::vector<std::string_view> payloads;
  auto add_array = [&](std::string attribute, const void* data, std::size_t bytes) {
    attributes.push_back(std::move(attribute));
    payloads.emplace_back(static_cast<const char*>(data), bytes);
  };
  for (const auto& array : poly_data.point_arrays)
    add_array(fmt::format("type=\"{}\" Name=\"{}\" NumberOfComponents=\"{}\"", array.vtk_type, array.name, array.components),
              array.data, point_count * array.components * array.element_bytes);
  add_array(fmt::format("type=\"{}\" NumberOfComponents=\"3\"", kRealType), poly_data.points.data(), point_count * sizeof(Vec3));
  add_array("type=\"Int64\" Name=\"connectivity\"", line_points.data(), line_points.size() * sizeof(std::int64_t));
  add_array("type=\"Int64\" Name=\"offsets\"", line_ends.data(), line_ends.size() * sizeof(std::int64_t));
  add_array("type=\"Int64\" Name=\"connectivity\"", triangle_points.data(), triangle_points.size() * sizeof(std::int64_t));
  add_array("type=\"Int64\" Name=\"offsets\"", triangle_ends.data(), triangle_ends.size() * sizeof(std::int64_t));
  const std::vector<std::string> encoded = encode_vtk_arrays(payloads, encoding.zlib_level);
  std::size_t next_array = 0;
  std::string text;
  auto write_array = [&] {
    text += fmt::format("        <DataArray {} format=\"binary\">\n", attributes[next_array]);
    text += encoded[next_array++];
    text += "\n        </DataArray>\n";
  };

  text += "<?xml version=\"1.0\"?>\n";
  text += fmt::format("<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\"{}>\n",
                      encoding.zlib_level >= 0 ? " compressor=\"vtkZLibDataCompressor\"" : "");
  text += "  <PolyData>\n";
  if (!poly_data.field_data.empty()) {
    text += "    <FieldData>\n";
    for (const auto& field : poly_data.field_data) {
      text += fmt::format("      <DataArray type=\"Float64\" Name=\"{}\" NumberOfComponents=\"{}\" NumberOfTuples=\"1\" format=\"ascii\">",
                          field.name, field.values.size());
      for (std::size_t v = 0; v < field.values.size(); ++v) text += fmt::format("{}{:.17g}", v ? " " : "", field.values[v]);
      text += "</DataArray>\n";
    }
    text += "    </FieldData>\n";
  }
  text += fmt::format("    <Piece NumberOfPoints=\"{}\" NumberOfVerts=\"0\" NumberOfLines=\"{}\" NumberOfStrips=\"0\" NumberOfPolys=\"{}\">\n",
                      point_count, line_ends.size(), triangle_ends.size());
  text += "      <PointData>\n";
  for (std::size_t a = 0; a < poly_data.point_arrays.size(); ++a) write_array();
  text += "      </PointData>\n      <Points>\n";
  write_array();
  text += "      </Points>\n      <Lines>\n";
  write_array();
  write_array();
  text += "      </Lines>\n      <Polys>\n";
  write_array();
  write_array();
  text += "      </Polys>\n    </Piece>\n  </PolyData>\n</VTKFile>\n";
  write_text_atomically(file, text);
}

namespace {
/// Text as an XML attribute value.
std::string xml_attribute(std::string_view text) {
  std::string escaped;
  for (const char c : text) {
    switch (c) {
      case '&': escaped += "&amp;"; break;
      case '<': escaped += "&lt;"; break;
      case '>': escaped += "&gt;"; break;
      case '"': escaped += "&quot;"; break;
      default: escaped += c;
    }
  }
  return escaped;
}
}  // namespace

void write_vtm(const std::filesystem::path& file, const std::vector<Block>& blocks) {
  std::string text = "<?xml version=\"1.0\"?>\n<VTKFile type=\"vtkMultiBlockDataSet\" version=\"1.0\" byte_order=\"LittleEndian\">\n";
  text += "  <vtkMultiBlockDataSet>\n";
  for (std::size_t b = 0; b < blocks.size(); ++b)
    text += fmt::format("    <DataSet index=\"{}\" name=\"{}\" file=\"{}\"/>\n", b, xml_attribute(blocks[b].name),
                        xml_attribute(std::filesystem::relative(blocks[b].file, file.parent_path()).generic_string()));
  text += "  </vtkMultiBlockDataSet>\n</VTKFile>\n";
  write_text_atomically(file, text);
}

void PvdCollection::add(double time, const std::filesystem::path& dataset_file) {
  entries_.push_back({time, std::filesystem::relative(dataset_file, file_.parent_path()).generic_string()});
  write();
}

void PvdCollection::save(StateWriter& out) const {
  out.put(static_cast<std::uint64_t>(entries_.size()));
  for (const Entry& entry : entries_) {
    out.put(entry.time);
    out.put(entry.relative_file);
  }
}

void PvdCollection::load(StateReader& in) {
  const auto count = in.get<std::uint64_t>();
  if (count > in.remaining()) in.fail("a time series longer than the file");
  entries_.resize(count);
  for (Entry& entry : entries_) {
    in.get(entry.time);
    in.get(entry.relative_file);
  }
  write();
}

void PvdCollection::write() const {
  std::string text = "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n  <Collection>\n";
  for (const auto& entry : entries_)
    text += fmt::format("    <DataSet timestep=\"{:.9g}\" group=\"\" part=\"0\" file=\"{}\"/>\n", entry.time, entry.relative_file);
  text += "  </Collection>\n</VTKFile>\n";
  write_text_atomically(file_, text);
}

}  // namespace m3dp::io
