// C++17, not the project's C++20: websocketpp 0.8.2's headers do not compile as C++20 (template-ids
// on constructors and destructors), so this file and its header keep to C++17.
#include "m3dp/record/foxglove_server.hpp"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <map>
#include <mutex>
#include <thread>

// websocketpp on standalone asio (Debian's libwebsocketpp-dev and libasio-dev), in this file only.
#define ASIO_STANDALONE
#include <websocketpp/base64/base64.hpp>
#include <websocketpp/config/asio_no_tls.hpp>
#include <websocketpp/server.hpp>

#include "m3dp/core/error.hpp"

namespace m3dp::record {

namespace {

using WebSocketServer = websocketpp::server<websocketpp::config::asio>;
using Handle = websocketpp::connection_hdl;
using Clock = std::chrono::steady_clock;

constexpr std::string_view kSubprotocol = "foxglove.websocket.v1";
constexpr std::uint8_t kMessageData = 0x01, kTime = 0x02, kPlaybackState = 0x05;  // the protocol's binary opcodes, server to client
constexpr std::uint8_t kPlaybackControlRequest = 0x03;                              // client to server
constexpr std::uint32_t kNoSubscription = 0xFFFFFFFF;       // a queued Time message

template <typename T>
void put(std::string& out, T value) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));  // the protocol is little-endian, as x86 and ARM
  out.append(bytes, sizeof(T));
}

/// RFC 6455's header of an unmasked, final binary frame of `length` bytes (a server's frame).
std::string binary_frame_header(std::uint64_t length) {
  std::string header(1, static_cast<char>(0x82));
  if (length < 126) {
    header += static_cast<char>(length);
  } else if (length < 65536) {
    header += static_cast<char>(126);
    header += static_cast<char>(length >> 8);
    header += static_cast<char>(length & 0xFF);
  } else {
    header += static_cast<char>(127);
    for (int shift = 56; shift >= 0; shift -= 8) header += static_cast<char>((length >> shift) & 0xFF);
  }
  return header;
}

/// What waits in a client's queue: a channel's message, the clock (Time), or a whole binary
/// message of the server's own (PlaybackState), which is never dropped.
enum class Kind { message, time, raw };
struct Pending {
  Kind kind = Kind::message;
  std::size_t channel = 0;
  std::uint32_t subscription = kNoSubscription;
  std::uint64_t time_ns = 0;
  std::shared_ptr<const std::string> data;  // the message's payload, or the raw message
};

struct Client {
  Handle handle;
  std::map<std::uint32_t, std::size_t> channel_of_subscription;
  std::map<std::size_t, std::uint32_t> subscription_of_channel;
  std::deque<Pending> queue;
  std::size_t queued_bytes = 0;
  std::uint64_t dropped = 0, dropped_told = 0;
  Clock::time_point told_at{};
};

}  // namespace

struct FoxgloveServer::Impl {
  std::vector<ServerChannel> channels;
  ServerOptions options;
  WebSocketServer server;
  std::thread thread;
  std::uint16_t port = 0;
  std::string session_id;

  mutable std::mutex mutex;  // everything below
  std::map<Handle, Client, std::owner_less<Handle>> clients;
  std::vector<std::size_t> subscribers;  // per channel
  std::vector<std::vector<std::pair<std::string, Pending>>> latched;  // per channel: (key, message), in first-publish order
  ServerStatistics statistics;
  bool pump_posted = false, stopping = false;
  std::condition_variable drained;
  std::unique_ptr<asio::steady_timer> retry_timer;

  void send_text(const Handle& handle, const nlohmann::json& message) {
    std::error_code error;
    server.send(handle, message.dump(), websocketpp::frame::opcode::text, error);
  }

