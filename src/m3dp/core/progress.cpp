#include "m3dp/core/progress.hpp"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>

namespace m3dp {

ProgressBar::ProgressBar(std::FILE* stream, bool enabled)
    : stream_(stream), enabled_(enabled), is_terminal_(isatty(fileno(stream)) != 0) {}

namespace {
std::string format_duration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "--:--";
  const auto total = static_cast<long long>(seconds + 0.5);
  if (total >= 3600) return fmt::format("{}:{:02}:{:02}", total / 3600, (total / 60) % 60, total % 60);
  return fmt::format("{:02}:{:02}", total / 60, total % 60);
}
}  // namespace

std::string ProgressBar::format_line(const ProgressSample& sample, int width) {
  const double fraction =
      sample.end_time_s > 0 ? std::clamp(sample.simulated_time_s / sample.end_time_s, 0.0, 1.0) : 0.0;
  const int filled = static_cast<int>(fraction * width);
  std::string bar(static_cast<std::size_t>(filled), '#');
  bar.resize(static_cast<std::size_t>(width), '.');
  const double steps_per_second = sample.wall_time_s > 0 ? sample.steps / sample.wall_time_s : 0.0;
  const double real_time_factor = sample.wall_time_s > 0 ? sample.simulated_time_s / sample.wall_time_s : 0.0;
  const double eta = fraction > 0 ? sample.wall_time_s * (1.0 - fraction) / fraction : -1.0;
  const std::string density =
      sample.density_error_p99 && sample.density_error_max
          ? fmt::format(" | rho/rho0-1 p99 {:+.2f}% max {:+.2f}%", 100 * *sample.density_error_p99, 100 * *sample.density_error_max)
          : std::string();
  return fmt::format("[{}] {:5.1f}% t={:.3f}/{:.3f} s | {:.0f} steps/s | RTF {:.3g} | {} particles{} | ETA {}", bar,
                     100.0 * fraction, sample.simulated_time_s, sample.end_time_s, steps_per_second,
                     real_time_factor, sample.particles, density, format_duration(eta));
}

void ProgressBar::update(const ProgressSample& sample) {
  if (!enabled_) return;
  if (is_terminal_) {
    const auto now = std::chrono::steady_clock::now();
    if (now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    draw(sample, false);
    return;
  }
  const int decile = sample.end_time_s > 0 ? static_cast<int>(10 * sample.simulated_time_s / sample.end_time_s) : 0;
  if (decile > last_decile_) {
    last_decile_ = decile;
    draw(sample, false);
  }
}

void ProgressBar::finish(const ProgressSample& sample) {
  if (!enabled_) return;
  // In a log the 100 % line may already be there: do not print it twice.
  const bool complete = sample.end_time_s > 0 && sample.simulated_time_s >= sample.end_time_s;
  if (!is_terminal_ && complete && last_decile_ >= 10) return;
  draw(sample, true);
}

void ProgressBar::draw(const ProgressSample& sample, bool final_draw) {
  const std::string line = format_line(sample, 24);
  if (is_terminal_) {
    fmt::print(stream_, "\r{}\x1b[K{}", line, final_draw ? "\n" : "");
  } else {
    fmt::print(stream_, "{}\n", line);
  }
  std::fflush(stream_);
}

}  // namespace m3dp
