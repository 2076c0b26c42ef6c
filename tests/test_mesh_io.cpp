// Reading OBJ and STL (ASCII and binary) triangle meshes, and the errors for bad files.
#include <gtest/gtest.h>

#include <limits>

#include <bit>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "m3dp/core/error.hpp"
#include "m3dp/io/atomic_file.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/io/particle_reader.hpp"
#include "m3dp/io/vtk_binary.hpp"
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

  /// The text of a particle frame m3dp writes (compressed base64 arrays) of `count` equal points.
  std::string written_frame(std::size_t count) const {
    const fs::path file = folder_ / "frame.vtu";
    m3dp::io::write_vtu(file, std::vector<Vec3>(count, Vec3(1, 2, 3)), {}, {});
    std::ifstream stream(file, std::ios::binary);
    return {std::istreambuf_iterator<char>(stream), std::istreambuf_iterator<char>()};
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

TEST_F(MeshIo, PlyReadsBackWhatItWrote) {
  // Binary as m3dp writes it, and ASCII with a quad and extra vertex properties as other tools write it.
  m3dp::TriangleMesh mesh;
  mesh.vertices = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  m3dp::io::write_triangle_mesh(folder_ / "tetrahedron.ply", mesh);
  const auto binary = read_triangle_mesh(folder_ / "tetrahedron.ply");
  ASSERT_EQ(binary.vertices.size(), 4u);
  ASSERT_EQ(binary.triangles.size(), 4u);
  EXPECT_TRUE(binary.vertices[3].isApprox(Vec3(0, 0, 1)));
  EXPECT_EQ(binary.triangles[3], (std::array<m3dp::Index, 3>{1, 2, 3}));
  const auto ascii = read_triangle_mesh(write("square.ply", "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                                                               "property float z\nproperty uchar red\nelement face 1\n"
                                                               "property list uchar int vertex_indices\nend_header\n"
                                                               "0 0 0 255\n1 0 0 255\n1 1 0 255\n0 1 0 255\n4 0 1 2 3\n"));
  ASSERT_EQ(ascii.triangles.size(), 2u);  // the quad fanned
  EXPECT_TRUE(ascii.vertices[2].isApprox(Vec3(1, 1, 0)));
  EXPECT_NE(read_error(write("bad.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nelement face 1\n"
                                         "property list uchar int vertex_indices\nend_header\n0\n3 0 1 2\n"))
                .find("a face uses vertex 1 of 1"),
            std::string::npos);
}

TEST_F(MeshIo, PlyHeadersAndNumbersThatCannotBeRightAreErrors) {
  // Found by fuzz_mesh: a face index of −1.2e9 was cast to an unsigned vertex number (undefined
  // behaviour); an element without properties or with more items than the body has bytes looped
  // for nothing; a NaN vertex went through.
  const std::string header = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string faces = "element face 1\nproperty list uchar int vertex_indices\nend_header\n";
  EXPECT_NE(read_error(write("index.ply", header + faces + "0 0 0\n1 0 0\n0 1 0\n3 0 1 -1157630000\n"))
                .find("face 0 uses vertex -1157630000: expected a vertex number"),
            std::string::npos);
  EXPECT_NE(read_error(write("count.ply", header + faces + "0 0 0\n1 0 0\n0 1 0\n-3 0 1 2\n"))
                .find("a list of -3 in element 'face'"),
            std::string::npos);
  EXPECT_NE(read_error(write("empty.ply", "ply\nformat ascii 1.0\nelement vertex 1000000000000\nend_header\n"))
                .find("element 'vertex' has 1000000000000 items and no properties"),
            std::string::npos);
  const std::string ten = "ply\nformat ascii 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n";
  EXPECT_NE(read_error(write("many.ply", ten)).find("element 'vertex' has 10 items; the file's body has 6 bytes"), std::string::npos);
  const float nan_vertex[3] = {0, std::numeric_limits<float>::quiet_NaN(), 0};
  std::string binary = "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
  binary.append(reinterpret_cast<const char*>(nan_vertex), sizeof nan_vertex);
  EXPECT_NE(read_error(write("nan.ply", binary)).find("vertex 0 is not a finite point"), std::string::npos);
}

TEST_F(MeshIo, UnknownExtensionAndMissingFile) {
  const std::string extension_message = read_error(write("part.3mf", "PK"));
  EXPECT_NE(extension_message.find("expected .obj or .ply or .stl"), std::string::npos) << extension_message;
  const std::string missing_message = read_error(folder_ / "nowhere.stl");
  EXPECT_NE(missing_message.find("nowhere.stl"), std::string::npos) << missing_message;
  EXPECT_NE(missing_message.find("no such file"), std::string::npos) << missing_message;
}

/// A frame as m3dp wrote it before base64 (raw appended data, UInt64 headers): readers must
/// still open the runs users already have.
std::string raw_appended_frame(const std::vector<Vec3>& points, const std::vector<std::uint64_t>& ids) {
  std::string text = R"(<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian" header_type="UInt64">
  <UnstructuredGrid>
    <FieldData><DataArray type="Float64" Name="particle_radius" NumberOfTuples="1" format="ascii">0.002</DataArray></FieldData>
)";
  const std::uint64_t id_bytes = ids.size() * 8, point_bytes = points.size() * sizeof(Vec3);
  text += "    <Piece NumberOfPoints=\"" + std::to_string(points.size()) + "\" NumberOfCells=\"0\">\n";
  text += "      <PointData><DataArray type=\"UInt64\" Name=\"id\" format=\"appended\" offset=\"0\"/></PointData>\n";
  text += "      <Points><DataArray type=\"Float32\" NumberOfComponents=\"3\" format=\"appended\" offset=\"" +
          std::to_string(8 + id_bytes) + "\"/></Points>\n";
  text += "    </Piece>\n  </UnstructuredGrid>\n  <AppendedData encoding=\"raw\">\n   _";
  text.append(reinterpret_cast<const char*>(&id_bytes), 8).append(reinterpret_cast<const char*>(ids.data()), id_bytes);
  text.append(reinterpret_cast<const char*>(&point_bytes), 8).append(reinterpret_cast<const char*>(points.data()), point_bytes);
  return text + "\n  </AppendedData>\n</VTKFile>\n";
}

