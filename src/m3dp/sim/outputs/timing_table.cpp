// timing.csv: a row per step with its time step, iterations, density error and the milliseconds of
// every stage (the solver's table sph::kStageNames, then the coupling, the world and the outputs).
// Written as timing.csv.partial during the run and renamed when the run ends.
#include <fmt/format.h>
#include <fmt/os.h>

#include <cstdio>

#include "m3dp/core/error.hpp"
#include "m3dp/sim/camera_rig.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

class TimingTable final : public RunObserver {
 public:
  explicit TimingTable(const std::filesystem::path& output_directory)
      : partial_(output_directory / "timing.csv.partial"), final_(output_directory / "timing.csv") {
    file_ = std::fopen(partial_.c_str(), "w");
    if (!file_) throw Error("cannot write " + partial_.string());
    std::string header = "step,time_s,dt_s,particles,density_iterations,divergence_iterations,viscosity_iterations,density_error";
    for (const auto name : sph::kStageNames) header += fmt::format(",ms_{}", name);
    // ms_cameras: the cameras' rendering, a part of ms_output (the outputs that asked for images).
    header += ",ms_coupling,ms_world,ms_output,ms_cameras,ms_total\n";
    std::fputs(header.c_str(), file_);
  }
  ~TimingTable() override {
    if (file_) std::fclose(file_);
  }
  TimingTable(const TimingTable&) = delete;
  TimingTable& operator=(const TimingTable&) = delete;

  void observe(const Simulation& simulation, const StepReport& report) override {
    const sph::StepStats& stats = report.stats;
    const auto& solver = simulation.solver();
    fmt::print(file_, "{},{:.8g},{:.6g},{},{},{},{},{:.4g}", solver.state().step, solver.time(), stats.time_step,
               solver.fluid().size(), stats.density_iterations, stats.divergence_iterations, stats.viscosity_iterations,
               stats.density_error);
    for (const double ms : stats.stage_ms.ms) fmt::print(file_, ",{:.4f}", ms);
    const double camera_ms = simulation.scene().cameras.empty() ? 0.0 : simulation.cameras().take_render_ms();
    fmt::print(file_, ",{:.4f},{:.4f},{:.4f},{:.4f},{:.4f}\n", simulation.last_coupling_ms(), simulation.last_world_ms(), report.output_ms,
               camera_ms, stats.stage_ms.total() + simulation.last_coupling_ms() + simulation.last_world_ms() + report.output_ms);
  }

  void finish(const Simulation& /*simulation*/, RunSummary& /*summary*/) override {
    std::fclose(file_);
    file_ = nullptr;
    std::filesystem::rename(partial_, final_);
  }

 private:
  std::filesystem::path partial_, final_;
  std::FILE* file_ = nullptr;
};

}  // namespace

std::unique_ptr<RunObserver> make_timing_table(Simulation& /*simulation*/, const RunOptions& options) {
  if (options.output_directory.empty()) return nullptr;
  return std::make_unique<TimingTable>(options.output_directory);
}

}  // namespace m3dp::sim::outputs
