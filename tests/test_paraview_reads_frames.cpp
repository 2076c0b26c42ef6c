// ParaView's own reader (pvpython's vtkXMLUnstructuredGridReader, on this machine's expat) opens
// the particle frames m3dp writes, in each encoding, and reads every point and field value back.
#include <gtest/gtest.h>

#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "m3dp/io/vtk_writer.hpp"

namespace {

namespace fs = std::filesystem;
using m3dp::Real;
using m3dp::Vec3;

/// Runs a shell command; its stdout, and its exit status in `status`. Stderr goes to the test log.
std::string run(const std::string& command, int& status) {
  std::string output;
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return output;
  std::array<char, 4096> buffer{};
  while (std::fgets(buffer.data(), buffer.size(), pipe)) output += buffer.data();
  status = pclose(pipe);
  return output;
}

// For each file: the point count, the sum of the points' z, and density[0], density[last] and
// the sum of the ids, as VTK reads them; "ERR" lines from VTK go to stderr, which the test shows.
constexpr const char* kReadBack = R"(
import sys
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader
from vtkmodules.util.numpy_support import vtk_to_numpy
for name in sys.argv[1:]:
    reader = vtkXMLUnstructuredGridReader()
    reader.SetFileName(name)
    reader.Update()
    grid = reader.GetOutput()
    n = grid.GetNumberOfPoints()
    if n == 0:
        print(name, 0)
        continue
    points = vtk_to_numpy(grid.GetPoints().GetData())
    density = vtk_to_numpy(grid.GetPointData().GetArray("density"))
    ids = vtk_to_numpy(grid.GetPointData().GetArray("id"))
    print(name, n, repr(float(points[:, 2].astype("float64").sum())), repr(float(density[0])), repr(float(density[-1])),
          int(ids.astype("uint64").sum()), grid.GetNumberOfCells())
)";

TEST(ParaViewReadsFrames, EveryEncodingGivesBackThePointsAndFields) {
  int status = 0;
  const std::string expat = run("dpkg-query -W -f='${Version}' libexpat1 2>/dev/null", status);
  std::printf("libexpat1 on this machine: %s\n", expat.c_str());

  const fs::path folder = fs::temp_directory_path() / ("m3dp_test_paraview_frames_" + std::to_string(::getpid()));
  fs::remove_all(folder);
  fs::create_directories(folder);
  constexpr std::size_t kCount = 100003;  // several zlib blocks, a partial last one
  std::vector<Vec3> points(kCount);
  std::vector<Real> density(kCount);
  std::vector<std::uint64_t> ids(kCount);
  double z_sum = 0;
  std::uint64_t id_sum = 0;
  for (std::size_t i = 0; i < kCount; ++i) {
    points[i] = Vec3(Real(i % 97) * Real(0.001), Real(i % 89) * Real(0.002), Real(i % 83) * Real(0.003));
    density[i] = Real(1000) + Real(i % 1000) * Real(0.25);
    ids[i] = (std::uint64_t{1} << 33) + i;  // beyond 32 bits: read as UInt64
    z_sum += static_cast<double>(points[i].z());
    id_sum += ids[i];
  }
  std::string files;
  for (const int level : {1, 9, -1}) {
    const fs::path file = folder / ("frame_zlib" + std::to_string(level) + ".vtu");
    m3dp::io::write_vtu(file, points, {m3dp::io::PointArray::of("density", density), m3dp::io::PointArray::of("id", ids)},
                        {{"particle_radius", 0.001}}, {level});
    files.append(" ").append(file.string());
  }
  const fs::path empty = folder / "empty.vtu";
  m3dp::io::write_vtu(empty, std::span<const Vec3>{}, {}, {});
  files.append(" ").append(empty.string());
  const fs::path script = folder / "read_back.py";
  std::ofstream(script) << kReadBack;

  std::string command = "pvpython --force-offscreen-rendering ";
  command.append(script.string()).append(files);
  const std::string output = run(command, status);
  std::printf("pvpython read:\n%s", output.c_str());
  ASSERT_EQ(status, 0) << "pvpython failed";
  std::istringstream lines(output);
  std::string line;
  int frames = 0;
  while (std::getline(lines, line)) {
    std::istringstream words(line);
    std::string name;
    std::size_t count = 0;
    words >> name >> count;
    if (name == empty.string()) {
      EXPECT_EQ(count, 0u);
      ++frames;
      continue;
    }
    double read_z_sum = 0, first_density = 0, last_density = 0;
    std::uint64_t read_id_sum = 0, cells = 0;
    words >> read_z_sum >> first_density >> last_density >> read_id_sum >> cells;
    EXPECT_EQ(count, kCount) << name;
    EXPECT_EQ(cells, kCount) << name;
    EXPECT_NEAR(read_z_sum, z_sum, 1e-9 * z_sum) << name;
    EXPECT_EQ(first_density, static_cast<double>(density.front())) << name;
    EXPECT_EQ(last_density, static_cast<double>(density.back())) << name;
    EXPECT_EQ(read_id_sum, id_sum) << name;
    ++frames;
  }
  EXPECT_EQ(frames, 4);
  fs::remove_all(folder);
}

}  // namespace
