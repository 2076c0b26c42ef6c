#include "m3dp/sensors/renderer.hpp"

#include <embree3/rtcore.h>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <limits>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"

namespace m3dp::sensors {

namespace {

using Clock = std::chrono::steady_clock;
constexpr unsigned kInvalid = RTC_INVALID_GEOMETRY_ID;
constexpr Rgb kSky{0.80f, 0.85f, 0.92f};
constexpr float kAmbient = 0.35f, kDirect = 0.65f;

/// The key light: from above, a little to the side, fixed in the world so every camera agrees.
Vec3d light_direction() { return Vec3d(0.35, 0.25, 1.0).normalized(); }

/// Embree reports errors through this callback (a C library: no exception may cross it); the
/// renderer throws them after the call that failed.
void keep_error(void* user, RTCError code, const char* message) {
  auto& kept = *static_cast<std::string*>(user);
  if (kept.empty()) kept = fmt::format("Embree error {}: {}", static_cast<int>(code), message ? message : "");
}

/// A triangle geometry of `mesh` (copied into Embree's padded buffers), committed.
RTCGeometry triangle_geometry(RTCDevice device, const TriangleMesh& mesh) {
  RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  auto* vertices = static_cast<float*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), mesh.vertices.size()));
  for (std::size_t v = 0; v < mesh.vertices.size(); ++v)
    for (int axis = 0; axis < 3; ++axis) vertices[3 * v + axis] = static_cast<float>(mesh.vertices[v][axis]);
  auto* indices = static_cast<unsigned*>(
      rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(unsigned), mesh.triangles.size()));
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int corner = 0; corner < 3; ++corner) indices[3 * t + corner] = mesh.triangles[t][corner];
  rtcCommitGeometry(geometry);
  return geometry;
}

/// splitmix64: a counter-based generator, so every pixel's noise is its own whatever the threads.
std::uint64_t mix(std::uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
/// A standard normal number for (frame, pixel, channel), by Box–Muller.
double gaussian(std::uint64_t frame, std::uint64_t pixel, std::uint64_t channel) {
  const std::uint64_t a = mix(frame * 0x100000001B3ull ^ mix(pixel * 8 + channel));
  const std::uint64_t b = mix(a);
  const double u1 = (static_cast<double>(a >> 11) + 0.5) * 0x1.0p-53, u2 = static_cast<double>(b >> 11) * 0x1.0p-53;
  return std::sqrt(-2 * std::log(u1)) * std::cos(2 * 3.141592653589793 * u2);
}

/// Linear [0, 1] to an sRGB byte (gamma 2.2), by a table of 4096 steps.
std::uint8_t srgb_byte(float linear) {
  static const auto table = [] {
    std::array<std::uint8_t, 4097> bytes{};
    for (std::size_t i = 0; i < bytes.size(); ++i)
      bytes[i] = static_cast<std::uint8_t>(std::lround(255 * std::pow(static_cast<double>(i) / 4096, 1 / 2.2)));
    return bytes;
  }();
  return table[static_cast<std::size_t>(std::clamp(linear, 0.0f, 1.0f) * 4096 + 0.5f)];
}

}  // namespace

struct Renderer::Impl {
  RTCDevice device = nullptr;
  RTCScene top = nullptr;
  // Static surfaces: one scene, built when first rendered after a change; an instance in the top scene.
  RTCScene static_scene = nullptr;
  unsigned static_instance = kInvalid;
  std::vector<std::uint16_t> static_segments;  // per geometry of static_scene
  bool static_changed = false;
  struct Body {
    RTCScene scene = nullptr;
    unsigned instance = kInvalid;  // none for an empty mesh
    std::uint16_t segment = 0;
    Quat rotation = Quat::Identity();
  };
  std::vector<Body> bodies;
  std::vector<unsigned> body_of_instance;  // top-scene geometry id → body index (or max)
  RTCScene printed_scene = nullptr;
  unsigned printed_instance = kInvalid;
  std::uint16_t printed_segment = 0;
  // Particles: sphere points, each set in a scene of its own, rebuilt when it changes; an instance
  // in the top scene, so that moving a body rebuilds only the top scene's few instances.
  struct ParticleLayer {
    RTCScene scene = nullptr;
    RTCGeometry geometry = nullptr;
    unsigned instance = kInvalid;
    bool changed = false;
    std::uint64_t version = ~0ull;         // the resting set's, as last built
    const float* shared_buffer = nullptr;  // what Embree was last given, and how many particles
    std::size_t shared_count = 0;
    std::vector<float> buffer;  // x, y, z, r per particle, and 4 more floats of padding Embree may read
    std::vector<std::uint16_t> segments;
  };
  ParticleLayer layers[2];  // ParticleSet::moving, ParticleSet::resting
  std::vector<Rgb> palette;
  bool top_changed = true;
  std::string error;  // the first error Embree reported, not yet thrown

