// M3DP's <plugin>: its blocks (solver, air, fluid blocks, print heads, output, meshing, the
// coordinator), the size check before anything is allocated, and the engine's own parameter check.
#include "m3dp/scene/scene_reader.hpp"

#include <unistd.h>

#include "m3dp/io/mesh_io.hpp"
#include "m3dp/sph/boundary_sampling.hpp"

namespace m3dp::scene::detail {

double physical_memory_bytes() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page_size = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page_size > 0 ? double(pages) * double(page_size) : 8e9;  // unknown: assume 8 GB
}

double default_max_particles() { return 0.8 * physical_memory_bytes() / double(kBytesPerParticle); }

// ---- the m3dp plugin ----

void SceneReader::read_plugin(const pugi::xml_node& plugin) {
  read_block(plugin, "plugin", &scene_);
  // The solver comes first: other checks need the particle radius and the bounds.
  if (const pugi::xml_node solver = plugin.child("solver")) read_solver(solver);
  if (const pugi::xml_node air = plugin.child("air")) read_air(air);
  for (const auto& material : child_elements(plugin, "material")) read_material(material);
  for (const auto& block : child_elements(plugin, "fluid_block")) read_fluid_block(block);
  for (const auto& robot : child_elements(plugin, "robot")) read_robot_settings(robot);
  for (const auto& head : child_elements(plugin, "print_head")) read_print_head(head);
  if (const pugi::xml_node output = plugin.child("output")) read_output(output);
  if (const pugi::xml_node meshing = plugin.child("meshing")) read_meshing(meshing);
  for (const auto& camera : child_elements(plugin, "camera")) read_plugin_camera(camera);
  if (const pugi::xml_node coordinator = plugin.child("coordinator")) read_coordinator(coordinator);

  if (!plugin.child("fluid_block") && !plugin.child("print_head")) {
    report(plugin, "the scene has no fluid: add a <fluid_block> or a <print_head>");
  }
  check_materials();
  check_engine_parameters();
  check_sizes();
}

void SceneReader::check_sizes() {
  // The particles the scene asks for, estimated before anything is sampled or allocated: a tiny
  // radius, a kilometre nozzle or box would otherwise end in std::bad_alloc with no line named.
  if (!particle_radius_) return;
  const double spacing = 2.0 * *particle_radius_;
  const double wall_spacing = spacing * scene_.solver.boundary_spacing_factor;
  struct Part {
    SourceLocation where;
    std::string what;
    double particles;
  };
  std::vector<Part> parts;
  for (const FluidBlock& block : scene_.fluid_blocks) {
    const Vec3 size = block.box.max - block.box.min;
    const double volume = block.cylinder_radius ? kPi * double(*block.cylinder_radius) * *block.cylinder_radius * size.z()
                                                : double(size.x()) * size.y() * size.z();
    parts.push_back({block.where, fmt::format("<fluid_block name=\"{}\"> ({:.3g} m³)", block.name, volume),
                     volume / (spacing * spacing * spacing)});
  }
  for (const PrintHead& head : scene_.print_heads) {
    const double duration = std::max(0.0, std::min(head.trajectory.end_time(), scene_.end_time) - head.trajectory.start_time());
    const double volume = kPi * double(head.inner_diameter) * head.inner_diameter / 4 * head.exit_speed * duration;
    parts.push_back({head.where, fmt::format("<print_head name=\"{}\"> ({:.3g} m³ extruded in {:.3g} s)", head.name, volume, duration),
                     volume / (spacing * spacing * spacing)});
  }
  for (const auto* bodies : {&scene_.bodies})
    for (const StaticBody& body : *bodies)
      for (const CollisionShape& collision : body.collisions) {
        const double area = sph::shape_surface_area(collision.shape);
        parts.push_back({collision.where, fmt::format("the wall particles of <collision> '{}' ({:.3g} m²)", collision.name, area),
                         area / (wall_spacing * wall_spacing)});
      }
  for (const DynamicBody& body : scene_.dynamic_bodies)
    for (const CollisionShape& collision : body.collisions) {
      const double area = sph::shape_surface_area(collision.shape);
      parts.push_back({collision.where, fmt::format("the wall particles of <collision> '{}' ({:.3g} m²)", collision.name, area),
                       area / (wall_spacing * wall_spacing)});
    }
  double total = 0;
  const Part* largest = nullptr;
  for (const Part& part : parts) {
    total += part.particles;
    if (!largest || part.particles > largest->particles) largest = &part;
  }
  const double limit = max_particles_.value_or(default_max_particles());
  if (!largest || !(total > limit)) return;
  report(largest->where,
         fmt::format("the scene would hold about {:.3g} particles at a particle radius of {:.3g} m, {:.3g} of them from {}; at most "
                     "{:.3g} fit ({}): use a larger <particle_radius> or a smaller part, or set <solver><max_particles>",
                     total, *particle_radius_, largest->particles, largest->what, limit,
                     max_particles_ ? "<max_particles>"
                                    : fmt::format("this machine's {:.3g} GB of memory at about {} bytes a particle",
                                                  physical_memory_bytes() / 1e9, kBytesPerParticle)));
}

