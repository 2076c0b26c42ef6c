#pragma once
// A one-line progress bar for long runs: simulated time, speed, particles, ETA.
// On a terminal it redraws in place; otherwise (CI logs, pipes) it prints a line every 10 %.
#include <chrono>
#include <cstdio>
#include <optional>
#include <string>

namespace m3dp {

struct ProgressSample {
  double simulated_time_s = 0;
  double end_time_s = 0;
  long long steps = 0;
  long long particles = 0;
  double wall_time_s = 0;
  /// The latest measured ρ/ρ0 − 1 (99th percentile and max over the particles), if there is one.
  std::optional<double> density_error_p99, density_error_max;
};

class ProgressBar {
 public:
  explicit ProgressBar(std::FILE* stream = stderr, bool enabled = true);
  /// Redraws at most ~10 times per second; cheap to call every step.
  void update(const ProgressSample& sample);
  /// Draws the final state and ends the line.
  void finish(const ProgressSample& sample);

  /// The text of the bar for a sample, without control characters (tested).
  [[nodiscard]] static std::string format_line(const ProgressSample& sample, int width);

 private:
  std::FILE* stream_;
  bool enabled_;
  bool is_terminal_;
  int last_decile_ = -1;
  std::chrono::steady_clock::time_point last_draw_{};
  void draw(const ProgressSample& sample, bool final_draw);
};

}  // namespace m3dp
