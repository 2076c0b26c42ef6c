// Seeds for the fuzz targets, written by the project's own writers: a tessellated cylinder in every
// mesh format (and ASCII STL and PLY by hand, the readers' other paths), particle frames as .vtu
// zlib-compressed and plain base64, .vtp, and .ply. Each seed's first byte picks the format as the
// targets read it. Usage: fuzz_seeds OUT_DIR (writes OUT_DIR/mesh/ and OUT_DIR/particles/).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "m3dp/core/geometry.hpp"
#include "m3dp/core/tessellation.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/io/vtk_writer.hpp"

namespace fs = std::filesystem;

namespace {
std::string read_bytes(const fs::path& file) {
  std::ifstream stream(file, std::ios::binary);
  std::stringstream buffer;
  buffer << stream.rdbuf();
  return buffer.str();
}
void write_seed(const fs::path& file, char selector, const std::string& bytes) {
  std::ofstream(file, std::ios::binary) << selector << bytes;
}
}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_seeds OUT_DIR\n");
    return 2;
  }
  const fs::path out = argv[1], scratch = out / "scratch";
  for (const auto* folder : {"mesh", "particles", "scratch"}) fs::create_directories(out / folder);

  const m3dp::TriangleMesh mesh = m3dp::tessellate(m3dp::CylinderShape{0.02f, 0.05f}, 8);
  const char* extensions[] = {"obj", "stl", "ply"};
  for (char selector = 0; selector < 3; ++selector) {
    const fs::path file = scratch / (std::string("mesh.") + extensions[int(selector)]);
    m3dp::io::write_triangle_mesh(file, mesh);
    write_seed(out / "mesh" / (std::string("seed.") + extensions[int(selector)]), selector, read_bytes(file));
  }
  write_seed(out / "mesh" / "ascii.stl", 1,
             "solid t\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid t\n");
  write_seed(out / "mesh" / "ascii.ply", 2,
             "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
             "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");

  std::vector<m3dp::Vec3> points(mesh.vertices.begin(), mesh.vertices.begin() + 12);
  std::vector<std::uint64_t> ids(points.size());
  std::vector<std::uint16_t> material(points.size(), 1);
  std::vector<m3dp::Real> birth(points.size(), 0.5f);
  for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = 100 + i;
  const std::vector<m3dp::io::PointArray> arrays{m3dp::io::PointArray::of("id", std::span<const std::uint64_t>(ids)),
                                                 m3dp::io::PointArray::of("material", std::span<const std::uint16_t>(material)),
                                                 m3dp::io::PointArray::of("birth_time", std::span<const m3dp::Real>(birth))};
  const std::vector<m3dp::io::FieldValue> radius{{"particle_radius", 0.0015}};
  for (const int level : {1, -1}) {
    const fs::path file = scratch / "frame.vtu";
    m3dp::io::write_vtu(file, points, arrays, radius, m3dp::io::VtuEncoding{level});
    write_seed(out / "particles" / (level > 0 ? "zlib.vtu" : "base64.vtu"), 0, read_bytes(file));
  }
  m3dp::io::PolyData poly;
  poly.points = points;
  poly.point_arrays = arrays;
  m3dp::io::write_vtp(scratch / "frame.vtp", poly);
  write_seed(out / "particles" / "seed.vtp", 1, read_bytes(scratch / "frame.vtp"));
  write_seed(out / "particles" / "seed.ply", 2, read_bytes(scratch / "mesh.ply"));
  fs::remove_all(scratch);
  return 0;
}