  Impl() {
    device = rtcNewDevice(nullptr);
    if (!device) throw Error(fmt::format("Embree: cannot create a device (error {})", static_cast<int>(rtcGetDeviceError(nullptr))));
    rtcSetDeviceErrorFunction(device, keep_error, &error);
    top = rtcNewScene(device);
    rtcSetSceneBuildQuality(top, RTC_BUILD_QUALITY_LOW);  // rebuilt every frame: the fast builder
  }
  ~Impl() {
    for (auto& body : bodies)
      if (body.scene) rtcReleaseScene(body.scene);
    if (static_scene) rtcReleaseScene(static_scene);
    if (printed_scene) rtcReleaseScene(printed_scene);
    for (auto& layer : layers) {
      if (layer.geometry) rtcReleaseGeometry(layer.geometry);
      if (layer.scene) rtcReleaseScene(layer.scene);
    }
    rtcReleaseScene(top);
    rtcReleaseDevice(device);
  }

  /// An instance of `scene` in the top scene with `pose`: its geometry id there.
  unsigned attach_instance(RTCScene scene, const Pose& pose) {
    RTCGeometry instance = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(instance, scene);
    set_transform(instance, pose);
    const unsigned id = rtcAttachGeometry(top, instance);
    rtcReleaseGeometry(instance);
    top_changed = true;
    return id;
  }
  void set_transform(RTCGeometry instance, const Pose& pose) {
    const Mat3 rotation = pose.orientation.toRotationMatrix();
    float transform[12];
    for (int column = 0; column < 3; ++column)
      for (int row = 0; row < 3; ++row) transform[3 * column + row] = static_cast<float>(rotation(row, column));
    for (int row = 0; row < 3; ++row) transform[9 + row] = static_cast<float>(pose.position[row]);
    rtcSetGeometryTransform(instance, 0, RTC_FORMAT_FLOAT3X4_COLUMN_MAJOR, transform);
    rtcCommitGeometry(instance);
  }
  void throw_if_failed() {
    if (error.empty()) return;
    const std::string message = std::move(error);
    error.clear();
    throw Error(message);
  }
  void note_instance(unsigned id, unsigned body) {
    if (body_of_instance.size() <= id) body_of_instance.resize(id + 1, std::numeric_limits<unsigned>::max());
    body_of_instance[id] = body;
  }
};

Renderer::Renderer() : impl_(std::make_unique<Impl>()) {}
Renderer::~Renderer() = default;

void Renderer::add_static(const TriangleMesh& mesh, std::uint16_t segment) {
  if (mesh.triangles.empty()) return;
  Impl& impl = *impl_;
  if (!impl.static_scene) {
    impl.static_scene = rtcNewScene(impl.device);
    rtcSetSceneBuildQuality(impl.static_scene, RTC_BUILD_QUALITY_HIGH);  // built once
  }
  RTCGeometry geometry = triangle_geometry(impl.device, mesh);
  const unsigned id = rtcAttachGeometry(impl.static_scene, geometry);
  rtcReleaseGeometry(geometry);
  if (impl.static_segments.size() <= id) impl.static_segments.resize(id + 1, kBackground);
  impl.static_segments[id] = segment;
  impl.static_changed = true;
}

std::size_t Renderer::add_body(const TriangleMesh& mesh, std::uint16_t segment) {
  Impl& impl = *impl_;
  Impl::Body body;
  body.segment = segment;
  if (!mesh.triangles.empty()) {
    body.scene = rtcNewScene(impl.device);
    rtcSetSceneBuildQuality(body.scene, RTC_BUILD_QUALITY_HIGH);
    RTCGeometry geometry = triangle_geometry(impl.device, mesh);
    rtcAttachGeometry(body.scene, geometry);
    rtcReleaseGeometry(geometry);
    rtcCommitScene(body.scene);
    body.instance = impl.attach_instance(body.scene, Pose{});
    impl.note_instance(body.instance, static_cast<unsigned>(impl.bodies.size()));
  }
  impl.bodies.push_back(body);
  return impl.bodies.size() - 1;
}

void Renderer::set_body_pose(std::size_t index, const Pose& pose) {
  Impl& impl = *impl_;
  Impl::Body& body = impl.bodies.at(index);
  body.rotation = pose.orientation;
  if (body.instance == kInvalid) return;
  impl.set_transform(rtcGetGeometry(impl.top, body.instance), pose);
  impl.top_changed = true;
}

