#include "m3dp/sim/observer.hpp"

#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <exception>
#include <typeinfo>

#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

RunObserver& ObserverSchedule::add(std::unique_ptr<RunObserver> observer) {
  entries_.push_back(Entry{std::move(observer), {}});
  return *entries_.back().observer;
}

void ObserverSchedule::start(const Simulation& simulation) {
  const double time = simulation.time();
  for (Entry& entry : entries_) {
    entry.observer->start(simulation);
    // The first multiple of the period after the start.
    entry.due.start(time, entry.observer->period());
  }
}

void ObserverSchedule::after_step(const Simulation& simulation, const sph::StepStats& stats) {
  using Clock = std::chrono::steady_clock;
  const double time = simulation.time();
  StepReport report{stats};
  // Every observer sees the step even when one before it fails (the timing row of the step a frame
  // failed in is still written); the first failure is thrown after them all.
  std::exception_ptr first_failure;
  for (Entry& entry : entries_) {
    const double period = entry.observer->period();
    if (period > 0 && !entry.due.take(time, period)) continue;
    const auto begin = Clock::now();
    try {
      entry.observer->observe(simulation, report);
    } catch (const std::exception&) {
      if (!first_failure) first_failure = std::current_exception();
    }
    if (entry.observer->is_output()) report.output_ms += std::chrono::duration<double, std::milli>(Clock::now() - begin).count();
  }
  if (first_failure) std::rethrow_exception(first_failure);
}

void ObserverSchedule::save(StateWriter& out) {
  out.section("observers");
  out.put(static_cast<std::uint64_t>(entries_.size()));
  for (Entry& entry : entries_) {
    StateWriter part;
    entry.observer->save(part);
    out.put(std::string(typeid(*entry.observer).name()));
    out.put(entry.due.next_time);
    out.put(part.bytes());
  }
}

void ObserverSchedule::resume(const Simulation& simulation, StateReader& in) {
  in.section("observers");
  if (in.get<std::uint64_t>() != entries_.size()) in.fail("another set of outputs than the checkpoint's run had");
  for (Entry& entry : entries_) {
    std::string name, bytes;
    in.get(name);
    if (name != typeid(*entry.observer).name()) in.fail("another set of outputs than the checkpoint's run had");
    in.get(entry.due.next_time);
    in.get(bytes);
    StateReader part(bytes, in.source());
    entry.observer->resume(simulation, part);
  }
}

void ObserverSchedule::finish(const Simulation& simulation, RunSummary& summary) {
  // Every observer finishes even when one before it fails, each filling its own section of the
  // summary; then the summary, whole (a failure included), is reported.
  // A failure names the output that failed (the others' files stand), and says whether the simulation
  // itself had reached its end.
  const bool simulated = summary.status == RunStatus::completed;
  auto failed = [&](const Entry& entry, const std::exception& error) {
    summary.fail(fmt::format("{} failed: {}{}", entry.observer->name(), error.what(),
                             simulated ? " (the simulation completed; every other output was written)" : ""));
  };
  for (Entry& entry : entries_) {
    try {
      entry.observer->finish(simulation, summary);
    } catch (const std::exception& error) {
      failed(entry, error);
    }
  }
  for (Entry& entry : entries_) {
    try {
      entry.observer->report(simulation, summary);
    } catch (const std::exception& error) {
      failed(entry, error);
    }
  }
}

}  // namespace m3dp::sim
