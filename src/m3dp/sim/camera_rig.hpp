#pragma once
// The scene's cameras on a simulation: one renderer (sensors::Renderer) fed from the world as the
// outputs draw it (world_view: static shapes, links, bodies, nozzles), the printed material's mesh
// and the particles; each camera where its link or the world puts it. Every pixel's segment id
// names what it saw in a legend: the background, each static shape, link, body and nozzle, the
// printed mesh, and each material's print layers (a particle's layer is the layer of its print
// head's path it was emitted in, by its birth time).
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "m3dp/sensors/renderer.hpp"
#include "m3dp/core/state_io.hpp"
#include "m3dp/sim/world_view.hpp"

namespace m3dp::sim {

class Simulation;

struct Segment {
  std::uint16_t id = 0;
  std::string kind;      // background, static, link, body, nozzle, printed_material, material
  std::string name;      // the body's, link's ("ur10/forearm_link") or material's name
  std::string robot;     // for a link
  int layer = -1;        // for a material: its print layer (0 first), -1: not printed by a path
  double layer_start = 0;  // s: when the first head printing it began that layer (on its path's clock)
  sensors::Rgb color;
};

class CameraRig {
 public:
  explicit CameraRig(const Simulation& simulation);

  [[nodiscard]] std::size_t size() const { return cameras_.size(); }
  [[nodiscard]] const sensors::CameraSettings& settings(std::size_t camera) const { return cameras_.at(camera).settings; }
  /// The camera frame's pose in the world now (x forward, z up).
  [[nodiscard]] Pose pose(const Simulation& simulation, std::size_t camera) const;
  /// The camera's image of the simulation as it is now (rendered once per step and camera).
  const sensors::CameraImage& image(const Simulation& simulation, std::size_t camera);
  /// Its point cloud (the camera's point_cloud setting says in which frame; empty for none), made
  /// once per image.
  const std::vector<sensors::CloudPoint>& points(const Simulation& simulation, std::size_t camera);
  /// What each segment id is (index: id): fixed when the rig is made, layers from the paths.
  [[nodiscard]] const std::vector<Segment>& legend() const { return legend_; }
  [[nodiscard]] const WorldLayout& layout() const { return layout_; }
  /// What the cameras see when it does not come from the simulation (a saved run: m3dp render):
  /// each layout body's and nozzle's pose (static ones ignored), the particles with their
  /// material (phase) and print layer (-1 or none: not printed by a path), and the printed mesh
  /// (null: none).
  struct State {
    std::span<const Pose> bodies;
    std::span<const Pose> nozzles;
    std::span<const Vec3> positions;
    std::span<const std::uint16_t> phases;
    std::span<const std::int32_t> layers;
    const TriangleMesh* printed_mesh = nullptr;
    /// Particles [settled_begin, settled_end) have not moved since build `settled_build` (their
    /// BVH is kept until it changes); none: every particle is drawn as moving.
    std::size_t settled_begin = 0, settled_end = 0;
    std::uint64_t settled_build = 0;
  };
  void show(const State& state);
  /// An image of what was last shown, from any camera at any pose (frame seeds the noise).
  void render(const sensors::CameraSettings& settings, const Pose& camera_pose, std::uint64_t frame, sensors::CameraImage& image);
  /// Wall ms spent rendering since the last call (timing.csv's cameras column).
  double take_render_ms();
  /// A camera's images rendered so far, the wall seconds they took and their rays.
  struct Totals {
    std::size_t frames = 0;
    double render_seconds = 0;
    std::uint64_t rays = 0;
  };
  [[nodiscard]] const Totals& totals(std::size_t camera) const { return cameras_.at(camera).totals; }
  [[nodiscard]] const sensors::RenderStats& last_stats() const { return renderer_.last_stats(); }
  /// A checkpoint: every camera's totals (the frame count seeds its noise), and back.
  void save_totals(StateWriter& out) const;
  void load_totals(StateReader& in);

 private:
  struct Camera {
    sensors::CameraSettings settings;
    std::optional<world::LinkIndex> link;  // what carries it (none: fixed in the world)
    Pose fixed_link_pose;                  // a fixed robot link's pose, if it is on one
    sensors::CameraImage image;
    std::uint64_t rendered_step = ~0ull;
    std::vector<sensors::CloudPoint> points;
    std::uint64_t points_step = ~0ull;
    Totals totals;
  };
  /// Brings the renderer's scene to the simulation's present (once per step).
  void update(const Simulation& simulation);
  std::uint16_t add_segment(Segment segment);

  WorldLayout layout_;
  std::vector<std::size_t> body_handles_;  // per moving layout body
  std::vector<std::size_t> nozzle_handles_;
  sensors::Renderer renderer_;
  std::vector<Camera> cameras_;
  std::vector<Segment> legend_;
  std::vector<sensors::Rgb> material_colors_;                  // per phase
  std::vector<std::vector<std::uint16_t>> layer_segments_;     // per phase: [0] no layer, [k + 1] layer k
  std::vector<std::uint16_t> particle_segments_;
  std::vector<Vec3> moving_positions_;               // the particles not settled, when some are
  std::vector<std::uint16_t> moving_segments_;
  Real particle_radius_;  // m
  std::uint16_t printed_segment_ = 0;
  std::size_t printed_version_ = 0;
  std::uint64_t updated_step_ = ~0ull;
  double render_ms_ = 0;
};

}  // namespace m3dp::sim
