#include "m3dp/io/particle_reader.hpp"

#include <cmath>
#include <fmt/format.h>
#include <pugixml.hpp>

#include <bit>
#include <cctype>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <type_traits>

#include "m3dp/core/error.hpp"
#include "m3dp/io/vtk_binary.hpp"

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

/// Where a file's binary arrays are and how they are stored.
struct BinaryLayout {
  const std::string* bytes = nullptr;   // the whole file
  std::size_t appended = std::string::npos;  // first byte after <AppendedData>'s '_', npos if none
  VtkPayloadFormat appended_format;     // base64 or raw; zlib and header size as the root says
  VtkPayloadFormat inline_format;       // format="binary": always base64
};

/// The `components` × `count` values of a DataArray: ascii, inline binary (base64) or appended
/// (raw or base64), each uncompressed or compressed by vtkZLibDataCompressor.
template <class T>
std::vector<T> read_data_array(const fs::path& file, const pugi::xml_node& array, std::size_t count, int components,
                               const BinaryLayout& layout) {
  const std::string name = array.attribute("Name").as_string("points");
  const std::string type = array.attribute("type").as_string();
  const std::size_t element = vtk_type_bytes(type);
  if (element == 0) fail(file, 0, fmt::format("array '{}' of unknown type '{}'", name, type));
  // Nothing is allocated for a count the array cannot hold: ascii takes at least two characters a
  // value, binary its decoded bytes (checked below, before the values are made).
  if (count > std::numeric_limits<std::size_t>::max() / 16 / static_cast<std::size_t>(components))
    fail(file, 0, fmt::format("{} points cannot be right", count));
  const std::size_t total = count * static_cast<std::size_t>(components);
  const std::string format = array.attribute("format").as_string();
  if (format == "ascii") {
    const std::string_view characters = array.text().as_string();
    if (total > characters.size() / 2 + 1)
      fail(file, 0, fmt::format("the {} array's {} characters cannot hold {} values", name, characters.size(), total));
    std::vector<T> values(total);
    std::istringstream text{std::string(characters)};
    for (std::size_t n = 0; n < total; ++n) {
      std::conditional_t<std::is_floating_point_v<T>, double, long long> value;
      if (!(text >> value)) fail(file, 0, fmt::format("the {} array ends after {} of {} values", name, n, total));
      values[n] = static_cast<T>(value);
    }
    return values;
  }
  std::string decoded, error;
  if (format == "appended") {
    if (layout.appended == std::string::npos) fail(file, 0, fmt::format("appended {} but no <AppendedData>", name));
    const std::size_t start = layout.appended + array.attribute("offset").as_ullong();
    if (start > layout.bytes->size()) fail(file, 0, fmt::format("the {} array's offset is past the end of the file (truncated?)", name));
    if (!decode_vtk_array(std::string_view(*layout.bytes).substr(start), layout.appended_format, decoded, error))
      fail(file, 0, fmt::format("array {}: {}", name, error));
  } else if (format == "binary") {
    std::string text = array.text().as_string();
    std::erase_if(text, [](char character) { return std::isspace(static_cast<unsigned char>(character)) != 0; });
    if (!decode_vtk_array(text, layout.inline_format, decoded, error))
      fail(file, 0, fmt::format("array {}: {}", name, error));
  } else {
    fail(file, 0, fmt::format("{} in '{}' format; expected ascii, binary or appended", name, format));
  }
  if (decoded.size() < total * element)
    fail(file, 0, fmt::format("the {} array holds {} bytes, {} values of {} need {}", name, decoded.size(), total, type, total * element));
  std::vector<T> values(total);
  for (std::size_t n = 0; n < total; ++n) values[n] = read_element<T>(decoded.data() + n * element, type);
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
  BinaryLayout layout;
  layout.bytes = &bytes;
  if (const std::string compressor = root.attribute("compressor").as_string(); !compressor.empty()) {
    if (compressor != "vtkZLibDataCompressor")
      fail(file, 0, fmt::format("compressor '{}' is not supported; expected vtkZLibDataCompressor or none", compressor));
    layout.appended_format.zlib = layout.inline_format.zlib = true;
  }
  const std::string header_type = root.attribute("header_type").as_string("UInt32");
  if (header_type != "UInt32" && header_type != "UInt64") fail(file, 0, fmt::format("header_type '{}'; expected UInt32 or UInt64", header_type));
  layout.appended_format.header_bytes = layout.inline_format.header_bytes = header_type == "UInt64" ? 8 : 4;
  if (std::string(root.attribute("byte_order").as_string("LittleEndian")) != "LittleEndian")
    fail(file, 0, "big-endian VTK files are not supported; expected byte_order=\"LittleEndian\"");
  if (appended != std::string::npos) {
    const std::size_t tag_end = bytes.find('>', appended);
    const std::size_t marker = tag_end == std::string::npos ? tag_end : bytes.find('_', tag_end);
    if (marker == std::string::npos) fail(file, 0, "<AppendedData> without its '_' marker");
    layout.appended = marker + 1;
    const std::string tag = bytes.substr(appended, tag_end - appended);
    if (tag.find("encoding=\"raw\"") != std::string::npos) layout.appended_format.base64 = false;
    else if (tag.find("encoding=\"base64\"") == std::string::npos) fail(file, 0, "<AppendedData> encoding must be raw or base64");
  }
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
  const std::vector<Real> coordinates = read_data_array<Real>(file, points, count, 3, layout);
  frame.positions.resize(count);
  for (std::size_t i = 0; i < count; ++i) frame.positions[i] = Vec3(coordinates[3 * i], coordinates[3 * i + 1], coordinates[3 * i + 2]);
  // Stable particle ids (m3dp run writes them): let a sequence be meshed incrementally.
  // Material and layer: what cameras draw a saved run's particles by (m3dp render).
  for (const pugi::xml_node array : piece.child("PointData").children("DataArray")) {
    const std::string name = array.attribute("Name").as_string();
    if (array.attribute("NumberOfComponents").as_int(1) != 1) continue;
    if (name == "id") frame.ids = read_data_array<std::uint64_t>(file, array, count, 1, layout);
    else if (name == "material") frame.material = read_data_array<std::uint16_t>(file, array, count, 1, layout);
    else if (name == "birth_time") frame.birth_time = read_data_array<Real>(file, array, count, 1, layout);
    else if (name == "layer") frame.layer = read_data_array<std::int32_t>(file, array, count, 1, layout);
  }
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
  if (format.empty()) fail(file, 0, "a PLY header without its 'format' line; expected ascii or binary_little_endian");
  int axis_property[3] = {-1, -1, -1};
  for (std::size_t p = 0; p < properties.size(); ++p)
    for (int k = 0; k < 3; ++k)
      if (properties[p].name == std::string(1, char('x' + k))) axis_property[k] = static_cast<int>(p);
  if (!vertex_seen || axis_property[0] < 0 || axis_property[1] < 0 || axis_property[2] < 0)
    fail(file, 0, "expected a vertex element with x, y and z properties");

  // Nothing is allocated for a count the data cannot hold: ascii takes at least two characters a
  // value, binary a record of its properties' bytes a vertex.
  const std::size_t data_start = bytes.find('\n', header_end);
  const std::size_t data = data_start == std::string::npos ? bytes.size() : data_start + 1;
  const std::size_t data_bytes = bytes.size() - data;
  std::size_t stride = 0;
  std::vector<std::size_t> offset(properties.size());
  for (std::size_t p = 0; p < properties.size(); ++p) {
    offset[p] = stride;
    stride += ply_type_bytes(properties[p].type);
  }
  const std::size_t capacity = format == "ascii" ? (data_bytes / 2 + 1) / properties.size() : data_bytes / stride;
  if (vertex_count > capacity)
    fail(file, 0, fmt::format("{} vertices declared, but the {} bytes after the header hold at most {} (truncated?)",
                              vertex_count, data_bytes, capacity));

  ParticleFrame frame;
  frame.positions.resize(vertex_count);
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
  ParticleFrame frame;
  if (extension == ".vtu" || extension == ".vtp") frame = read_vtk_xml(file);
  else if (extension == ".ply") frame = read_ply_points(file);
  else fail(file, 0, fmt::format("unsupported particle file extension '{}'; expected .vtu, .vtp, .ply or a .pvd collection", extension));
  // A NaN or infinite position would poison a surface grid or a renderer's bounds downstream.
  for (std::size_t i = 0; i < frame.positions.size(); ++i)
    if (!frame.positions[i].allFinite()) fail(file, 0, fmt::format("particle {} is not at a finite position", i));
  if (frame.particle_radius && !(std::isfinite(*frame.particle_radius) && *frame.particle_radius > 0))
    fail(file, 0, fmt::format("particle_radius {} in the FieldData: expected a finite length > 0", *frame.particle_radius));
  return frame;
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

std::vector<NamedBlock> read_vtm(const fs::path& file) {
  pugi::xml_document document;
  const pugi::xml_parse_result parsed = document.load_file(file.c_str());
  if (!parsed) fail(file, 0, fmt::format("not a VTK multiblock file: {}", parsed.description()));
  const pugi::xml_node multiblock = document.child("VTKFile").child("vtkMultiBlockDataSet");
  if (!multiblock) fail(file, 0, "expected <VTKFile type=\"vtkMultiBlockDataSet\"><vtkMultiBlockDataSet>");
  std::vector<NamedBlock> blocks;
  for (const pugi::xml_node dataset : multiblock.children("DataSet")) {
    const char* name = dataset.attribute("file").as_string();
    if (*name == '\0') fail(file, 0, "a <DataSet> without a file attribute");
    blocks.push_back({dataset.attribute("name").as_string(), file.parent_path() / name});
  }
  return blocks;
}

std::map<std::string, std::vector<double>> read_field_data(const fs::path& file) {
  const std::string bytes = read_bytes(file);
  pugi::xml_document document;
  if (!document.load_string(bytes.c_str())) fail(file, 0, "not a VTK XML file");
  const pugi::xml_node root = document.child("VTKFile");
  const pugi::xml_node dataset = root.first_child();
  std::map<std::string, std::vector<double>> fields;
  for (const pugi::xml_node array : dataset.child("FieldData").children("DataArray")) {
    if (std::string(array.attribute("format").as_string()) != "ascii") continue;
    std::vector<double> values;
    std::istringstream text(array.text().as_string());
    for (double value; text >> value;) values.push_back(value);
    fields[array.attribute("Name").as_string()] = std::move(values);
  }
  return fields;
}

}  // namespace m3dp::io
