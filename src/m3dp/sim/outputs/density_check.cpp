// The density the run reports: measured from the positions (Simulation::measured_density) at every
// particle frame, or a hundred times a run without frames, and at its end; the summary keeps the last
// check and the worst ones. Always on: a run's summary says how compressed its material is.
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

class DensityCheck final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the density check"; }
  explicit DensityCheck(double period) : period_(period) {}
  [[nodiscard]] double period() const override { return period_; }
  // Its time is output time: at the frames, it is the measuring of the density they write.
  [[nodiscard]] bool is_output() const override { return true; }
  void start(const Simulation& simulation) override { check(simulation); }
  void observe(const Simulation& simulation, const StepReport& /*report*/) override { check(simulation); }
  void finish(const Simulation& simulation, RunSummary& summary) override {
    check(simulation);  // the end state: the run's last frame, or its last step
    summary.density = report_;
  }
  void save(StateWriter& out) override { out.put(report_); }
  void resume(const Simulation& /*simulation*/, StateReader& in) override { in.get(report_); }

 private:
  void check(const Simulation& simulation) {
    const auto& measurement = simulation.measured_density();
    if (report_.checks > 0 && report_.last.time == measurement.time) return;
    const RunSummary::DensityCheck check{measurement.time, measurement.statistics};
    if (report_.checks == 0 || check.statistics.p99 > report_.worst_p99.statistics.p99) report_.worst_p99 = check;
    if (report_.checks == 0 || check.statistics.max > report_.worst_max.statistics.max) report_.worst_max = check;
    report_.last = check;
    ++report_.checks;
  }

  double period_;
  RunSummary::DensityReport report_;
};

}  // namespace

std::unique_ptr<RunObserver> make_density_check(Simulation& simulation, const RunOptions& options) {
  const auto& output = simulation.scene().output;
  const double end_time = options.until.value_or(simulation.scene().end_time);
  const double period = frame_period(simulation, options);
  const bool frames = !options.output_directory.empty() && output.write_particles && period > 0;
  return std::make_unique<DensityCheck>(frames ? period : end_time / 100);
}

}  // namespace m3dp::sim::outputs
