#include "m3dp/core/memory.hpp"

#include <cstdlib>
#include <fstream>
#include <string>

namespace m3dp {

ResidentMemory resident_memory() {
  ResidentMemory memory;
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.starts_with("VmRSS:")) memory.now_megabytes = std::atof(line.c_str() + 6) / 1024;
    if (line.starts_with("VmHWM:")) memory.peak_megabytes = std::atof(line.c_str() + 6) / 1024;
  }
  return memory;
}

}  // namespace m3dp