TEST_F(MeshIo, ParticleFramesKeepTheirIds) {
  // m3dp run's frames (base64, compressed or not; UInt64 ids beyond a float's 2^24), the raw frames
  // it wrote before, and a hand-written ASCII file.
  const std::vector<Vec3> points{Vec3(0.1f, 0.2f, 0.3f), Vec3(-1, 2, 4), Vec3(5e-4f, 0, 1)};
  const std::vector<std::uint64_t> ids{7, (std::uint64_t{1} << 40) + 3, 16777217};
  for (const int level : {1, 9, -1}) {
    const fs::path written = folder_ / "frame.vtu";
    m3dp::io::write_vtu(written, points, {m3dp::io::PointArray::of("id", ids)}, {{"particle_radius", 0.001}}, {level});
    std::ifstream stream(written, std::ios::binary);
    const std::string text{std::istreambuf_iterator<char>(stream), std::istreambuf_iterator<char>()};
    EXPECT_EQ(text.find("<AppendedData"), std::string::npos);  // all XML: see vtk_writer.hpp
    EXPECT_NE(text.find("format=\"binary\""), std::string::npos);
    EXPECT_EQ(text.find("vtkZLibDataCompressor") != std::string::npos, level >= 0);
    const auto frame = m3dp::io::read_particle_frame(written);
    ASSERT_EQ(frame.positions.size(), 3u) << "zlib level " << level;
    EXPECT_EQ(frame.positions[1], points[1]);
    EXPECT_EQ(frame.ids, ids);
    EXPECT_NEAR(*frame.particle_radius, 0.001, 1e-9);
  }
  const auto raw = m3dp::io::read_particle_frame(write("raw.vtu", raw_appended_frame(points, ids)));
  EXPECT_EQ(raw.positions, points);
  EXPECT_EQ(raw.ids, ids);
  EXPECT_NEAR(*raw.particle_radius, 0.002, 1e-9);

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

TEST_F(MeshIo, LargeFramesRoundTripInEveryEncoding) {
  // Several zlib blocks (64 KiB each) with a partial last one, and ParaView's inline binary and
  // UInt32 headers written by hand from the same bytes.
  std::mt19937 random(5);
  std::uniform_real_distribution<float> coordinate(-1, 1);
  std::vector<Vec3> points(23456);
  std::vector<std::uint64_t> ids(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) {
    points[i] = Vec3(coordinate(random), coordinate(random), coordinate(random));
    ids[i] = i * 1000003u;
  }
  for (const int level : {1, 6, -1}) {
    const fs::path file = folder_ / ("large_" + std::to_string(level) + ".vtu");
    m3dp::io::write_vtu(file, points, {m3dp::io::PointArray::of("id", ids)}, {}, {level});
    const auto frame = m3dp::io::read_particle_frame(file);
    EXPECT_EQ(frame.positions, points) << "zlib level " << level;
    EXPECT_EQ(frame.ids, ids) << "zlib level " << level;
  }
  // An empty frame (a print before its first layer) reads as no particles.
  m3dp::io::write_vtu(folder_ / "empty.vtu", std::span<const Vec3>{}, {}, {});
  EXPECT_TRUE(m3dp::io::read_particle_frame(folder_ / "empty.vtu").positions.empty());

  // Inline binary: a UInt32 byte count and the bytes in one base64 stream.
  const std::vector<Vec3> few(points.begin(), points.begin() + 5);
  std::string payload(4, '\0');
  const std::uint32_t bytes = few.size() * sizeof(Vec3);
  std::memcpy(payload.data(), &bytes, 4);
  payload.append(reinterpret_cast<const char*>(few.data()), bytes);
  std::string encoded;
  m3dp::io::append_base64(payload, encoded);
  const fs::path inline_file = write("inline.vtu", R"(<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">
  <PolyData><Piece NumberOfPoints="5">
    <Points><DataArray type="Float32" NumberOfComponents="3" format="binary">
      )" + encoded + R"(
    </DataArray></Points>
  </Piece></PolyData>
</VTKFile>
)");
  EXPECT_EQ(m3dp::io::read_particle_frame(inline_file).positions, few);
}

TEST_F(MeshIo, DamagedFramesNameTheArray) {
  const std::string text = written_frame(4000);
  auto error_of = [&](const std::string& contents) {
    try {
      (void)m3dp::io::read_particle_frame(write("damaged.vtu", contents));
    } catch (const InputError& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  // Cut inside the points' data.
  const std::size_t points_at = text.find('\n', text.find("<Points>") + 20) + 1;
  const std::string truncated = error_of(text.substr(0, points_at + 80) + "</DataArray></Points></Piece></UnstructuredGrid></VTKFile>");
  EXPECT_NE(truncated.find("damaged.vtu"), std::string::npos) << truncated;
  EXPECT_NE(truncated.find("array points: a compressed array's header names more compressed bytes than the file holds (truncated?)"), std::string::npos) << truncated;
  // A character that is not base64 inside the data.
  std::string garbled = text;
  garbled[points_at + 50] = '%';
  const std::string garbled_error = error_of(garbled);
  EXPECT_NE(garbled_error.find("array points:"), std::string::npos) << garbled_error;
  // A compressor the reader does not have.
  std::string lz4 = text;
  lz4.replace(lz4.find("vtkZLibDataCompressor"), 21, "vtkLZ4DataCompressor");
  const std::string lz4_error = error_of(lz4);
  EXPECT_NE(lz4_error.find("compressor 'vtkLZ4DataCompressor' is not supported"), std::string::npos) << lz4_error;
}

TEST_F(MeshIo, AParticleAtANonFinitePositionIsAnError) {
  // A NaN position read from a frame would poison `m3dp mesh`'s surface grid or a camera's bounds.
  const std::vector<Vec3> points{Vec3(0, 0, 0), Vec3(0, std::numeric_limits<m3dp::Real>::infinity(), 0)};
  const auto file = write("nan.vtu", raw_appended_frame(points, {1, 2}));
  try {
    (void)m3dp::io::read_particle_frame(file);
    ADD_FAILURE() << "a frame with an infinite position was read";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("particle 1 is not at a finite position"), std::string::npos) << error.what();
  }
}

TEST_F(MeshIo, ACompressedArrayThatClaimsMoreThanZlibCanInflateIsAnError) {
  // Found by fuzz_particles: a header whose block size says 2^38 bytes made the reader allocate
  // it before inflating a byte. Patch the points' header words (blocks, block size, last size).
  std::string text = written_frame(4000);
  const std::size_t points_at = text.find_first_not_of(" \n", text.find('>', text.find("<DataArray", text.find("<Points>"))) + 1);
  std::string words;
  ASSERT_TRUE(m3dp::io::decode_base64(text.substr(points_at, 32), words));  // 24 bytes: three UInt64 words
  ASSERT_EQ(words.size(), 24U);
  const std::uint64_t block_size = std::uint64_t(1) << 38, last_size = 0;
  std::memcpy(words.data() + 8, &block_size, 8);
  std::memcpy(words.data() + 16, &last_size, 8);
  std::string patched;
  m3dp::io::append_base64(words, patched);
  text.replace(points_at, 32, patched);
  try {
    (void)m3dp::io::read_particle_frame(write("huge_block.vtu", text));
    ADD_FAILURE() << "a frame whose header claims 256 GiB was read";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("more than zlib can inflate to"), std::string::npos) << error.what();
  }
}

TEST_F(MeshIo, APointCountTheArraysCannotHoldIsAnError) {
  // Found by fuzz_particles: NumberOfPoints="126666666666666" allocated its values before the
  // array's bytes were decoded. Binary and ascii arrays alike.
  std::string text = written_frame(40);
  const std::string count = "NumberOfPoints=\"40\"";
  const std::size_t at = text.find(count);
  ASSERT_NE(at, std::string::npos);
  text.replace(at, count.size(), "NumberOfPoints=\"126666666666666\"");
  try {
    (void)m3dp::io::read_particle_frame(write("huge_count.vtu", text));
    ADD_FAILURE() << "a frame of 126666666666666 points was read";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("the points array holds 480 bytes, 379999999999998 values of Float32 need"), std::string::npos) << error.what();
  }
  const std::string ascii = R"(<?xml version="1.0"?>
<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian">
  <PolyData><Piece NumberOfPoints="900000000000">
    <Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">0 0 0 1 1 1</DataArray></Points>
  </Piece></PolyData>
</VTKFile>
)";
  try {
    (void)m3dp::io::read_particle_frame(write("huge_ascii.vtp", ascii));
    ADD_FAILURE() << "an ascii frame of 9e11 points was read";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("the points array's 11 characters cannot hold 2700000000000 values"), std::string::npos)
        << error.what();
  }
}

