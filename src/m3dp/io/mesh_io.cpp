#include "m3dp/io/mesh_io.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/core/text.hpp"
#include "m3dp/io/atomic_file.hpp"

namespace m3dp::io {

namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------
// Text helpers
// ---------------------------------------------------------------------------------------------

bool is_blank(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n' || c == '\v' || c == '\f'; }

/// A finite decimal number, the whole word. Accepts a leading '+', which from_chars does not.
std::optional<Real> parse_real(std::string_view word) {
  if (!word.empty() && word.front() == '+') word.remove_prefix(1);
  double value = 0;
  const auto [end, error] = std::from_chars(word.data(), word.data() + word.size(), value);
  if (error != std::errc() || end != word.data() + word.size() || !std::isfinite(value)) return std::nullopt;
  return static_cast<Real>(value);
}

std::optional<long long> parse_integer(std::string_view word) {
  if (!word.empty() && word.front() == '+') word.remove_prefix(1);
  long long value = 0;
  const auto [end, error] = std::from_chars(word.data(), word.data() + word.size(), value);
  if (error != std::errc() || end != word.data() + word.size()) return std::nullopt;
  return value;
}

std::string lowercase(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return text;
}

[[noreturn]] void fail(const fs::path& file, int line, const std::string& message) {
  throw InputError(SourceLocation{file.string(), line}, message);
}

std::string read_whole_file(const fs::path& file) {
  std::error_code error;
  if (!fs::exists(file, error)) {
    fail(file, 0, "cannot read mesh: no such file (expected an existing .obj or .stl file)");
  }
  if (!fs::is_regular_file(file, error)) {
    fail(file, 0, "cannot read mesh: not a regular file (expected an .obj or .stl file)");
  }
  std::ifstream stream(file, std::ios::binary);
  if (!stream) fail(file, 0, "cannot open mesh file for reading (expected a readable .obj or .stl file)");
  std::string bytes((std::istreambuf_iterator<char>(stream)), std::istreambuf_iterator<char>());
  if (stream.bad()) fail(file, 0, "error while reading mesh file");
  return bytes;
}

/// Three coordinates from words[first..first+3), or an error naming what came after `keyword`.
Vec3 parse_point(const std::vector<std::string_view>& words, std::size_t first, std::string_view keyword,
                 const fs::path& file, int line) {
  Vec3 point;
  for (int axis = 0; axis < 3; ++axis) {
    const std::size_t index = first + std::size_t(axis);
    if (index >= words.size()) {
      fail(file, line, fmt::format("expected 3 numbers after '{}', got {}", keyword, index - first));
    }
    const auto value = parse_real(words[index]);
    if (!value) fail(file, line, fmt::format("expected 3 numbers after '{}', got '{}'", keyword, words[index]));
    point[axis] = *value;
  }
  return point;
}

void require_triangles(const TriangleMesh& mesh, const fs::path& file, std::string_view what_makes_a_face) {
  if (mesh.triangles.empty()) {
    fail(file, 0, fmt::format("mesh has no triangles; expected at least one {}", what_makes_a_face));
  }
}

// ---------------------------------------------------------------------------------------------
// OBJ
// ---------------------------------------------------------------------------------------------

/// OBJ files may use vertices before defining them, so face indices are checked after the last line.
struct ObjFace {
  std::size_t first_corner;  // into ObjFaces::corners
  std::size_t corner_count;
  int line;
};
struct ObjFaces {
  std::vector<long long> corners;   // 0-based vertex indices as written (negative ones already resolved)
  std::vector<long long> written;   // the index as written in the file, for messages
  std::vector<ObjFace> faces;
};

void parse_obj_face(const std::vector<std::string_view>& words, std::size_t vertices_so_far, ObjFaces& faces,
                    const fs::path& file, int line) {
  const std::size_t corner_count = words.size() - 1;
  if (corner_count < 3) fail(file, line, fmt::format("a face needs at least 3 vertices, got {}", corner_count));
  faces.faces.push_back(ObjFace{faces.corners.size(), corner_count, line});
  for (std::size_t corner = 1; corner < words.size(); ++corner) {
    // "v", "v/vt", "v//vn" or "v/vt/vn": only the position index matters here.
    const std::string_view word = words[corner];
    const std::string_view position_word = word.substr(0, word.find('/'));
    const auto index = parse_integer(position_word);
    if (!index) fail(file, line, fmt::format("expected a vertex index in face, got '{}'", word));
    if (*index == 0) fail(file, line, "face index 0 is invalid (OBJ indices start at 1)");
    long long resolved = *index > 0 ? *index - 1 : static_cast<long long>(vertices_so_far) + *index;
    if (resolved < 0) {
      fail(file, line,
           fmt::format("face index {} out of range ({} vertices defined before this line)", *index, vertices_so_far));
    }
    faces.corners.push_back(resolved);
    faces.written.push_back(*index);
  }
}

TriangleMesh read_obj(const fs::path& file) {
  const std::string text = read_whole_file(file);
  TriangleMesh mesh;
  ObjFaces faces;
  for_each_line(text, [&](std::string_view line_text, int line) {
    line_text = line_text.substr(0, line_text.find('#'));
    const auto words = split_words(line_text);
    if (words.empty()) return;
    const std::string_view keyword = words.front();
    if (keyword == "v") {
      // "v x y z [w]" or "v x y z r g b": the first three are the position.
      mesh.vertices.push_back(parse_point(words, 1, keyword, file, line));
    } else if (keyword == "f") {
      parse_obj_face(words, mesh.vertices.size(), faces, file, line);
    }
    // Everything else (vt, vn, o, g, s, usemtl, mtllib, l, p, ...) does not change the shape.
  });

  if (mesh.vertices.size() > std::numeric_limits<Index>::max()) {
    fail(file, 0, fmt::format("mesh has {} vertices; at most {} are supported", mesh.vertices.size(),
                              std::numeric_limits<Index>::max()));
  }
  const auto vertex_count = static_cast<long long>(mesh.vertices.size());
  for (const ObjFace& face : faces.faces) {
    for (std::size_t corner = face.first_corner; corner < face.first_corner + face.corner_count; ++corner) {
      if (faces.corners[corner] >= vertex_count) {
        fail(file, face.line,
             fmt::format("face index {} out of range (file has {} vertices)", faces.written[corner], vertex_count));
      }
    }
    // Polygons become a fan around their first corner (exact for convex polygons, as OBJ exporters write).
    const auto corner_index = [&](std::size_t k) { return static_cast<Index>(faces.corners[face.first_corner + k]); };
    for (std::size_t k = 1; k + 1 < face.corner_count; ++k) {
      mesh.triangles.push_back({corner_index(0), corner_index(k), corner_index(k + 1)});
    }
  }
  require_triangles(mesh, file, "face ('f' line)");
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// STL
// ---------------------------------------------------------------------------------------------

/// STL stores every triangle's corners separately; equal corners become one shared vertex.
class VertexWelder {
 public:
  explicit VertexWelder(TriangleMesh& mesh) : mesh_(mesh) {}

  Index index_of(const Vec3& point) {
    const auto [entry, inserted] = index_by_point_.try_emplace(point, static_cast<Index>(mesh_.vertices.size()));
    if (inserted) mesh_.vertices.push_back(point);
    return entry->second;
  }

  void add_triangle(const Vec3& a, const Vec3& b, const Vec3& c) {
    mesh_.triangles.push_back({index_of(a), index_of(b), index_of(c)});
  }

 private:
  struct PointHash {
    std::size_t operator()(const Vec3& point) const {
      std::size_t hash = 0;
      for (int axis = 0; axis < 3; ++axis) {
        hash ^= std::hash<Real>{}(point[axis]) + 0x9e3779b97f4a7c15ULL + (hash << 6) + (hash >> 2);
      }
      return hash;
    }
  };
  struct PointEqual {
    bool operator()(const Vec3& a, const Vec3& b) const { return a == b; }
  };

  TriangleMesh& mesh_;
  std::unordered_map<Vec3, Index, PointHash, PointEqual> index_by_point_;
};

constexpr std::size_t kBinaryStlHeaderBytes = 80;
constexpr std::size_t kBinaryStlPrologueBytes = kBinaryStlHeaderBytes + 4;  // header + triangle count
constexpr std::size_t kBinaryStlTriangleBytes = 50;  // normal, 3 corners (12 float32), attribute uint16

std::uint32_t read_le_uint32(const std::string& bytes, std::size_t offset) {
  std::uint32_t value = 0;
  for (int k = 3; k >= 0; --k) value = (value << 8) | static_cast<unsigned char>(bytes[offset + std::size_t(k)]);
  return value;
}

float read_le_float32(const std::string& bytes, std::size_t offset) {
  return std::bit_cast<float>(read_le_uint32(bytes, offset));
}

bool starts_with_solid(const std::string& bytes) {
  std::size_t position = 0;
  while (position < bytes.size() && is_blank(bytes[position])) ++position;
  return std::string_view(bytes).substr(position).starts_with("solid");
}

TriangleMesh read_binary_stl(const std::string& bytes, std::uint32_t triangle_count, const fs::path& file) {
  TriangleMesh mesh;
  VertexWelder welder(mesh);
  mesh.triangles.reserve(triangle_count);
  for (std::uint32_t triangle = 0; triangle < triangle_count; ++triangle) {
    const std::size_t record = kBinaryStlPrologueBytes + std::size_t(triangle) * kBinaryStlTriangleBytes;
    std::array<Vec3, 3> corners;
    for (std::size_t corner = 0; corner < 3; ++corner) {
      for (std::size_t axis = 0; axis < 3; ++axis) {
        // Skip the 12-byte facet normal: the winding order defines the outside.
        const float value = read_le_float32(bytes, record + 12 + 12 * corner + 4 * axis);
        if (!std::isfinite(value)) {
          fail(file, 0, fmt::format("binary STL triangle {} has a non-finite coordinate", triangle + 1));
        }
        corners[corner][Eigen::Index(axis)] = static_cast<Real>(value);
      }
    }
    welder.add_triangle(corners[0], corners[1], corners[2]);
  }
  require_triangles(mesh, file, "triangle");
  return mesh;
}

TriangleMesh read_ascii_stl(const std::string& text, const fs::path& file) {
  TriangleMesh mesh;
  VertexWelder welder(mesh);
  bool in_loop = false;
  int loop_line = 0;
  std::vector<Vec3> loop_corners;

  for_each_line(text, [&](std::string_view line_text, int line) {
    const auto words = split_words(line_text);
    if (words.empty()) return;
    const std::string_view keyword = words.front();
    if (keyword == "vertex") {
      if (!in_loop) fail(file, line, "'vertex' outside 'outer loop' ... 'endloop'");
      loop_corners.push_back(parse_point(words, 1, keyword, file, line));
    } else if (keyword == "outer") {
      if (words.size() < 2 || words[1] != "loop") fail(file, line, "expected 'outer loop'");
      if (in_loop) fail(file, line, "'outer loop' inside another loop; expected 'endloop' first");
      in_loop = true;
      loop_line = line;
      loop_corners.clear();
    } else if (keyword == "endloop") {
      if (!in_loop) fail(file, line, "'endloop' without 'outer loop'");
      if (loop_corners.size() < 3) {
        fail(file, line, fmt::format("facet has {} vertices, expected 3", loop_corners.size()));
      }
      for (std::size_t k = 1; k + 1 < loop_corners.size(); ++k) {
        welder.add_triangle(loop_corners[0], loop_corners[k], loop_corners[k + 1]);
      }
      in_loop = false;
    } else if (keyword == "facet") {
      if (in_loop) fail(file, line, "'facet' inside a loop; expected 'endloop' first");
      // "facet normal nx ny nz": the normal is checked for syntax only; the winding defines the outside.
      if (words.size() > 1 && words[1] == "normal") parse_point(words, 2, "facet normal", file, line);
    } else if (keyword != "solid" && keyword != "endfacet" && keyword != "endsolid") {
      fail(file, line,
           fmt::format("unexpected '{}'; expected one of: solid, facet normal, outer loop, vertex, endloop, "
                       "endfacet, endsolid",
                       keyword));
    }
  });
  if (in_loop) fail(file, loop_line, "'outer loop' is never closed by 'endloop'");
  require_triangles(mesh, file, "facet");
  return mesh;
}

/// PLY meshes as m3dp, MeshLab and most tools write them: binary little-endian or ASCII, vertices
/// with x, y, z (any numeric properties beside them), faces as index lists (polygons fanned into triangles).
TriangleMesh read_ply(const fs::path& file) {
  const std::string bytes = read_whole_file(file);
  const std::size_t header_end = bytes.find("end_header");
  if (bytes.rfind("ply", 0) != 0 || header_end == std::string::npos) fail(file, 0, "not a PLY file: expected 'ply' ... 'end_header'");
  const std::size_t body = bytes.find('\n', header_end) + 1;
  std::istringstream header(bytes.substr(0, header_end));
  struct Property {
    std::string name, type, count_type;  // count_type: a list's
  };
  struct Element {
    std::string name;
    std::size_t count = 0;
    std::vector<Property> properties;
  };
  std::vector<Element> elements;
  std::string format;
  int line_number = 0;
  for (std::string line; std::getline(header, line);) {
    ++line_number;
    std::istringstream words(line);
    std::string keyword;
    words >> keyword;
    if (keyword == "format") words >> format;
    else if (keyword == "element") {
      elements.emplace_back();
      words >> elements.back().name >> elements.back().count;
    } else if (keyword == "property") {
      if (elements.empty()) fail(file, line_number, "a property before any element");
      Property property;
      words >> property.type;
      if (property.type == "list") words >> property.count_type >> property.type;
      words >> property.name;
      elements.back().properties.push_back(property);
    }
  }
  if (format != "binary_little_endian" && format != "ascii")
    fail(file, 0, fmt::format("PLY format '{}'; expected binary_little_endian or ascii", format));
  const bool binary = format == "binary_little_endian";
  // Every item reads at least a byte (binary) or a number (ASCII): an element with no properties,
  // or more items than the body has bytes, is a header that cannot be right (and would loop or
  // allocate for nothing).
  for (const Element& element : elements)
    if (element.count > 0 && (element.properties.empty() || element.count > bytes.size() - std::min(bytes.size(), body)))
      fail(file, 0, fmt::format("element '{}' has {} items{}; the file's body has {} bytes", element.name, element.count,
                                element.properties.empty() ? " and no properties" : "", bytes.size() - std::min(bytes.size(), body)));
  auto type_bytes = [&](const std::string& type) -> std::size_t {
    if (type == "char" || type == "uchar" || type == "int8" || type == "uint8") return 1;
    if (type == "short" || type == "ushort" || type == "int16" || type == "uint16") return 2;
    if (type == "int" || type == "uint" || type == "float" || type == "int32" || type == "uint32" || type == "float32") return 4;
    if (type == "double" || type == "float64") return 8;
    fail(file, 0, fmt::format("unknown PLY property type '{}'", type));
  };
  std::size_t at = body;
  std::istringstream ascii(binary ? std::string() : bytes.substr(body));
  // One number of `type` from the body, as a double.
  auto next = [&](const std::string& type) -> double {
    if (!binary) {
      double value;
      if (!(ascii >> value)) fail(file, 0, "the PLY body ends early");
      return value;
    }
    const std::size_t size = type_bytes(type);
    if (at + size > bytes.size()) fail(file, 0, "the PLY body ends early");
    double value = 0;
    auto as = [&]<class T>(T) {
      T typed;
      std::memcpy(&typed, bytes.data() + at, sizeof(T));
      value = static_cast<double>(typed);
    };
    if (type == "char" || type == "int8") as(std::int8_t{});
    else if (type == "uchar" || type == "uint8") as(std::uint8_t{});
    else if (type == "short" || type == "int16") as(std::int16_t{});
    else if (type == "ushort" || type == "uint16") as(std::uint16_t{});
    else if (type == "int" || type == "int32") as(std::int32_t{});
    else if (type == "uint" || type == "uint32") as(std::uint32_t{});
    else if (type == "float" || type == "float32") as(float{});
    else as(double{});
    at += size;
    return value;
  };
  TriangleMesh mesh;
  for (const Element& element : elements) {
    for (std::size_t item = 0; item < element.count; ++item) {
      Vec3 vertex = Vec3::Zero();
      std::vector<Index> polygon;
      for (const Property& property : element.properties) {
        if (!property.count_type.empty()) {
          const double count = next(property.count_type);
          if (!(count >= 0 && count <= double(bytes.size())) || count != std::floor(count))
            fail(file, 0, fmt::format("a list of {} in element '{}': expected a count from 0 to the file's size", count, element.name));
          for (std::size_t k = 0; k < static_cast<std::size_t>(count); ++k) {
            const double index = next(property.type);
            if (element.name == "face" && (property.name == "vertex_indices" || property.name == "vertex_index")) {
              if (!(index >= 0 && index < 4294967296.0) || index != std::floor(index))
                fail(file, 0, fmt::format("face {} uses vertex {}: expected a vertex number", item, index));
              polygon.push_back(static_cast<Index>(index));
            }
          }
          continue;
        }
        const double value = next(property.type);
        if (element.name == "vertex") {
          if (property.name == "x") vertex.x() = static_cast<Real>(value);
          else if (property.name == "y") vertex.y() = static_cast<Real>(value);
          else if (property.name == "z") vertex.z() = static_cast<Real>(value);
        }
      }
      if (element.name == "vertex") {
        if (!vertex.allFinite()) fail(file, 0, fmt::format("vertex {} is not a finite point", item));
        mesh.vertices.push_back(vertex);
      }
      for (std::size_t k = 2; k < polygon.size(); ++k) mesh.triangles.push_back({polygon[0], polygon[k - 1], polygon[k]});
    }
  }
  for (const auto& triangle : mesh.triangles)
    for (const Index index : triangle)
      if (index >= mesh.vertices.size()) fail(file, 0, fmt::format("a face uses vertex {} of {}", index, mesh.vertices.size()));
  return mesh;
}

TriangleMesh read_stl(const fs::path& file) {
  const std::string bytes = read_whole_file(file);
  // Some binary exporters also start their header with "solid", so the size decides first.
  if (bytes.size() >= kBinaryStlPrologueBytes) {
    const std::uint32_t triangle_count = read_le_uint32(bytes, kBinaryStlHeaderBytes);
    const std::uint64_t binary_size =
        kBinaryStlPrologueBytes + std::uint64_t(triangle_count) * kBinaryStlTriangleBytes;
    if (bytes.size() == binary_size) return read_binary_stl(bytes, triangle_count, file);
    if (!starts_with_solid(bytes)) {
      fail(file, 0,
           fmt::format("not a valid STL file: as binary STL its header says {} triangles ({} bytes) but the file "
                       "has {} bytes, and an ASCII STL would start with 'solid'",
                       triangle_count, binary_size, bytes.size()));
    }
  } else if (!starts_with_solid(bytes)) {
    fail(file, 0,
         fmt::format("not a valid STL file: {} bytes is too short for binary STL (at least {}) and an ASCII STL "
                     "would start with 'solid'",
                     bytes.size(), kBinaryStlPrologueBytes));
  }
  return read_ascii_stl(bytes, file);
}

}  // namespace

namespace {
template <class T>
void write_le(std::ostream& stream, T value) {
  static_assert(std::endian::native == std::endian::little, "binary mesh writers assume a little-endian machine");
  stream.write(reinterpret_cast<const char*>(&value), sizeof(T));
}

void write_obj(std::ostream& stream, const TriangleMesh& mesh) {
  stream << "# M3DP surface mesh: " << mesh.vertices.size() << " vertices, " << mesh.triangles.size()
         << " triangles, metres\n";
  for (const Vec3& v : mesh.vertices) stream << fmt::format("v {:.9g} {:.9g} {:.9g}\n", v.x(), v.y(), v.z());
  for (const auto& t : mesh.triangles) stream << fmt::format("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
}

/// Binary PLY; with `quality` (one value a vertex), a float vertex property "quality", which MeshLab
/// takes as the vertex quality it colours by.
void write_ply_with(std::ostream& stream, const TriangleMesh& mesh, std::span<const float> quality, std::string_view comment) {
  stream << "ply\nformat binary_little_endian 1.0\ncomment M3DP surface mesh, metres\n";
  if (!comment.empty()) stream << "comment " << comment << "\n";
  stream << "element vertex " << mesh.vertices.size() << "\nproperty float x\nproperty float y\nproperty float z\n"
         << (quality.empty() ? "" : "property float quality\n") << "element face " << mesh.triangles.size()
         << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    for (int k = 0; k < 3; ++k) write_le(stream, static_cast<float>(mesh.vertices[i][k]));
    if (!quality.empty()) write_le(stream, quality[i]);
  }
  for (const auto& t : mesh.triangles) {
    write_le(stream, std::uint8_t(3));
    for (const Index index : t) write_le(stream, static_cast<std::int32_t>(index));
  }
}

void write_ply(std::ostream& stream, const TriangleMesh& mesh) { write_ply_with(stream, mesh, {}, ""); }

void write_binary_stl(std::ostream& stream, const TriangleMesh& mesh) {
  std::string header = "M3DP surface mesh, metres";
  header.resize(80, ' ');
  stream.write(header.data(), 80);
  write_le(stream, static_cast<std::uint32_t>(mesh.triangles.size()));
  for (const auto& t : mesh.triangles) {
    const Vec3 a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], c = mesh.vertices[t[2]];
    Vec3 normal = (b - a).cross(c - a);
    if (normal.norm() > 0) normal.normalize();
    for (const Vec3& v : {normal, a, b, c})
      for (int k = 0; k < 3; ++k) write_le(stream, static_cast<float>(v[k]));
    write_le(stream, std::uint16_t(0));
  }
}
}  // namespace

constexpr MeshFormat kMeshFormats[] = {
    {"obj", ".obj", "Wavefront OBJ (text)", false, write_obj, read_obj},
    {"ply", ".ply", "binary PLY (read: binary or ASCII)", true, write_ply, read_ply},
    {"stl", ".stl", "binary STL (read: ASCII or binary)", true, write_binary_stl, read_stl},
};

std::span<const MeshFormat> mesh_formats() { return kMeshFormats; }

const MeshFormat* find_mesh_format(std::string_view name) {
  for (const MeshFormat& format : kMeshFormats)
    if (format.name == name) return &format;
  return nullptr;
}

const MeshFormat* mesh_format_of(const std::filesystem::path& file) {
  const std::string extension = lowercase(file.extension().string());
  for (const MeshFormat& format : kMeshFormats)
    if (format.extension == extension) return &format;
  return nullptr;
}

std::string mesh_format_names(bool readable_only) {
  std::string names;
  for (const MeshFormat& format : kMeshFormats)
    if (!readable_only || format.read) names += (names.empty() ? "" : ", ") + std::string(format.name);
  return names;
}

TriangleMesh read_triangle_mesh(const std::filesystem::path& file) {
  const MeshFormat* format = mesh_format_of(file);
  if (!format || !format->read) {
    std::string extensions;
    for (const MeshFormat& each : kMeshFormats)
      if (each.read) extensions += (extensions.empty() ? "" : " or ") + std::string(each.extension);
    fail(file, 0, fmt::format("unsupported mesh file extension '{}'; expected {}", file.extension().string(), extensions));
  }
  return format->read(file);
}

void write_triangle_mesh(const std::filesystem::path& file, const TriangleMesh& mesh) {
  const MeshFormat* format = mesh_format_of(file);
  if (!format)
    throw Error(fmt::format("{}: unsupported mesh file extension '{}'; expected one of {}", file.string(),
                            file.extension().string(), mesh_format_names()));
  write_file_atomically(file, [&](std::ostream& stream) { format->write(stream, mesh); }, format->binary);
}

void write_sdf_model(const std::filesystem::path& folder, const std::string& model_name, const TriangleMesh& mesh) {
  std::filesystem::create_directories(folder / "meshes");
  write_triangle_mesh(folder / "meshes" / (model_name + ".stl"), mesh);
  const std::string uri = fmt::format("model://{}/meshes/{}.stl", model_name, model_name);
  write_text_atomically(folder / "model.config", fmt::format(R"(<?xml version="1.0"?>
<model>
  <name>{0}</name>
  <version>1.0</version>
  <sdf version="1.9">model.sdf</sdf>
  <description>Printed material reconstructed by M3DP ({1} triangles, metres).</description>
</model>
)", model_name, mesh.triangles.size()));
  write_text_atomically(folder / "model.sdf", fmt::format(R"(<?xml version="1.0"?>
<sdf version="1.9">
  <model name="{0}">
    <static>true</static>
    <link name="surface">
      <collision name="collision">
        <geometry><mesh><uri>{1}</uri></mesh></geometry>
      </collision>
      <visual name="visual">
        <geometry><mesh><uri>{1}</uri></mesh></geometry>
      </visual>
    </link>
  </model>
</sdf>
)", model_name, uri));
}

void write_ply_with_quality(const std::filesystem::path& file, const TriangleMesh& mesh, std::span<const float> quality,
                            std::string_view comment) {
  if (quality.size() != mesh.vertices.size()) throw Error(fmt::format("{}: {} quality values for {} vertices", file.string(), quality.size(), mesh.vertices.size()));
  write_file_atomically(file, [&](std::ostream& stream) { write_ply_with(stream, mesh, quality, comment); }, true);
}

}  // namespace m3dp::io
