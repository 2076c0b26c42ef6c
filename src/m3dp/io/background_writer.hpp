#pragma once
// File-writing jobs run in order on a thread of their own (camera images: PNG encoding and writes),
// so that they overlap the solver's serial stretches instead of holding the run. At most `capacity`
// jobs wait; submit() then waits for room, so memory stays bounded. The first error a job throws is
// kept and rethrown by finish(): nothing written in the background fails silently.
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <thread>
#include <utility>

namespace m3dp::io {

class BackgroundWriter {
 public:
  explicit BackgroundWriter(std::size_t capacity = 8);
  ~BackgroundWriter();  // runs what is queued, swallowing errors (call finish() to see them)
  BackgroundWriter(const BackgroundWriter&) = delete;
  BackgroundWriter& operator=(const BackgroundWriter&) = delete;

  void submit(std::function<void()> job);
  /// Waits until every job has run; throws the first error a job threw.
  void finish();

 private:
  void run();

  std::size_t capacity_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::deque<std::function<void()>> jobs_;
  bool running_job_ = false, stopping_ = false;
  std::exception_ptr error_;
  std::thread thread_;
};

}  // namespace m3dp::io
