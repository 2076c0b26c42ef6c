// The SDF world the reader walks: the world, its models and links, their geometry and meshes, and
// the models and robots it includes.
#include "m3dp/scene/scene_reader.hpp"

#include <sstream>

#include "m3dp/io/mesh_io.hpp"
#include "m3dp/scene/urdf_check.hpp"

namespace m3dp::scene::detail {

// ---- SDF world ----

pugi::xml_node SceneReader::parse_root(pugi::xml_document& document, std::string_view expected_root) {
  const pugi::xml_parse_result parsed =
      document.load_buffer(text_.data(), text_.size(), pugi::parse_default, pugi::encoding_utf8);
  if (!parsed) {
    throw InputError(SourceLocation{file_.string(), lines_.line_at(parsed.offset)},
                     fmt::format("the file is not well-formed XML: {}", parsed.description()));
  }
  const pugi::xml_node root = document.document_element();
  if (std::string_view(root.name()) != expected_root) {
    throw InputError(where(root), fmt::format("expected the root element <{}>, got <{}>", expected_root, root.name()));
  }
  return root;
}

Scene SceneReader::read() {
  pugi::xml_document document;
  const pugi::xml_node sdf = parse_root(document, "sdf");
  scene_.file = file_;
  const auto worlds = child_elements(sdf, "world");
  if (worlds.empty()) {
    report(sdf, "missing <world> in <sdf>; a scene is an SDF world");
  } else {
    for (std::size_t extra = 1; extra < worlds.size(); ++extra) {
      report(worlds[extra], fmt::format("only one <world> per scene file; the first is at line {}",
                                        where(worlds.front()).line));
    }
    read_world(worlds.front());
  }

  if (!diagnostics_.empty()) {
    // The scene's own problems first, by line; then those of other files (presets) it uses.
    std::stable_sort(diagnostics_.begin(), diagnostics_.end(), [&](const Diagnostic& a, const Diagnostic& b) {
      const bool a_elsewhere = a.location.file != file_.string(), b_elsewhere = b.location.file != file_.string();
      return a_elsewhere != b_elsewhere ? b_elsewhere : a.location.line < b.location.line;
    });
    throw InputError(std::move(diagnostics_));
  }
  return std::move(scene_);
}

void SceneReader::warn_unknown_children(const pugi::xml_node& element, std::string_view block) {
  std::vector<std::string_view> known;
  for (const SchemaRow* row : schema_block(block)) known.push_back(row->name);
  for (const auto& child : element.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string_view name = child.name();
    if (std::find(known.begin(), known.end(), name) != known.end()) continue;
    const std::string_view closest = closest_name(name, known);
    scene_.warnings.push_back({where(child), closest.empty()
                                                 ? fmt::format("unknown element <{}> in <{}>, ignored: SDF has no such element there", name, element.name())
                                                 : fmt::format("unknown element <{}> in <{}>, ignored; did you mean <{}>?", name, element.name(), closest)});
  }
}

void SceneReader::read_world(const pugi::xml_node& world) {
  scene_.world_name = world.attribute("name").value();
  warn_unknown_children(world, "world");
  if (const auto gravity = read_vector(world, "gravity", Quantity::acceleration, Presence::optional)) {
    scene_.solver.gravity = *gravity;
  }

  std::vector<pugi::xml_node> m3dp_plugins;
  for (const auto& child : world.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string_view name = child.name();
    if (name == "model") {
      read_model(child);
    } else if (name == "include") {
      read_include(child);
    } else if (name == "plugin" && is_m3dp_plugin(child)) {
      m3dp_plugins.push_back(child);
    }
    // Other SDF world elements (physics, scene, light, other plugins, ...) are valid SDF that M3DP does not use.
  }

  if (m3dp_plugins.empty()) {
    report(world, fmt::format("missing <plugin name=\"m3dp\" filename=\"m3dp\"> in {}; it holds the solver, "
                              "materials and fluid",
                              describe(world)));
    return;
  }
  for (std::size_t extra = 1; extra < m3dp_plugins.size(); ++extra) {
    report(m3dp_plugins[extra], fmt::format("more than one m3dp <plugin> in the world; the first is at line {}",
                                            where(m3dp_plugins.front()).line));
  }
  read_plugin(m3dp_plugins.front());
}

void SceneReader::read_model(const pugi::xml_node& model) {
  StaticBody body;
  body.name = read_attribute(model, "name", Presence::required).value_or("");
  body.where = where(model);
  if (!body.name.empty()) check_unique_name(model, body.name, model_names_);
  warn_unknown_children(model, "model");
  if (!read_bool(model, "static").value_or(false)) {
    read_dynamic_model(model, body.name);
    return;
  }
  const Pose model_pose = read_pose(model);
  for (const auto& child : model.children()) {
    if (child.type() != pugi::node_element) continue;
    const std::string_view name = child.name();
    if (name == "link") {
      read_link(child, model_pose, body.name, body);
    } else if (name == "model") {
      report(child, "nested <model> is not supported yet; put each model directly in the <world>");
    } else if (name == "include") {
      report(child, "<include> is not supported yet; copy the model into the world");
    }
    // Joints, plugins and the like are valid SDF with no meaning for a static boundary.
  }
  scene_.bodies.push_back(std::move(body));
}

void SceneReader::read_dynamic_model(const pugi::xml_node& model, const std::string& name) {
  DynamicBody body;
  body.name = name;
  body.where = where(model);
  const auto links = child_elements(model, "link");
  if (links.size() != 1) {
    report(model, fmt::format("{}: a dynamic (not <static>) model needs exactly one <link>, found {}; M3DP has no "
                              "jointed SDF models yet (robots come from URDF through <include>)",
                              describe(model), links.size()));
    return;
  }
  for (const auto& child : model.children())
    if (child.type() == pugi::node_element && (std::string_view(child.name()) == "model" || std::string_view(child.name()) == "include"))
      report(child, fmt::format("<{}> inside a dynamic model is not supported", child.name()));
  const pugi::xml_node link = links.front();
  warn_unknown_children(link, "link");
  body.pose = read_pose(model) * read_pose(link);
  const pugi::xml_node inertial = link.child("inertial");
  if (!inertial) {
    report(link, fmt::format("{} of dynamic model '{}' needs <inertial><mass>...</mass></inertial> (kg)", describe(link), name));
  } else {
    if (const auto mass = read_scalar(inertial, "mass", Quantity::mass, Limits::positive(), Presence::required))
      body.mass = *mass;
    if (inertial.child("pose")) report(inertial.child("pose"), "an <inertial><pose> is not supported yet: the centre of mass is the link origin");
    if (const pugi::xml_node inertia = inertial.child("inertia")) {
      Mat3 tensor = Mat3::Zero();
      bool valid = true;
      const char* names[3][3] = {{"ixx", "ixy", "ixz"}, {"ixy", "iyy", "iyz"}, {"ixz", "iyz", "izz"}};
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) {
          const bool diagonal = r == c;
          const auto value = read_scalar(inertia, names[r][c], Quantity::plain_number,
                                         diagonal ? Limits::positive() : Limits::any(),
                                         diagonal ? Presence::required : Presence::optional);
          if (diagonal && !value) valid = false;
          tensor(r, c) = Real(value.value_or(0));
        }
      if (valid) body.inertia = tensor;
    }
  }
  for (const auto& collision : child_elements(link, "collision")) {
    warn_unknown_children(collision, "collision");
    const std::string collision_name = read_attribute(collision, "name", Presence::required).value_or("");
    const pugi::xml_node geometry = find_child(collision, "geometry", Presence::required);
    if (!geometry) continue;
    if (auto shape = read_geometry(geometry)) {
      if (std::holds_alternative<PlaneShape>(*shape)) {
        report(geometry, "a <plane> cannot move: put it in a <static> model");
        continue;
      }
      body.collisions.push_back(CollisionShape{fmt::format("{}/{}/{}", name, link.attribute("name").value(), collision_name),
                                               std::move(*shape), read_pose(collision), where(collision)});
    }
  }
  if (body.collisions.empty() && link.child("collision").empty() && inertial) {
    report(link, fmt::format("dynamic model '{}' has no <collision>: the world and the fluid would not see it", name));
  }
  scene_.dynamic_bodies.push_back(std::move(body));
}

