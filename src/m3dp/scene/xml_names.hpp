#pragma once
// What the scene module's XML code shares (the reader and the overrides by path): which <plugin> is
// M3DP's, and how messages name an element. Internal to the scene library.
#include <fmt/format.h>
#include <pugixml.hpp>

#include <string>
#include <string_view>

namespace m3dp::scene {

/// M3DP's <plugin name="m3dp" filename="m3dp"> (either attribute names it).
inline bool is_m3dp_plugin(const pugi::xml_node& plugin) {
  return std::string_view(plugin.attribute("name").value()) == "m3dp" || std::string_view(plugin.attribute("filename").value()) == "m3dp";
}

/// "<fluid_block name="column">" or "<solver>": how messages name an element.
inline std::string describe(const pugi::xml_node& element) {
  if (const auto name = element.attribute("name")) return fmt::format("<{} name=\"{}\">", element.name(), name.value());
  return fmt::format("<{}>", element.name());
}

}  // namespace m3dp::scene