  void on_open(const Handle& handle) {
    nlohmann::json advertised = nlohmann::json::array();
    for (std::size_t c = 0; c < channels.size(); ++c)
      advertised.push_back({{"id", c + 1},
                            {"topic", channels[c].topic},
                            {"encoding", "protobuf"},
                            {"schemaName", channels[c].schema_name},
                            {"schema", websocketpp::base64_encode(channels[c].schema)},
                            {"schemaEncoding", "protobuf"}});
    {
      std::lock_guard lock(mutex);
      Client client;
      client.handle = handle;
      clients.emplace(handle, std::move(client));
      ++statistics.clients;
    }
    nlohmann::json info = {{"op", "serverInfo"},
                           {"name", options.name},
                           {"capabilities", {"time"}},
                           {"supportedEncodings", nlohmann::json::array()},
                           {"metadata", nlohmann::json::object()},
                           {"sessionId", session_id}};
    if (options.playback_range) {
      info["capabilities"].push_back("rangedPlayback");
      info["dataStartTime"] = options.playback_range->first;
      info["dataEndTime"] = options.playback_range->second;
    }
    send_text(handle, info);
    send_text(handle, {{"op", "advertise"}, {"channels", advertised}});
  }

  void on_close(const Handle& handle) {
    std::lock_guard lock(mutex);
    const auto found = clients.find(handle);
    if (found == clients.end()) return;
    for (const auto& [channel, subscription] : found->second.subscription_of_channel) --subscribers[channel];
    clients.erase(found);
    drained.notify_all();
  }

  void on_message(const Handle& handle, const WebSocketServer::message_ptr& message) {
    if (message->get_opcode() != websocketpp::frame::opcode::text) {
      const std::string& payload = message->get_payload();
      // PlaybackControlRequest: status u8, speed f32, had_seek u8, seek_time u64 (little-endian).
      if (options.playback_range && options.on_playback_request && payload.size() >= 15 &&
          static_cast<std::uint8_t>(payload[0]) == kPlaybackControlRequest) {
        PlaybackRequest request;
        request.status = static_cast<std::uint8_t>(payload[1]) == 0 ? PlaybackStatus::playing : PlaybackStatus::paused;
        std::memcpy(&request.speed, payload.data() + 2, 4);
        if (payload[6] != 0) {
          std::uint64_t seek = 0;
          std::memcpy(&seek, payload.data() + 7, 8);
          request.seek_time = seek;
        }
        options.on_playback_request(request);
        return;
      }
      send_text(handle, {{"op", "status"}, {"level", 1}, {"message", "m3dp's server takes no client messages (clientPublish)"}});
      return;
    }
    const nlohmann::json request = nlohmann::json::parse(message->get_payload(), nullptr, false);
    const std::string op = request.is_object() ? request.value("op", "") : "";
    std::vector<std::string> problems;
    std::vector<std::size_t> subscribed;  // channels newly subscribed to, for on_subscribe
    {
      std::lock_guard lock(mutex);
      const auto found = clients.find(handle);
      if (found == clients.end()) return;
      Client& client = found->second;
      if (op == "subscribe" && request.contains("subscriptions") && request["subscriptions"].is_array()) {
        for (const auto& subscription : request["subscriptions"]) {
          const auto id = subscription.value("id", std::int64_t(-1));
          const auto channel_id = subscription.value("channelId", std::int64_t(0));
          if (id < 0 || id >= kNoSubscription || channel_id < 1 || channel_id > static_cast<std::int64_t>(channels.size())) {
            problems.push_back(fmt::format("subscription {} to channel {}: no such channel", id, channel_id));
            continue;
          }
          const auto channel = static_cast<std::size_t>(channel_id - 1);
          const auto subscription_id = static_cast<std::uint32_t>(id);
          if (client.channel_of_subscription.count(subscription_id) > 0 || client.subscription_of_channel.count(channel) > 0) {
            problems.push_back(fmt::format("subscription {} to channel {}: already subscribed", id, channel_id));
            continue;
          }
          client.channel_of_subscription[subscription_id] = channel;
          client.subscription_of_channel[channel] = subscription_id;
          ++subscribers[channel];
          // What a late client needs first: the channel's kept messages.
          for (const auto& [key, kept] : latched[channel])
            enqueue(client, Pending{Kind::message, channel, subscription_id, kept.time_ns, kept.data});
          subscribed.push_back(channel);
        }
        post_pump_locked();
      } else if (op == "unsubscribe" && request.contains("subscriptionIds") && request["subscriptionIds"].is_array()) {
        for (const auto& id : request["subscriptionIds"]) {
          if (!id.is_number_unsigned()) continue;
          const auto subscription = client.channel_of_subscription.find(id.get<std::uint32_t>());
          if (subscription == client.channel_of_subscription.end()) continue;
          const std::size_t channel = subscription->second;
          --subscribers[channel];
          client.subscription_of_channel.erase(channel);
          client.channel_of_subscription.erase(subscription);
          const auto kept_end = std::remove_if(client.queue.begin(), client.queue.end(), [&](const Pending& pending) {
            const bool drop = pending.kind == Kind::message && pending.channel == channel;
            if (drop) client.queued_bytes -= pending.data->size();
            return drop;
          });
          client.queue.erase(kept_end, client.queue.end());
        }
      } else {
        problems.push_back(fmt::format("'{}' is not an operation m3dp's server supports (subscribe, unsubscribe)",
                                       op.empty() ? message->get_payload().substr(0, 80) : op));
      }
    }
    for (const auto& problem : problems) send_text(handle, {{"op", "status"}, {"level", 2}, {"message", problem}});
    if (options.on_subscribe)
      for (const std::size_t channel : subscribed) options.on_subscribe(channel);
  }

