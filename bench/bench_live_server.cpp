// The live server's own cost: a particle frame of a dam break (10⁵ particles by default, 5.6 MB)
// published at --rate frames per second for --seconds to the clients that connect (bench/live_clients.js
// --server-only connects them), and the CPU the process used meanwhile: what a run that keeps every
// core busy would lose to the server: its own code (user) and the kernel's sockets (system; on
// localhost the kernel also does the clients' half of TCP there).
//   bench_live_server [--particles N] [--rate HZ] [--seconds S] [--clients C]
// Prints "port P", waits for C clients subscribed to /particles, publishes, then one CSV line.
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <thread>

#include "m3dp/record/foxglove_messages.hpp"
#include "m3dp/record/foxglove_server.hpp"
#include "m3dp/sim/particle_cloud.hpp"
#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/simulation.hpp"

using namespace m3dp;
using Clock = std::chrono::steady_clock;

namespace {
/// The process's CPU seconds so far: in its own code (user) and in the kernel (system: the sockets).
std::pair<double, double> cpu_seconds() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return {double(usage.ru_utime.tv_sec) + 1e-6 * double(usage.ru_utime.tv_usec),
          double(usage.ru_stime.tv_sec) + 1e-6 * double(usage.ru_stime.tv_usec)};
}
}  // namespace

int main(int argc, char** argv) {
  std::size_t particles = 100000;
  double rate = 20, seconds = 10;
  std::size_t clients = 4;
  CLI::App app("The live server's CPU cost at a frame rate");
  app.add_option("--particles", particles)->capture_default_str();
  app.add_option("--rate", rate)->capture_default_str();
  app.add_option("--seconds", seconds)->capture_default_str();
  app.add_option("--clients", clients)->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  sim::DamBreakSetup setup;
  setup.column_width = Real(0.5);
  setup.depth = Real(0.25);
  setup.particle_radius = sim::dam_break_radius_for_count(particles, setup.column_width, setup.depth);
  sim::Simulation simulation(sim::dam_break_scene(setup));
  simulation.step();
  std::string cloud;
  sim::encode_particle_cloud(simulation, cloud);
  const auto frame = std::make_shared<const std::string>(std::move(cloud));

  record::FoxgloveServer server({{"/particles", "foxglove.PointCloud", record::schema_descriptor_set("foxglove.PointCloud"),
                                  record::Delivery::latest}},
                                record::ServerOptions{.port = 0});
  fmt::print("port {}\n", server.port());
  std::fflush(stdout);
  while (server.statistics().clients_now < clients || !server.subscribed(0)) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  std::this_thread::sleep_for(std::chrono::milliseconds(500));  // every client's subscription in

  const auto cpu_start = cpu_seconds();
  const auto start = Clock::now();
  std::size_t frames = 0;
  for (; frames < static_cast<std::size_t>(rate * seconds); ++frames) {
    std::this_thread::sleep_until(start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(double(frames) / rate)));
    server.publish(0, frames * 50'000'000ull, frame);
  }
  server.stop();
  const double wall = std::chrono::duration<double>(Clock::now() - start).count();
  const double user = cpu_seconds().first - cpu_start.first, system = cpu_seconds().second - cpu_start.second;
  const auto statistics = server.statistics();
  fmt::print("particles,frame_MB,rate_hz,clients,frames,messages_sent,messages_dropped,MB_sent,wall_s,cores_user,cores_system\n");
  fmt::print("{},{:.2f},{:.1f},{},{},{},{},{:.0f},{:.2f},{:.4f},{:.4f}\n", simulation.solver().fluid().size(), 1e-6 * double(frame->size()),
             rate, clients, frames, statistics.messages_sent, statistics.messages_dropped, 1e-6 * double(statistics.bytes_sent), wall,
             user / wall, system / wall);
  return 0;
}
