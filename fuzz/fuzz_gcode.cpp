// The G-code reader on arbitrary text, with the scene's settings silent (the file's own settings
// block decides), and at construction scale with the arcs split into 1 cm lines. At most 10³ moves
// a file (the limit's own path is what is tested): at the default 2·10⁷ the fuzzer spends its time
// making the arcs of random centres; at 10⁵ and 10⁴ such arcs (3 µs a move under the sanitizers,
// mutated inputs near the limit common) still took it from 4,500 to about 300 inputs a second.
#include "fuzz/fuzz_input.hpp"
#include "m3dp/toolpath/gcode.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  m3dp::toolpath::GcodeSettings settings;
  settings.max_moves = 1'000;
  m3dp::fuzz::expect_clear_error_or_success([&] { (void)m3dp::toolpath::parse_gcode(text, "fuzz.gcode", settings); });
  m3dp::toolpath::GcodeSettings enlarged = settings;
  enlarged.geometry_scale = 10;
  enlarged.arc_segment_length = 0.01f;
  m3dp::fuzz::expect_clear_error_or_success([&] { (void)m3dp::toolpath::parse_gcode(text, "fuzz.gcode", enlarged).path_segments(); });
  return 0;
}
