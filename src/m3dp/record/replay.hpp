#pragma once
// Replays an MCAP recording through a Foxglove WebSocket server (m3dp view): the same channels as
// the live stream, the recording's messages sent at their log times scaled by the playback speed,
// with the protocol's playback controls (play, pause, speed, seek). On a seek, and when a client
// subscribes, the state at the current time is sent first: every scene update and run number up
// to it and each other channel's latest message, so that the picture and the plots are whole at once.
#include <filesystem>
#include <memory>
#include <optional>

#include "m3dp/record/foxglove_server.hpp"

namespace m3dp::record {

struct ReplayOptions {
  std::uint16_t port = 8765;  // 0: any free port
  /// Plain HTTP GETs on the same port (the viewer's page and scripts).
  std::function<std::optional<HttpFile>(std::string_view path)> http = {};
  bool play = true;    // start playing (else paused at the start)
  float speed = 1;     // times real time
  bool loop = false;   // start again at the end
};

class McapReplay {
 public:
  /// Opens the recording and starts serving it (m3dp::Error if the file or the port fails).
  McapReplay(const std::filesystem::path& mcap_file, const ReplayOptions& options);
  ~McapReplay();
  McapReplay(const McapReplay&) = delete;
  McapReplay& operator=(const McapReplay&) = delete;

  [[nodiscard]] std::uint16_t port() const;
  [[nodiscard]] double duration() const;  // s of recorded time
  [[nodiscard]] std::size_t message_count() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace m3dp::record