void SceneReader::read_air(const pugi::xml_node& air) {
  // The air around the print: its drag on the material's surface (Gissler et al. 2017) is on when
  // the block is there, unless <drag>false</drag>.
  check_attributes(air, {});
  scene_.solver.air_drag = true;
  read_block(air, "air", &scene_, &scene_.solver_fields);
  if (const auto velocity = read_vector(air, "velocity", Quantity::speed, Presence::optional)) scene_.solver.air_velocity = *velocity;
}

void SceneReader::read_solver(const pugi::xml_node& solver) {
  check_attributes(solver, {});
  sph::SolverSettings& settings = scene_.solver;
  scene_.solver_fields.emplace_back("", where(solver));  // for settings the file does not name
  // The table's values (schema.cpp), then what ties them together or is not a plain value.
  read_block(solver, "solver", &scene_, &scene_.solver_fields);
  if (solver.child("particle_radius") && settings.particle_radius > 0) particle_radius_ = settings.particle_radius;
  if (const auto limit = read_scalar(solver, "max_particles", Quantity::plain_number, Limits::positive(), Presence::optional))
    max_particles_ = *limit;
  if ((solver.child("min_time_step") || solver.child("max_time_step")) && settings.max_time_step < settings.min_time_step) {
    const pugi::xml_node culprit = solver.child("max_time_step") ? solver.child("max_time_step") : solver.child("min_time_step");
    report(culprit, fmt::format("<max_time_step> ({} s) must be >= <min_time_step> ({} s)", settings.max_time_step,
                                settings.min_time_step));
  }
  if (const pugi::xml_node bounds = solver.child("bounds")) {
    check_attributes(bounds, {});
    check_children(bounds, {"min", "max"});
    if (const auto box = read_box(bounds)) {
      settings.bounds = *box;
      bounds_ = *box;
    }
  }
}

