// Printed material keeps its volume (issue 21): every preset material printed as a straight bead and
// as a ring, then left to come to rest, must hold its rest density inside and its particles evenly
// spaced. Liquids (water, honey, silicone) are printed into a tray so they pool rather than spread
// into a film one particle thick. Each case prints what it measured next to the bound.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/sph/measure.hpp"
#include "m3dp/sph/neighbors/neighbor_search.hpp"
#include "m3dp/surface/mesh_tools.hpp"
#include "m3dp/surface/surface.hpp"

namespace {

using m3dp::Real;
using m3dp::Vec3;

struct Case {
  const char* material;
  bool liquid;  // printed into a tray
  bool ring;    // a ring of radius 12 mm, else a straight bead 48 mm long
};

constexpr double kDiameter = 0.01;    // m, nozzle
constexpr double kRadius = 0.0005;  // m, particle radius: ten particles across the nozzle
constexpr double kSpeed = 0.05;       // m/s, nozzle and exit speed

std::string scene_text(const Case& c) {
  // A 5 mm plate 70 mm wide; the tray adds walls 20 mm high around a 36 × 36 mm floor (the ring) or a
  // 54 × 12 mm one (the bead), so the liquid pools 4.5 to 6 mm deep.
  const double inner_x = c.ring ? 0.036 : 0.054, inner_y = c.ring ? 0.036 : 0.012;
  std::string collisions = R"(<collision name="plate"><pose>0 0 -0.0025 0 0 0</pose><geometry><box><size>0.07 0.07 0.005</size></box></geometry></collision>)";
  if (c.liquid) {
    const double wall = 0.005, height = 0.02;
    collisions += fmt::format(R"(<collision name="wall_px"><pose>{} 0 {} 0 0 0</pose><geometry><box><size>{} {} {}</size></box></geometry></collision>)",
                              (inner_x + wall) / 2, height / 2, wall, inner_y + 2 * wall, height);
    collisions += fmt::format(R"(<collision name="wall_nx"><pose>{} 0 {} 0 0 0</pose><geometry><box><size>{} {} {}</size></box></geometry></collision>)",
                              -(inner_x + wall) / 2, height / 2, wall, inner_y + 2 * wall, height);
    collisions += fmt::format(R"(<collision name="wall_py"><pose>0 {} {} 0 0 0</pose><geometry><box><size>{} {} {}</size></box></geometry></collision>)",
                              (inner_y + wall) / 2, height / 2, inner_x, wall, height);
    collisions += fmt::format(R"(<collision name="wall_ny"><pose>0 {} {} 0 0 0</pose><geometry><box><size>{} {} {}</size></box></geometry></collision>)",
                              -(inner_y + wall) / 2, height / 2, inner_x, wall, height);
  }
  const double gap = 0.008;
  const std::string path = c.ring ? fmt::format("<circle><centre>0 0 {}</centre><radius>0.012</radius><turns>1</turns></circle>", gap)
                                  : fmt::format("<line><start>-0.024 0 {0}</start><end>0.024 0 {0}</end></line>", gap);
  return fmt::format(R"(<?xml version="1.0"?>
<sdf version="1.9">
  <world name="printed_volume">
    <gravity>0 0 -9.81</gravity>
    <model name="bed"><static>true</static><link name="bed">{}</link></model>
    <plugin name="m3dp" filename="m3dp">
      <solver>
        <particle_radius>{}</particle_radius>
        <max_time_step>0.002</max_time_step>
        <bounds><min>-0.05 -0.05 -0.02</min><max>0.05 0.05 0.05</max></bounds>
      </solver>
      <material name="printed" preset="{}"/>
      <print_head name="head" material="printed">
        <nozzle><inner_diameter>{}</inner_diameter><exit_speed>{}</exit_speed><direction>0 0 -1</direction></nozzle>
        <path start_time="0" speed="{}">{}</path>
      </print_head>
    </plugin>
  </world>
</sdf>)",
                     collisions, kRadius, c.material, kDiameter, kSpeed, kSpeed, path);
}

double percentile(std::vector<double> values, double fraction) {
  std::sort(values.begin(), values.end());
  return m3dp::sph::percentile_of_sorted(values, fraction);
}

class PrintedVolume : public ::testing::TestWithParam<Case> {};