std::optional<fs::path> SceneReader::resolve_model_uri(const pugi::xml_node& uri_element) {
  const std::string uri(trim(uri_element.child_value()));
  constexpr std::string_view kModel = "model://", kFile = "file://";
  if (uri.starts_with(kModel)) {
    const std::string name = uri.substr(kModel.size());
    std::vector<std::string> looked;
    for (const fs::path& folder : model_search_path(file_)) {
      for (const fs::path& candidate : {folder / name / (name + ".urdf"), folder / name / "model.urdf"}) {
        if (path_exists(candidate)) {
          scene_.input_files.push_back(candidate);
          return candidate;
        }
        looked.push_back(candidate.string());
      }
    }
    report(uri_element, fmt::format("'{}' not found; looked for {}", uri, fmt::join(looked, ", ")));
    return std::nullopt;
  }
  fs::path path(uri.starts_with(kFile) ? uri.substr(kFile.size()) : uri);
  if (path.is_relative()) path = file_.parent_path() / path;
  if (!path_exists(path)) {
    report(uri_element, fmt::format("'{}' not found (looked for {})", uri, path.string()));
    return std::nullopt;
  }
  scene_.input_files.push_back(path);
  return path;
}

void SceneReader::read_include(const pugi::xml_node& include) {
  check_block_children(include, "include");
  const pugi::xml_node uri_element = find_child(include, "uri", Presence::required);
  if (!uri_element) return;
  const auto file = resolve_model_uri(uri_element);
  if (!file) return;
  if (file->extension() != ".urdf") {
    report(uri_element, fmt::format("'{}' is not a URDF file; <include> takes URDF robots for now (SDF models go "
                                    "directly into the world as <model>)",
                                    file->string()));
    return;
  }
  RobotInclude robot;
  robot.urdf_file = *file;
  robot.pose = read_pose(include);
  robot.where = where(include);
  // The URDF is read here too, so that `m3dp validate` reports its XML errors with its own lines
  // and the scene's checks (link and joint names) need no physics engine.
  const std::string text = read_text_file(*file, "URDF file");
  pugi::xml_document urdf;
  const pugi::xml_parse_result parsed = urdf.load_buffer(text.data(), text.size());
  if (!parsed) {
    report(SourceLocation{file->string(), LineIndex(text).line_at(parsed.offset)},
           fmt::format("the URDF is not well-formed XML: {}", parsed.description()));
    return;
  }
  const pugi::xml_node root = urdf.document_element();
  if (std::string_view(root.name()) != "robot") {
    report(SourceLocation{file->string(), LineIndex(text).line_at(root.offset_debug())},
           fmt::format("expected the root element <robot> in a URDF, got <{}>", root.name()));
    return;
  }
  const LineIndex urdf_lines(text);
  const auto urdf_problems = check_urdf(root, *file, [&](std::ptrdiff_t offset) { return urdf_lines.line_at(offset); });
  for (const Diagnostic& problem : urdf_problems) report(problem.location, problem.message);
  if (!urdf_problems.empty()) return;
  const std::string urdf_name = root.attribute("name").value();
  if (const pugi::xml_node name_element = include.child("name")) {
    robot.name = std::string(trim(name_element.child_value()));
  } else {
    robot.name = urdf_name;
  }
  if (robot.name.empty()) {
    report(include, "the robot has no name: give the <include> a <name> or the URDF's <robot> a name=\"...\"");
    return;
  }
  check_unique_name(include, robot.name, model_names_);
  for (const auto& link : root.children("link")) robot.link_names.emplace_back(link.attribute("name").value());
  // Colours for cameras: a link's first visual material, given there or by name at the robot's top level.
  std::map<std::string, std::string> named_colors;
  for (const auto& material : root.children("material"))
    if (const auto color = material.child("color")) named_colors[material.attribute("name").value()] = color.attribute("rgba").value();
  for (const auto& link : root.children("link")) {
    const pugi::xml_node material = link.child("visual").child("material");
    if (!material) continue;
    std::string rgba = material.child("color").attribute("rgba").value();
    if (rgba.empty() && named_colors.contains(material.attribute("name").value())) rgba = named_colors[material.attribute("name").value()];
    std::istringstream values(rgba);
    std::array<float, 3> color{};
    if (values >> color[0] >> color[1] >> color[2] && std::all_of(color.begin(), color.end(), [](float c) { return c >= 0 && c <= 1; }))
      robot.link_colors.emplace_back(link.attribute("name").value(), color);
  }
  for (const auto& joint : root.children("joint")) {
    const std::string_view type = joint.attribute("type").value();
    if (type == "revolute" || type == "continuous" || type == "prismatic") robot.joint_names.emplace_back(joint.attribute("name").value());
  }
  scene_.robots.push_back(std::move(robot));
}

