// hashes.csv (and stdout): with `m3dp run --hash`, a hash of the state after every step, so that
// anyone can check that a scene gives the same run, bit for bit, on their machine: the fluid
// (positions, velocities, ids, materials, rest times), the free bodies (poses and velocities) and the
// robots (joint positions and velocities), each hashed apart so a difference says where it began.
// Written as hashes.csv.partial and renamed when the run ends.
#include <fmt/format.h>
#include <fmt/os.h>

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <span>

#include "m3dp/core/error.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/outputs/partial_text_file.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

/// A 64-bit hash of bytes, eight at a time: each word is mixed in with a multiply and rotation
/// (the state only needs equality checked, not cryptographic strength).
class StateHasher {
 public:
  template <class T>
  void add(std::span<const T> values) {
    const auto* bytes = reinterpret_cast<const unsigned char*>(values.data());
    const std::size_t size = values.size_bytes();
    std::size_t offset = 0;
    for (; offset + 8 <= size; offset += 8) {
      std::uint64_t word;
      std::memcpy(&word, bytes + offset, 8);
      mix(word);
    }
    std::uint64_t tail = 0;
    std::memcpy(&tail, bytes + offset, size - offset);
    mix(tail ^ (std::uint64_t(size) << 56));
  }
  template <class T>
  void add(const std::vector<T>& values) {
    add(std::span<const T>(values));
  }
  [[nodiscard]] std::uint64_t value() const {
    std::uint64_t h = state_;  // finalised as in splitmix64
    h = (h ^ (h >> 30)) * 0xbf58476d1ce4e5b9ULL;
    h = (h ^ (h >> 27)) * 0x94d049bb133111ebULL;
    return h ^ (h >> 31);
  }

 private:
  void mix(std::uint64_t word) {
    state_ ^= word * 0x9e3779b97f4a7c15ULL;
    state_ = ((state_ << 31) | (state_ >> 33)) * 0xff51afd7ed558ccdULL;
  }
  std::uint64_t state_ = 0x243f6a8885a308d3ULL;
};

class StateHash final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the state hashes"; }
  explicit StateHash(const std::filesystem::path& output_directory) : file_(output_directory / "hashes.csv") {}

  void start(const Simulation& /*simulation*/) override { file_.create("step,time_s,fluid,bodies,robots,state\n"); }
  void save(StateWriter& out) override { file_.save(out); }
  void resume(const Simulation& /*simulation*/, StateReader& in) override { file_.resume(in); }

  void observe(const Simulation& simulation, const StepReport& /*report*/) override {
    const auto& fluid = simulation.solver().fluid();
    StateHasher fluid_hash, bodies_hash, robots_hash, state_hash;
    fluid_hash.add(fluid.position);
    fluid_hash.add(fluid.velocity);
    fluid_hash.add(fluid.id);
    fluid_hash.add(fluid.phase);
    fluid_hash.add(fluid.rest_time);
    const world::World& world = simulation.world();
    for (const world::BodyIndex body : simulation.dynamic_bodies()) {
      const Pose pose = world.pose(body);
      const Vec3 velocity = world.linear_velocity(body);
      const std::array<Real, 10> values{pose.position.x(),    pose.position.y(),    pose.position.z(),    pose.orientation.w(),
                                        pose.orientation.x(), pose.orientation.y(), pose.orientation.z(), velocity.x(),
                                        velocity.y(),         velocity.z()};
      bodies_hash.add(std::span<const Real>(values));
    }
    for (const world::RobotIndex robot : simulation.robots()) {
      robots_hash.add(world.joint_positions(robot));
      robots_hash.add(world.joint_velocities(robot));
    }
    const std::array<std::uint64_t, 3> parts{fluid_hash.value(), bodies_hash.value(), robots_hash.value()};
    state_hash.add(std::span<const std::uint64_t>(parts));
    const std::int64_t step = simulation.solver().state().step;
    fmt::print(file_.get(), "{},{:.9g},{:016x},{:016x},{:016x},{:016x}\n", step, simulation.time(), parts[0], parts[1], parts[2],
               state_hash.value());
    fmt::print("hash {} {:.9g} {:016x}\n", step, simulation.time(), state_hash.value());
  }

  void finish(const Simulation& /*simulation*/, RunSummary& /*summary*/) override {
    file_.finish();
    std::fflush(stdout);
  }

 private:
  PartialTextFile file_;
};

}  // namespace

std::unique_ptr<RunObserver> make_state_hash(Simulation& /*simulation*/, const RunOptions& options) {
  if (!options.hash || options.output_directory.empty()) return nullptr;
  return std::make_unique<StateHash>(options.output_directory);
}

}  // namespace m3dp::sim::outputs
