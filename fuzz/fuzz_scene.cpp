// The scene reader on arbitrary text, read as if it were a file in the project's scenes/ folder, so
// that the models, meshes, G-code and waypoint files a scene names are found as in the real scenes
// (its seeds). A scene that loads must also give its sizes (the particle estimate) without failing.
#include "fuzz/fuzz_input.hpp"
#include "m3dp/scene/scene.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  m3dp::fuzz::expect_clear_error_or_success(
      [&] { (void)m3dp::scene::load_scene_from_string(text, std::filesystem::path(M3DP_SCENES) / "fuzz.sdf"); });
  return 0;
}
