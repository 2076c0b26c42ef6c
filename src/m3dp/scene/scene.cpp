// The scene module's public entry points: loading a scene, a path or the material presets (through
// the reader, scene_reader.hpp), and what is derived from a loaded scene.
#include "m3dp/scene/scene.hpp"
#include "m3dp/scene/scene_reader.hpp"

#include <cmath>
#include <cstdlib>

#include "m3dp/core/text.hpp"

namespace m3dp::scene {

namespace fs = std::filesystem;
using detail::SceneReader;

const RobotInclude* Scene::find_robot(const std::string& name) const {
  for (const auto& robot : robots)
    if (robot.name == name) return &robot;
  return nullptr;
}

std::vector<fs::path> model_search_path(const fs::path& scene_file) {
  std::vector<fs::path> folders;
  const fs::path scene_folder = scene_file.parent_path().empty() ? fs::path(".") : scene_file.parent_path();
  folders.push_back(scene_folder / "models");
  folders.push_back(scene_folder / ".." / "models");
  if (const char* variable = std::getenv("M3DP_MODEL_PATH")) {
    std::string_view rest(variable);
    while (!rest.empty()) {
      const auto colon = rest.find(':');
      if (const auto folder = rest.substr(0, colon); !folder.empty()) folders.emplace_back(folder);
      rest = colon == std::string_view::npos ? std::string_view{} : rest.substr(colon + 1);
    }
  }
  folders.emplace_back(M3DP_PROJECT_MODELS);
  return folders;
}

std::uint16_t Scene::material_index(const std::string& name) const {
  for (std::size_t i = 0; i < materials.size(); ++i)
    if (materials[i].material.name == name) return static_cast<std::uint16_t>(i);
  return 0;
}

bool Scene::holds_on_beds(const MaterialEntry& entry) const {
  const material::Material& material = entry.material;
  const bool printed = std::any_of(print_heads.begin(), print_heads.end(), [&](const PrintHead& head) { return head.material == material.name; });
  const bool set = material.sticks_to_walls || material.boundary_viscosity > 0 ||
                   std::any_of(entry.fields.begin(), entry.fields.end(), [](const auto& field) { return field.first == "boundary_viscosity"; });
  return printed && !set;
}

sph::Parameters solver_parameters(const Scene& scene) {
  sph::Parameters parameters;
  parameters.settings = scene.solver;
  for (const auto& entry : scene.materials) {
    parameters.phases.push_back(entry.material);
    // A bed, a floor and a printed layer hold what is laid on them: the one place the default is
    // applied, for scenes read and scenes made in code alike.
    if (scene.holds_on_beds(entry)) parameters.phases.back().sticks_to_static_walls = true;
  }
  for (const auto& head : scene.print_heads)
    parameters.nozzles.push_back(
        sph::NozzleSettings{head.name, head.inner_diameter, head.exit_speed, scene.material_index(head.material), head.bore_length,
                            head.outer_diameter});
  return parameters;
}

const MaterialEntry* Scene::find_material(const std::string& name) const {
  const auto entry = std::find_if(materials.begin(), materials.end(),
                                  [&](const MaterialEntry& candidate) { return candidate.material.name == name; });
  return entry == materials.end() ? nullptr : &*entry;
}

std::filesystem::path material_presets_file() {
  if (const char* variable = std::getenv("M3DP_MATERIALS"); variable && *variable) return variable;
  return fs::path(M3DP_PROJECT_DATA) / "materials.xml";
}

std::vector<MaterialEntry> load_material_presets() {
  const fs::path file = material_presets_file();
  return SceneReader(read_text_file(file, "material presets"), file).read_material_library();
}

std::string read_scene_text(const std::filesystem::path& file, std::span<const SceneOverride> overrides) {
  return apply_overrides(read_text_file(file, "scene (expected an SDF world file, e.g. scenes/dam_break.sdf)"), file, overrides);
}

Scene load_scene(const std::filesystem::path& file) { return load_scene_from_string(read_scene_text(file), file); }

Scene load_scene(const std::filesystem::path& file, std::span<const SceneOverride> overrides) {
  return load_scene_from_string(read_scene_text(file, overrides), file);
}

Scene load_scene_from_string(const std::string& text, const std::filesystem::path& file_name) {
  return SceneReader(text, file_name).read();
}

PathSegments load_path_from_string(const std::string& text, const std::filesystem::path& file_name) {
  return SceneReader(text, file_name).read_path_text();
}

double particle_frame_period(const OutputSettings& output, double end_time) {
  if (output.particles_period) return double(*output.particles_period);
  constexpr double kShortest = 0.02;  // s: smooth playback of a short run
  const double wanted = end_time / kDefaultMostParticleFrames;
  if (!(wanted > kShortest)) return kShortest;
  const double decade = std::pow(10.0, std::floor(std::log10(wanted)));
  for (const double step : {1.0, 2.0, 5.0, 10.0})
    if (step * decade >= wanted * (1 - 1e-9)) return step * decade;
  return 10 * decade;
}

}  // namespace m3dp::scene
