// Scene values replaced by their path (studies, the Python API): `material[mortar].rheology.yield_stress`
// names the <yield_stress> of the <rheology> of the <material name="mortar"> in M3DP's plugin. The
// text is edited as XML and read again by the scene reader, so that each value is checked exactly as
// if the user had written it, and the file's other lines keep their numbers.
#include <fmt/format.h>
#include <pugixml.hpp>

#include <algorithm>
#include <cctype>
#include <sstream>
#include <string>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/core/text.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/scene/xml_names.hpp"

namespace m3dp::scene {

namespace {

struct PathStep {
  std::string name;  // the element's name
  std::string key;   // [key]: its name="..." (or, all digits, its index among its namesakes); empty: the only one
};

std::vector<PathStep> parse_path(const std::string& path, const std::string& problem_prefix, const SourceLocation& where) {
  std::vector<PathStep> steps(1);
  auto bad = [&](const std::string& why) { return InputError(where, fmt::format("{}: {}", problem_prefix, why)); };
  for (std::size_t i = 0; i < path.size(); ++i) {
    const char c = path[i];
    if (c == '.') {
      if (steps.back().name.empty()) throw bad(fmt::format("an empty step at character {}", i + 1));
      steps.emplace_back();
    } else if (c == '[') {
      const std::size_t close = path.find(']', i);
      if (close == std::string::npos) throw bad("'[' without its ']'");
      if (steps.back().name.empty()) throw bad("'[' must follow an element's name, as in material[mortar]");
      steps.back().key = path.substr(i + 1, close - i - 1);
      if (steps.back().key.empty()) throw bad("[] names nothing: put the element's name=\"...\" in it, as in material[mortar]");
      i = close;
      if (i + 1 < path.size() && path[i + 1] != '.') throw bad(fmt::format("expected '.' after ']' at character {}", i + 1));
    } else if (std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-') {
      if (!steps.back().key.empty()) throw bad(fmt::format("expected '.' after ']' at character {}", i + 1));
      steps.back().name += c;
    } else {
      throw bad(fmt::format("'{}' at character {} (a path is names and [keys] joined by '.', as in "
                            "material[mortar].rheology.yield_stress)",
                            c, i + 1));
    }
  }
  if (steps.back().name.empty()) throw bad("it ends with '.'");
  return steps;
}

}  // namespace

std::string apply_overrides(const std::string& text, const std::filesystem::path& file_name, std::span<const SceneOverride> overrides) {
  if (overrides.empty()) return text;
  pugi::xml_document document;
  // Everything kept (declaration, comments, whitespace), so that the text written back has the
  // original's lines.
  const pugi::xml_parse_result parsed = document.load_buffer(text.data(), text.size(), pugi::parse_full | pugi::parse_ws_pcdata);
  if (!parsed) throw InputError(SourceLocation{file_name.string(), 0}, fmt::format("the scene is not well-formed XML: {}", parsed.description()));
  const pugi::xml_node world = document.child("sdf").child("world");
  pugi::xml_node plugin;
  for (const auto& child : world.children("plugin"))
    if (is_m3dp_plugin(child)) plugin = child;
  const LineIndex lines(text);
  for (const SceneOverride& override_value : overrides) {
    const std::string prefix = fmt::format("the value of '{}'", override_value.path);
    const SourceLocation scene_file{file_name.string(), 0};
    const std::vector<PathStep> steps = parse_path(override_value.path, prefix, scene_file);
    // From the world for its own children (models, includes, gravity), else from M3DP's plugin.
    pugi::xml_node at = world.child(steps.front().name.c_str()) ? world : plugin;
    if (!at) throw InputError(scene_file, fmt::format("{}: the scene has no <world> with an m3dp <plugin>", prefix));
    bool attribute_set = false;
    for (std::size_t s = 0; s < steps.size() && !attribute_set; ++s) {
      const PathStep& step = steps[s];
      const SourceLocation here{file_name.string(), at.offset_debug() >= 0 ? lines.line_at(at.offset_debug()) : 0};
      std::vector<pugi::xml_node> namesakes;
      for (const auto& child : at.children(step.name.c_str())) namesakes.push_back(child);
      pugi::xml_node next;
      if (!step.key.empty()) {
        for (const auto& candidate : namesakes)
          if (candidate.attribute("name").value() == step.key) next = candidate;
        const bool index = std::all_of(step.key.begin(), step.key.end(), [](char c) { return std::isdigit(static_cast<unsigned char>(c)); });
        if (!next && index && std::stoul(step.key) < namesakes.size()) next = namesakes[std::stoul(step.key)];
        if (!next) {
          std::vector<std::string> names;
          for (const auto& candidate : namesakes) names.emplace_back(candidate.attribute("name").value());
          throw InputError(here, fmt::format("{}: {} has no <{} name=\"{}\"> ({})", prefix, describe(at), step.name, step.key,
                                             names.empty() ? fmt::format("it has no <{}>", step.name)
                                                           : fmt::format("its <{}>: {}", step.name, fmt::join(names, ", "))));
        }
      } else if (namesakes.size() > 1) {
        throw InputError(here, fmt::format("{}: {} has {} <{}>: say which, as in {}[{}]", prefix, describe(at), namesakes.size(),
                                           step.name, step.name,
                                           namesakes.front().attribute("name") ? namesakes.front().attribute("name").value() : "0"));
      } else if (namesakes.size() == 1) {
        next = namesakes.front();
      } else if (pugi::xml_attribute attribute = at.attribute(step.name.c_str()); attribute && s + 1 == steps.size()) {
        // The last step names an attribute the element has (<path speed="0.05">: print_head[head].path.speed).
        attribute.set_value(override_value.value.c_str());
        attribute_set = true;
        break;
      } else {
        // Not written: made, as the scene reader would have read it (it then checks that the element
        // belongs there and its value).
        next = at.append_child(step.name.c_str());
      }
      at = next;
    }
    if (attribute_set) continue;
    for (const auto& child : at.children())
      if (child.type() == pugi::node_element)
        throw InputError(SourceLocation{file_name.string(), at.offset_debug() >= 0 ? lines.line_at(at.offset_debug()) : 0},
                         fmt::format("{}: {} holds elements, not a value", prefix, describe(at)));
    while (at.first_child()) at.remove_child(at.first_child());
    at.remove_attribute("unit");  // the value given is SI
    at.append_child(pugi::node_pcdata).set_value(override_value.value.c_str());
  }
  // The root element written back as it was parsed (whitespace and comments kept), after the text
  // before it as it was: pugixml keeps no whitespace between the declaration, comments and the root,
  // and a lost line break there would move every line.
  const pugi::xml_node root = document.document_element();
  const std::ptrdiff_t root_name = root.offset_debug();
  const std::size_t root_start = root_name > 0 && text[std::size_t(root_name) - 1] == '<' ? std::size_t(root_name) - 1 : 0;
  std::ostringstream out;
  out << text.substr(0, root_start);
  root.print(out, "", pugi::format_raw);
  out << '\n';
  return out.str();
}

}  // namespace m3dp::scene
