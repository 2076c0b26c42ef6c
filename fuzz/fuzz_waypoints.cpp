// The waypoint CSV reader on arbitrary text.
#include "fuzz/fuzz_input.hpp"
#include "m3dp/toolpath/waypoints.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  m3dp::fuzz::expect_clear_error_or_success([&] { (void)m3dp::toolpath::parse_waypoints(text, "fuzz.csv"); });
  return 0;
}
