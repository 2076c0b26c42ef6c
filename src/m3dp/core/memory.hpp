#pragma once
// The process's resident memory, for benchmarks and the run summary.

namespace m3dp {

struct ResidentMemory {
  double now_megabytes = 0;   // VmRSS
  double peak_megabytes = 0;  // VmHWM: the most the process has held
};

/// From /proc/self/status (Linux); zeros where it is not there.
ResidentMemory resident_memory();

}  // namespace m3dp
