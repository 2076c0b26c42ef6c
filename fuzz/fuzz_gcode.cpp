// The G-code reader on arbitrary text, with the scene's settings silent (the file's own settings
// block decides), and at construction scale with the arcs split into 1 cm lines (at 0.5 mm, a
// random arc of a metre is 10⁴ lines: the fuzzer would spend its time making them).
#include "fuzz/fuzz_input.hpp"
#include "m3dp/toolpath/gcode.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  m3dp::fuzz::expect_clear_error_or_success([&] { (void)m3dp::toolpath::parse_gcode(text, "fuzz.gcode", {}); });
  m3dp::toolpath::GcodeSettings enlarged;
  enlarged.geometry_scale = 10;
  enlarged.arc_segment_length = 0.01f;
  m3dp::fuzz::expect_clear_error_or_success([&] { (void)m3dp::toolpath::parse_gcode(text, "fuzz.gcode", enlarged).path_segments(); });
  return 0;
}
