#pragma once
// A Foxglove WebSocket server (subprotocol foxglove.websocket.v1, github.com/foxglove/ws-protocol):
// it advertises the run's channels, streams each client the channels it subscribes to, and sends
// the simulated time. Foxglove, Lichtblick and M3DP's own viewer are its clients.
//
// The run never waits for a client. Each client has a queue that the server's own thread sends from
// while the client's socket keeps up; a channel's newer message replaces its unsent older one where
// the channel says so (particle frames), and what is dropped is counted and told to the client as a
// status. Messages a late client needs (the scene) are kept and sent when it subscribes.
// websocketpp and asio stay in foxglove_server.cpp.
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

namespace m3dp::record {

/// How the server treats a channel's message it cannot send at once.
enum class Delivery {
  latest,   // replaced by the channel's next message while unsent (particle frames, transforms)
  queued,   // kept in order while the client's queue is under its limit, else dropped (numbers, joints)
  latched,  // also kept by the server, one per key, and sent to every client that subscribes later
};

struct ServerChannel {
  std::string topic;
  std::string schema_name;  // "foxglove.PointCloud"
  std::string schema;       // its protobuf FileDescriptorSet (sent base64)
  Delivery delivery = Delivery::queued;
};

/// The protocol's playback (capability rangedPlayback): what a client asks of a replay.
enum class PlaybackStatus : std::uint8_t { playing = 0, paused = 1, buffering = 2, ended = 3 };
struct PlaybackRequest {
  PlaybackStatus status = PlaybackStatus::paused;  // playing or paused
  float speed = 1;                                 // times real time
  std::optional<std::uint64_t> seek_time;          // ns, when the client seeks
};

/// A file the server answers a plain HTTP GET with (the viewer's page and scripts).
struct HttpFile {
  std::string content_type;
  std::string body;
};

struct ServerOptions {
  std::string host = "127.0.0.1";             // localhost only by default
  std::uint16_t port = 8765;                  // 0: any free port (port() says which)
  std::string name = "m3dp";
  std::size_t client_queue_bytes = 64 << 20;  // a client's unsent bytes beyond which queued messages drop
  std::size_t socket_bytes = 8 << 20;         // bytes handed to a client's socket and unsent, beyond which the server waits
  /// A replay's time range (ns): the server announces rangedPlayback and takes playback requests.
  std::optional<std::pair<std::uint64_t, std::uint64_t>> playback_range = {};
  // Called on the server's thread, the server's lock not held.
  std::function<void(std::size_t channel)> on_subscribe = {};                 // a client subscribed to a channel
  std::function<void(const PlaybackRequest& request)> on_playback_request = {};
  std::function<std::optional<HttpFile>(std::string_view path)> http = {};     // plain GETs; none: 404
};

struct ServerStatistics {
  std::size_t clients = 0;          // connected over the server's life
  std::size_t clients_now = 0;
  std::uint64_t messages_sent = 0;  // message data to clients
  std::uint64_t bytes_sent = 0;
  std::uint64_t messages_dropped = 0;  // replaced or dropped unsent (slow clients)
};

class FoxgloveServer {
 public:
  /// Listens on options.host:port at once (m3dp::Error if it cannot) and serves on a thread of its own.
  explicit FoxgloveServer(std::vector<ServerChannel> channels, const ServerOptions& options = {});
  ~FoxgloveServer();  // stop() with a short drain
  FoxgloveServer(const FoxgloveServer&) = delete;
  FoxgloveServer& operator=(const FoxgloveServer&) = delete;

  [[nodiscard]] std::uint16_t port() const;
  /// Whether a client is subscribed to `channel` (an index into the channels given) now.
  [[nodiscard]] bool subscribed(std::size_t channel) const;
  /// A message on `channel` at `time_ns`. `key` names what a latched message replaces (an entity id).
  void publish(std::size_t channel, std::uint64_t time_ns, std::shared_ptr<const std::string> data, std::string_view key = {});
  /// Moves the clients' clocks to `time_ns` (the protocol's Time message).
  void publish_time(std::uint64_t time_ns);
  /// Tells every client how a replay plays (the protocol's PlaybackState).
  void publish_playback_state(PlaybackStatus status, std::uint64_t time_ns, float speed);
  /// Waits up to `drain` for the clients' queues to be sent, closes every connection and stops.
  void stop(std::chrono::milliseconds drain = std::chrono::milliseconds(2000));
  [[nodiscard]] ServerStatistics statistics() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace m3dp::record
