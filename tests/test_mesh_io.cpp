// Reading OBJ and STL (ASCII and binary) triangle meshes, and the errors for bad files.
#include <gtest/gtest.h>

#include <bit>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "m3dp/core/error.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/io/particle_reader.hpp"
#include "m3dp/io/vtk_writer.hpp"

namespace {

namespace fs = std::filesystem;
using m3dp::InputError;
using m3dp::io::read_triangle_mesh;
using m3dp::Vec3;

/// A fresh folder per test, removed afterwards.
class MeshIo : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device random;
    folder_ = fs::temp_directory_path() / ("m3dp_test_mesh_io_" + std::to_string(random()) + "_" +
                                           ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(folder_);
  }
  void TearDown() override {
    std::error_code ignored;
    fs::remove_all(folder_, ignored);
  }

  fs::path write(const std::string& name, const std::string& contents) const {
    const fs::path file = folder_ / name;
    std::ofstream(file, std::ios::binary) << contents;
    return file;
  }

  /// The message of the InputError that reading `file` throws.
  static std::string read_error(const fs::path& file) {
    try {
      read_triangle_mesh(file);
    } catch (const InputError& error) {
      return error.what();
    }
    ADD_FAILURE() << "reading " << file << " did not throw an InputError";
    return {};
  }

  fs::path folder_;
};

// A unit tetrahedron, counter-clockwise seen from outside.
constexpr float kTetrahedron[4][3][3] = {
    {{0, 0, 0}, {0, 1, 0}, {1, 0, 0}},
    {{0, 0, 0}, {1, 0, 0}, {0, 0, 1}},
    {{0, 0, 0}, {0, 0, 1}, {0, 1, 0}},
    {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}},
};

std::string ascii_stl_tetrahedron() {
  std::string text = "solid tetra\n";
  for (const auto& triangle : kTetrahedron) {
    text += "  facet normal 0 0 0\n    outer loop\n";
    for (const auto& corner : triangle) {
      text += "      vertex " + std::to_string(corner[0]) + " " + std::to_string(corner[1]) + " " +
              std::to_string(corner[2]) + "\n";
    }
    text += "    endloop\n  endfacet\n";
  }
  return text + "endsolid tetra\n";
}

void append_le_uint32(std::string& bytes, std::uint32_t value) {
  for (int k = 0; k < 4; ++k) bytes.push_back(char((value >> (8 * k)) & 0xff));
}

/// `header` is padded to 80 bytes; `declared_count` may differ from the real count to make a broken file.
std::string binary_stl_tetrahedron(const std::string& header, std::uint32_t declared_count) {
  std::string bytes = header;
  bytes.resize(80, ' ');
  append_le_uint32(bytes, declared_count);
  for (const auto& triangle : kTetrahedron) {
    for (int k = 0; k < 3; ++k) append_le_uint32(bytes, std::bit_cast<std::uint32_t>(0.0f));  // normal
    for (const auto& corner : triangle) {
      for (const float coordinate : corner) append_le_uint32(bytes, std::bit_cast<std::uint32_t>(coordinate));
    }
    bytes.append(2, '\0');  // attribute byte count
  }
  return bytes;
}

TEST_F(MeshIo, ObjCubeWithQuadsAndTextureNormalIndices) {
  const auto file = write("cube.obj", R"(# a unit cube
mtllib cube.mtl
o cube
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vt 0 0
vt 1 0
vt 1 1
vn 0 0 -1
g sides
usemtl clay
s off
f 1/1/1 4/2/1 3/3/1 2/1/1
f 5/1 6/2 7/3 8/1
f 1//1 2//1 6//1 5//1
f -5 -1 -2 -6
f 3 4 8 7
l 1 2
f 4 1 5 8  # trailing comment
)");
  const auto mesh = read_triangle_mesh(file);
  EXPECT_EQ(mesh.vertices.size(), 8u);
  ASSERT_EQ(mesh.triangles.size(), 12u);
  // Negative indices count back from the last vertex defined: -5 is vertex 4 (0-based 3).
  EXPECT_EQ(mesh.triangles[6][0], 3u);
  EXPECT_EQ(mesh.triangles[6][1], 7u);
  EXPECT_FLOAT_EQ(mesh.vertices[6].x(), 1.0f);
  EXPECT_FLOAT_EQ(mesh.vertices[6].z(), 1.0f);
}

TEST_F(MeshIo, ObjBadVertexNamesLineAndText) {
  const auto file = write("bad.obj", "# comment\nv 0 0 0\nv 1 abc 0\nv 0 1 0\nf 1 2 3\n");
  const std::string message = read_error(file);
  EXPECT_NE(message.find("bad.obj:3"), std::string::npos) << message;
  EXPECT_NE(message.find("expected 3 numbers after 'v', got 'abc'"), std::string::npos) << message;
}

TEST_F(MeshIo, ObjFaceIndexOutOfRange) {
  const auto file = write("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 7\n");
  const std::string message = read_error(file);
  EXPECT_NE(message.find("range.obj:6"), std::string::npos) << message;
  EXPECT_NE(message.find("face index 7 out of range (file has 4 vertices)"), std::string::npos) << message;
}