  void on_http(const Handle& handle) {
    const auto connection = server.get_con_from_hdl(handle);
    std::string path = connection->get_resource();
    path = path.substr(0, path.find('?'));
    std::optional<HttpFile> file;
    if (options.http) file = options.http(path);
    if (!file) {
      connection->set_status(websocketpp::http::status_code::not_found);
      connection->set_body(fmt::format("{} is not a file of m3dp's viewer\n", path));
      connection->append_header("Content-Type", "text/plain");
      return;
    }
    connection->set_status(websocketpp::http::status_code::ok);
    connection->append_header("Content-Type", file->content_type);
    connection->append_header("Cache-Control", "no-cache");
    connection->set_body(std::move(file->body));
  }

  /// Puts `pending` on the client's queue by its channel's delivery (the lock held).
  void enqueue(Client& client, Pending pending) {
    const Delivery delivery = pending.kind == Kind::message ? channels[pending.channel].delivery
                              : pending.kind == Kind::time  ? Delivery::latest
                                                            : Delivery::latched;  // raw: kept in order, never dropped
    if (delivery == Delivery::latest) {
      // The unsent older message of the channel (or the older time) gives way to this one.
      for (auto& queued : client.queue)
        if (queued.kind == pending.kind && queued.channel == pending.channel) {
          if (queued.kind == Kind::message) {
            client.queued_bytes -= queued.data->size();
            ++client.dropped;
            ++statistics.messages_dropped;
          }
          client.queued_bytes += pending.data ? pending.data->size() : 0;
          queued = std::move(pending);
          return;
        }
    } else if (delivery == Delivery::queued && client.queued_bytes + pending.data->size() > options.client_queue_bytes) {
      ++client.dropped;
      ++statistics.messages_dropped;
      return;
    }
    client.queued_bytes += pending.data ? pending.data->size() : 0;
    client.queue.push_back(std::move(pending));
  }

  void post_pump_locked() {
    if (pump_posted) return;
    pump_posted = true;
    asio::post(server.get_io_service(), [this] { pump(); });
  }