void SceneReader::read_fluid_block(const pugi::xml_node& element) {
  check_attributes(element, {"name", "material"});
  FluidBlock block;
  read_block(element, "fluid_block", &block);
  block.name = read_attribute(element, "name", Presence::required).value_or("");
  block.material = read_attribute(element, "material", Presence::required).value_or("");
  block.where = where(element);
  if (!block.name.empty()) check_unique_name(element, block.name, fluid_block_names_);
  if (!block.material.empty()) material_uses_.push_back(MaterialUse{block.material, describe(element), block.where});

  std::optional<Aabb> box;
  if (const pugi::xml_node cylinder = element.child("cylinder")) {
    // A vertical cylinder: the slump test's mould.
    if (element.child("min") || element.child("max")) {
      report(cylinder, fmt::format("{} has both <cylinder> and <min>/<max>; give one shape", describe(element)));
    }
    check_attributes(cylinder, {});
    const std::size_t problems_before = diagnostics_.size();
    read_block(cylinder, "cylinder", &block);
    const auto base = read_vector(cylinder, "base", Quantity::length, Presence::optional);
    if (base && diagnostics_.size() == problems_before) {
      const Real radius = *block.cylinder_radius;
      box = Aabb{*base - Vec3(radius, radius, 0), *base + Vec3(radius, radius, block.cylinder_height)};
    }
  } else {
    box = read_box(element);
  }
  if (box) block.box = *box;
  // Particles outside the solver bounds are removed at once, so a block reaching out of them is a mistake.
  if (box && bounds_ && !(bounds_->contains(box->min) && bounds_->contains(box->max))) {
    report(element, fmt::format("{} reaches outside the solver <bounds>; particles there would be removed at once",
                                describe(element)));
  }
  if (const auto velocity = read_vector(element, "velocity", Quantity::speed, Presence::optional)) {
    block.initial_velocity = *velocity;
  }
  scene_.fluid_blocks.push_back(std::move(block));
}

void SceneReader::read_print_head(const pugi::xml_node& element) {
  check_attributes(element, {"name", "material"});
  PrintHead head;
  read_block(element, "print_head", &head);
  head.name = read_attribute(element, "name", Presence::required).value_or("");
  head.material = read_attribute(element, "material", Presence::required).value_or("");
  head.where = where(element);
  if (!head.name.empty()) check_unique_name(element, head.name, print_head_names_);
  if (!head.material.empty()) material_uses_.push_back(MaterialUse{head.material, describe(element), head.where});

  if (const pugi::xml_node nozzle = element.child("nozzle")) {
    check_attributes(nozzle, {});
    // The table's values (schema.cpp), then the checks against the particles and each other.
    read_block(nozzle, "nozzle", &head, &head.nozzle_fields);
    if (nozzle.child("inner_diameter") && particle_radius_ && head.inner_diameter < 2 * *particle_radius_) {
      report(nozzle.child("inner_diameter"),
             fmt::format("the nozzle is narrower than one particle: <inner_diameter> {} m is below the particle "
                         "diameter 2*<particle_radius> = {} m; widen the nozzle or use smaller particles",
                         head.inner_diameter, 2 * *particle_radius_));
    }
    if (const auto direction = read_direction(nozzle, "direction", Presence::optional)) head.direction = *direction;
    // A nozzle with walls: the bore above the exit and the tip's lip (sph::NozzleSettings); the engine
    // checks the bore against the particles (sph::check_parameters) at these elements' lines.
    if (nozzle.child("outer_diameter") && head.outer_diameter > 0) {
      if (head.outer_diameter <= head.inner_diameter)
        report(nozzle.child("outer_diameter"), fmt::format("<outer_diameter> {} m must be larger than <inner_diameter> {} m",
                                                           head.outer_diameter, head.inner_diameter));
    }
  }
  if (const pugi::xml_node path = element.child("path")) {
    if (auto trajectory = read_path(path)) head.trajectory = std::move(*trajectory);
  }
  if (const pugi::xml_node mount = element.child("mount")) head.mount = read_mount(mount);
  scene_.print_heads.push_back(std::move(head));
}

void SceneReader::read_output(const pugi::xml_node& output) {
  check_attributes(output, {});
  read_block(output, "output", &scene_);
}

void SceneReader::read_meshing(const pugi::xml_node& meshing) {
  check_attributes(meshing, {});
  read_block(meshing, "meshing", &scene_);
  MeshingSettings& settings = scene_.meshing;
  settings.enabled = true;
  settings.where = where(meshing);
  if (const pugi::xml_node method = meshing.child("method")) {
    const std::string_view name = leaf_text(method, {});
    if (const auto parsed = surface::parse_method(name)) {
      settings.surface.method = *parsed;
    } else {
      report(method, fmt::format("<method> must be one of: {}; got '{}'", surface::method_names(), name));
    }
  }
  if (const pugi::xml_node format = meshing.child("format")) {
    const std::string_view name = leaf_text(format, {});
    if (io::find_mesh_format(name))
      settings.format = std::string(name);
    else
      report(format, fmt::format("<format> must be one of: {}; got '{}'", io::mesh_format_names(), name));
  }
  if (const pugi::xml_node material = meshing.child("material")) {
    settings.material = std::string(leaf_text(material, {}));
    material_uses_.push_back(MaterialUse{settings.material, "<meshing>", where(material)});
  }
  if (const pugi::xml_node region = meshing.child("region")) {
    check_attributes(region, {});
    check_children(region, {"min", "max"});
    settings.region = read_box(region);
  }
}

