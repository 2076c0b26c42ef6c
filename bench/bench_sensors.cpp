// Google Benchmark: a 640×480 RGB-D frame (colour with shadows, depth, segmentation) of N particles
// in a heap in front of the UR10 of the demo, its links where the demo starts them, over the
// demo's floor: the goal is <= 20 ms at 10⁵ particles and <= 100 ms at 10⁶ on 2 cores.
//   BM_RenderMovedParticles: every particle moved since the last frame (their whole BVH rebuilt): a dam break;
//   BM_RenderPrint:          a print: 95 % of the particles rest (their BVH kept), the fresh 5 % and the
//                            arm moved (the moving particles' BVH and the top scene rebuilt).
// Counters: rays per second, and the BVH build times of the frame.
#include <benchmark/benchmark.h>

#include <cmath>
#include <memory>

#include "m3dp/scene/scene.hpp"
#include "m3dp/sensors/renderer.hpp"
#include "m3dp/sim/camera_rig.hpp"
#include "m3dp/sim/simulation.hpp"

using namespace m3dp;

namespace {

/// A heap of `count` particles of radius r on a lattice in a cone under the nozzle's reach.
std::vector<Vec3> heap(std::size_t count, Real radius) {
  std::vector<Vec3> positions;
  const Real spacing = 2 * radius;
  const Real height = Real(0.12);
  for (int layer = 0; positions.size() < count; ++layer) {
    const Real z = radius + spacing * Real(layer);
    const Real reach = Real(0.2) * (1 - z / height) + 8 * spacing;
    for (Real x = -reach; x <= reach && positions.size() < count; x += spacing)
      for (Real y = -reach; y <= reach && positions.size() < count; y += spacing)
        if (x * x + y * y <= reach * reach) positions.emplace_back(Real(0.7) + x, y, z);
  }
  return positions;
}

struct BenchScene {
  sensors::Renderer renderer;
  std::vector<std::size_t> links;
  std::vector<Pose> link_poses;
  sensors::CameraSettings camera;
  Pose camera_pose;
  std::vector<Vec3> positions;
  std::vector<std::uint16_t> segments;
  Real radius = 0;
};

/// The demo's robot and floor (from scenes/ur10_wall.sdf's world view) and a heap of particles.
std::unique_ptr<BenchScene> make_scene(std::size_t particles) {
  auto made = std::make_unique<BenchScene>();
  BenchScene& scene = *made;
  const scene::Scene demo = scene::load_scene(std::filesystem::path(M3DP_SCENES) / "ur10_wall.sdf");
  sim::Simulation simulation(demo);
  const sim::WorldLayout layout = sim::world_layout(simulation);
  const sim::WorldPoses poses = sim::world_poses(simulation, layout);
  scene.renderer.set_palette({{}, {0.4f, 0.4f, 0.42f}, {0.3f, 0.45f, 0.7f}, {0.62f, 0.6f, 0.56f}});
  for (std::size_t b = 0; b < layout.bodies.size(); ++b) {
    if (!layout.bodies[b].link) {
      TriangleMesh mesh = layout.bodies[b].triangles;
      for (Vec3& vertex : mesh.vertices) vertex = layout.bodies[b].fixed_pose.apply(vertex);
      scene.renderer.add_static(mesh, 1);
      continue;
    }
    scene.links.push_back(scene.renderer.add_body(layout.bodies[b].triangles, 2));
    scene.link_poses.push_back(poses.bodies[b]);
    scene.renderer.set_body_pose(scene.links.back(), poses.bodies[b]);
  }
  // Particles the size that fits `particles` in the heap's cone.
  scene.radius = Real(0.0015) * std::cbrt(Real(100000) / Real(particles));
  scene.positions = heap(particles, scene.radius);
  scene.segments.assign(scene.positions.size(), 3);
  scene.camera.type = sensors::CameraType::rgbd_camera;
  scene.camera.width = 640;
  scene.camera.height = 480;
  scene.camera.horizontal_fov = 1.0;
  scene.camera.near = 0.05;
  scene.camera.far = 10;
  scene.camera.shadows = true;
  scene.camera_pose.position = Vec3(1.9f, -1.3f, 1.1f);
  scene.camera_pose.orientation = Quat(Eigen::AngleAxis<Real>(Real(2.3751), Vec3::UnitZ()) * Eigen::AngleAxis<Real>(Real(0.3807), Vec3::UnitY()));
  return made;
}

void report(benchmark::State& state, const sensors::Renderer& renderer, double build_ms, double particle_build_ms, double rays) {
  const double iterations = static_cast<double>(state.iterations());
  state.counters["rays_per_s"] = benchmark::Counter(rays, benchmark::Counter::kIsRate);
  state.counters["build_ms"] = build_ms / iterations;
  state.counters["particle_bvh_ms"] = particle_build_ms / iterations;
  state.counters["trace_ms"] = renderer.last_stats().trace_ms;
}

void BM_RenderMovedParticles(benchmark::State& state) {
  const auto made = make_scene(static_cast<std::size_t>(state.range(0)));
  BenchScene& scene = *made;
  sensors::CameraImage image;
  double build_ms = 0, particle_build_ms = 0, rays = 0;
  std::uint64_t frame = 0;
  for (auto _ : state) {
    // As after a step: every particle moved a little.
    const Real shift = Real(1e-5) * Real(frame % 2 ? 1 : -1);
    for (Vec3& position : scene.positions) position.z() += shift;
    scene.renderer.set_particles(scene.positions, scene.radius, scene.segments);
    scene.renderer.render(scene.camera, scene.camera_pose, frame++, image);
    build_ms += scene.renderer.last_stats().build_ms;
    particle_build_ms += scene.renderer.last_stats().particle_build_ms;
    rays += static_cast<double>(scene.renderer.last_stats().rays);
  }
  report(state, scene.renderer, build_ms, particle_build_ms, rays);
  state.counters["particles"] = static_cast<double>(scene.positions.size());
}
BENCHMARK(BM_RenderMovedParticles)->Arg(100000)->Arg(1000000)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_RenderPrint(benchmark::State& state) {
  // A print: the material laid down rests (95 %, its BVH kept), the fresh bead moves (5 %, rebuilt
  // every frame), and the arm moves (its instances in the top scene).
  const auto made = make_scene(static_cast<std::size_t>(state.range(0)));
  BenchScene& scene = *made;
  const std::size_t settled = scene.positions.size() * 95 / 100;
  using Set = sensors::Renderer::ParticleSet;
  scene.renderer.set_particles(std::span<const Vec3>(scene.positions).first(settled), scene.radius,
                               std::span<const std::uint16_t>(scene.segments).first(settled), Set::resting, 1);
  std::vector<Vec3> moving(scene.positions.begin() + static_cast<std::ptrdiff_t>(settled), scene.positions.end());
  const std::vector<std::uint16_t> moving_segments(moving.size(), 3);
  sensors::CameraImage image;
  scene.renderer.render(scene.camera, scene.camera_pose, 0, image);  // the resting BVH built once, before timing
  double build_ms = 0, particle_build_ms = 0, rays = 0;
  std::uint64_t frame = 1;
  for (auto _ : state) {
    const Real shift = Real(1e-5) * Real(frame % 2 ? 1 : -1);
    for (Vec3& position : moving) position.z() += shift;
    scene.renderer.set_particles(std::span<const Vec3>(scene.positions).first(settled), scene.radius,
                                 std::span<const std::uint16_t>(scene.segments).first(settled), Set::resting, 1);  // unchanged: kept
    scene.renderer.set_particles(moving, scene.radius, moving_segments, Set::moving);
    const Pose turn{Vec3::Zero(), Quat(Eigen::AngleAxis<Real>(Real(frame % 2 ? 0.01 : -0.01), Vec3::UnitZ()))};
    for (std::size_t l = 0; l < scene.links.size(); ++l) scene.renderer.set_body_pose(scene.links[l], turn * scene.link_poses[l]);
    scene.renderer.render(scene.camera, scene.camera_pose, frame++, image);
    build_ms += scene.renderer.last_stats().build_ms;
    particle_build_ms += scene.renderer.last_stats().particle_build_ms;
    rays += static_cast<double>(scene.renderer.last_stats().rays);
  }
  report(state, scene.renderer, build_ms, particle_build_ms, rays);
  state.counters["particles"] = static_cast<double>(scene.positions.size());
}
BENCHMARK(BM_RenderPrint)->Arg(100000)->Arg(1000000)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
