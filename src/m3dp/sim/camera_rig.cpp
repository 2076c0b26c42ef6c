#include "m3dp/sim/camera_rig.hpp"

#include "m3dp/core/state_io.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

namespace {

using Clock = std::chrono::steady_clock;

/// Colours of things that are not materials (linear RGB).
constexpr sensors::Rgb kStaticColor{0.36f, 0.37f, 0.40f}, kLinkColor{0.30f, 0.45f, 0.70f}, kBodyColor{0.85f, 0.50f, 0.15f},
    kNozzleColor{0.20f, 0.20f, 0.22f}, kPrintedMeshColor{0.60f, 0.52f, 0.45f};
/// Materials without a <color>: a palette that tells them apart.
constexpr sensors::Rgb kMaterialPalette[] = {{0.80f, 0.55f, 0.35f}, {0.35f, 0.65f, 0.45f}, {0.75f, 0.35f, 0.45f},
                                             {0.55f, 0.45f, 0.75f}, {0.80f, 0.75f, 0.35f}, {0.35f, 0.65f, 0.75f}};
/// A material's layers alternate a little in brightness, so that a picture shows them.
constexpr float kLayerShade[] = {1.0f, 0.86f};
constexpr std::size_t kMaxLayers = 4000;  // per material; later layers share the last id

TriangleMesh transformed(const TriangleMesh& mesh, const Pose& pose) {
  TriangleMesh out;
  out.triangles = mesh.triangles;
  out.vertices.reserve(mesh.vertices.size());
  for (const Vec3& vertex : mesh.vertices) out.vertices.push_back(pose.apply(vertex));
  return out;
}

}  // namespace

CameraRig::CameraRig(const Simulation& simulation)
    : layout_(world_layout(simulation)), particle_radius_(simulation.solver().parameters().settings.particle_radius) {
  const auto& scene = simulation.scene();
  add_segment({0, "background", "", "", -1, 0, {}});
  // Everything that is not fluid, each its own segment.
  for (std::size_t b = 0; b < layout_.bodies.size(); ++b) {
    const BodyView& body = layout_.bodies[b];
    const std::string kind = body.kind == BodyKind::static_body ? "static" : body.kind == BodyKind::free_body ? "body" : "link";
    sensors::Rgb color = body.kind == BodyKind::static_body ? kStaticColor : body.kind == BodyKind::free_body ? kBodyColor : kLinkColor;
    if (body.kind == BodyKind::robot_link)
      if (const auto* robot = scene.find_robot(body.robot))
        for (const auto& [link, rgb] : robot->link_colors)
          if (body.name == body.robot + "/" + link) color = {rgb[0], rgb[1], rgb[2]};  // the URDF's own colour
    const std::uint16_t segment = add_segment({0, kind, body.name, body.robot, -1, 0, color});
    if (!body.link) {
      renderer_.add_static(transformed(body.triangles, body.fixed_pose), segment);
      body_handles_.push_back(~std::size_t(0));
    } else {
      body_handles_.push_back(renderer_.add_body(body.triangles, segment));
    }
  }
  for (const auto& nozzle : layout_.nozzles)
    nozzle_handles_.push_back(renderer_.add_body(nozzle.triangles, add_segment({0, "nozzle", "nozzle/" + nozzle.name, "", -1, 0, kNozzleColor})));
  printed_segment_ = add_segment({0, "printed_material", "printed_material", "", -1, 0, kPrintedMeshColor});

  // Materials: a segment per print layer (each particle keeps the layer its nozzle's path was on
  // when it left), and one for what no path printed (fluid blocks).
  const std::size_t phases = scene.materials.size();
  material_colors_.resize(phases);
  layer_segments_.resize(phases);
  for (std::size_t phase = 0; phase < phases; ++phase) {
    const auto& color = scene.materials[phase].color;
    material_colors_[phase] = color ? sensors::Rgb{(*color)[0], (*color)[1], (*color)[2]} : kMaterialPalette[phase % std::size(kMaterialPalette)];
    // As many layers as the head with the most; each began when the first of them began it.
    std::vector<double> starts;  // s, on the paths' clocks
    for (std::size_t head = 0; head < scene.print_heads.size(); ++head) {
      if (scene.material_index(scene.print_heads[head].material) != phase) continue;
      const auto& head_starts = simulation.layer_start_times(head);
      for (std::size_t layer = 0; layer < head_starts.size(); ++layer)
        if (layer < starts.size()) starts[layer] = std::min(starts[layer], head_starts[layer]);
        else starts.push_back(head_starts[layer]);
    }
    if (starts.size() > kMaxLayers) starts.resize(kMaxLayers);
    const std::string& name = scene.materials[phase].material.name;
    layer_segments_[phase].push_back(add_segment({0, "material", name, "", -1, 0, material_colors_[phase]}));
    for (std::size_t layer = 0; layer < starts.size(); ++layer) {
      sensors::Rgb shaded = material_colors_[phase];
      const float shade = kLayerShade[layer % std::size(kLayerShade)];
      shaded = {shaded.r * shade, shaded.g * shade, shaded.b * shade};
      layer_segments_[phase].push_back(add_segment({0, "material", name, "", static_cast<int>(layer), starts[layer], shaded}));
    }
  }
  std::vector<sensors::Rgb> palette;
  for (const Segment& segment : legend_) palette.push_back(segment.color);
  renderer_.set_palette(std::move(palette));

  // The cameras, each on its link (found by name among the robots) or fixed in the world.
  for (const auto& entry : scene.cameras) {
    Camera camera;
    camera.settings = entry.settings;
    cameras_.push_back(std::move(camera));
  }
}

