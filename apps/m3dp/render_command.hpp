#pragma once
#include <CLI/CLI.hpp>

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace m3dp::app {

struct RenderOptions {
  std::filesystem::path run;         // a run folder (m3dp run's output)
  std::filesystem::path output = "render.png";
  std::optional<double> time;        // s; default the last frame
  std::string camera;                // one of the scene's cameras
  std::vector<double> eye, target;   // m, world: a free camera instead
  int width = 1280, height = 960;    // the free camera's image
  double fov_degrees = 45;           // the free camera's horizontal field of view
  int threads = 0;
};

void add_render_options(CLI::App& command, RenderOptions& options);
int render_command(const RenderOptions& options);

}  // namespace m3dp::app
