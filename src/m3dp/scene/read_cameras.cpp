// Cameras: SDF <sensor type="camera"> in static links and the plugin's <camera>, on a robot or in the world.
#include "m3dp/scene/scene_reader.hpp"

namespace m3dp::scene::detail {

// ---- cameras ----

bool SceneReader::read_camera_settings(const pugi::xml_node& named, const pugi::xml_node& intrinsics,
                                       sensors::CameraSettings& settings) {
  bool valid = true;
  if (const auto name = read_attribute(named, "name", Presence::required)) {
    settings.name = *name;
    const auto earlier = std::find_if(scene_.cameras.begin(), scene_.cameras.end(),
                                      [&](const CameraEntry& camera) { return camera.settings.name == *name; });
    if (earlier != scene_.cameras.end()) {
      report(named, fmt::format("a camera '{}' is already defined at line {}", *name, earlier->where.line));
      valid = false;
    }
  } else {
    valid = false;
  }
  const auto type = read_attribute(named, "type", Presence::required).value_or("");
  if (type == "camera") settings.type = sensors::CameraType::camera;
  else if (type == "depth_camera" || type == "depth") settings.type = sensors::CameraType::depth_camera;
  else if (type == "rgbd_camera" || type == "rgbd") settings.type = sensors::CameraType::rgbd_camera;
  else {
    if (!type.empty()) report(named, fmt::format("camera type '{}' is not one M3DP renders; expected camera, depth_camera or rgbd_camera", type));
    valid = false;
  }
  // The table's values (schema.cpp). The plugin's <camera> has had its own rows read (read_block);
  // SDF keeps <update_rate> on the <sensor> and <horizontal_fov> in its <camera>.
  const std::size_t problems_before = diagnostics_.size();
  if (named != intrinsics) read_row(named, schema_row("camera", "update_rate"), &settings);
  if (intrinsics) {
    if (named != intrinsics) read_row(intrinsics, schema_row("camera", "horizontal_fov"), &settings);
    if (const pugi::xml_node image = intrinsics.child("image")) read_block(image, "image", &settings);
    if (const pugi::xml_node clip = intrinsics.child("clip")) {
      read_block(clip, "clip", &settings);
      if (diagnostics_.size() == problems_before && settings.far <= settings.near)
        report(clip, fmt::format("<far> ({} m) must be beyond <near> ({} m)", settings.far, settings.near));
    }
    if (const pugi::xml_node noise = intrinsics.child("noise")) {
      check_attributes(noise, {"type"});
      const std::string kind = noise.attribute("type") ? noise.attribute("type").value() : std::string(trim(noise.child_value("type")));
      if (kind != "gaussian" && kind != "none") report(noise, fmt::format("camera noise '{}' is not simulated; expected gaussian (or none)", kind));
      sensors::CameraSettings read = settings;
      read_block(noise, "noise", &read);
      if (kind == "gaussian") settings.noise = read.noise;
    }
  }
  return valid && diagnostics_.size() == problems_before;
}

void SceneReader::read_sensor(const pugi::xml_node& sensor, const Pose& link_pose, const std::string& link_name) {
  const std::string type = sensor.attribute("type").value();
  if (type != "camera" && type != "depth_camera" && type != "depth" && type != "rgbd_camera" && type != "rgbd") {
    scene_.warnings.push_back({where(sensor), fmt::format("<sensor type=\"{}\"> in link '{}' is not simulated (M3DP renders "
                                                          "camera, depth_camera and rgbd_camera); ignored", type, link_name)});
    return;
  }
  check_attributes(sensor, {"name", "type"});
  // SDF's children of a sensor M3DP reads, and those it accepts with no effect on the images.
  check_children(sensor, {"pose", "update_rate", "camera", "always_on", "visualize", "topic", "enable_metrics", "frame", "plugin"},
                 {"plugin"});
  const pugi::xml_node camera = sensor.child("camera");
  if (camera)
    check_children(camera, {"horizontal_fov", "image", "clip", "noise", "save", "depth_camera", "distortion", "lens",
                            "visibility_mask", "optical_frame_id", "camera_info_topic", "trigger_topic", "triggered", "pose"});
  CameraEntry entry;
  entry.where = where(sensor);
  if (!read_camera_settings(sensor, camera, entry.settings)) return;
  entry.settings.pose = link_pose * read_pose(sensor) * (camera ? read_pose(camera) : Pose{});
  scene_.cameras.push_back(std::move(entry));
}

void SceneReader::read_plugin_camera(const pugi::xml_node& element) {
  check_attributes(element, {"name", "type"});
  CameraEntry entry;
  entry.where = where(element);
  // The table checks the children and reads <shadows>; read_camera_settings reads the rest.
  const std::size_t problems_before = diagnostics_.size();
  read_block(element, "camera", &entry.settings);
  bool valid = read_camera_settings(element, element, entry.settings) && diagnostics_.size() == problems_before;
  if (const pugi::xml_node cloud = element.child("point_cloud")) {
    // <point_cloud frame="optical|world">true</point_cloud>
    const std::string_view text = leaf_text(cloud, {"frame"});
    const auto enabled = parse_bool(text);
    const std::string frame = cloud.attribute("frame").as_string("optical");
    if (!enabled) {
      report(cloud, fmt::format("<point_cloud> must be true or false (or 1 or 0), got '{}'", text));
      valid = false;
    } else if (frame != "optical" && frame != "world") {
      report(cloud, fmt::format("<point_cloud frame=\"{}\">: expected optical or world", frame));
      valid = false;
    } else if (*enabled) {
      if (!sensors::has_depth(entry.settings.type)) {
        report(cloud, "a point cloud needs depth: the camera's type must be depth_camera or rgbd_camera");
        valid = false;
      }
      entry.settings.point_cloud = frame == "world" ? sensors::CameraSettings::PointCloud::world : sensors::CameraSettings::PointCloud::optical;
    }
  }
  if (const pugi::xml_node mount = element.child("mount")) {
    check_attributes(mount, {"robot", "link"});
    check_children(mount, {"pose"});  // the camera's mount: only its pose (a print head's <mount> has a barrel too)
    if (element.child("pose")) {
      report(element.child("pose"), "a mounted camera's <pose> goes inside its <mount> (in the link's frame)");
      valid = false;
    }
    const auto robot = read_attribute(mount, "robot", Presence::required);
    const auto link = read_attribute(mount, "link", Presence::required);
    if (!robot || !link || !check_robot_link(mount, *robot, *link)) return;
    entry.settings.robot = *robot;
    entry.settings.link = *link;
    entry.settings.pose = read_pose(mount);
  } else {
    entry.settings.pose = read_pose(element);
  }
  entry.in_plugin = true;
  if (valid) scene_.cameras.push_back(std::move(entry));
}

}  // namespace m3dp::scene::detail
