// Robots in a scene: the plugin's <robot> settings (controllers, mobile bases) and the mounts that put
// a nozzle or a camera on a robot's link.
#include "m3dp/scene/scene_reader.hpp"

namespace m3dp::scene::detail {

void SceneReader::read_robot_settings(const pugi::xml_node& element) {
  check_attributes(element, {"name"});
  read_block(element, "robot", &scene_);
  // The mobile base's own values are checked whether or not the robot is found: every error at once.
  const pugi::xml_node base = element.child("mobile_base");
  MobileBase mobile;
  const std::size_t problems_before = diagnostics_.size();
  if (base) {
    check_attributes(base, {});
    read_block(base, "mobile_base", &mobile);
    mobile.where = where(base);
  }
  bool base_valid = diagnostics_.size() == problems_before;
  const auto name = read_attribute(element, "name", Presence::required);
  if (!name) return;
  check_unique_name(element, *name, robot_setting_names_);
  auto robot = std::find_if(scene_.robots.begin(), scene_.robots.end(), [&](const RobotInclude& r) { return r.name == *name; });
  if (robot == scene_.robots.end()) {
    std::vector<std::string> names;
    for (const auto& r : scene_.robots) names.push_back(r.name);
    report(element, fmt::format("<robot name=\"{}\">: no robot of that name is included in the world{}", *name,
                                names.empty() ? std::string("; add <include><uri>model://...</uri></include>")
                                              : fmt::format(" (robots: {})", fmt::join(names, ", "))));
    return;
  }
  auto is_joint = [&](const std::string& joint) {
    return std::find(robot->joint_names.begin(), robot->joint_names.end(), joint) != robot->joint_names.end();
  };
  for (const auto& joint : child_elements(element, "joint")) {
    const auto joint_name = read_attribute(joint, "name", Presence::required);
    if (!joint_name) continue;
    if (!is_joint(*joint_name)) {
      report(joint, fmt::format("robot '{}' has no movable joint '{}'; its joints: {}", robot->name, *joint_name,
                                fmt::join(robot->joint_names, ", ")));
      continue;
    }
    const auto text = leaf_text(joint, {"name", "unit"});
    const auto factor = unit_factor(joint, Quantity::angle);
    const auto value = parse_numbers(joint, text, 1, "an initial joint position (rad, or unit=\"deg\")");
    if (value && factor) robot->initial_joint_positions.emplace_back(*joint_name, value->front() * *factor);
  }
  if (!base) return;
  for (const auto& [tag, target] : {std::pair{"left_wheel", &mobile.left_wheel_joint}, std::pair{"right_wheel", &mobile.right_wheel_joint}}) {
    const pugi::xml_node wheel = base.child(tag);
    if (!wheel) continue;
    *target = std::string(leaf_text(wheel, {}));
    if (!is_joint(*target)) {
      report(wheel, fmt::format("robot '{}' has no movable joint '{}' for a wheel; its joints: {}", robot->name, *target,
                                fmt::join(robot->joint_names, ", ")));
      base_valid = false;
    }
  }
  if (const pugi::xml_node path = base.child("path")) {
    mobile.path = read_path(path);
    if (!mobile.path) base_valid = false;
  }
  if (base_valid) robot->mobile_base = std::move(mobile);
}

std::optional<NozzleMount> SceneReader::read_mount(const pugi::xml_node& element) {
  check_attributes(element, {"robot", "link"});
  NozzleMount mount;
  read_block(element, "mount", &mount);
  mount.where = where(element);
  const auto robot_name = read_attribute(element, "robot", Presence::required);
  const auto link = read_attribute(element, "link", Presence::required);
  mount.offset = read_pose(element);
  if (!robot_name || !link || !check_robot_link(element, *robot_name, *link)) return std::nullopt;
  mount.robot = *robot_name;
  mount.link = *link;
  return mount;
}

bool SceneReader::check_robot_link(const pugi::xml_node& element, const std::string& robot_name, const std::string& link) {
  const RobotInclude* robot = scene_.find_robot(robot_name);
  if (!robot) {
    report(element, fmt::format("<mount robot=\"{}\">: no robot of that name is included in the world", robot_name));
    return false;
  }
  if (std::find(robot->link_names.begin(), robot->link_names.end(), link) == robot->link_names.end()) {
    report(element, fmt::format("robot '{}' has no link '{}'; its links: {}", robot->name, link, fmt::join(robot->link_names, ", ")));
    return false;
  }
  return true;
}

}  // namespace m3dp::scene::detail