std::uint16_t CameraRig::add_segment(Segment segment) {
  if (legend_.size() >= 65535) throw Error("cameras: more than 65535 things to tell apart in the segmentation images");
  segment.id = static_cast<std::uint16_t>(legend_.size());
  legend_.push_back(std::move(segment));
  return legend_.back().id;
}

Pose CameraRig::pose(const Simulation& simulation, std::size_t index) const {
  const sensors::CameraSettings& settings = cameras_.at(index).settings;
  if (settings.robot.empty()) return settings.pose;
  const auto& world = simulation.world();
  for (const world::RobotIndex robot : simulation.robots()) {
    if (world.robot_name(robot) != settings.robot) continue;
    if (const auto link = world.robot_link_pose(robot, settings.link)) return *link * settings.pose;
  }
  throw Error(fmt::format("camera '{}': robot '{}' has no link '{}'", settings.name, settings.robot, settings.link));
}

void CameraRig::update(const Simulation& simulation) {
  const auto step = static_cast<std::uint64_t>(simulation.solver().state().step);
  if (step == updated_step_) return;
  updated_step_ = step;
  const WorldPoses poses = world_poses(simulation, layout_);
  std::vector<Pose> nozzles;
  for (const auto& nozzle : poses.nozzles) nozzles.push_back(nozzle.pose);
  const auto& fluid = simulation.solver().fluid();
  const bool new_mesh = simulation.printed_mesh() && simulation.printed_mesh_version() != printed_version_;
  printed_version_ = simulation.printed_mesh_version();
  const auto settled = simulation.solver().settled_particles();
  show({poses.bodies, nozzles, fluid.position, fluid.phase, fluid.print_layer, new_mesh ? simulation.printed_mesh().get() : nullptr,
        settled.begin, settled.end, settled.build});
}