TEST_F(MeshIo, APlyVertexCountTheDataCannotHoldIsAnError) {
  // Found by fuzz_particles in CI: a PLY header's vertex count too large for size_t (read as its
  // maximum) was allocated before the data was looked at, and threw std::length_error.
  const std::string binary =
      "ply\nformat binary_little_endian 1.0\nelement vertex 99999999999999999999999\n"
      "property float x\nproperty float y\nproperty float z\nend_header\n" + std::string(24, '\0');
  const std::string ascii =
      "ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n0 0 0\n1 1 1\n";
  for (const auto& [name, text, expected] :
       {std::tuple{"huge.ply", binary, "vertices declared, but the 24 bytes after the header hold at most 2"},
        std::tuple{"huge_ascii.ply", ascii, "4000000000 vertices declared, but the 12 bytes after the header hold at most 2"}}) {
    try {
      (void)m3dp::io::read_particle_frame(write(name, text));
      ADD_FAILURE() << name << " was read";
    } catch (const InputError& error) {
      EXPECT_NE(std::string(error.what()).find(expected), std::string::npos) << error.what();
      EXPECT_NE(std::string(error.what()).find(name), std::string::npos) << error.what();
    }
  }
  // The counts that fit are still read.
  const std::string fitting = "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                              "property float z\nend_header\n0 0 0\n1 2 3\n";
  const auto frame = m3dp::io::read_particle_frame(write("two.ply", fitting));
  ASSERT_EQ(frame.positions.size(), 2u);
  EXPECT_NEAR(frame.positions[1].z(), 3.0, 1e-6);
}

