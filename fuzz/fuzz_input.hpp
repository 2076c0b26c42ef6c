#pragma once
// What the fuzz targets share: the bytes as a file for readers that take a path (in /dev/shm, one
// per process), and the one kind of failure a reader may answer bad input with.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>

#include "m3dp/core/error.hpp"

namespace m3dp::fuzz {

/// Writes `bytes` to a per-process scratch file with `extension` ("ply") and returns its path.
inline std::filesystem::path as_file(const std::uint8_t* bytes, std::size_t size, std::string_view extension) {
  const std::filesystem::path folder = std::filesystem::exists("/dev/shm") ? "/dev/shm" : std::filesystem::temp_directory_path();
  const auto file = folder / ("m3dp_fuzz_" + std::to_string(::getpid()) + "." + std::string(extension));
  std::ofstream(file, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(bytes), std::streamsize(size));
  return file;
}

/// Runs `read`; an m3dp::Error (a message naming the file and what was expected) is the accepted
/// answer to bad input. Anything else propagates to libFuzzer as a finding.
template <class Read>
void expect_clear_error_or_success(Read&& read) {
  try {
    read();
  } catch (const m3dp::Error&) {
  }
}

}  // namespace m3dp::fuzz