TEST_P(PrintedVolume, RestDensityInsideAndEvenSpacing) {
  const Case c = GetParam();
  const m3dp::scene::Scene scene = m3dp::scene::load_scene_from_string(scene_text(c), "printed_volume.sdf");
  m3dp::sim::Simulation simulation(scene);
  const double print_time = c.ring ? 2 * 3.14159265 * 0.012 / kSpeed : 0.048 / kSpeed;
  // Printed, then a second to settle: pastes stop (and rest), liquids pool.
  while (simulation.time() < print_time + 1.0) simulation.step();

  const auto& solver = simulation.solver();
  const auto& positions = solver.fluid().position;
  const std::size_t count = positions.size();
  ASSERT_GT(count, 1000u);
  const Real d = solver.model().particle_diameter, support = solver.model().support_radius;
  const std::vector<Real>& density = simulation.measured_density().density;
  const Real rest_density = solver.model().phases[0].density;

  // Fluid and wall particles in one grid: a particle whose neighbourhood (walls included) is lopsided
  // is at the free surface; the interior is every particle farther than a support radius from one.
  std::vector<Vec3> points(positions.begin(), positions.end());
  points.insert(points.end(), solver.boundary().position.begin(), solver.boundary().position.end());
  m3dp::sph::SpatialHashGrid grid;
  grid.build(points, support);
  std::vector<char> at_surface(count, 0);
  std::vector<double> nearest(count, 1e9);
  for (std::size_t i = 0; i < count; ++i) {
    Vec3 sum = Vec3::Zero();
    int neighbours = 0;
    grid.for_each_candidate(positions[i], [&](std::size_t j, const Vec3& p) {
      const Real distance = (p - positions[i]).norm();
      if (j == i || distance >= support) return;
      sum += p - positions[i];
      ++neighbours;
      if (j < count) nearest[i] = std::min(nearest[i], double(distance / d));
    });
    at_surface[i] = neighbours == 0 || (sum / Real(neighbours)).norm() > Real(0.2) * d;
  }
  m3dp::sph::SpatialHashGrid surface_grid;
  std::vector<m3dp::Index> surface_subset;
  for (std::size_t i = 0; i < count; ++i)
    if (at_surface[i]) surface_subset.push_back(static_cast<m3dp::Index>(i));
  surface_grid.build(positions, surface_subset, support);
  std::vector<double> interior_error;
  for (std::size_t i = 0; i < count; ++i) {
    bool near_surface = false;
    surface_grid.for_each_candidate(positions[i], [&](std::size_t, const Vec3& p) {
      near_surface = near_surface || (p - positions[i]).norm() < support;
    });
    if (!near_surface) interior_error.push_back(double(density[i] / rest_density) - 1);
  }

  const double median = percentile(interior_error, 0.5), p99 = percentile(interior_error, 0.99);
  // A paste comes to rest with the compression the volume correction leaves, its tolerance (1 % by
  // default): its interior's median reads +1.00 to +1.07 %. A tolerance of 0.5 % halves that but lets
  // unyielded columns creep (the slump and buildability tests fail), so the bound for a paste is the
  // tolerance and a quarter of it; liquids flow until the density solve has them at ρ0.
  const double tolerance = solver.parameters().settings.volume_tolerance;
  const double median_bound = c.liquid ? 0.01 : 1.25 * tolerance;
  const double nearest_median = percentile(nearest, 0.5), nearest_p1 = percentile(nearest, 0.01);
  std::printf("%s %s: %zu particles, %zu inside: rho/rho0 - 1 median %+.2f %% (bound %.2f %%), p99 %+.2f %% (bound 3 %%); nearest "
              "neighbour median %.3f d (bound 0.85, paste 0.83), 1st percentile %.3f d (bound 0.5)\n",
              c.material, c.ring ? "ring" : "bead", count, interior_error.size(), 100 * median, 100 * median_bound, 100 * p99, nearest_median,
              nearest_p1);
  // A paste's bead held by its bed (the default since issue 56; a preset's Navier slip before) stands
  // narrower: 65-125 particles inside, its nearest-neighbour median 0.839-0.854 d (0.85 was the bound
  // on the slipping beads).
  ASSERT_GE(interior_error.size(), 50u) << "too few particles inside to measure";
  EXPECT_LT(std::abs(median), median_bound);
  EXPECT_LT(std::abs(p99), 0.03);
  EXPECT_GE(nearest_median, c.liquid ? 0.85 : 0.83);
  EXPECT_GE(nearest_p1, 0.5);
}

std::string case_name(const ::testing::TestParamInfo<Case>& info) {
  return std::string(info.param.material) + (info.param.ring ? "_ring" : "_bead");
}

INSTANTIATE_TEST_SUITE_P(Presets, PrintedVolume,
                         ::testing::Values(Case{"water", true, false}, Case{"water", true, true}, Case{"honey", true, false},
                                           Case{"honey", true, true}, Case{"silicone", true, false}, Case{"silicone", true, true},
                                           Case{"clay_paste", false, false}, Case{"clay_paste", false, true},
                                           Case{"printable_mortar", false, false}, Case{"printable_mortar", false, true},
                                           Case{"printable_concrete", false, false}, Case{"printable_concrete", false, true}),
                         case_name);

