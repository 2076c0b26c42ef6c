#pragma once
// Something due every `period` s of simulated time (frames, meshes, checkpoints, camera images): at
// the multiples of the period, from the first one after the time it starts at. Steps land on the
// multiples only up to rounding, so a step that ends within kTimeSlack short of one is at it.
#include <cmath>

namespace m3dp {

inline constexpr double kTimeSlack = 1e-9;  // s

/// The first multiple of `period` (s, > 0) after `time` (s).
[[nodiscard]] inline double next_multiple(double time, double period) {
  return period * (std::floor((time + kTimeSlack) / period) + 1);
}

struct Periodic {
  double next_time = 0;  // s: when it is next due

  /// Starts at `time`: next due at the first multiple of `period` after it.
  void start(double time, double period) { next_time = period > 0 ? next_multiple(time, period) : 0; }
  /// Whether it is due at `time`; if so, moves on to the first multiple of `period` after it. A
  /// period ≤ 0 is never due.
  bool take(double time, double period) {
    if (!(period > 0) || time + kTimeSlack < next_time) return false;
    while (next_time <= time + kTimeSlack) next_time += period;
    return true;
  }
};

}  // namespace m3dp
