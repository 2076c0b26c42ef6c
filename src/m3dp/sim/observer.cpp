#include "m3dp/sim/observer.hpp"

#include <chrono>
#include <cmath>

#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

namespace {
constexpr double kTimeSlack = 1e-12;  // s: a step that lands a rounding short of a multiple is at it
}

RunObserver& ObserverSchedule::add(std::unique_ptr<RunObserver> observer) {
  entries_.push_back(Entry{std::move(observer)});
  return *entries_.back().observer;
}

void ObserverSchedule::start(const Simulation& simulation) {
  const double time = simulation.time();
  for (Entry& entry : entries_) {
    entry.observer->start(simulation);
    // The first multiple of the period after the start.
    const double period = entry.observer->period();
    if (period > 0) entry.next_time = period * (std::floor((time + kTimeSlack) / period) + 1);
  }
}

void ObserverSchedule::after_step(const Simulation& simulation, const sph::StepStats& stats) {
  using Clock = std::chrono::steady_clock;
  const double time = simulation.time();
  StepReport report{stats};
  for (Entry& entry : entries_) {
    const double period = entry.observer->period();
    if (period > 0) {
      if (time + kTimeSlack < entry.next_time) continue;
      while (entry.next_time <= time + kTimeSlack) entry.next_time += period;
    }
    const auto begin = Clock::now();
    entry.observer->observe(simulation, report);
    if (entry.observer->is_output()) report.output_ms += std::chrono::duration<double, std::milli>(Clock::now() - begin).count();
  }
}

void ObserverSchedule::finish(const Simulation& simulation, RunSummary& summary) {
  for (Entry& entry : entries_) entry.observer->finish(simulation, summary);
}

}  // namespace m3dp::sim
