#pragma once
// The run as a schedule of observers: every output, sensor or stream is an object that watches the
// simulation at its own period of simulated time (particle frames, timing.csv, the summary, the
// printed-material meshes; cameras, recordings and live streams the same way). Observers read the
// simulation; only its step changes it.
#include <memory>
#include <string_view>

#include "m3dp/core/periodic.hpp"
#include <vector>

#include "m3dp/core/state_io.hpp"
#include "m3dp/sim/run.hpp"
#include "m3dp/sph/state.hpp"

namespace m3dp::sim {

/// What an observer is told of the step it sees.
struct StepReport {
  const sph::StepStats& stats;
  double output_ms = 0;  // wall ms the observers that ran before it spent on this step's outputs
};

class RunObserver {
 public:
  virtual ~RunObserver() = default;
  /// What it is, for messages: "the quality report (quality.json)".
  [[nodiscard]] virtual std::string_view name() const { return "an output"; }
  /// Simulated seconds between observations (at multiples of it); 0: after every step.
  [[nodiscard]] virtual double period() const { return 0; }
  /// Whether its time is the run's output time (timing.csv's ms_output): files it writes.
  [[nodiscard]] virtual bool is_output() const { return true; }
  /// The run starts at the simulation's current time (its first frame, its files' headers).
  virtual void start(const Simulation& /*simulation*/) {}
  /// After a step at which it is due.
  virtual void observe(const Simulation& simulation, const StepReport& report) = 0;
  /// The run has ended (summary.status says how): complete its files and fill its own section of the
  /// summary (never reading another's: observers finish in any order).
  virtual void finish(const Simulation& /*simulation*/, RunSummary& /*summary*/) {}
  /// After every observer finished, the summary whole: report it (summary.json). A failure fails the run.
  virtual void report(const Simulation& /*simulation*/, RunSummary& /*summary*/) {}

  /// A checkpoint is written after this step: finish what is in flight (queued files, a mesh being
  /// made), then save what it needs to go on: its counters, and how far its files got. Files are
  /// made in start(), never in the constructor, so that a resumed run finds them as they were.
  virtual void save(StateWriter& /*out*/) {}
  /// Instead of start(), in a run resumed from a checkpoint (the simulation already restored): take
  /// back what save() wrote, and put its files back to what they were then. Observers without files
  /// or sums just start again.
  virtual void resume(const Simulation& simulation, StateReader& /*in*/) { start(simulation); }
};

/// The observers of one run, in the order they were added (which is the order they observe in).
class ObserverSchedule {
 public:
  RunObserver& add(std::unique_ptr<RunObserver> observer);
  void start(const Simulation& simulation);
  void after_step(const Simulation& simulation, const sph::StepStats& stats);
  void finish(const Simulation& simulation, RunSummary& summary);
  /// Every observer's save(), each as its own part of `out`; resume() takes them back in order.
  void save(StateWriter& out);
  void resume(const Simulation& simulation, StateReader& in);

 private:
  struct Entry {
    std::unique_ptr<RunObserver> observer;
    Periodic due;  // a periodic observer's next time
  };
  std::vector<Entry> entries_;
};

}  // namespace m3dp::sim