void SceneReader::read_coordinator(const pugi::xml_node& coordinator) {
  check_attributes(coordinator, {"enabled"});
  read_block(coordinator, "coordinator", &scene_);
  CoordinatorSettings& settings = scene_.coordinator;
  settings.enabled = read_bool_attribute(coordinator, "enabled").value_or(true);
  settings.where = where(coordinator);
  if (const pugi::xml_node priority = coordinator.child("priority")) {
    for (const auto& name : split_words(leaf_text(priority, {}))) {
      const std::string robot(name);
      if (!scene_.find_robot(robot)) {
        std::vector<std::string> names;
        for (const auto& included : scene_.robots) names.push_back(included.name);
        report(priority, fmt::format("<priority>: no robot '{}' is included in the world; its robots: {}", robot,
                                     names.empty() ? "none" : fmt::format("{}", fmt::join(names, ", "))));
      } else if (std::find(settings.priority.begin(), settings.priority.end(), robot) != settings.priority.end()) {
        report(priority, fmt::format("<priority>: robot '{}' is named twice", robot));
      } else {
        settings.priority.push_back(robot);
      }
    }
  }
  if (scene_.robots.size() < 2) report(coordinator, "<coordinator> coordinates robots: the world needs at least two");
}

void SceneReader::check_engine_parameters() {
  if (scene_.materials.empty()) return;  // already reported: no material, or none that could be read
  const sph::Parameters parameters = solver_parameters(scene_);
  report_parameter_problems(sph::check_parameters(parameters), parameters, scene_.materials);
}

void SceneReader::report_parameter_problems(const std::vector<sph::ParameterProblem>& problems, const sph::Parameters& parameters,
                                            std::span<const MaterialEntry> phase_entries) {
  auto location_of = [](const FieldLocations& fields, const std::string& field, const SourceLocation& fallback) {
    for (const auto& [name, location] : fields)
      if (name == field) return location;
    return fallback;
  };
  for (const sph::ParameterProblem& problem : problems) {
    SourceLocation location{file_.string(), 0};
    std::string owner;
    switch (problem.subject) {
      case sph::ParameterProblem::Subject::settings:
        location = location_of(scene_.solver_fields, problem.field, location_of(scene_.solver_fields, "", location));
        break;
      case sph::ParameterProblem::Subject::phase: {
        const MaterialEntry& entry = phase_entries[problem.index];
        location = location_of(entry.fields, problem.field, entry.where);
        owner = fmt::format("material '{}'", entry.material.name);
        break;
      }
      case sph::ParameterProblem::Subject::nozzle:
        if (problem.index < scene_.print_heads.size())
          location = location_of(scene_.print_heads[problem.index].nozzle_fields, problem.field, scene_.print_heads[problem.index].where);
        owner = fmt::format("print head '{}'", parameters.nozzles[problem.index].name);
        break;
    }
    // "<poisson_ratio> must be in [0, 0.49], got 0.5"; a whole material's problem names the material.
    const std::size_t dot = problem.field.rfind('.');
    const auto written = written_as_.find(problem.field);
    const std::string element = written != written_as_.end() ? written->second : problem.field.substr(dot == std::string::npos ? 0 : dot + 1);
    report(location, problem.field.empty() ? fmt::format("{} {}", owner, problem.message)
                                           : fmt::format("<{}> {}", element, problem.message));
  }
}

}  // namespace m3dp::scene::detail