void CameraRig::show(const State& state) {
  for (std::size_t b = 0; b < layout_.bodies.size() && b < state.bodies.size(); ++b)
    if (layout_.bodies[b].link) renderer_.set_body_pose(body_handles_[b], state.bodies[b]);
  for (std::size_t n = 0; n < nozzle_handles_.size() && n < state.nozzles.size(); ++n) renderer_.set_body_pose(nozzle_handles_[n], state.nozzles[n]);
  if (state.printed_mesh) renderer_.set_printed_mesh(*state.printed_mesh, printed_segment_);
  const std::size_t count = state.positions.size();
  particle_segments_.resize(count);
  parallel_for_each_index(count, [&](std::size_t i) {
    const std::uint16_t phase = i < state.phases.size() && state.phases[i] < layer_segments_.size() ? state.phases[i] : 0;
    if (layer_segments_.empty()) return;
    // The segments list "no layer" first, then each layer; layers past the last share its id.
    const std::int32_t layer = i < state.layers.size() ? std::max(state.layers[i], -1) : -1;
    particle_segments_[i] = layer_segments_[phase][std::min(static_cast<std::size_t>(layer + 1), layer_segments_[phase].size() - 1)];
  }, 4096);
  using Set = sensors::Renderer::ParticleSet;
  if (state.settled_end <= state.settled_begin || state.settled_end > count) {
    renderer_.set_particles({}, particle_radius_, {}, Set::resting, 0);
    renderer_.set_particles(state.positions, particle_radius_, particle_segments_, Set::moving);
    return;
  }
  // Settled particles keep their BVH until the solver chooses them anew; the rest are rebuilt.
  const std::size_t begin = state.settled_begin, end = state.settled_end;
  renderer_.set_particles(state.positions.subspan(begin, end - begin), particle_radius_,
                          std::span<const std::uint16_t>(particle_segments_).subspan(begin, end - begin), Set::resting, state.settled_build);
  moving_positions_.assign(state.positions.begin(), state.positions.begin() + static_cast<std::ptrdiff_t>(begin));
  moving_positions_.insert(moving_positions_.end(), state.positions.begin() + static_cast<std::ptrdiff_t>(end), state.positions.end());
  moving_segments_.assign(particle_segments_.begin(), particle_segments_.begin() + static_cast<std::ptrdiff_t>(begin));
  moving_segments_.insert(moving_segments_.end(), particle_segments_.begin() + static_cast<std::ptrdiff_t>(end), particle_segments_.end());
  renderer_.set_particles(moving_positions_, particle_radius_, moving_segments_, Set::moving);
}

void CameraRig::render(const sensors::CameraSettings& settings, const Pose& camera_pose, std::uint64_t frame, sensors::CameraImage& image) {
  renderer_.render(settings, camera_pose, frame, image);
}

const sensors::CameraImage& CameraRig::image(const Simulation& simulation, std::size_t index) {
  Camera& camera = cameras_.at(index);
  const auto step = static_cast<std::uint64_t>(simulation.solver().state().step);
  if (camera.rendered_step == step) return camera.image;
  const auto began = Clock::now();
  update(simulation);
  renderer_.render(camera.settings, pose(simulation, index), camera.totals.frames++ * 1000003ull + index, camera.image);
  camera.rendered_step = step;
  const double ms = std::chrono::duration<double, std::milli>(Clock::now() - began).count();
  render_ms_ += ms;
  camera.totals.render_seconds += 1e-3 * ms;
  camera.totals.rays += renderer_.last_stats().rays;
  return camera.image;
}

const std::vector<sensors::CloudPoint>& CameraRig::points(const Simulation& simulation, std::size_t index) {
  Camera& camera = cameras_.at(index);
  const sensors::CameraImage& rendered = image(simulation, index);
  if (camera.points_step == camera.rendered_step) return camera.points;
  camera.points_step = camera.rendered_step;
  camera.points.clear();
  using Frame = sensors::CameraSettings::PointCloud;
  if (camera.settings.point_cloud == Frame::none) return camera.points;
  const Pose to_frame = camera.settings.point_cloud == Frame::world ? sensors::optical_pose(pose(simulation, index)) : Pose{};
  sensors::point_cloud(rendered, sensors::Intrinsics::of(camera.settings), camera.points, to_frame);
  return camera.points;
}

double CameraRig::take_render_ms() {
  const double ms = render_ms_;
  render_ms_ = 0;
  return ms;
}

void CameraRig::save_totals(StateWriter& out) const {
  out.put(static_cast<std::uint64_t>(cameras_.size()));
  for (const Camera& camera : cameras_) out.put(camera.totals);
}

void CameraRig::load_totals(StateReader& in) {
  if (in.get<std::uint64_t>() != cameras_.size()) in.fail("another number of cameras than the scene has");
  for (Camera& camera : cameras_) in.get(camera.totals);
}

}  // namespace m3dp::sim
