// Materials: <material> definitions over a preset or from scratch, their rheology, ageing, granular,
// micropolar and elastic blocks, the preset library (data/materials.xml), and the check that each is used.
#include "m3dp/scene/scene_reader.hpp"

namespace m3dp::scene::detail {

void SceneReader::read_material(const pugi::xml_node& element) {
  check_attributes(element, {"name", "preset"});
  const auto name = read_attribute(element, "name", Presence::required);
  const auto preset_name = read_attribute(element, "preset", Presence::optional);
  const MaterialEntry* preset = nullptr;
  if (preset_name) {
    const auto& presets = material_presets();
    const auto found = std::find_if(presets.begin(), presets.end(),
                                    [&](const MaterialEntry& entry) { return entry.material.name == *preset_name; });
    if (found == presets.end()) {
      std::string known;
      for (const auto& entry : presets) known += (known.empty() ? "" : ", ") + entry.material.name;
      report(element, fmt::format("unknown material preset '{}'; the presets ({}) are: {}", *preset_name,
                                  material_presets_file().string(), known.empty() ? "none" : known));
      if (name) defined_materials_.push_back(DefinedMaterial{*name, where(element)});
      return;
    }
    preset = &*found;
  }
  // A preset's fields where the material does not set them again (its own are found first).
  FieldLocations fields;
  auto material = read_material_values(element, preset ? &preset->material : nullptr, fields);
  if (preset) fields.insert(fields.end(), preset->fields.begin(), preset->fields.end());
  if (!name) return;

  const auto earlier = std::find_if(defined_materials_.begin(), defined_materials_.end(),
                                    [&](const DefinedMaterial& defined) { return defined.name == *name; });
  if (earlier != defined_materials_.end()) {
    report(element, fmt::format("material '{}' is defined twice; the first is at line {}", *name, earlier->where.line));
    return;
  }
  defined_materials_.push_back(DefinedMaterial{*name, where(element)});
  if (!material) return;
  material->name = *name;
  if (preset) material->preset = preset->material.name;
  auto color = read_color(element);
  if (!color && preset) color = preset->color;
  scene_.materials.push_back(MaterialEntry{std::move(*material), where(element), std::move(fields), color});
}

std::optional<material::Material> SceneReader::read_material_values(const pugi::xml_node& element,
                                                                   const material::Material* base, FieldLocations& fields) {
  material::Material material = base ? *base : material::Material{};
  bool valid = true;
  // The table's values (schema.cpp: density, nozzle_wall, surface_tension, adhesion), then what is special.
  read_block(element, "material", &material, &fields);
  if (!base && !find_child(element, "density", Presence::required)) valid = false;
  const pugi::xml_node viscosity = element.child("viscosity");
  const pugi::xml_node rheology = element.child("rheology");
  if (viscosity && rheology) {
    report(viscosity, fmt::format("{} has both <viscosity> (a Newtonian fluid) and <rheology> (line {}); give one",
                                  describe(element), where(rheology).line));
    valid = false;
  } else if (viscosity) {
    if (const auto value = read_scalar(element, "viscosity", Quantity::dynamic_viscosity, Limits::non_negative(),
                                       Presence::required)) {
      material.rheology = material::Rheology{};
      material.rheology.viscosity = Real(*value);
    } else {
      valid = false;
    }
  } else if (rheology) {
    if (auto read = read_rheology(rheology, base ? &base->rheology : nullptr)) material.rheology = *read;
    else valid = false;
  } else if (!base) {
    report(element, fmt::format("missing <viscosity> (Pa*s, a Newtonian fluid) or <rheology model=\"...\"> in {}",
                                describe(element)));
    valid = false;
  }
  if (const pugi::xml_node ageing = element.child("ageing")) read_ageing(ageing, material);
  // A viscosity in Pa·s (Navier slip: the wall carries μ_b × slip rate), or no_slip: the material sticks.
  if (const pugi::xml_node wall = element.child("boundary_viscosity")) {
    fields.emplace_back("boundary_viscosity", where(wall));  // set: a printed material takes no default (Scene::holds_on_beds)
    if (trim(wall.child_value()) == "no_slip") {
      leaf_text(wall, {});
      material.sticks_to_walls = true;
    } else if (const auto value = read_scalar(element, "boundary_viscosity", Quantity::dynamic_viscosity,
                                              Limits::non_negative(), Presence::optional)) {
      material.boundary_viscosity = Real(*value);
      material.sticks_to_walls = false;
    }
  }
  if (const pugi::xml_node granular = element.child("granular")) read_granular(granular, material, fields);
  if (const pugi::xml_node micropolar = element.child("micropolar")) read_micropolar(micropolar, material);
  if (const pugi::xml_node elasticity = element.child("elasticity")) read_elasticity(elasticity, material, fields);
  if (const pugi::xml_node source = element.child("source")) leaf_text(source, {});
  if (!valid) return std::nullopt;
  return material;
}

std::optional<material::Rheology> SceneReader::read_rheology(const pugi::xml_node& element,
                                                             const material::Rheology* base) {
  using material::RheologyModel;
  check_attributes(element, {"model"});
  constexpr RheologyModel kModels[] = {RheologyModel::newtonian, RheologyModel::power_law, RheologyModel::cross,
                                       RheologyModel::carreau,   RheologyModel::bingham,   RheologyModel::herschel_bulkley};
  // The model: as written, or the preset's when the scene only changes some of its values.
  std::optional<RheologyModel> model;
  if (const auto written = read_attribute(element, "model", base ? Presence::optional : Presence::required)) {
    for (const RheologyModel candidate : kModels)
      if (material::to_string(candidate) == *written) model = candidate;
    if (!model) {
      report(element, fmt::format("unknown rheology model '{}'; expected one of: newtonian, power_law, cross, carreau, "
                                  "bingham, herschel_bulkley",
                                  *written));
      return std::nullopt;
    }
  } else if (base) {
    model = base->model;
  } else {
    return std::nullopt;
  }
  // Over the preset's values when the model is the same; a different model starts from scratch.
  const bool over_base = base && base->model == *model;
  material::Rheology rheology = over_base ? *base : material::Rheology{};
  rheology.model = *model;
  // The model's parameters from its rows (schema.cpp), then what ties them together.
  const std::size_t problems_before = diagnostics_.size();
  read_block(element, fmt::format("rheology {}", material::to_string(*model)), &rheology, nullptr, over_base);
  bool valid = diagnostics_.size() == problems_before;
  if (valid && rheology.infinite_shear_viscosity > rheology.viscosity) {
    report(element.child("infinite_shear_viscosity"),
           fmt::format("<infinite_shear_viscosity> ({} Pa*s) must not exceed <zero_shear_viscosity> ({} Pa*s)",
                       rheology.infinite_shear_viscosity, rheology.viscosity));
    valid = false;
  }
  if (!valid) return std::nullopt;
  return rheology;
}

void SceneReader::read_ageing(const pugi::xml_node& element, material::Material& material) {
  check_attributes(element, {});
  read_block(element, "ageing", &material);
}

void SceneReader::read_granular(const pugi::xml_node& element, material::Material& material, FieldLocations& fields) {
  // <granular/> on its own switches the material to discrete spheres with the default contact law.
  check_attributes(element, {});
  material.granular.enabled = true;
  fields.emplace_back("granular", where(element));
  read_block(element, "granular", &material, &fields);
}

void SceneReader::read_micropolar(const pugi::xml_node& element, material::Material& material) {
  // <micropolar/> on its own turns the model on with its defaults.
  check_attributes(element, {});
  material.micropolar.enabled = true;
  read_block(element, "micropolar", &material);
}

void SceneReader::read_elasticity(const pugi::xml_node& element, material::Material& material, FieldLocations& fields) {
  check_attributes(element, {});
  material.elasticity.enabled = true;
  fields.emplace_back("elasticity", where(element));
  read_block(element, "elasticity", &material, &fields);
}

const std::vector<MaterialEntry>& SceneReader::material_presets() {
  if (!material_presets_) {
    const fs::path file = material_presets_file();
    try {
      material_presets_ = SceneReader(read_text_file(file, "material presets"), file).read_material_library();
    } catch (const InputError& error) {
      for (const auto& diagnostic : error.diagnostics()) diagnostics_.push_back(diagnostic);
      material_presets_.emplace();
    }
  }
  return *material_presets_;
}

std::vector<MaterialEntry> SceneReader::read_material_library() {
  pugi::xml_document document;
  const pugi::xml_node root = parse_root(document, "materials");
  check_children(root, {"material"}, {"material"});
  std::vector<MaterialEntry> entries;
  for (const auto& element : child_elements(root, "material")) {
    check_attributes(element, {"name"});
    const auto name = read_attribute(element, "name", Presence::required);
    FieldLocations fields;
    auto material = read_material_values(element, nullptr, fields);
    if (!name || !material) continue;
    material->name = *name;
    entries.push_back(MaterialEntry{std::move(*material), where(element), std::move(fields), read_color(element)});
  }
  // Each preset as the one material of default settings: what the engine would refuse in any scene.
  for (const MaterialEntry& entry : entries) {
    sph::Parameters parameters;
    parameters.phases.push_back(entry.material);
    report_parameter_problems(sph::check_parameters(parameters), parameters, std::span(&entry, 1));
  }
  if (!diagnostics_.empty()) throw InputError(std::move(diagnostics_));
  return entries;
}

void SceneReader::check_materials() {
  std::string defined_names;
  for (const auto& defined : defined_materials_) defined_names += (defined_names.empty() ? "" : ", ") + defined.name;
  if (defined_names.empty()) defined_names = "none (add a <material name=\"...\">)";

  for (const MaterialUse& use : material_uses_) {
    const auto defined = std::find_if(defined_materials_.begin(), defined_materials_.end(),
                                      [&](const DefinedMaterial& material) { return material.name == use.material; });
    if (defined == defined_materials_.end()) {
      report(use.where, fmt::format("material '{}' used by {} is not defined; defined: {}", use.material, use.user,
                                    defined_names));
    } else {
      defined->used = true;
    }
  }
  for (const DefinedMaterial& defined : defined_materials_) {
    if (!defined.used) {
      report(defined.where, fmt::format("material '{}' is not used by any <fluid_block> or <print_head>; remove it "
                                        "or use it",
                                        defined.name));
    }
  }
}

}  // namespace m3dp::scene::detail