void Renderer::set_particles(std::span<const Vec3> positions, Real radius, std::span<const std::uint16_t> segments, ParticleSet set,
                             std::uint64_t version) {
  Impl& impl = *impl_;
  Impl::ParticleLayer& layer = impl.layers[static_cast<int>(set)];
  if (set == ParticleSet::resting && version == layer.version) return;  // as built
  layer.version = version;
  const std::size_t count = positions.size();
  layer.buffer.resize(4 * count + 4);
  layer.segments.assign(segments.begin(), segments.end());
  parallel_for_each_index(count, [&](std::size_t i) {
    float* point = layer.buffer.data() + 4 * i;
    point[0] = static_cast<float>(positions[i].x());
    point[1] = static_cast<float>(positions[i].y());
    point[2] = static_cast<float>(positions[i].z());
    point[3] = static_cast<float>(radius);
  }, 4096);
  if (!layer.scene) {
    layer.scene = rtcNewScene(impl.device);
    rtcSetSceneBuildQuality(layer.scene, RTC_BUILD_QUALITY_LOW);  // rebuilt whenever they move: the fast builder
    rtcSetSceneFlags(layer.scene, RTC_SCENE_FLAG_DYNAMIC);        // and its memory kept from build to build
    layer.geometry = rtcNewGeometry(impl.device, RTC_GEOMETRY_TYPE_SPHERE_POINT);
    rtcAttachGeometry(layer.scene, layer.geometry);
    layer.instance = impl.attach_instance(layer.scene, Pose{});
  }
  layer.changed = true;
  // No particles: an empty buffer (Embree accepts a geometry of no primitives).
  if (layer.buffer.data() == layer.shared_buffer && count == layer.shared_count) {
    rtcUpdateGeometryBuffer(layer.geometry, RTC_BUFFER_TYPE_VERTEX, 0);
  } else {
    rtcSetSharedGeometryBuffer(layer.geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, layer.buffer.data(), 0, 4 * sizeof(float),
                               count);
    layer.shared_buffer = layer.buffer.data();
    layer.shared_count = count;
  }
  impl.top_changed = true;
  rtcCommitGeometry(layer.geometry);
  impl.throw_if_failed();
}

