#include "m3dp/record/replay.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "m3dp/core/error.hpp"
#include "m3dp/record/mcap_reader.hpp"

namespace m3dp::record {

namespace {
using Clock = std::chrono::steady_clock;
constexpr auto kTick = std::chrono::milliseconds(15);               // how often a playing replay sends
constexpr auto kSubscribeSettle = std::chrono::milliseconds(100);  // a new client's subscriptions come one by one
}  // namespace

struct McapReplay::Impl {
  McapReader reader;
  ReplayOptions options;
  std::vector<std::size_t> server_channel;  // by the MCAP channel's index in reader.channels()
  std::vector<std::size_t> channel_of_id;   // MCAP channel id → index in reader.channels()
  std::vector<bool> whole_history;          // by channel index: sent whole up to a time (the scene, numbers for plots)
  std::unique_ptr<FoxgloveServer> server;

  std::mutex mutex;  // the state below
  std::condition_variable wake;
  PlaybackStatus status = PlaybackStatus::paused;
  float speed = 1;
  std::uint64_t current = 0;  // ns, the replay's clock
  std::optional<std::uint64_t> seek;
  std::optional<Clock::time_point> resend_at;
  bool changed = true, quit = false;
  std::size_t cursor = 0;  // the next message to send
  std::thread thread;

  explicit Impl(const std::filesystem::path& file, const ReplayOptions& replay_options) : reader(file), options(replay_options) {}

  std::size_t first_after(std::uint64_t time) const {
    const auto& messages = reader.messages();
    return static_cast<std::size_t>(std::upper_bound(messages.begin(), messages.end(), time,
                                                     [](std::uint64_t t, const McapReader::Message& m) { return t < m.log_time; }) -
                                    messages.begin());
  }

  void send(const McapReader::Message& message) {
    const std::string_view data = reader.data(message);
    server->publish(server_channel[channel_of_id[message.channel]], message.log_time, std::make_shared<const std::string>(data));
  }

  /// The picture at `time`: every scene update (and every run number, for the plots) up to it,
  /// then each other channel's latest message.
  void send_state(std::uint64_t time) {
    const auto& messages = reader.messages();
    const std::size_t end = first_after(time);
    std::vector<std::size_t> latest(reader.channels().size(), ~std::size_t(0));
    for (std::size_t m = 0; m < end; ++m) {
      const std::size_t channel = channel_of_id[messages[m].channel];
      if (whole_history[channel]) send(messages[m]);
      else latest[channel] = m;
    }
    for (const std::size_t m : latest)
      if (m != ~std::size_t(0)) send(messages[m]);
    server->publish_time(time);
  }

  void run() {
    std::unique_lock lock(mutex);
    auto last = Clock::now();
    while (!quit) {
      if (seek || (resend_at && Clock::now() >= *resend_at)) {
        const std::uint64_t time = seek ? std::clamp(*seek, reader.start_time(), reader.end_time()) : current;
        const bool sought = seek.has_value();
        seek.reset();
        resend_at.reset();
        current = time;
        lock.unlock();
        send_state(time);
        lock.lock();
        if (sought) {
          cursor = first_after(time);
          if (status == PlaybackStatus::ended) status = PlaybackStatus::paused;
          changed = true;
        }
        last = Clock::now();
      }
      if (status == PlaybackStatus::playing) {
        const auto now = Clock::now();
        const auto elapsed = std::chrono::duration_cast<std::chrono::nanoseconds>(now - last).count();
        last = now;
        const std::uint64_t target = std::min(reader.end_time(), current + static_cast<std::uint64_t>(double(elapsed) * speed));
        const std::size_t from = cursor, to = first_after(target);
        cursor = to;
        current = target;
        lock.unlock();
        for (std::size_t m = from; m < to; ++m) send(reader.messages()[m]);
        server->publish_time(target);
        lock.lock();
        if (cursor >= reader.messages().size()) {
          if (options.loop) {
            seek = reader.start_time();
          } else {
            status = PlaybackStatus::ended;
          }
          changed = true;
        }
      } else {
        last = Clock::now();
      }
      if (changed) {
        changed = false;
        const auto state = status;
        const auto time = current;
        const float rate = speed;
        lock.unlock();
        server->publish_playback_state(state, time, rate);
        lock.lock();
      }
      wake.wait_for(lock, kTick);
    }
  }
};

McapReplay::McapReplay(const std::filesystem::path& mcap_file, const ReplayOptions& options)
    : impl_(std::make_unique<Impl>(mcap_file, options)) {
  Impl& impl = *impl_;
  const auto& reader = impl.reader;
  if (reader.messages().empty()) throw Error(fmt::format("{}: the recording has no messages", mcap_file.string()));
  std::vector<ServerChannel> channels;
  for (std::size_t c = 0; c < reader.channels().size(); ++c) {
    const auto& channel = reader.channels()[c];
    if (impl.channel_of_id.size() <= channel.id) impl.channel_of_id.resize(channel.id + 1, 0);
    impl.channel_of_id[channel.id] = c;
    // The scene's updates and the run's numbers go in order, and whole up to a time on a seek; the
    // rest give way to newer ones.
    const bool in_order = channel.topic == "/scene" || channel.topic == "/run" || channel.topic == "/joints";
    impl.whole_history.push_back(in_order);
    impl.server_channel.push_back(channels.size());
    channels.push_back({channel.topic, channel.schema_name, channel.schema_data, in_order ? Delivery::queued : Delivery::latest});
  }
  ServerOptions server_options;
  server_options.port = options.port;
  server_options.name = "m3dp view";
  server_options.playback_range = std::make_pair(reader.start_time(), reader.end_time());
  server_options.http = options.http;
  server_options.on_subscribe = [&impl](std::size_t) {
    std::lock_guard lock(impl.mutex);
    impl.resend_at = Clock::now() + kSubscribeSettle;
    impl.wake.notify_all();
  };
  server_options.on_playback_request = [&impl](const PlaybackRequest& request) {
    std::lock_guard lock(impl.mutex);
    if (request.seek_time) impl.seek = *request.seek_time;
    if (request.speed > 0 && request.speed < 1000) impl.speed = request.speed;
    if (request.status == PlaybackStatus::playing) {
      // Play at the end: again from the start.
      if (impl.cursor >= impl.reader.messages().size() && !request.seek_time) impl.seek = impl.reader.start_time();
      impl.status = PlaybackStatus::playing;
    } else {
      impl.status = PlaybackStatus::paused;
    }
    impl.changed = true;
    impl.wake.notify_all();
  };
  impl.server = std::make_unique<FoxgloveServer>(std::move(channels), server_options);
  impl.current = reader.start_time();
  impl.speed = options.speed;
  impl.status = options.play ? PlaybackStatus::playing : PlaybackStatus::paused;
  impl.thread = std::thread([&impl] { impl.run(); });
}

McapReplay::~McapReplay() {
  {
    std::lock_guard lock(impl_->mutex);
    impl_->quit = true;
    impl_->wake.notify_all();
  }
  impl_->thread.join();
  impl_->server->stop(std::chrono::milliseconds(200));
}

std::uint16_t McapReplay::port() const { return impl_->server->port(); }
double McapReplay::duration() const { return 1e-9 * double(impl_->reader.end_time() - impl_->reader.start_time()); }
std::size_t McapReplay::message_count() const { return impl_->reader.messages().size(); }

}  // namespace m3dp::record
