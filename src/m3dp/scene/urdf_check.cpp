#include "m3dp/scene/urdf_check.hpp"

#include <fmt/format.h>

#include <array>
#include <charconv>
#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <string_view>

#include "m3dp/core/text.hpp"

namespace m3dp::scene {

namespace {

class UrdfChecker {
 public:
  UrdfChecker(const std::filesystem::path& file, const std::function<int(std::ptrdiff_t)>& line_of)
      : file_(file), line_of_(line_of) {}

  std::vector<Diagnostic> check(const pugi::xml_node& robot) {
    std::map<std::string, pugi::xml_node> links;
    for (const pugi::xml_node& link : robot.children("link")) {
      const std::string name = link.attribute("name").value();
      if (name.empty()) {
        report(link, "<link> needs a name=\"...\"");
        continue;
      }
      if (!links.emplace(name, link).second) report(link, fmt::format("a second <link name=\"{}\">: link names must be unique", name));
      check_link(link);
    }
    if (links.empty()) report(robot, "the robot has no <link>");
    // DART's loader takes a link named "world" for the world frame (the robot is fixed to it), not a body.
    else if (links.size() == 1 && links.contains("world"))
      report(links.at("world"), "the robot's only <link> is \"world\", which stands for the world frame: it needs a link of its own");

    std::set<std::string> joint_names;
    std::map<std::string, std::string> parent_of;  // child link → parent link
    for (const pugi::xml_node& joint : robot.children("joint")) {
      const std::string name = joint.attribute("name").value();
      if (name.empty()) report(joint, "<joint> needs a name=\"...\"");
      else if (!joint_names.insert(name).second) report(joint, fmt::format("a second <joint name=\"{}\">: joint names must be unique", name));
      check_joint(joint, name, links, parent_of);
    }
    // One tree: a single root, no link its own ancestor.
    std::vector<std::string> roots;
    for (const auto& [name, link] : links)
      if (!parent_of.contains(name)) roots.push_back(name);
    if (roots.size() > 1 && !links.empty())
      report(robot, fmt::format("the links form {} separate trees (roots {}): every link but one must be a joint's <child>",
                                roots.size(), fmt::format("{}", fmt::join(roots, ", "))));
    for (const auto& [child, parent] : parent_of) {
      std::string ancestor = parent;
      for (std::size_t depth = 0; depth <= parent_of.size() && parent_of.contains(ancestor); ++depth) {
        if (ancestor == child) {
          report(links.at(child), fmt::format("link '{}' is its own ancestor: the joints form a loop", child));
          break;
        }
        ancestor = parent_of.at(ancestor);
      }
    }
    return std::move(diagnostics_);
  }

 private:
  void report(const pugi::xml_node& node, std::string message) {
    diagnostics_.push_back(Diagnostic{SourceLocation{file_.string(), line_of_(node.offset_debug())}, std::move(message)});
  }

  /// `count` finite numbers from an attribute, or a report.
  std::optional<std::vector<double>> numbers(const pugi::xml_node& element, const char* attribute, std::size_t count,
                                             bool required) {
    const pugi::xml_attribute value = element.attribute(attribute);
    if (!value) {
      if (required) report(element, fmt::format("<{}> needs {}=\"...\" ({} number{})", element.name(), attribute, count, count == 1 ? "" : "s"));
      return std::nullopt;
    }
    std::vector<double> result;
    for (const std::string_view word : split_words(value.value())) {
      double number = 0;
      const auto [end, error] = std::from_chars(word.data(), word.data() + word.size(), number);
      if (error != std::errc() || end != word.data() + word.size() || !std::isfinite(number)) {
        report(element, fmt::format("<{} {}=\"{}\">: '{}' is not a finite number", element.name(), attribute, value.value(), word));
        return std::nullopt;
      }
      result.push_back(number);
    }
    if (result.size() != count) {
      report(element, fmt::format("<{} {}=\"{}\">: expected {} number{}, got {}", element.name(), attribute, value.value(), count,
                                  count == 1 ? "" : "s", result.size()));
      return std::nullopt;
    }
    return result;
  }
  void positive(const pugi::xml_node& element, const char* attribute, std::size_t count) {
    if (const auto values = numbers(element, attribute, count, true))
      for (const double value : *values)
        if (!(value > 0)) {
          report(element, fmt::format("<{} {}=\"{}\">: must be > 0", element.name(), attribute, element.attribute(attribute).value()));
          return;
        }
  }
  void origin(const pugi::xml_node& parent) {
    if (const pugi::xml_node element = parent.child("origin")) {
      numbers(element, "xyz", 3, false);
      numbers(element, "rpy", 3, false);
    }
  }

