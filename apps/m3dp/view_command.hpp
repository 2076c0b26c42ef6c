#pragma once
#include <CLI/CLI.hpp>

#include <atomic>
#include <filesystem>

namespace m3dp::app {

struct ViewOptions {
  std::filesystem::path run;  // a run folder with run.mcap, or an .mcap file
  int port = 8765;            // 0: any free port
  double speed = 1;           // times real time
  bool paused = false;
  bool loop = false;
};

void add_view_options(CLI::App& command, ViewOptions& options);
/// Serves the recording and the viewer until `stop` is set (Ctrl-C).
int view_command(const ViewOptions& options, const std::atomic<bool>& stop);

}  // namespace m3dp::app