// A printed wall's surface holds the volume that left the nozzle, and stands as high as commanded.
// Both surfaces are compared with the emitted volume N d³ (mass over rest density), and each is the
// fair surface of that volume: Yu & Turk's anisotropic mesh puts a flat face a radius beyond the last
// centres (as the particles' own cells d³ would), and the union of spheres of radius 1.31 r is the
// one whose mean skin on a cubic lattice lies there too (R = 0.657 d; the default 1.5 r, chosen to
// close a single sheet's faces, adds 15 % to a wall this thin).
void expect_wall_keeps_its_volume(m3dp::scene::Scene scene, double commanded_height) {
  scene.output.write_particles = false;
  scene.meshing.enabled = false;
  m3dp::sim::Simulation simulation(scene);
  while (simulation.time() < scene.end_time) simulation.step();
  const auto& solver = simulation.solver();
  const auto& positions = solver.fluid().position;
  const double d = solver.model().particle_diameter, r = d / 2;
  const double emitted = double(positions.size()) * d * d * d;
  ASSERT_GT(positions.size(), 1000u);
  double top = 0;
  for (const Vec3& p : positions) top = std::max(top, double(p.z()));
  const double height = top + r;  // the bed's top at z = 0
  m3dp::surface::SurfaceSettings anisotropic;
  anisotropic.particle_radius = Real(r);
  m3dp::surface::SurfaceSettings spherical = anisotropic;
  spherical.method = m3dp::surface::Method::spherical;
  spherical.sphere_radius = Real(1.31 * r);
  const double anisotropic_volume = m3dp::surface::signed_volume(m3dp::surface::reconstruct_surface(positions, anisotropic));
  const double spherical_volume = m3dp::surface::signed_volume(m3dp::surface::reconstruct_surface(positions, spherical));
  std::printf("%s: %zu particles, %.1f cm3 emitted; anisotropic mesh %.1f cm3 (%+.1f %%), spherical (1.31 r) %.1f cm3 (%+.1f %%) "
              "(bound 5 %%); height %.1f mm, commanded %.1f mm (bound one diameter, %.1f mm)\n",
              scene.file.filename().string().c_str(), positions.size(), 1e6 * emitted, 1e6 * anisotropic_volume, 100 * (anisotropic_volume / emitted - 1),
              1e6 * spherical_volume, 100 * (spherical_volume / emitted - 1), 1e3 * height, 1e3 * commanded_height, 1e3 * d);
  EXPECT_LT(std::abs(anisotropic_volume / emitted - 1), 0.05);
  EXPECT_LT(std::abs(spherical_volume / emitted - 1), 0.05);
  EXPECT_LT(std::abs(height - commanded_height), d);
}

std::string read_text(const std::filesystem::path& path) {
  std::ifstream file(path);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

TEST(PrintedWall, TheUr10DemoHoldsItsVolumeAndHeight) {
  // Three 8 mm layers of a 0.24 m square.
  expect_wall_keeps_its_volume(m3dp::scene::load_scene(std::filesystem::path(M3DP_SCENES) / "ur10_wall.sdf"), 3 * 0.008);
}

TEST(PrintedWall, TenLayersHoldTheirVolumeAndHeight) {
  // The demo's strand and material, ten layers of a 0.08 m square, the print head on its path.
  std::string text = read_text(std::filesystem::path(M3DP_SCENES) / "ur10_wall.sdf");
  const auto cut = [&](const std::string& from, const std::string& to) {
    const std::size_t begin = text.find(from), end = text.find(to, begin);
    ASSERT_NE(begin, std::string::npos);
    ASSERT_NE(end, std::string::npos);
    text.erase(begin, end + to.size() - begin);
  };
  cut("<include>", "</include>");
  cut("<sensor", "</sensor>");                 // the cameras look at the demo's arm
  cut("<camera name=\"wrist\"", "</camera>");
  cut("<robot", "</robot>");
  cut("<mount", "</mount>");
  const std::size_t path_begin = text.find("<path"), path_end = text.find("</path>") + std::string("</path>").size();
  text.replace(path_begin, path_end - path_begin, R"(<path speed="0.1">
          <line extrude="false" speed="0.2"><start>0.66 -0.04 0.05</start><end>0.66 -0.04 0.008</end></line>
          <wall><corner>0.66 -0.04 0.008</corner><size>0.08 0.08</size><layers>10</layers><layer_height>0.008</layer_height></wall>
          <line extrude="false"><start>0.66 -0.04 0.08</start><end>0.66 -0.04 0.12</end></line>
        </path>)");
  const std::size_t end_begin = text.find("<end_time>"), end_end = text.find("</end_time>");
  text.replace(end_begin, end_end - end_begin, "<end_time>34.5");  // 0.2 s down, 32.8 s printing, 1.5 s to settle
  m3dp::scene::Scene scene = m3dp::scene::load_scene_from_string(text, "ten_layer_wall.sdf");
  expect_wall_keeps_its_volume(scene, 10 * 0.008);
}

}  // namespace

