#pragma once
#include <CLI/CLI.hpp>

#include <filesystem>
#include <string>

#include "m3dp/surface/surface.hpp"

namespace m3dp::app {

struct MeshOptions {
  std::filesystem::path input;   // .vtu/.vtp/.ply frame or .pvd sequence
  std::filesystem::path output;  // mesh file, or folder (sequence, sdf model)
  std::string method = "anisotropic";
  std::string format;            // obj, ply, stl, sdf; default from the output's extension, else obj
  double particle_radius = 0;    // m; 0 = from the file's FieldData
  double voxel_size = 0, kernel_radius = 0, sphere_radius = 0, iso_level = 0.5;
  int smoothing_iterations = 0;
  int threads = 0;
  bool quiet = false;
};

void add_mesh_options(CLI::App& command, MeshOptions& options);
int mesh_command(const MeshOptions& options);

}  // namespace m3dp::app
