#pragma once
// checkpoint.bin in a run's folder, replaced (atomically) every <output><checkpoint_period> of
// simulated time: what the run was asked (scene, threads, options), the simulation's state and every
// output's, so that `m3dp run --resume RUN_DIR` goes on as if the run had never stopped.
#include <cstdint>
#include <filesystem>
#include <string>

#include "m3dp/core/state_io.hpp"

namespace m3dp::sim {

/// What a resumed run must be asked again: the same scene file, unchanged, and the same options.
struct CheckpointRun {
  std::filesystem::path scene_file;  // absolute
  std::uint64_t scene_hash = 0;      // of the scene file's bytes
  int threads = 0;                   // 0: all cores
  double until = 0;                  // s
  bool hash = false, record = false, wait_for_meshes = false;
  double checkpoint_period = 0, live_rate = 20;
  double time = 0;                   // s, the state's
  std::int64_t step = 0;
  void save(StateWriter& out) const;
  void load(StateReader& in);
};

inline constexpr const char* kCheckpointFile = "checkpoint.bin";

/// A hash of a file's bytes (FNV-1a, 64 bits); throws InputError if it cannot be read.
[[nodiscard]] std::uint64_t file_hash(const std::filesystem::path& file);
/// The bytes of RUN_DIR/checkpoint.bin; throws InputError naming the file if there is none.
[[nodiscard]] std::string read_checkpoint_bytes(const std::filesystem::path& run_directory);
/// The run's part of RUN_DIR/checkpoint.bin (for the command line, before the scene is loaded).
[[nodiscard]] CheckpointRun read_checkpoint_run(const std::filesystem::path& run_directory);

}  // namespace m3dp::sim
