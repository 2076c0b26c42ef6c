// The progress line on the terminal (core/progress.hpp): simulated time, speed, particles, the latest
// measured density error, ETA.
#include <chrono>
#include <cstdio>

#include "m3dp/core/progress.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

class Progress final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the progress bar"; }
  explicit Progress(double end_time) : end_time_(end_time) {}
  [[nodiscard]] bool is_output() const override { return false; }
  void start(const Simulation& /*simulation*/) override { wall_start_ = std::chrono::steady_clock::now(); }
  void observe(const Simulation& simulation, const StepReport& /*report*/) override {
    bar_.update(sample(simulation, static_cast<long long>(simulation.solver().fluid().size()),
                       std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start_).count()));
  }
  void finish(const Simulation& simulation, RunSummary& /*summary*/) override {
    bar_.finish(sample(simulation, static_cast<long long>(simulation.solver().fluid().size()),
                       std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start_).count()));
  }

 private:
  [[nodiscard]] ProgressSample sample(const Simulation& simulation, long long particles, double wall_time) const {
    ProgressSample sample;
    sample.simulated_time_s = simulation.time();
    sample.end_time_s = end_time_;
    sample.steps = simulation.solver().state().step;
    sample.particles = particles;
    sample.wall_time_s = wall_time;
    if (const auto* density = simulation.latest_density_measurement()) {
      sample.density_error_p99 = density->statistics.p99;
      sample.density_error_max = density->statistics.max;
    }
    return sample;
  }

  ProgressBar bar_{stderr, true};
  double end_time_;
  std::chrono::steady_clock::time_point wall_start_;
};

}  // namespace

std::unique_ptr<RunObserver> make_progress_bar(Simulation& simulation, const RunOptions& options) {
  if (!options.show_progress) return nullptr;
  return std::make_unique<Progress>(options.until.value_or(simulation.scene().end_time));
}

}  // namespace m3dp::sim::outputs
