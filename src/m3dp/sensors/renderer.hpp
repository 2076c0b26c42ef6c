#pragma once
// What a camera sees, by ray casting on the CPU with Embree (Debian's libembree-dev 3.13): the
// particles as true spheres of their radius (Embree's sphere points, so a million particles cost a
// BVH, not a mesh), rigid things (links, bodies, nozzles) as triangles in their own frames, moved by
// their poses, static surfaces, and the printed material's mesh. Each is its own Embree scene under
// one top scene of instances, so a frame rebuilds only what changed: the particles' BVH, a new
// printed mesh, and the top scene; static surfaces are built once and bodies only move.
//
// A pixel keeps the segment id of what it hit (a legend, kept by the caller, says what each id is)
// and its colour comes from a palette of segment colours, shaded by a key light (with shadows) and
// an ambient term. Images are the same whatever the thread count: every pixel is its own rays.
#include <chrono>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "m3dp/core/geometry.hpp"
#include "m3dp/sensors/camera.hpp"

namespace m3dp::sensors {

struct Rgb {
  float r = 0.6f, g = 0.6f, b = 0.6f;  // linear, 0 to 1
};

/// One camera's image of a frame, row-major from the top left.
struct CameraImage {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;       // 3 bytes a pixel, sRGB (empty for a depth camera)
  std::vector<float> depth;            // m along the optical axis; +inf where nothing was hit (empty for a colour camera)
  std::vector<std::uint16_t> segment;  // the segment id of what each pixel saw; 0: nothing (the background)
};

struct RenderStats {
  double build_ms = 0;    // BVH builds and refits of this frame, all of them
  double particle_build_ms = 0;  // of which the particles' BVH (rebuilt when they moved)
  double trace_ms = 0;    // rays
  std::uint64_t rays = 0; // primary and shadow rays
};

class Renderer {
 public:
  static constexpr std::uint16_t kBackground = 0;
  Renderer();
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  /// A surface that never moves, in the world frame (static shapes, the floor).
  void add_static(const TriangleMesh& mesh, std::uint16_t segment);
  /// A rigid thing with its triangles in its own frame (a link, a body, a nozzle): its handle.
  std::size_t add_body(const TriangleMesh& mesh, std::uint16_t segment);
  void set_body_pose(std::size_t body, const Pose& pose);
  /// Two sets of particles, each its own BVH: those that move (rebuilt whenever set) and those at
  /// rest, rebuilt only when `version` changes (a print's resting material stays built).
  enum class ParticleSet { moving = 0, resting = 1 };
  /// The set's particles as spheres of `radius` (m) at `positions`, each with its segment id.
  void set_particles(std::span<const Vec3> positions, Real radius, std::span<const std::uint16_t> segments,
                     ParticleSet set = ParticleSet::moving, std::uint64_t version = 0);
  /// Replaces the printed material's mesh (world frame); an empty one removes it.
  void set_printed_mesh(const TriangleMesh& mesh, std::uint16_t segment);
  /// Each segment id's colour (index: id). Ids beyond it are drawn grey.
  void set_palette(std::vector<Rgb> colors);

  /// Renders the scene as set, from a camera whose frame is at `camera_pose` (world), into `image`
  /// (resized). `frame` seeds the noise. Builds what changed first.
  void render(const CameraSettings& settings, const Pose& camera_pose, std::uint64_t frame, CameraImage& image);
  [[nodiscard]] const RenderStats& last_stats() const { return stats_; }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  RenderStats stats_;
};

/// A point of a camera's point cloud: in the optical frame (m), its colour and segment.
struct CloudPoint {
  float x, y, z;
  std::uint8_t r, g, b, a;
  std::uint16_t segment;
  std::uint16_t padding;
};
static_assert(sizeof(CloudPoint) == 20);

/// The image's pixels that hit something as points in the optical frame (depth along the ray
/// through each pixel's centre), or moved by `to_frame` (e.g. the optical frame's pose in the world).
void point_cloud(const CameraImage& image, const Intrinsics& intrinsics, std::vector<CloudPoint>& points, const Pose& to_frame = Pose{});

}  // namespace m3dp::sensors