  /// On the server's thread: hands each client's queue to its socket while the socket keeps up.
  void pump() {
    struct Send {
      Handle handle;
      Pending pending;
    };
    std::vector<Send> sends;
    std::vector<std::pair<Handle, std::string>> notices;
    bool more = false;
    {
      std::lock_guard lock(mutex);
      pump_posted = false;
      for (auto& [handle, client] : clients) {
        std::error_code error;
        const auto connection = server.get_con_from_hdl(handle, error);
        if (error) continue;
        std::size_t in_socket = connection->get_buffered_amount();
        while (!client.queue.empty() && in_socket < options.socket_bytes) {
          Pending pending = std::move(client.queue.front());
          client.queue.pop_front();
          const std::size_t bytes = pending.data ? pending.data->size() : 0;
          client.queued_bytes -= bytes;
          in_socket += bytes + 13;
          sends.push_back({handle, std::move(pending)});
        }
        more = more || !client.queue.empty();
        if (client.dropped > client.dropped_told && Clock::now() - client.told_at > std::chrono::seconds(1)) {
          notices.emplace_back(handle, fmt::format("m3dp dropped {} of this client's unread messages: it reads slower than the run "
                                                   "makes them (particle frames give way to newer ones)",
                                                   client.dropped - client.dropped_told));
          client.dropped_told = client.dropped;
          client.told_at = Clock::now();
        }
      }
      if (!more) drained.notify_all();  // every queue handed to its socket (stop() waits for it)
    }
    std::uint64_t messages = 0, bytes = 0;
    for (const Send& send : sends) {
      std::error_code error;
      const auto connection = server.get_con_from_hdl(send.handle, error);
      if (error) continue;
      // The frame prepared here, so websocketpp sends it without another copy.
      std::string payload;
      if (send.pending.kind == Kind::raw) {
        payload = *send.pending.data;
      } else if (send.pending.kind == Kind::message) {
        payload.reserve(13 + send.pending.data->size());
        put(payload, kMessageData);
        put(payload, send.pending.subscription);
        put(payload, send.pending.time_ns);
        payload.append(*send.pending.data);
        ++messages;
        bytes += payload.size();
      } else {
        put(payload, kTime);
        put(payload, send.pending.time_ns);
      }
      auto message = connection->get_message(websocketpp::frame::opcode::binary, 0);
      message->set_header(binary_frame_header(payload.size()));
      message->get_raw_payload() = std::move(payload);
      message->set_prepared(true);
      connection->send(message);
    }
    for (const auto& [handle, text] : notices) send_text(handle, {{"op", "status"}, {"level", 1}, {"message", text}});
    {
      std::lock_guard lock(mutex);
      statistics.messages_sent += messages;
      statistics.bytes_sent += bytes;
    }
    if (more) {
      // A socket is full: look again soon (websocketpp has no "drained" callback).
      retry_timer->expires_after(std::chrono::milliseconds(2));
      retry_timer->async_wait([this](const std::error_code& error) {
        if (error) return;
        std::lock_guard lock(mutex);
        post_pump_locked();
      });
    }
  }
};

FoxgloveServer::FoxgloveServer(std::vector<ServerChannel> channels, const ServerOptions& options) : impl_(std::make_unique<Impl>()) {
  Impl& impl = *impl_;
  impl.channels = std::move(channels);
  impl.options = options;
  impl.subscribers.assign(impl.channels.size(), 0);
  impl.latched.resize(impl.channels.size());
  impl.session_id = std::to_string(std::chrono::system_clock::now().time_since_epoch().count());
  auto& server = impl.server;
  server.clear_access_channels(websocketpp::log::alevel::all);
  server.clear_error_channels(websocketpp::log::elevel::all);
  server.init_asio();
  server.set_reuse_addr(true);
  server.set_close_handshake_timeout(500);
  server.set_validate_handler([&server](Handle handle) {
    const auto connection = server.get_con_from_hdl(handle);
    for (const auto& requested : connection->get_requested_subprotocols())
      if (requested == kSubprotocol) {
        connection->select_subprotocol(std::string(kSubprotocol));
        return true;
      }
    return false;  // the protocol asks the server to pick it; a client that offers none is refused
  });
  server.set_open_handler([&impl](Handle handle) { impl.on_open(handle); });
  server.set_close_handler([&impl](Handle handle) { impl.on_close(handle); });
  server.set_fail_handler([&impl](Handle handle) { impl.on_close(handle); });
  server.set_message_handler([&impl](Handle handle, WebSocketServer::message_ptr message) { impl.on_message(handle, message); });
  server.set_http_handler([&impl](Handle handle) { impl.on_http(handle); });
  std::error_code error;
  const auto address = asio::ip::make_address(options.host, error);
  if (error) throw Error(fmt::format("live stream: '{}' is not an IP address", options.host));
  server.listen(asio::ip::tcp::endpoint(address, options.port), error);
  if (error) throw Error(fmt::format("live stream: cannot listen on {}:{}: {}", options.host, options.port, error.message()));
  impl.port = server.get_local_endpoint(error).port();
  server.start_accept(error);
  if (error) throw Error(fmt::format("live stream: cannot accept connections: {}", error.message()));
  impl.retry_timer = std::make_unique<asio::steady_timer>(server.get_io_service());
  impl.thread = std::thread([&server] { server.run(); });
}

