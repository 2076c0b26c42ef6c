#pragma once
// Sums over particles that are the same on every run and any number of threads: each range sums in
// index order and the ranges are added in a fixed order (tbb::parallel_deterministic_reduce).
#include <tbb/blocked_range.h>
#include <tbb/parallel_reduce.h>

#include <array>
#include <cstddef>

namespace m3dp {

/// Runs range_body(range, sums) over ranges of [0, count) and returns the N sums (double), added in a
/// fixed order: the same on every run, so two identical simulations stay identical.
template <std::size_t N, class RangeBody>
std::array<double, N> deterministic_range_sums(std::size_t count, RangeBody&& range_body) {
  using Sums = std::array<double, N>;
  return tbb::parallel_deterministic_reduce(
      tbb::blocked_range<std::size_t>(0, count, 256), Sums{},
      [&](const tbb::blocked_range<std::size_t>& range, Sums sums) {
        range_body(range, sums);
        return sums;
      },
      [](Sums a, const Sums& b) {
        for (std::size_t n = 0; n < N; ++n) a[n] += b[n];
        return a;
      });
}

/// body(i, sums) for every i in [0, count).
template <std::size_t N, class Body>
std::array<double, N> deterministic_sums(std::size_t count, Body&& body) {
  return deterministic_range_sums<N>(count, [&](const tbb::blocked_range<std::size_t>& range, std::array<double, N>& sums) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) body(i, sums);
  });
}

}  // namespace m3dp