TEST_F(MeshIo, ObjWithoutFacesIsAnError) {
  const std::string message = read_error(write("points.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"));
  EXPECT_NE(message.find("no triangles"), std::string::npos) << message;
}

TEST_F(MeshIo, AsciiStlWeldsSharedCorners) {
  const auto mesh = read_triangle_mesh(write("tetra.stl", ascii_stl_tetrahedron()));
  EXPECT_EQ(mesh.vertices.size(), 4u);
  ASSERT_EQ(mesh.triangles.size(), 4u);
  const auto& last = mesh.triangles[3];
  EXPECT_FLOAT_EQ(mesh.vertices[last[0]].x(), 1.0f);
  EXPECT_FLOAT_EQ(mesh.vertices[last[2]].z(), 1.0f);
}

TEST_F(MeshIo, AsciiStlBadVertexNamesLine) {
  std::string text = ascii_stl_tetrahedron();
  const std::string good = "vertex 0.000000 1.000000 0.000000";
  text.replace(text.find(good), good.size(), "vertex 0 one 0");
  const std::string message = read_error(write("bad.stl", text));
  EXPECT_NE(message.find("bad.stl:5"), std::string::npos) << message;
  EXPECT_NE(message.find("got 'one'"), std::string::npos) << message;
}

TEST_F(MeshIo, BinaryStlEvenWhenHeaderSaysSolid) {
  // Many exporters start binary headers with "solid"; the size identifies the file as binary.
  const auto mesh = read_triangle_mesh(write("tetra.stl", binary_stl_tetrahedron("solid exported by CAD", 4)));
  EXPECT_EQ(mesh.vertices.size(), 4u);
  EXPECT_EQ(mesh.triangles.size(), 4u);
}

TEST_F(MeshIo, BinaryStlWithWrongSizeIsAnError) {
  const std::string message = read_error(write("cut.stl", binary_stl_tetrahedron("binary", 5)));
  EXPECT_NE(message.find("cut.stl"), std::string::npos) << message;
  EXPECT_NE(message.find("5 triangles"), std::string::npos) << message;
}

TEST_F(MeshIo, UnknownExtensionAndMissingFile) {
  const std::string extension_message = read_error(write("part.ply", "ply\n"));
  EXPECT_NE(extension_message.find("expected .obj or .stl"), std::string::npos) << extension_message;
  const std::string missing_message = read_error(folder_ / "nowhere.stl");
  EXPECT_NE(missing_message.find("nowhere.stl"), std::string::npos) << missing_message;
  EXPECT_NE(missing_message.find("no such file"), std::string::npos) << missing_message;
}

TEST_F(MeshIo, ParticleFramesKeepTheirIds) {
  // m3dp run's frames (raw appended, UInt64 ids beyond a float's 2^24) and a hand-written ASCII file.
  const std::vector<Vec3> points{Vec3(0.1f, 0.2f, 0.3f), Vec3(-1, 2, 4), Vec3(5e-4f, 0, 1)};
  const std::vector<std::uint64_t> ids{7, (std::uint64_t{1} << 40) + 3, 16777217};
  const fs::path written = folder_ / "frame.vtu";
  m3dp::io::write_vtu(written, points, {m3dp::io::PointArray::of("id", ids)}, {{"particle_radius", 0.001}});
  const auto frame = m3dp::io::read_particle_frame(written);
  ASSERT_EQ(frame.positions.size(), 3u);
  EXPECT_EQ(frame.positions[1], points[1]);
  EXPECT_EQ(frame.ids, ids);
  EXPECT_NEAR(*frame.particle_radius, 0.001, 1e-9);

  const fs::path ascii = write("ascii.vtu", R"(<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0">
  <UnstructuredGrid><Piece NumberOfPoints="2" NumberOfCells="0">
    <PointData><DataArray type="Int32" Name="id" format="ascii">12 5</DataArray></PointData>
    <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">0 0 0 1 1 1</DataArray></Points>
  </Piece></UnstructuredGrid>
</VTKFile>
)");
  const auto ascii_frame = m3dp::io::read_particle_frame(ascii);
  EXPECT_EQ(ascii_frame.ids, (std::vector<std::uint64_t>{12, 5}));
  EXPECT_EQ(ascii_frame.positions[1], Vec3(1, 1, 1));

  const fs::path short_ids = write("short.vtu", R"(<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0">
  <UnstructuredGrid><Piece NumberOfPoints="2" NumberOfCells="0">
    <PointData><DataArray type="Int32" Name="id" format="ascii">12</DataArray></PointData>
    <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">0 0 0 1 1 1</DataArray></Points>
  </Piece></UnstructuredGrid>
</VTKFile>
)");
  try {
    (void)m3dp::io::read_particle_frame(short_ids);
    ADD_FAILURE() << "a short id array was read";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("the id array ends after 1 of 2 values"), std::string::npos) << error.what();
  }
}

}  // namespace