TEST(PrintedWall, LayersLaidOnRestingLayersConvergeAsOnTheFloor) {
  // A mortar wall of the construction scale's bead (a 20 mm nozzle, 10 mm layers, 32 mm wide) around a
  // 0.2 m square, three layers, the first on the floor and each next one on the last, which has come
  // to rest. Resting material is a fixed neighbour of the bead laid on it: counted as moving in the
  // density solve's diagonal, it halved the κ of the particles touching it, and the compression a
  // woken particle had rested with held the solve's mean error up. The density solve then took 4
  // iterations a step on the floor, 36-40 on the first layer and 94 on the second (a 0.5 m wall,
  // issue 57). And a bead settling on resting material pressed it together, which woke it, and the
  // woken particles pressed the next: a band of moving particles down to the floor (345 in layer 2
  // and 161 in layer 1 while layer 3 was laid) until the resting particles pushed back in the solve.
  const m3dp::scene::Scene scene = m3dp::scene::load_scene_from_string(R"(<?xml version="1.0"?>
<sdf version="1.9"><world name="layers_on_rest">
  <model name="floor"><static>true</static><link name="floor"><collision name="floor">
    <pose>0 0 -0.01 0 0 0</pose><geometry><box><size>0.5 0.5 0.02</size></box></geometry>
  </collision></link></model>
  <plugin name="m3dp" filename="m3dp">
    <solver><particle_radius unit="mm">1.5</particle_radius><end_time>24.3</end_time>
      <bounds><min>-0.25 -0.25 -0.05</min><max>0.25 0.25 0.2</max></bounds></solver>
    <material name="mortar"><density>2100</density>
      <rheology model="bingham"><yield_stress>1500</yield_stress><plastic_viscosity>10</plastic_viscosity></rheology>
      <boundary_viscosity>no_slip</boundary_viscosity></material>
    <print_head name="nozzle" material="mortar">
      <nozzle><inner_diameter unit="mm">20</inner_diameter><exit_speed>0.1019</exit_speed></nozzle>
      <path speed="0.1">
        <wall><corner>-0.1 -0.1 0.01</corner><size>0.2 0.2</size><layers>3</layers><layer_height>0.01</layer_height></wall>
      </path>
    </print_head>
  </plugin>
</world></sdf>)", "layers_on_rest.sdf");
  m3dp::sim::Simulation simulation(scene);
  double iterations[3] = {0, 0, 0}, start[3] = {-1, -1, -1}, moving_below[3] = {0, 0, 0};
  int steps[3] = {0, 0, 0};
  while (simulation.time() < scene.end_time) {
    simulation.step();
    const auto& nozzle = simulation.solver().state().nozzles[0];
    const int layer = nozzle.print_layer;
    if (layer < 0 || layer > 2 || !nozzle.extruding) continue;
    if (start[layer] < 0) start[layer] = simulation.time();
    // Each layer from a second after it began (past the bead's start).
    if (simulation.time() < start[layer] + 1.0) continue;
    iterations[layer] += simulation.solver().state().last_step.density_iterations;
    // Moving particles in the layers under the bead being laid (its base at 10 mm a layer).
    const auto& fluid = simulation.solver().fluid();
    for (std::size_t i = 0; i < simulation.solver().state().active_count; ++i)
      moving_below[layer] += fluid.position[i].z() < 0.01 * layer - 0.0015;
    ++steps[layer];
  }
  for (int layer = 0; layer < 3; ++layer) {
    iterations[layer] /= std::max(steps[layer], 1);
    moving_below[layer] /= std::max(steps[layer], 1);
  }
  const auto& measured = simulation.measured_density();
  std::printf("three layers on a 0.2 m square: density iterations a step %.1f (on the floor), %.1f, %.1f (on resting layers); "
              "%zu particles, %zu resting; density rho/rho0 - 1 median %+.2f %%, 99th percentile %+.2f %%; moving under the bead "
              "%.0f, %.0f (layers 2, 3)\n",
              iterations[0], iterations[1], iterations[2], measured.statistics.particles,
              simulation.solver().fluid().size() - simulation.solver().state().active_count, 100 * measured.statistics.median,
              100 * measured.statistics.p99, moving_below[1], moving_below[2]);
  // Now 4.0, 6.6 and 7.4, and 24-25 moving under the bead (before the resting particles pushed back:
  // 4.0, 9.0 and 14.5, rising a layer at a time, and ~500 under the bead; before the diagonal and the
  // allowance: 4.0, 35.8 and 90.4).
  ASSERT_GT(steps[2], 100);
  EXPECT_LT(iterations[1], 2 * iterations[0]);
  EXPECT_LT(iterations[2], 1.25 * iterations[1]) << "a layer on resting layers costs what the one below it did";
  EXPECT_LT(moving_below[2], 100) << "the layers under the bead stay at rest";
  // Nor is the wall pressed together: the median within 2 % (1.0), the 99th percentile within 2 % (1.45;
  // rest detection lets resting material keep 3 %).
  EXPECT_LT(measured.statistics.median, 0.02);
  EXPECT_LT(measured.statistics.p99, 0.02);
}