void Renderer::set_printed_mesh(const TriangleMesh& mesh, std::uint16_t segment) {
  Impl& impl = *impl_;
  if (impl.printed_instance != kInvalid) {
    rtcDetachGeometry(impl.top, impl.printed_instance);
    impl.note_instance(impl.printed_instance, std::numeric_limits<unsigned>::max());
    impl.printed_instance = kInvalid;
    rtcReleaseScene(impl.printed_scene);
    impl.printed_scene = nullptr;
    impl.top_changed = true;
  }
  impl.printed_segment = segment;
  if (mesh.triangles.empty()) return;
  impl.printed_scene = rtcNewScene(impl.device);
  RTCGeometry geometry = triangle_geometry(impl.device, mesh);
  rtcAttachGeometry(impl.printed_scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(impl.printed_scene);
  impl.printed_instance = impl.attach_instance(impl.printed_scene, Pose{});
}

void Renderer::set_palette(std::vector<Rgb> colors) { impl_->palette = std::move(colors); }

void Renderer::render(const CameraSettings& settings, const Pose& camera_pose, std::uint64_t frame, CameraImage& image) {
  Impl& impl = *impl_;
  // The noise's numbers by frame, pixel and channel; another seed, other numbers (seed 0: the frame's own).
  const std::uint64_t noise_frame = frame + settings.noise.seed * 0x9E3779B97F4A7C15ull;
  const auto build_start = Clock::now();
  if (impl.static_changed) {
    rtcCommitScene(impl.static_scene);
    if (impl.static_instance == kInvalid) impl.static_instance = impl.attach_instance(impl.static_scene, Pose{});
    else impl.top_changed = true;
    impl.static_changed = false;
  }
  stats_.particle_build_ms = 0;
  for (auto& layer : impl.layers) {
    if (!layer.changed) continue;
    const auto particles_start = Clock::now();
    rtcCommitScene(layer.scene);
    stats_.particle_build_ms += std::chrono::duration<double, std::milli>(Clock::now() - particles_start).count();
    layer.changed = false;
    // The instance sees its scene's new bounds only when committed again.
    rtcCommitGeometry(rtcGetGeometry(impl.top, layer.instance));
  }
  if (impl.top_changed) {
    rtcCommitScene(impl.top);
    impl.top_changed = false;
  }
  impl.throw_if_failed();
  const auto trace_start = Clock::now();

  const Intrinsics intrinsics = Intrinsics::of(settings);
  const int width = settings.width, height = settings.height;
  image.width = width;
  image.height = height;
  const bool color = has_color(settings.type), depth = has_depth(settings.type);
  image.rgb.assign(color ? std::size_t(3) * width * height : 0, 0);
  image.depth.assign(depth ? std::size_t(width) * height : 0, std::numeric_limits<float>::infinity());
  image.segment.assign(std::size_t(width) * height, kBackground);

  const Pose optical = optical_pose(camera_pose);
  const Eigen::Matrix3d rotation = optical.orientation.cast<double>().toRotationMatrix();
  const Vec3d origin = optical.position.cast<double>();
  const Vec3d light = light_direction();
  std::atomic<std::uint64_t> shadow_rays{0};

  // Rows in parallel; each row in packets of 8 neighbouring rays (Embree traces coherent packets
  // faster than single rays), then their shadow rays as a packet.
  const float origin_x = static_cast<float>(origin.x()), origin_y = static_cast<float>(origin.y()), origin_z = static_cast<float>(origin.z());
  parallel_for_each_index(static_cast<std::size_t>(height), [&](std::size_t row) {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
    std::uint64_t shadows_cast = 0;
    alignas(32) int valid[8];
    alignas(32) int shadow_valid[8];
    alignas(32) RTCRayHit8 hits;
    alignas(32) RTCRay8 shadows;
    Vec3d directions[8], normals[8];
    for (int first = 0; first < width; first += 8) {
      const int lanes = std::min(8, width - first);
      for (int k = 0; k < 8; ++k) {
        valid[k] = k < lanes ? -1 : 0;
        // Through the pixel's centre; z = 1 in the optical frame, so t is the depth along the axis.
        directions[k] = rotation * ray_through(intrinsics, first + k + 0.5, static_cast<double>(row) + 0.5);
        hits.ray.org_x[k] = origin_x;
        hits.ray.org_y[k] = origin_y;
        hits.ray.org_z[k] = origin_z;
        hits.ray.dir_x[k] = static_cast<float>(directions[k].x());
        hits.ray.dir_y[k] = static_cast<float>(directions[k].y());
        hits.ray.dir_z[k] = static_cast<float>(directions[k].z());
        hits.ray.tnear[k] = static_cast<float>(settings.near);
        hits.ray.tfar[k] = static_cast<float>(settings.far);
        hits.ray.time[k] = 0;
        hits.ray.mask[k] = 0xFFFFFFFF;
        hits.ray.id[k] = static_cast<unsigned>(k);
        hits.ray.flags[k] = 0;
        hits.hit.geomID[k] = kInvalid;
        hits.hit.instID[0][k] = kInvalid;
      }
      rtcIntersect8(valid, impl.top, &context, &hits);

      std::uint16_t segments[8];
      for (int k = 0; k < lanes; ++k) {
        shadow_valid[k] = 0;
        segments[k] = kBackground;
        if (hits.hit.geomID[k] == kInvalid) continue;
        // What it hit, and the surface's normal in the world.
        Vec3d normal(hits.hit.Ng_x[k], hits.hit.Ng_y[k], hits.hit.Ng_z[k]);
        const unsigned instance = hits.hit.instID[0][k];
        const unsigned primitive = hits.hit.primID[k];
        if (instance == impl.layers[0].instance || instance == impl.layers[1].instance) {
          const auto& layer = impl.layers[instance == impl.layers[0].instance ? 0 : 1];
          segments[k] = primitive < layer.segments.size() ? layer.segments[primitive] : kBackground;
        } else if (instance == impl.static_instance) {
          segments[k] = impl.static_segments[hits.hit.geomID[k]];
        } else if (instance == impl.printed_instance) {
          segments[k] = impl.printed_segment;
        } else if (instance < impl.body_of_instance.size() && impl.body_of_instance[instance] < impl.bodies.size()) {
          const auto& body = impl.bodies[impl.body_of_instance[instance]];
          segments[k] = body.segment;
          normal = body.rotation.cast<double>() * normal;
        }
        normal.normalize();
        if (normal.dot(directions[k]) > 0) normal = -normal;
        normals[k] = normal;
        if (color && settings.shadows && normal.dot(light) > 0) {
          // A shadow ray toward the key light, from just off the surface.
          const float t = hits.ray.tfar[k];
          const Vec3d start = origin + double(t) * directions[k] + (1e-5 + 1e-4 * double(t)) * normal;
          shadow_valid[k] = -1;
          shadows.org_x[k] = static_cast<float>(start.x());
          shadows.org_y[k] = static_cast<float>(start.y());
          shadows.org_z[k] = static_cast<float>(start.z());
          shadows.dir_x[k] = static_cast<float>(light.x());
          shadows.dir_y[k] = static_cast<float>(light.y());
          shadows.dir_z[k] = static_cast<float>(light.z());
          shadows.tnear[k] = 0;
          shadows.tfar[k] = std::numeric_limits<float>::infinity();
          shadows.time[k] = 0;
          shadows.mask[k] = 0xFFFFFFFF;
          shadows.id[k] = static_cast<unsigned>(k);
          shadows.flags[k] = 0;
          ++shadows_cast;
        }
      }
      for (int k = lanes; k < 8; ++k) shadow_valid[k] = 0;
      if (std::any_of(shadow_valid, shadow_valid + 8, [](int lane) { return lane != 0; })) {
        RTCIntersectContext incoherent;
        rtcInitIntersectContext(&incoherent);
        rtcOccluded8(shadow_valid, impl.top, &incoherent, &shadows);
      }

      for (int k = 0; k < lanes; ++k) {
        const std::size_t pixel = row * static_cast<std::size_t>(width) + static_cast<std::size_t>(first + k);
        const bool hit = hits.hit.geomID[k] != kInvalid;
        image.segment[pixel] = segments[k];
        if (depth && hit) image.depth[pixel] = hits.ray.tfar[k];
        // SDF's Gaussian noise: on each colour channel (0 to 1) and on the depth (m).
        if (depth && hit && settings.noise.enabled())
          image.depth[pixel] += static_cast<float>(settings.noise.mean + settings.noise.stddev * gaussian(noise_frame, pixel, 3));
        if (!color) continue;
        Rgb shade = kSky;
        if (hit) {
          double lit = std::max(0.0, normals[k].dot(light));
          if (shadow_valid[k] != 0 && shadows.tfar[k] < 0) lit = 0;  // Embree marks an occluded ray with tfar = -inf
          const Rgb albedo = segments[k] < impl.palette.size() ? impl.palette[segments[k]] : Rgb{};
          const float light_amount = kAmbient + kDirect * static_cast<float>(lit);
          shade = {albedo.r * light_amount, albedo.g * light_amount, albedo.b * light_amount};
        }
        float channels[3] = {shade.r, shade.g, shade.b};
        for (int c = 0; c < 3; ++c) {
          if (settings.noise.enabled()) channels[c] += static_cast<float>(settings.noise.mean + settings.noise.stddev * gaussian(noise_frame, pixel, c));
          image.rgb[3 * pixel + c] = srgb_byte(channels[c]);
        }
      }
    }
    shadow_rays += shadows_cast;
  }, 1);

  const auto end = Clock::now();
  stats_.build_ms = std::chrono::duration<double, std::milli>(trace_start - build_start).count();
  stats_.trace_ms = std::chrono::duration<double, std::milli>(end - trace_start).count();
  stats_.rays = static_cast<std::uint64_t>(width) * static_cast<std::uint64_t>(height) + shadow_rays.load();
}

void point_cloud(const CameraImage& image, const Intrinsics& intrinsics, std::vector<CloudPoint>& points, const Pose& to_frame) {
  points.clear();
  if (image.depth.empty()) return;
  const Eigen::Matrix3d rotation = to_frame.orientation.cast<double>().toRotationMatrix();
  const Vec3d translation = to_frame.position.cast<double>();
  for (int row = 0; row < image.height; ++row)
    for (int column = 0; column < image.width; ++column) {
      const std::size_t pixel = static_cast<std::size_t>(row) * static_cast<std::size_t>(image.width) + static_cast<std::size_t>(column);
      const float depth = image.depth[pixel];
      if (!std::isfinite(depth)) continue;
      const Vec3d at = rotation * (double(depth) * ray_through(intrinsics, column + 0.5, row + 0.5)) + translation;
      CloudPoint point{static_cast<float>(at.x()), static_cast<float>(at.y()), static_cast<float>(at.z()), 200, 200, 200, 255,
                       image.segment[pixel], 0};
      if (!image.rgb.empty()) {
        point.r = image.rgb[3 * pixel];
        point.g = image.rgb[3 * pixel + 1];
        point.b = image.rgb[3 * pixel + 2];
      }
      points.push_back(point);
    }
}

}  // namespace m3dp::sensors
