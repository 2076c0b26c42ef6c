// The particle frame readers (VTK XML .vtu and .vtp in every encoding, PLY) on arbitrary bytes: the
// first byte picks the format, the rest is the file.
#include "fuzz/fuzz_input.hpp"
#include "m3dp/io/particle_reader.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static constexpr std::string_view kExtensions[] = {"vtu", "vtp", "ply"};
  const auto file = m3dp::fuzz::as_file(data + 1, size - 1, kExtensions[data[0] % 3]);
  m3dp::fuzz::expect_clear_error_or_success([&] { (void)m3dp::io::read_particle_frame(file); });
  return 0;
}
