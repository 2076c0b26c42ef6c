// timing.csv: a row per step with its time step (and the limit that set it), iterations, density error and the milliseconds of
// every stage (the solver's table sph::kStageNames, then the coupling, the world and the outputs).
// Written as timing.csv.partial during the run and renamed when the run ends (partial_text_file.hpp).
#include <fmt/format.h>
#include <fmt/os.h>

#include <cstdio>

#include "m3dp/core/error.hpp"
#include "m3dp/sim/camera_rig.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/outputs/partial_text_file.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

class TimingTable final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the timing table (timing.csv)"; }
  explicit TimingTable(const std::filesystem::path& output_directory) : file_(output_directory / "timing.csv") {}

  void start(const Simulation& /*simulation*/) override {
    std::string header = "step,time_s,dt_s,particles,moving_particles,density_iterations,divergence_iterations,viscosity_iterations,density_error,dt_set_by";
    for (const auto name : sph::kStageNames) header += fmt::format(",ms_{}", name);
    // ms_cameras: the cameras' rendering, a part of ms_output (the outputs that asked for images).
    header += ",ms_coupling,ms_world,ms_output,ms_cameras,ms_total\n";
    file_.create(header);
  }
  void save(StateWriter& out) override { file_.save(out); }
  void resume(const Simulation& /*simulation*/, StateReader& in) override { file_.resume(in); }

  void observe(const Simulation& simulation, const StepReport& report) override {
    std::FILE* file = file_.get();
    const sph::StepStats& stats = report.stats;
    const auto& solver = simulation.solver();
    // moving_particles: those the step simulated (the rest stood as resting neighbours).
    fmt::print(file, "{},{:.8g},{:.6g},{},{},{},{},{},{:.4g},{}", solver.state().step, solver.time(), stats.time_step,
               solver.fluid().size(), solver.fluid().size() - stats.particles_at_rest, stats.density_iterations, stats.divergence_iterations, stats.viscosity_iterations,
               stats.density_error, sph::kTimeStepBoundNames[static_cast<std::size_t>(stats.time_step_bound)]);
    for (const double ms : stats.stage_ms.ms) fmt::print(file, ",{:.4f}", ms);
    const double camera_ms = simulation.scene().cameras.empty() ? 0.0 : simulation.cameras().take_render_ms();
    fmt::print(file, ",{:.4f},{:.4f},{:.4f},{:.4f},{:.4f}\n", simulation.last_coupling_ms(), simulation.last_world_ms(), report.output_ms,
               camera_ms, stats.stage_ms.total() + simulation.last_coupling_ms() + simulation.last_world_ms() + report.output_ms);
  }

  void finish(const Simulation& /*simulation*/, RunSummary& /*summary*/) override { file_.finish(); }

 private:
  PartialTextFile file_;
};

}  // namespace

std::unique_ptr<RunObserver> make_timing_table(Simulation& /*simulation*/, const RunOptions& options) {
  if (options.output_directory.empty()) return nullptr;
  return std::make_unique<TimingTable>(options.output_directory);
}

}  // namespace m3dp::sim::outputs