std::optional<std::array<float, 3>> SceneReader::read_color(const pugi::xml_node& parent) {
  const pugi::xml_node element = parent.child("color");
  if (!element) return std::nullopt;
  const auto values = parse_numbers(element, leaf_text(element, {}), 3, "r g b");
  if (!values) return std::nullopt;
  std::array<float, 3> color{};
  for (std::size_t c = 0; c < 3; ++c) {
    if (!((*values)[c] >= 0 && (*values)[c] <= 1)) {
      report(element, fmt::format("<color> is red, green and blue in [0, 1], got '{}'", leaf_text(element, {})));
      return std::nullopt;
    }
    color[c] = static_cast<float>((*values)[c]);
  }
  return color;
}

void SceneReader::read_link(const pugi::xml_node& link, const Pose& model_pose, const std::string& model_name,
                            StaticBody& body) {
  const std::string link_name = read_attribute(link, "name", Presence::required).value_or("");
  const Pose link_pose = model_pose * read_pose(link);
  warn_unknown_children(link, "link");
  for (const auto& collision : child_elements(link, "collision")) {
    warn_unknown_children(collision, "collision");
    const std::string collision_name = read_attribute(collision, "name", Presence::required).value_or("");
    const Pose collision_pose = link_pose * read_pose(collision);
    const pugi::xml_node geometry = find_child(collision, "geometry", Presence::required);
    if (!geometry) continue;
    if (auto shape = read_geometry(geometry)) {
      body.collisions.push_back(CollisionShape{fmt::format("{}/{}/{}", model_name, link_name, collision_name),
                                               std::move(*shape), collision_pose, where(collision)});
    }
  }
  for (const auto& sensor : child_elements(link, "sensor")) read_sensor(sensor, link_pose, fmt::format("{}/{}", model_name, link_name));
  // <visual>, <inertial> ... are valid SDF that the fluid does not see.
}

