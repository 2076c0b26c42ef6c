// Google Benchmark: the run's particle frame as a foxglove.PointCloud (what run.mcap and the live
// stream carry), made from a dam break of 10⁵ and 10⁶ particles: encoding alone, and encoding plus
// writing it to an MCAP file as the recording does (a zstd chunk, flushed). Bytes are the
// message's (56 per particle); the goal is >= 200 MB/s at 10⁶ particles.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <map>
#include <memory>
#include <unistd.h>

#include "m3dp/record/foxglove_messages.hpp"
#include "m3dp/record/mcap_writer.hpp"
#include "m3dp/sim/particle_cloud.hpp"
#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/simulation.hpp"

using namespace m3dp;

namespace {

/// One dam break per size, stepped once (moving, measured values), kept for every benchmark.
sim::Simulation& dam_break(std::size_t particles) {
  static std::map<std::size_t, std::unique_ptr<sim::Simulation>> simulations;
  auto& simulation = simulations[particles];
  if (!simulation) {
    sim::DamBreakSetup setup;
    setup.column_width = Real(0.5);
    setup.depth = Real(0.25);
    setup.particle_radius = sim::dam_break_radius_for_count(particles, setup.column_width, setup.depth);
    simulation = std::make_unique<sim::Simulation>(sim::dam_break_scene(setup));
    simulation->step();
    (void)simulation->measured_density();  // measured once per step: outside the timed loop
  }
  return *simulation;
}

void BM_EncodeParticleCloud(benchmark::State& state) {
  const sim::Simulation& simulation = dam_break(static_cast<std::size_t>(state.range(0)));
  std::string message;
  for (auto _ : state) {
    sim::encode_particle_cloud(simulation, message);
    benchmark::DoNotOptimize(message.data());
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * message.size()));
  state.counters["particles"] = static_cast<double>(simulation.solver().fluid().size());
}
BENCHMARK(BM_EncodeParticleCloud)->Arg(100000)->Arg(1000000)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RecordParticleFrame(benchmark::State& state) {
  const sim::Simulation& simulation = dam_break(static_cast<std::size_t>(state.range(0)));
  const auto file = std::filesystem::temp_directory_path() / ("m3dp_bench_record_" + std::to_string(::getpid()) + ".mcap");
  std::string message;
  std::size_t file_bytes = 0;
  {
    record::McapWriter writer(file, record::McapOptions{.zstd_threads = static_cast<int>(state.range(1))});
    const auto schema = writer.add_schema("foxglove.PointCloud", "protobuf", record::schema_descriptor_set("foxglove.PointCloud"));
    const auto channel = writer.add_channel("/particles", "protobuf", schema);
    std::uint64_t time = 0;
    for (auto _ : state) {
      sim::encode_particle_cloud(simulation, message);
      writer.write(channel, time += 1000000, message);
      writer.flush();  // a chunk per frame, as the recording writes
    }
    writer.close();
    file_bytes = writer.bytes_written();
  }
  state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations() * message.size()));
  state.counters["compressed_ratio"] = static_cast<double>(file_bytes) / static_cast<double>(state.iterations() * message.size());
  std::filesystem::remove(file);
}
// Arguments: particles, zstd threads (1: compression on the calling thread).
BENCHMARK(BM_RecordParticleFrame)
    ->Args({10000, 1})->Args({10000, 2})->Args({100000, 1})->Args({100000, 2})->Args({1000000, 1})->Args({1000000, 2})
    ->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
