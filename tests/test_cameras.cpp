// Cameras' geometry against the pinhole model: projections land where they should, depth is the
// distance along the optical axis, flat things look flat, and the same scene gives the same image
// whatever the thread count.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <map>

#include "m3dp/core/parallel.hpp"
#include "m3dp/core/tessellation.hpp"
#include "m3dp/sensors/renderer.hpp"

namespace {

using namespace m3dp;
using namespace m3dp::sensors;

/// A camera at the origin looking along +x (its frame is the world's), `width` × `height`, 90° wide.
CameraSettings camera(int width, int height, CameraType type = CameraType::rgbd_camera) {
  CameraSettings settings;
  settings.name = "test";
  settings.type = type;
  settings.width = width;
  settings.height = height;
  settings.horizontal_fov = std::acos(-1.0) / 2;
  settings.near = 0.01;
  settings.far = 20;
  settings.shadows = false;
  return settings;
}

/// The optical-frame coordinates of a world point for a camera whose frame is the world's.
Vec3d optical(const Vec3d& world) { return Vec3d(-world.y(), -world.z(), world.x()); }

TEST(Cameras, IntrinsicsFollowTheFieldOfView) {
  const Intrinsics intrinsics = Intrinsics::of(camera(640, 480));
  EXPECT_DOUBLE_EQ(intrinsics.fx, 320);  // tan(45°) = 1
  EXPECT_DOUBLE_EQ(intrinsics.fy, 320);
  EXPECT_DOUBLE_EQ(intrinsics.cx, 320);
  EXPECT_DOUBLE_EQ(intrinsics.cy, 240);
  EXPECT_NEAR(intrinsics.vertical_fov(), 2 * std::atan(0.75), 1e-12);
  // The optical frame: z forward (camera +x), x right (camera −y), y down (camera −z).
  EXPECT_TRUE((optical_to_camera() * Vec3(0, 0, 1)).isApprox(Vec3(1, 0, 0)));
  EXPECT_TRUE((optical_to_camera() * Vec3(1, 0, 0)).isApprox(Vec3(0, -1, 0)));
  EXPECT_TRUE((optical_to_camera() * Vec3(0, 1, 0)).isApprox(Vec3(0, 0, -1)));
  const auto pixel = project(intrinsics, Vec3d(0.1, -0.05, 1));
  ASSERT_TRUE(pixel);
  EXPECT_DOUBLE_EQ(pixel->x(), 352);
  EXPECT_DOUBLE_EQ(pixel->y(), 224);
  EXPECT_FALSE(project(intrinsics, Vec3d(0, 0, -1)));
}

TEST(Cameras, SpheresLandOnTheirProjections) {
  const CameraSettings settings = camera(640, 480);
  const Intrinsics intrinsics = Intrinsics::of(settings);
  const std::vector<Vec3> centres = {Vec3(2, 0, 0), Vec3(2, 0.6, 0.3), Vec3(3, -1.1, -0.8), Vec3(1.5, 0.9, -0.5)};
  std::vector<std::uint16_t> segments;
  for (std::size_t s = 0; s < centres.size(); ++s) segments.push_back(static_cast<std::uint16_t>(s + 1));
  Renderer renderer;
  renderer.set_particles(centres, Real(0.05), segments);
  CameraImage image;
  renderer.render(settings, Pose{}, 0, image);
  ASSERT_EQ(image.width, 640);
  ASSERT_EQ(image.height, 480);
  for (std::size_t s = 0; s < centres.size(); ++s) {
    double sum_u = 0, sum_v = 0, count = 0;
    for (int row = 0; row < image.height; ++row)
      for (int column = 0; column < image.width; ++column)
        if (image.segment[std::size_t(row) * 640 + std::size_t(column)] == segments[s]) {
          sum_u += column + 0.5;
          sum_v += row + 0.5;
          ++count;
        }
    ASSERT_GT(count, 20) << "sphere " << s << " covers too few pixels";
    const auto expected = project(intrinsics, optical(centres[s].cast<double>()));
    ASSERT_TRUE(expected);
    EXPECT_NEAR(sum_u / count, expected->x(), 0.5) << "sphere " << s;
    EXPECT_NEAR(sum_v / count, expected->y(), 0.5) << "sphere " << s;
  }
}

TEST(Cameras, DepthOfASphereIsAlongTheAxis) {
  // An odd image: the centre pixel's ray is the optical axis.
  const CameraSettings settings = camera(321, 241, CameraType::depth_camera);
  const Real radius = 0.1f;
  const double distance = 1.25;
  Renderer renderer;
  const std::vector<Vec3> centre{Vec3(Real(distance), 0, 0)};
  const std::vector<std::uint16_t> segment{1};
  renderer.set_particles(centre, radius, segment);
  CameraImage image;
  renderer.render(settings, Pose{}, 0, image);
  EXPECT_TRUE(image.rgb.empty());
  const float at_centre = image.depth[120 * 321 + 160];
  EXPECT_NEAR(at_centre, distance - radius, 0.5e-3);
  // Off the axis, depth is z along the axis, not the distance along the ray: a pixel 8 columns
  // right sees the sphere at the depth where its ray enters it.
  const Vec3d ray = ray_through(Intrinsics::of(settings), 168.5, 120.5).normalized();
  const double along = ray.z() * distance;  // the closest approach of the ray to the centre
  const double entry = along - std::sqrt(radius * radius - (distance * distance - along * along));
  EXPECT_NEAR(image.depth[120 * 321 + 168], entry * ray.z(), 0.5e-3);
  EXPECT_TRUE(std::isinf(image.depth[0])) << "a corner that sees nothing has no depth";
  EXPECT_EQ(image.segment[0], Renderer::kBackground);
}

TEST(Cameras, AFlatPlateGivesAFlatDepthImage) {
  const CameraSettings settings = camera(160, 120, CameraType::depth_camera);
  Renderer renderer;
  // A plate 2 cm thick whose face is 0.75 m in front, far wider than the view, turned square to it.
  Pose plate;
  plate.position = Vec3(0.76f, 0, 0);
  TriangleMesh mesh;
  append_transformed(tessellate(BoxShape{Vec3(0.02f, 10, 10)}), plate, mesh);
  renderer.add_static(mesh, 7);
  CameraImage image;
  renderer.render(settings, Pose{}, 0, image);
  for (std::size_t pixel = 0; pixel < image.depth.size(); ++pixel) {
    ASSERT_NEAR(image.depth[pixel], 0.75, 1e-5) << "pixel " << pixel;
    ASSERT_EQ(image.segment[pixel], 7);
  }
}

TEST(Cameras, BodiesMoveWithTheirPoses) {
  const CameraSettings settings = camera(101, 101, CameraType::rgbd_camera);
  Renderer renderer;
  renderer.set_palette({Rgb{}, Rgb{1, 0, 0}});
  const std::size_t box = renderer.add_body(tessellate(BoxShape{Vec3(0.2f, 0.2f, 0.2f)}), 1);
  CameraImage image;
  for (const double x : {1.0, 2.0}) {
    Pose pose;
    pose.position = Vec3(Real(x), 0, 0);
    pose.orientation = Quat(Eigen::AngleAxis<Real>(Real(0.3), Vec3::UnitY()) * Eigen::AngleAxis<Real>(Real(0.5), Vec3::UnitZ()));
    renderer.set_body_pose(box, pose);
    renderer.render(settings, Pose{}, 0, image);
    const std::size_t centre = 50 * 101 + 50;
    EXPECT_EQ(image.segment[centre], 1);
    // The turned cube's nearest face is within its half-diagonal of the centre.
    EXPECT_GT(image.depth[centre], x - 0.18);
    EXPECT_LT(image.depth[centre], x - 0.1 + 1e-6);
    EXPECT_GT(image.rgb[3 * centre], image.rgb[3 * centre + 1]) << "the box is drawn red";
  }
}

TEST(Cameras, ANoisesSeedPicksItsNumbers) {
  // The same seed, the same noise (a run is repeatable); another seed, another noise (a study's repeats).
  auto render_with = [](std::uint64_t seed) {
    CameraSettings settings = camera(40, 30);
    settings.noise = {0.0, 0.02, seed};
    Renderer renderer;
    renderer.set_palette({Rgb{}, Rgb{0.5f, 0.5f, 0.5f}});
    TriangleMesh floor_mesh;
    Pose floor;
    floor.position = Vec3(0, 0, -0.3f);
    append_transformed(tessellate(PlaneShape{Vec3::UnitZ(), 10, 10}), floor, floor_mesh);
    renderer.add_static(floor_mesh, 1);
    Pose camera_pose;
    camera_pose.orientation = Quat(Eigen::AngleAxis<Real>(Real(0.6), Vec3::UnitY()));
    CameraImage image;
    renderer.render(settings, camera_pose, 7, image);
    return image;
  };
  const CameraImage first = render_with(0), again = render_with(0), other = render_with(1);
  EXPECT_EQ(first.rgb, again.rgb);
  EXPECT_NE(first.rgb, other.rgb);
  EXPECT_EQ(first.segment, other.segment);  // the noise is on colour and depth only
  std::size_t differing = 0;
  for (std::size_t k = 0; k < first.depth.size(); ++k) differing += first.depth[k] != other.depth[k];
  EXPECT_GT(differing, first.depth.size() / 2);
}

TEST(Cameras, TheSameImageOnOneAndTwoThreads) {
  CameraSettings settings = camera(200, 150);
  settings.shadows = true;
  settings.noise = {0.0, 0.02};
  // Many particles in a heap over a floor, and a tilted body: what a printing camera sees.
  std::vector<Vec3> positions;
  std::vector<std::uint16_t> segments;
  for (int i = 0; i < 20000; ++i) {
    const double a = 0.618033988749895 * i, r = 0.2 * std::sqrt(i / 20000.0);
    positions.emplace_back(Real(1.5 + r * std::cos(a * 6.283)), Real(r * std::sin(a * 6.283)), Real(-0.3 + 0.1 * (1 - r / 0.2) + 0.003 * (i % 7)));
    segments.push_back(static_cast<std::uint16_t>(2 + i % 3));
  }
  auto render_with = [&](int threads) {
    ThreadLimit limit(threads);
    Renderer renderer;
    renderer.set_palette({Rgb{}, Rgb{0.5f, 0.5f, 0.5f}, Rgb{0.8f, 0.6f, 0.4f}, Rgb{0.7f, 0.5f, 0.3f}, Rgb{0.6f, 0.4f, 0.2f}, Rgb{0.2f, 0.3f, 0.8f}});
    Pose floor;
    floor.position = Vec3(0, 0, -0.31f);
    TriangleMesh floor_mesh;
    append_transformed(tessellate(PlaneShape{Vec3::UnitZ(), 10, 10}), floor, floor_mesh);
    renderer.add_static(floor_mesh, 1);
    renderer.set_particles(positions, Real(0.004), segments);
    Pose tilted;
    tilted.position = Vec3(1.2f, 0.3f, 0.0f);
    tilted.orientation = Quat(Eigen::AngleAxis<Real>(Real(0.7), Vec3(1, 1, 0).normalized()));
    renderer.set_body_pose(renderer.add_body(tessellate(CylinderShape{0.05f, 0.4f}), 5), tilted);
    Pose camera_pose;
    camera_pose.position = Vec3(0.6f, 0, 0.4f);
    camera_pose.orientation = Quat(Eigen::AngleAxis<Real>(Real(0.5), Vec3::UnitY()));
    CameraImage image;
    renderer.render(settings, camera_pose, 42, image);
    return image;
  };
  const CameraImage one = render_with(1), two = render_with(2);
  EXPECT_EQ(one.rgb, two.rgb);
  EXPECT_EQ(one.segment, two.segment);
  ASSERT_EQ(one.depth.size(), two.depth.size());
  EXPECT_EQ(0, std::memcmp(one.depth.data(), two.depth.data(), one.depth.size() * sizeof(float)));
  std::map<std::uint16_t, int> seen;
  for (const auto segment : one.segment) ++seen[segment];
  EXPECT_GT(seen[2] + seen[3] + seen[4], 300) << "the heap is in view";
  EXPECT_GT(seen[5], 100) << "the body is in view";
  EXPECT_GT(seen[1], 1000) << "the floor is in view";
}

TEST(Cameras, PointCloudIsTheDepthImageBackProjected) {
  const CameraSettings settings = camera(64, 48, CameraType::rgbd_camera);
  Renderer renderer;
  Pose plate;
  plate.position = Vec3(2.01f, 0, 0);
  TriangleMesh mesh;
  append_transformed(tessellate(BoxShape{Vec3(0.02f, 1, 1)}), plate, mesh);
  renderer.add_static(mesh, 3);
  CameraImage image;
  renderer.render(settings, Pose{}, 0, image);
  std::vector<CloudPoint> points;
  point_cloud(image, Intrinsics::of(settings), points);
  ASSERT_GT(points.size(), 100u);
  for (const auto& point : points) {
    EXPECT_NEAR(point.z, 2.0, 1e-5);  // on the plate's face, in the optical frame
    EXPECT_LE(std::abs(point.x), 0.5 + 1e-5);
    EXPECT_LE(std::abs(point.y), 0.5 + 1e-5);
    EXPECT_EQ(point.segment, 3);
  }
}

}  // namespace