TEST(Base64, MatchesRfc4648Vectors) {
  // RFC 4648 section 10.
  const std::pair<const char*, const char*> vectors[] = {{"", ""},         {"f", "Zg=="},         {"fo", "Zm8="},
                                                         {"foo", "Zm9v"}, {"foob", "Zm9vYg=="}, {"fooba", "Zm9vYmE="},
                                                         {"foobar", "Zm9vYmFy"}};
  for (const auto& [plain, encoded] : vectors) {
    std::string text, decoded;
    m3dp::io::append_base64(plain, text);
    EXPECT_EQ(text, encoded);
    EXPECT_TRUE(m3dp::io::decode_base64(std::string(" ") + encoded + "\n", decoded));
    EXPECT_EQ(decoded, plain);
  }
  std::string decoded;
  EXPECT_FALSE(m3dp::io::decode_base64("Zg==Zm8=", decoded));  // text after padding
  EXPECT_FALSE(m3dp::io::decode_base64("Zm9", decoded));       // a partial group
  EXPECT_FALSE(m3dp::io::decode_base64("Z===", decoded));
}

}  // namespace

TEST_F(MeshIo, WhatAKilledWriterLeftIsRemovedAndNothingElse) {
  // write_file_atomically's temporary names (NAME.tmpPID), as a SIGKILL leaves them; a resumed run clears them.
  fs::create_directories(folder_ / "particles");
  write("particles/particles_000003.vtu.tmp4242", "half a frame");
  write("run.mcap.tmp17", "");
  write("particles/particles_000002.vtu", "a frame");
  write("notes.tmp", "the user's");
  write("data.tmp12x", "the user's");
  EXPECT_EQ(m3dp::io::remove_leftover_temporaries(folder_), 2u);
  EXPECT_FALSE(fs::exists(folder_ / "particles/particles_000003.vtu.tmp4242"));
  EXPECT_FALSE(fs::exists(folder_ / "run.mcap.tmp17"));
  EXPECT_TRUE(fs::exists(folder_ / "particles/particles_000002.vtu"));
  EXPECT_TRUE(fs::exists(folder_ / "notes.tmp"));
  EXPECT_TRUE(fs::exists(folder_ / "data.tmp12x"));
}
