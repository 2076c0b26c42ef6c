// m3dp view RUN_DIR: a run's recording (run.mcap) played back through the same Foxglove WebSocket
// server as the live stream, with the protocol's playback controls, and the browser viewer's page
// served from the same port: open the URL it prints, or connect Foxglove or Lichtblick to it.
#include "view_command.hpp"

#include <fmt/format.h>

#include <chrono>
#include <cstdio>
#include <thread>

#include "m3dp/core/error.hpp"
#include "m3dp/record/replay.hpp"
#include "viewer_files.hpp"

namespace m3dp::app {

void add_view_options(CLI::App& command, ViewOptions& options) {
  command.add_option("run", options.run, "A run folder (with run.mcap, as m3dp run --record writes) or an .mcap file")
      ->required()
      ->check(CLI::ExistingPath);
  command.add_option("--port", options.port, "Port on localhost (0: any free one)")->check(CLI::Range(0, 65535))->capture_default_str();
  command.add_option("--speed", options.speed, "Playback speed, times real time")->check(CLI::Range(0.01, 100.0))->capture_default_str();
  command.add_flag("--paused", options.paused, "Start paused at the beginning");
  command.add_flag("--loop", options.loop, "Start again at the end");
}

int view_command(const ViewOptions& options, const std::atomic<bool>& stop) {
  const std::filesystem::path file = std::filesystem::is_directory(options.run) ? options.run / "run.mcap" : options.run;
  if (!std::filesystem::exists(file))
    throw Error(fmt::format("{}: no run.mcap: record the run with m3dp run --record (or <output><mcap>true</mcap> in its scene)",
                            options.run.string()));
  record::ReplayOptions replay_options;
  replay_options.port = static_cast<std::uint16_t>(options.port);
  replay_options.http = viewer_file;
  replay_options.play = !options.paused;
  replay_options.speed = static_cast<float>(options.speed);
  replay_options.loop = options.loop;
  record::McapReplay replay(file, replay_options);
  fmt::print("m3dp: {} ({:.1f} s, {} messages) at http://127.0.0.1:{}/ (the viewer; Foxglove or Lichtblick: Open connection, "
             "Foxglove WebSocket, ws://127.0.0.1:{}); Ctrl-C stops\n",
             file.string(), replay.duration(), replay.message_count(), replay.port(), replay.port());
  std::fflush(stdout);
  while (!stop.load()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  return 0;
}

}  // namespace m3dp::app