std::optional<Shape> SceneReader::read_geometry(const pugi::xml_node& geometry) {
  constexpr std::string_view kSupported = "box, sphere, cylinder, plane, mesh";
  const auto shapes = [&] {
    std::vector<pugi::xml_node> elements;
    for (const auto& child : geometry.children()) {
      if (child.type() == pugi::node_element) elements.push_back(child);
    }
    return elements;
  }();
  if (shapes.empty()) {
    report(geometry, fmt::format("<geometry> has no shape; expected one of: {}", kSupported));
    return std::nullopt;
  }
  if (shapes.size() > 1) {
    report(shapes[1], fmt::format("<geometry> must hold exactly one shape; found <{}> and <{}>", shapes[0].name(),
                                  shapes[1].name()));
    return std::nullopt;
  }
  const pugi::xml_node shape = shapes.front();
  const std::string_view kind = shape.name();
  if (kind == "box") {
    const pugi::xml_node size_element = find_child(shape, "size", Presence::required);
    if (!size_element) return std::nullopt;
    const auto size = read_numbers(size_element, 3, Quantity::length, "x y z");
    if (!size) return std::nullopt;
    if (std::any_of(size->begin(), size->end(), [](double edge) { return edge <= 0; })) {
      report(size_element, fmt::format("<size> of a <box> must be > 0 m on every axis, got '{}'",
                                       trim(size_element.child_value())));
      return std::nullopt;
    }
    return BoxShape{Vec3(Real((*size)[0]), Real((*size)[1]), Real((*size)[2]))};
  }
  if (kind == "sphere") {
    const auto radius = read_scalar(shape, "radius", Quantity::length, Limits::positive(), Presence::required);
    if (!radius) return std::nullopt;
    return SphereShape{Real(*radius)};
  }
  if (kind == "cylinder") {
    const auto radius = read_scalar(shape, "radius", Quantity::length, Limits::positive(), Presence::required);
    const auto length = read_scalar(shape, "length", Quantity::length, Limits::positive(), Presence::required);
    if (!radius || !length) return std::nullopt;
    return CylinderShape{Real(*radius), Real(*length)};
  }
  if (kind == "plane") {
    const auto normal = shape.child("normal") ? read_direction(shape, "normal", Presence::optional)
                                              : std::optional<Vec3>(Vec3::UnitZ());
    // SDF planes are infinite; boundary particles need a finite patch.
    const pugi::xml_node size_element = shape.child("size");
    if (!size_element) {
      report(shape, "missing required <size> in <plane>; M3DP samples a finite patch, e.g. <size>2 2</size>");
      return std::nullopt;
    }
    const auto size = read_numbers(size_element, 2, Quantity::length, "x y");
    if (!normal || !size) return std::nullopt;
    if ((*size)[0] <= 0 || (*size)[1] <= 0) {
      report(size_element,
             fmt::format("<size> of a <plane> must be > 0 m on both axes, got '{}'", trim(size_element.child_value())));
      return std::nullopt;
    }
    return PlaneShape{*normal, Real((*size)[0]), Real((*size)[1])};
  }
  if (kind == "mesh") {
    auto mesh = read_mesh(shape);
    if (!mesh) return std::nullopt;
    return std::move(*mesh);
  }
  report(shape, fmt::format("<{}> geometry is not supported yet; expected one of: {}", kind, kSupported));
  return std::nullopt;
}