namespace {
/// Where a bead laid by a minimal scene, written from docs/scene_reference.md alone, lies: a paste,
/// a 10 mm nozzle 8 mm above a static box, U = V along a 0.1 m line from x = -0.05 m; its wall
/// friction as written (nothing: the default). Returns the material's x extent and its top (m).
struct BeadPlace {
  double first_x, last_x, top;
};
BeadPlace lay_minimal_bead(const std::string& wall_friction) {
  const m3dp::scene::Scene scene = m3dp::scene::load_scene_from_string(fmt::format(R"(<?xml version="1.0"?>
<sdf version="1.9"><world name="minimal_bead">
  <model name="bed"><static>true</static><link name="bed"><collision name="bed">
    <pose>0 0 -0.01 0 0 0</pose><geometry><box><size>0.2 0.06 0.02</size></box></geometry>
  </collision></link></model>
  <plugin name="m3dp" filename="m3dp">
    <solver><particle_radius unit="mm">1</particle_radius><end_time>2.6</end_time>
      <bounds><min>-0.1 -0.05 -0.03</min><max>0.1 0.05 0.05</max></bounds></solver>
    <material name="paste"><density>1800</density>
      <rheology model="herschel_bulkley"><yield_stress>300</yield_stress><consistency>60</consistency><flow_index>0.5</flow_index></rheology>
      {}</material>
    <print_head name="head" material="paste">
      <nozzle><inner_diameter unit="mm">10</inner_diameter><exit_speed>0.05</exit_speed></nozzle>
      <path speed="0.05"><line><start>-0.05 0 0.008</start><end>0.05 0 0.008</end></line></path>
    </print_head>
    <output><particles>false</particles></output>
  </plugin>
</world></sdf>)", wall_friction), "minimal_bead.sdf");
  m3dp::sim::Simulation simulation(scene);
  while (simulation.time() < scene.end_time - 1e-9) simulation.step();
  BeadPlace place{1e9, -1e9, -1e9};
  for (const Vec3& position : simulation.solver().fluid().position) {
    place.first_x = std::min(place.first_x, double(position.x()));
    place.last_x = std::max(place.last_x, double(position.x()));
    place.top = std::max(place.top, double(position.z()));
  }
  return place;
}
}  // namespace

TEST(PrintedBead, AMinimalScenesBeadStaysWhereItIsLaid) {
  // Issue 56: with the bed's friction free slip by default the nozzle plowed the whole bead 10 cm along
  // the bed. A printed material now sticks to static walls unless the scene says otherwise.
  const BeadPlace held = lay_minimal_bead("");
  const BeadPlace slipping = lay_minimal_bead("<boundary_viscosity>0</boundary_viscosity>");
  std::printf("bead from x = -50 mm to +50 mm, 8 mm gap: by default %.1f to %.1f mm, top %.1f mm; with free slip written %.1f to %.1f mm\n",
              1e3 * held.first_x, 1e3 * held.last_x, 1e3 * held.top, 1e3 * slipping.first_x, 1e3 * slipping.last_x);
  // Its start stays at the path's start (within half the nozzle: the bead's round end), its top near the gap.
  EXPECT_NEAR(held.first_x, -0.05, 0.005);
  EXPECT_LT(held.last_x, 0.05 + 0.01);
  EXPECT_NEAR(held.top, 0.008, 0.002);
  // Free slip, asked for, still slides: the default is what holds it.
  EXPECT_GT(slipping.first_x - held.first_x, 0.01);
}
