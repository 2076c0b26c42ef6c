#pragma once
// Thin helpers over TBB so that loops read the same everywhere.
#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <cstddef>
#include <memory>

namespace m3dp {

/// Calls body(i) for i in [0, count) in parallel. Grain keeps per-task overhead small for cheap bodies.
template <class Body>
void parallel_for_each_index(std::size_t count, Body&& body, std::size_t grain = 256) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, grain), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) body(i);
  });
}

/// Limits TBB to at most `threads` worker threads while alive (0 = all cores).
class ThreadLimit {
 public:
  explicit ThreadLimit(int threads);
  ~ThreadLimit();
  ThreadLimit(const ThreadLimit&) = delete;
  ThreadLimit& operator=(const ThreadLimit&) = delete;
  [[nodiscard]] static int active_threads();

 private:
  std::unique_ptr<tbb::global_control> control_;
};

}  // namespace m3dp