  void check_link(const pugi::xml_node& link) {
    if (const pugi::xml_node inertial = link.child("inertial")) {
      origin(inertial);
      if (const pugi::xml_node mass = inertial.child("mass")) positive(mass, "value", 1);
      else report(inertial, "<inertial> needs a <mass value=\"...\"/> (kg)");
      if (const pugi::xml_node inertia = inertial.child("inertia"))
        for (const char* component : {"ixx", "ixy", "ixz", "iyy", "iyz", "izz"}) numbers(inertia, component, 1, true);
      else report(inertial, "<inertial> needs an <inertia ixx ixy ixz iyy iyz izz/> (kg m²)");
    }
    for (const char* kind : {"visual", "collision"})
      for (const pugi::xml_node& shape : link.children(kind)) {
        origin(shape);
        const pugi::xml_node geometry = shape.child("geometry");
        if (!geometry) {
          report(shape, fmt::format("<{}> needs a <geometry>", kind));
          continue;
        }
        check_geometry(geometry, kind);
      }
  }

  void check_geometry(const pugi::xml_node& geometry, const char* kind) {
    const pugi::xml_node shape = geometry.first_child();
    if (!shape || shape.type() != pugi::node_element) {
      report(geometry, "<geometry> needs one of <box>, <cylinder>, <sphere>, <mesh>");
      return;
    }
    const std::string_view type = shape.name();
    if (type == "box") positive(shape, "size", 3);
    else if (type == "sphere") positive(shape, "radius", 1);
    else if (type == "cylinder") {
      positive(shape, "radius", 1);
      positive(shape, "length", 1);
    } else if (type == "mesh") {
      check_mesh(shape, kind);
    } else {
      report(shape, fmt::format("<{}> is not a URDF geometry; expected <box>, <cylinder>, <sphere> or <mesh>", type));
    }
  }

  void check_mesh(const pugi::xml_node& mesh, const char* kind) {
    numbers(mesh, "scale", 3, false);
    std::string filename = mesh.attribute("filename").value();
    if (filename.empty()) {
      report(mesh, "<mesh> needs a filename=\"...\"");
      return;
    }
    if (filename.rfind("package://", 0) == 0) {
      report(mesh, fmt::format("<mesh filename=\"{}\">: package:// is not resolved here (no ROS package path); write the path "
                               "relative to the URDF file",
                               filename));
      return;
    }
    if (filename.rfind("file://", 0) == 0) filename = filename.substr(7);
    std::filesystem::path path(filename);
    if (path.is_relative()) path = file_.parent_path() / path;
    if (!std::filesystem::exists(path))
      report(mesh, fmt::format("<mesh filename=\"{}\">: not found (looked for {}); the {} shape would be missing", filename,
                               path.string(), kind));
  }

  void check_joint(const pugi::xml_node& joint, const std::string& name, const std::map<std::string, pugi::xml_node>& links,
                   std::map<std::string, std::string>& parent_of) {
    static constexpr std::array<std::string_view, 6> kTypes{"revolute", "continuous", "prismatic", "fixed", "floating", "planar"};
    const std::string_view type = joint.attribute("type").value();
    if (std::find(kTypes.begin(), kTypes.end(), type) == kTypes.end())
      report(joint, fmt::format("<joint name=\"{}\" type=\"{}\">: expected type revolute, continuous, prismatic, fixed, floating or "
                                "planar",
                                name, type));
    origin(joint);
    std::string parent, child;
    for (const auto& [tag, target] : {std::pair{"parent", &parent}, std::pair{"child", &child}}) {
      const pugi::xml_node element = joint.child(tag);
      *target = element.attribute("link").value();
      if (target->empty()) report(element ? element : joint, fmt::format("joint '{}' needs a <{} link=\"...\"/>", name, tag));
      else if (!links.contains(*target))
        report(element, fmt::format("joint '{}': no <link name=\"{}\"> in the robot", name, *target));
    }
    if (!child.empty() && links.contains(child) && !parent.empty()) {
      if (!parent_of.emplace(child, parent).second)
        report(joint.child("child"), fmt::format("link '{}' is the child of a second joint ('{}'): a link has one parent", child, name));
    }
    if (const pugi::xml_node axis = joint.child("axis")) {
      if (const auto values = numbers(axis, "xyz", 3, false); values && std::hypot((*values)[0], (*values)[1], (*values)[2]) == 0)
        report(axis, "<axis xyz=\"0 0 0\">: the axis needs a direction");
    }
    const pugi::xml_node limit = joint.child("limit");
    if ((type == "revolute" || type == "prismatic") && !limit)
      report(joint, fmt::format("{} joint '{}' needs a <limit lower upper effort velocity/>", type, name));
    if (limit)
      for (const char* bound : {"lower", "upper", "effort", "velocity"}) numbers(limit, bound, 1, false);
  }

  std::filesystem::path file_;
  const std::function<int(std::ptrdiff_t)>& line_of_;
  std::vector<Diagnostic> diagnostics_;
};

}  // namespace

std::vector<Diagnostic> check_urdf(const pugi::xml_node& robot, const std::filesystem::path& file,
                                   const std::function<int(std::ptrdiff_t)>& line_of) {
  return UrdfChecker(file, line_of).check(robot);
}

}  // namespace m3dp::scene
