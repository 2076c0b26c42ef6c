#include "m3dp/sim/checkpoint.hpp"

#include <fstream>
#include <iterator>

#include "m3dp/core/error.hpp"

namespace m3dp::sim {

namespace {
constexpr const char* kMagic = "m3dp checkpoint 2";  // 2: particles keep their print layer
}

void CheckpointRun::save(StateWriter& out) const {
  out.section(kMagic);
  out.put(scene_file.string());
  out.put(scene_hash);
  out.put(threads);
  out.put(until);
  out.put(hash);
  out.put(record);
  out.put(wait_for_meshes);
  out.put(checkpoint_period);
  out.put(live_rate);
  out.put(time);
  out.put(step);
}

void CheckpointRun::load(StateReader& in) {
  in.section(kMagic);
  std::string scene;
  in.get(scene);
  scene_file = scene;
  in.get(scene_hash);
  in.get(threads);
  in.get(until);
  in.get(hash);
  in.get(record);
  in.get(wait_for_meshes);
  in.get(checkpoint_period);
  in.get(live_rate);
  in.get(time);
  in.get(step);
}

std::uint64_t file_hash(const std::filesystem::path& file) {
  std::ifstream stream(file, std::ios::binary);
  if (!stream) throw InputError({file.string(), 0}, "cannot read the file");
  std::uint64_t hash = 0xcbf29ce484222325ULL;
  for (std::istreambuf_iterator<char> it(stream), end; it != end; ++it) {
    hash ^= static_cast<unsigned char>(*it);
    hash *= 0x100000001b3ULL;
  }
  return hash;
}

std::string read_checkpoint_bytes(const std::filesystem::path& run_directory) {
  const auto file = run_directory / kCheckpointFile;
  std::ifstream stream(file, std::ios::binary);
  if (!stream)
    throw InputError({file.string(), 0}, "no checkpoint to resume from: run the scene with <output><checkpoint_period> (or "
                                         "m3dp run --checkpoint-period SECONDS) first");
  return {std::istreambuf_iterator<char>(stream), std::istreambuf_iterator<char>()};
}

CheckpointRun read_checkpoint_run(const std::filesystem::path& run_directory) {
  const std::string bytes = read_checkpoint_bytes(run_directory);
  StateReader in(bytes, (run_directory / kCheckpointFile).string());
  CheckpointRun run;
  run.load(in);
  return run;
}

}  // namespace m3dp::sim