std::optional<MeshShape> SceneReader::read_mesh(const pugi::xml_node& mesh) {
  const pugi::xml_node uri_element = find_child(mesh, "uri", Presence::required);
  if (!uri_element) return std::nullopt;
  const std::string_view uri = leaf_text(uri_element, {});

  constexpr std::string_view kFileScheme = "file://";
  fs::path mesh_path;
  if (uri.starts_with("model://")) {
    report(uri_element, fmt::format("'{}': model:// URIs need a Gazebo model path, which M3DP does not search; use a "
                                    "path relative to the scene file's folder (e.g. meshes/part.stl)",
                                    uri));
    return std::nullopt;
  }
  if (uri.starts_with(kFileScheme)) {
    mesh_path = fs::path(std::string(uri.substr(kFileScheme.size())));
  } else if (uri.find("://") != std::string_view::npos) {
    report(uri_element, fmt::format("'{}': unsupported URI scheme; use a path relative to the scene file's folder or "
                                    "file:///absolute/path",
                                    uri));
    return std::nullopt;
  } else if (uri.empty()) {
    report(uri_element, "<uri> is empty; expected the path of an .obj or .stl file");
    return std::nullopt;
  } else {
    mesh_path = fs::path(std::string(uri));
  }
  if (mesh_path.is_relative()) mesh_path = file_.parent_path() / mesh_path;
  scene_.input_files.push_back(mesh_path);

  Vec3 scale = Vec3::Ones();
  if (const pugi::xml_node scale_element = mesh.child("scale")) {
    const auto values = read_numbers(scale_element, 3, Quantity::plain_number, "x y z");
    if (!values) return std::nullopt;
    scale = Vec3(Real((*values)[0]), Real((*values)[1]), Real((*values)[2]));
    if ((scale.array() == 0).any()) {
      report(scale_element, "<scale> must not be 0 on any axis (it would flatten the mesh)");
      return std::nullopt;
    }
  }

  MeshShape shape;
  shape.file = mesh_path.string();
  try {
    shape.mesh = io::read_triangle_mesh(mesh_path);
  } catch (const InputError& error) {
    std::string details;
    for (const auto& diagnostic : error.diagnostics()) {
      details += (details.empty() ? "" : "; ") + diagnostic.str();
    }
    report(uri_element, fmt::format("cannot load mesh '{}': {}", shape.file, details));
    return std::nullopt;
  }
  for (Vec3& vertex : shape.mesh.vertices) vertex = vertex.cwiseProduct(scale);
  // A mirroring scale turns the triangles inside out; swap two corners to keep them counter-clockwise.
  if (scale.prod() < 0) {
    for (auto& triangle : shape.mesh.triangles) std::swap(triangle[1], triangle[2]);
  }
  return shape;
}

}  // namespace m3dp::scene::detail
