#include "m3dp/io/particle_reader.hpp"

#include <fmt/format.h>
#include <pugixml.hpp>

#include <bit>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <type_traits>

#include "m3dp/core/error.hpp"

namespace m3dp::io {

namespace fs = std::filesystem;

namespace {

[[noreturn]] void fail(const fs::path& file, int line, const std::string& message) {
  throw InputError(SourceLocation{file.string(), line}, message);
}

std::string read_bytes(const fs::path& file) {
  std::ifstream stream(file, std::ios::binary);
  if (!stream) fail(file, 0, "cannot open the file");
  return {std::istreambuf_iterator<char>(stream), std::istreambuf_iterator<char>()};
}

std::size_t vtk_type_bytes(const std::string& type) {
  if (type == "Float32" || type == "Int32" || type == "UInt32") return 4;
  if (type == "Float64" || type == "Int64" || type == "UInt64") return 8;
  if (type == "Int16" || type == "UInt16") return 2;
  if (type == "Int8" || type == "UInt8") return 1;
  return 0;
}

/// One value of a VTK/PLY binary type (little-endian) as T.
template <class T>
T read_element(const char* bytes, const std::string& type) {
  static_assert(std::endian::native == std::endian::little, "the readers assume a little-endian machine");
  auto as = [&]<class Stored>(Stored) {
    Stored value;
    std::memcpy(&value, bytes, sizeof(Stored));
    return static_cast<T>(value);
  };
  if (type == "Float32") return as(float{});
  if (type == "Float64") return as(double{});
  if (type == "Int8") return as(std::int8_t{});
  if (type == "UInt8") return as(std::uint8_t{});
  if (type == "Int16") return as(std::int16_t{});
  if (type == "UInt16") return as(std::uint16_t{});
  if (type == "Int32") return as(std::int32_t{});
  if (type == "UInt32") return as(std::uint32_t{});
  if (type == "Int64") return as(std::int64_t{});
  return as(std::uint64_t{});
}

Real read_scalar(const char* bytes, const std::string& type) { return read_element<Real>(bytes, type); }

/// The `components` × `count` values of a DataArray, ascii or raw appended (`appended` is where
/// <AppendedData> starts in `bytes`, npos if none).
template <class T>
std::vector<T> read_data_array(const fs::path& file, const pugi::xml_node& array, std::size_t count, int components,
                               const std::string& bytes, std::size_t appended, const std::string& header_type) {
  const std::string name = array.attribute("Name").as_string("points");
  const std::string type = array.attribute("type").as_string();
  if (vtk_type_bytes(type) == 0) fail(file, 0, fmt::format("array '{}' of unknown type '{}'", name, type));
  const std::size_t total = count * static_cast<std::size_t>(components);
  std::vector<T> values(total);
  const std::string format = array.attribute("format").as_string();
  if (format == "ascii") {
    std::istringstream text(array.text().as_string());
    for (std::size_t n = 0; n < total; ++n) {
      std::conditional_t<std::is_floating_point_v<T>, double, long long> value;
      if (!(text >> value)) fail(file, 0, fmt::format("the {} array ends after {} of {} values", name, n, total));
      values[n] = static_cast<T>(value);
    }
  } else if (format == "appended") {
    if (appended == std::string::npos) fail(file, 0, fmt::format("appended {} but no <AppendedData>", name));
    const std::size_t marker = bytes.find('_', appended);
    if (marker == std::string::npos) fail(file, 0, "<AppendedData> without its '_' marker");
    const std::size_t size_bytes = header_type == "UInt64" ? 8 : 4;
    const std::size_t start = marker + 1 + array.attribute("offset").as_ullong() + size_bytes;
    const std::size_t element = vtk_type_bytes(type);
    if (start + total * element > bytes.size()) fail(file, 0, fmt::format("the file ends inside the {} data (truncated?)", name));
    for (std::size_t n = 0; n < total; ++n) values[n] = read_element<T>(bytes.data() + start + n * element, type);
  } else {
    fail(file, 0, fmt::format("{} in '{}' format; expected ascii or raw appended (ParaView: Data Mode Ascii or Appended, "
                              "Encode Appended Data off)", name, format));
  }
  return values;
}

ParticleFrame read_vtk_xml(const fs::path& file) {
  const std::string bytes = read_bytes(file);
  // Raw appended data is not XML: parse the text before it (<AppendedData> is the last child of
  // <VTKFile>) and close the root by hand.
  const std::size_t appended = bytes.find("<AppendedData");
  const std::string xml = appended == std::string::npos ? bytes : bytes.substr(0, appended) + "</VTKFile>";
  pugi::xml_document document;
  const pugi::xml_parse_result parsed = document.load_string(xml.c_str());
  if (!parsed) fail(file, 0, fmt::format("not a VTK XML file: {}", parsed.description()));
  const pugi::xml_node root = document.child("VTKFile");
  if (!root) fail(file, 0, "not a VTK XML file: no <VTKFile> element");
  if (root.attribute("compressor")) fail(file, 0, "compressed VTK files are not supported; save without compression");
  const std::string header_type = root.attribute("header_type").as_string("UInt32");
  const pugi::xml_node dataset = root.child("UnstructuredGrid") ? root.child("UnstructuredGrid") : root.child("PolyData");
  if (!dataset) fail(file, 0, "expected an UnstructuredGrid or PolyData dataset");
  const pugi::xml_node piece = dataset.child("Piece");
  if (!piece) fail(file, 0, "no <Piece> in the dataset");
  const std::size_t count = piece.attribute("NumberOfPoints").as_ullong();
  const pugi::xml_node points = piece.child("Points").child("DataArray");
  if (!points) fail(file, 0, "no <Points> array");
  const std::string type = points.attribute("type").as_string();
  if (type != "Float32" && type != "Float64") fail(file, 0, fmt::format("points of type '{}'; expected Float32 or Float64", type));
  if (points.attribute("NumberOfComponents").as_int(3) != 3) fail(file, 0, "points must have 3 components");

  ParticleFrame frame;
  const std::vector<Real> coordinates = read_data_array<Real>(file, points, count, 3, bytes, appended, header_type);
  frame.positions.resize(count);
  for (std::size_t i = 0; i < count; ++i) frame.positions[i] = Vec3(coordinates[3 * i], coordinates[3 * i + 1], coordinates[3 * i + 2]);
  // Stable particle ids (m3dp run writes them): let a sequence be meshed incrementally.
  for (const pugi::xml_node array : piece.child("PointData").children("DataArray"))
    if (std::string(array.attribute("Name").as_string()) == "id" && array.attribute("NumberOfComponents").as_int(1) == 1)
      frame.ids = read_data_array<std::uint64_t>(file, array, count, 1, bytes, appended, header_type);
  for (const pugi::xml_node array : dataset.child("FieldData").children("DataArray"))
    if (std::string(array.attribute("Name").as_string()) == "particle_radius")
      frame.particle_radius = static_cast<Real>(array.text().as_double());
  return frame;
}

std::size_t ply_type_bytes(const std::string& type) {
  if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
  if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
  if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" || type == "float32") return 4;
  if (type == "double" || type == "float64") return 8;
  return 0;
}

ParticleFrame read_ply_points(const fs::path& file) {
  const std::string bytes = read_bytes(file);
  const std::size_t header_end = bytes.find("end_header");
  if (bytes.rfind("ply", 0) != 0 || header_end == std::string::npos) fail(file, 1, "not a PLY file: expected 'ply' ... 'end_header'");
  std::istringstream header(bytes.substr(0, header_end));
  std::string line, format;
  std::size_t vertex_count = 0;
  bool in_vertex = false, vertex_seen = false;
  struct Property {
    std::string name, type;
  };
  std::vector<Property> properties;
  int line_number = 0;
  while (std::getline(header, line)) {
    ++line_number;
    std::istringstream words(line);
    std::string keyword;
    words >> keyword;
    if (keyword == "format") {
      words >> format;
      if (format != "ascii" && format != "binary_little_endian")
        fail(file, line_number, fmt::format("PLY format '{}' is not supported; expected ascii or binary_little_endian", format));
    } else if (keyword == "element") {
      std::string name;
      words >> name;
      if (name == "vertex") {
        if (vertex_seen) fail(file, line_number, "a second vertex element");
        words >> vertex_count;
        in_vertex = vertex_seen = true;
      } else {
        if (!vertex_seen) fail(file, line_number, fmt::format("element '{}' before 'vertex'; expected vertex first", name));
        in_vertex = false;
      }
    } else if (keyword == "property" && in_vertex) {
      Property property;
      words >> property.type >> property.name;
      if (property.type == "list") fail(file, line_number, "a list property on vertices is not supported");
      if (ply_type_bytes(property.type) == 0) fail(file, line_number, fmt::format("unknown PLY type '{}'", property.type));
      properties.push_back(property);
    }
  }
  int axis_property[3] = {-1, -1, -1};
  for (std::size_t p = 0; p < properties.size(); ++p)
    for (int k = 0; k < 3; ++k)
      if (properties[p].name == std::string(1, char('x' + k))) axis_property[k] = static_cast<int>(p);
  if (!vertex_seen || axis_property[0] < 0 || axis_property[1] < 0 || axis_property[2] < 0)
    fail(file, 0, "expected a vertex element with x, y and z properties");

  ParticleFrame frame;
  frame.positions.resize(vertex_count);
  const std::size_t data = bytes.find('\n', header_end) + 1;
  if (format == "ascii") {
    std::istringstream values(bytes.substr(data));
    for (std::size_t i = 0; i < vertex_count; ++i)
      for (std::size_t p = 0; p < properties.size(); ++p) {
        double value;
        if (!(values >> value)) fail(file, 0, fmt::format("vertex {} of {} is incomplete", i + 1, vertex_count));
        for (int k = 0; k < 3; ++k)
          if (axis_property[k] == static_cast<int>(p)) frame.positions[i][k] = static_cast<Real>(value);
      }
    return frame;
  }
  std::size_t stride = 0;
  std::vector<std::size_t> offset(properties.size());
  for (std::size_t p = 0; p < properties.size(); ++p) {
    offset[p] = stride;
    stride += ply_type_bytes(properties[p].type);
  }
  if (data + vertex_count * stride > bytes.size()) fail(file, 0, "the file ends inside the vertex data (truncated?)");
  for (int k = 0; k < 3; ++k) {
    const Property& property = properties[axis_property[k]];
    if (property.type != "float" && property.type != "float32" && property.type != "double" && property.type != "float64")
      fail(file, 0, fmt::format("vertex coordinate '{}' of type '{}'; expected float or double", property.name, property.type));
  }
  for (std::size_t i = 0; i < vertex_count; ++i)
    for (int k = 0; k < 3; ++k) {
      const Property& property = properties[axis_property[k]];
      frame.positions[i][k] = read_scalar(bytes.data() + data + i * stride + offset[axis_property[k]],
                                          ply_type_bytes(property.type) == 4 ? "Float32" : "Float64");
    }
  return frame;
}

}  // namespace

ParticleFrame read_particle_frame(const fs::path& file) {
  const std::string extension = file.extension().string();
  if (extension == ".vtu" || extension == ".vtp") return read_vtk_xml(file);
  if (extension == ".ply") return read_ply_points(file);
  fail(file, 0, fmt::format("unsupported particle file extension '{}'; expected .vtu, .vtp, .ply or a .pvd collection", extension));
}

std::vector<CollectionEntry> read_pvd(const fs::path& file) {
  pugi::xml_document document;
  const pugi::xml_parse_result parsed = document.load_file(file.c_str());
  if (!parsed) fail(file, 0, fmt::format("not a ParaView collection: {}", parsed.description()));
  const pugi::xml_node collection = document.child("VTKFile").child("Collection");
  if (!collection) fail(file, 0, "expected <VTKFile type=\"Collection\"><Collection>");
  std::vector<CollectionEntry> entries;
  for (const pugi::xml_node dataset : collection.children("DataSet")) {
    const char* name = dataset.attribute("file").as_string();
    if (*name == '\0') fail(file, 0, "a <DataSet> without a file attribute");
    entries.push_back({dataset.attribute("timestep").as_double(), file.parent_path() / name});
  }
  return entries;
}

}  // namespace m3dp::io
