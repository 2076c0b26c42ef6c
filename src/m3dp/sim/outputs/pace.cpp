// Pace (`m3dp run --pace F`): the run waits after a step that is ahead of F simulated seconds per
// wall second, so that a live viewer sees the print at a speed it can follow (1: real time).
// Waiting changes nothing of the run but its wall time.
#include <chrono>
#include <thread>

#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

using Clock = std::chrono::steady_clock;

class Pace final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the pace"; }
  explicit Pace(double pace) : pace_(pace) {}
  [[nodiscard]] bool is_output() const override { return false; }
  void start(const Simulation& simulation) override {
    wall_start_ = Clock::now();
    time_start_ = simulation.time();
  }
  void observe(const Simulation& simulation, const StepReport& /*report*/) override {
    const auto due = wall_start_ + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>((simulation.time() - time_start_) / pace_));
    std::this_thread::sleep_until(due);
  }

 private:
  double pace_;  // simulated s per wall s
  Clock::time_point wall_start_;
  double time_start_ = 0;
};

}  // namespace

std::unique_ptr<RunObserver> make_pace(Simulation& /*simulation*/, const RunOptions& options) {
  if (!(options.pace > 0)) return nullptr;
  return std::make_unique<Pace>(options.pace);
}

}  // namespace m3dp::sim::outputs