FoxgloveServer::~FoxgloveServer() {
  try {
    stop(std::chrono::milliseconds(200));
  } catch (...) {  // a destructor must not throw
  }
}

std::uint16_t FoxgloveServer::port() const { return impl_->port; }

bool FoxgloveServer::subscribed(std::size_t channel) const {
  std::lock_guard lock(impl_->mutex);
  return impl_->subscribers.at(channel) > 0;
}

void FoxgloveServer::publish(std::size_t channel, std::uint64_t time_ns, std::shared_ptr<const std::string> data, std::string_view key) {
  Impl& impl = *impl_;
  std::lock_guard lock(impl.mutex);
  if (impl.stopping) return;
  if (impl.channels.at(channel).delivery == Delivery::latched) {
    auto& kept = impl.latched[channel];
    const auto same_key = std::find_if(kept.begin(), kept.end(), [&](const auto& entry) { return entry.first == key; });
    Pending pending{Kind::message, channel, kNoSubscription, time_ns, data};
    if (same_key != kept.end()) same_key->second = std::move(pending);
    else kept.emplace_back(std::string(key), std::move(pending));
  }
  if (impl.subscribers[channel] == 0) return;
  for (auto& [handle, client] : impl.clients) {
    const auto subscription = client.subscription_of_channel.find(channel);
    if (subscription != client.subscription_of_channel.end()) impl.enqueue(client, Pending{Kind::message, channel, subscription->second, time_ns, data});
  }
  impl.post_pump_locked();
}

void FoxgloveServer::publish_time(std::uint64_t time_ns) {
  Impl& impl = *impl_;
  std::lock_guard lock(impl.mutex);
  if (impl.stopping || impl.clients.empty()) return;
  for (auto& [handle, client] : impl.clients) impl.enqueue(client, Pending{Kind::time, 0, kNoSubscription, time_ns, nullptr});
  impl.post_pump_locked();
}

void FoxgloveServer::publish_playback_state(PlaybackStatus status, std::uint64_t time_ns, float speed) {
  Impl& impl = *impl_;
  // status u8, current_time u64, speed f32, request id length u32 (none).
  auto message = std::make_shared<std::string>();
  put(*message, kPlaybackState);
  put(*message, static_cast<std::uint8_t>(status));
  put(*message, time_ns);
  put(*message, speed);
  put(*message, std::uint32_t(0));
  std::lock_guard lock(impl.mutex);
  if (impl.stopping || impl.clients.empty()) return;
  for (auto& [handle, client] : impl.clients) impl.enqueue(client, Pending{Kind::raw, 0, kNoSubscription, time_ns, message});
  impl.post_pump_locked();
}

void FoxgloveServer::stop(std::chrono::milliseconds drain) {
  Impl& impl = *impl_;
  if (!impl.thread.joinable()) return;
  {
    std::unique_lock lock(impl.mutex);
    impl.stopping = true;
    impl.post_pump_locked();
    impl.drained.wait_for(lock, drain, [&] {
      return std::all_of(impl.clients.begin(), impl.clients.end(), [](const auto& entry) { return entry.second.queue.empty(); });
    });
  }
  asio::post(impl.server.get_io_service(), [&impl] {
    std::error_code error;
    impl.server.stop_listening(error);
    impl.retry_timer->cancel();
    std::vector<Handle> handles;
    {
      std::lock_guard lock(impl.mutex);
      for (const auto& [handle, client] : impl.clients) handles.push_back(handle);
    }
    for (const Handle& handle : handles) impl.server.close(handle, websocketpp::close::status::going_away, "the run ended", error);
  });
  {
    // Clients answer the close within the handshake timeout; then the loop runs out of work.
    std::unique_lock lock(impl.mutex);
    impl.drained.wait_for(lock, std::chrono::milliseconds(1000), [&] { return impl.clients.empty(); });
  }
  impl.server.stop();
  impl.thread.join();
}

ServerStatistics FoxgloveServer::statistics() const {
  std::lock_guard lock(impl_->mutex);
  ServerStatistics statistics = impl_->statistics;
  statistics.clients_now = impl_->clients.size();
  return statistics;
}

}  // namespace m3dp::record
