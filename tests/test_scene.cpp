// Loading SDF scene files: values land in the right fields in SI units, and every mistake is reported
// with file:line and what was expected.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <variant>

#include "m3dp/core/error.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/scene/schema.hpp"

namespace {

namespace fs = std::filesystem;
using m3dp::InputError;
using m3dp::Real;
using m3dp::Vec3;
using m3dp::scene::load_scene_from_string;

std::string valid_scene() {
  return R"(<?xml version="1.0"?>
<sdf version="1.9">
  <world name="dam_break">
    <gravity>0 0 -9.8</gravity>
    <physics type="ode"><max_step_size>0.001</max_step_size></physics>
    <light name="sun" type="directional"/>
    <model name="tank">
      <static>true</static>
      <pose degrees="true">1 0 0 0 0 90</pose>
      <link name="walls">
        <pose>0 1 0 0 0 0</pose>
        <collision name="floor">
          <pose>0 0 -0.01 0 0 0</pose>
          <geometry><box><size>1 1 0.02</size></box></geometry>
        </collision>
        <collision name="ground">
          <geometry><plane><normal>0 0 2</normal><size>2 2</size></plane></geometry>
        </collision>
        <visual name="floor_visual"><geometry><box><size>1 1 0.02</size></box></geometry></visual>
        <inertial><mass>1</mass></inertial>
      </link>
    </model>
    <plugin name="other" filename="libother.so"><anything/></plugin>
    <plugin name="m3dp" filename="m3dp">
      <solver>
        <particle_radius unit="mm">5</particle_radius>
        <kernel>wendland_c2</kernel>
        <cfl_factor>0.4</cfl_factor>
        <min_time_step unit="ms">0.01</min_time_step>
        <max_time_step>0.005</max_time_step>
        <max_density_error unit="%">0.05</max_density_error>
        <max_divergence_error>0.001</max_divergence_error>
        <max_iterations>50</max_iterations>
        <divergence_solver>false</divergence_solver>
        <warm_start>1</warm_start>
        <end_time>2</end_time>
        <bounds><min>-1 -1 -1</min><max>1 1 1</max></bounds>
      </solver>
      <material name="water">
        <density>1000</density>
        <viscosity unit="mPa*s">1</viscosity>
        <boundary_viscosity unit="cP">2</boundary_viscosity>
      </material>
      <fluid_block name="column" material="water">
        <min>0 0 0</min>
        <max>0.1 0.1 0.2</max>
        <velocity unit="mm/s">0 0 -10</velocity>
      </fluid_block>
      <print_head name="head" material="water">
        <nozzle>
          <inner_diameter unit="cm">1</inner_diameter>
          <exit_speed>0.1</exit_speed>
          <direction>0 0 -2</direction>
        </nozzle>
        <path start_time="0.5" speed="0.05">
          <line><start>0 0 0.1</start><end>0.1 0 0.1</end></line>
          <polyline><point>0.1 0 0.1</point><point>0.1 0.1 0.1</point></polyline>
          <circle speed="0.1">
            <center>0 0 0.1</center><radius>0.05</radius><start_angle unit="deg">90</start_angle>
          </circle>
          <helix extrude="false">
            <centre>0 0 0.2</centre><radius>0.05</radius><turns>2</turns><rise_per_turn>0.01</rise_per_turn>
          </helix>
        </path>
      </print_head>
      <output>
        <particles_period unit="ms">20</particles_period>
        <particles>true</particles>
      </output>
    </plugin>
  </world>
</sdf>
)";
}

/// `text` with the first `from` replaced by `to` (the test fails if `from` is not there).
std::string replaced(std::string text, const std::string& from, const std::string& to) {
  const auto position = text.find(from);
  if (position == std::string::npos) {
    ADD_FAILURE() << "'" << from << "' is not in the scene";
    return text;
  }
  return text.replace(position, from.size(), to);
}

/// `text` without the part from the first `begin` up to and including the next `end`.
std::string erased(std::string text, const std::string& begin, const std::string& end) {
  const auto first = text.find(begin);
  const auto last = first == std::string::npos ? std::string::npos : text.find(end, first);
  if (last == std::string::npos) {
    ADD_FAILURE() << "'" << begin << "' ... '" << end << "' is not in the scene";
    return text;
  }
  return text.erase(first, last + end.size() - first);
}

/// The 1-based line of the first `needle` in `text`.
int line_of(const std::string& text, const std::string& needle) {
  const auto position = text.find(needle);
  EXPECT_NE(position, std::string::npos) << "'" << needle << "' is not in the scene";
  return 1 + int(std::count(text.begin(), text.begin() + std::ptrdiff_t(position), '\n'));
}

/// "bad.sdf:N:" where N is the line of the first `needle` in `text`.
std::string location_of(const std::string& text, const std::string& needle) {
  return "bad.sdf:" + std::to_string(line_of(text, needle)) + ":";
}

/// The InputError that loading `text` as "bad.sdf" throws.
InputError load_error(const std::string& text) {
  try {
    load_scene_from_string(text, "bad.sdf");
  } catch (const InputError& error) {
    return error;
  }
  ADD_FAILURE() << "the scene loaded without an error";
  return InputError(m3dp::SourceLocation{}, "no error");
}

#define EXPECT_CONTAINS(haystack, needle) \
  EXPECT_NE(std::string(haystack).find(needle), std::string::npos) << "'" << (needle) << "' not in:\n" << (haystack)

/// Loading must fail with one message at the line of `needle` saying `message`.
void expect_error_at(const std::string& text, const std::string& needle, const std::string& message) {
  const InputError error = load_error(text);
  EXPECT_CONTAINS(error.what(), location_of(text, needle) + " error: " + message);
}

TEST(Scene, ValidSceneLoadsInSiUnits) {
  const auto scene = load_scene_from_string(valid_scene(), "scenes/valid.sdf");
  EXPECT_EQ(scene.world_name, "dam_break");
  EXPECT_EQ(scene.file, fs::path("scenes/valid.sdf"));
  EXPECT_FLOAT_EQ(scene.solver.particle_radius, 0.005f);
  EXPECT_EQ(scene.solver.kernel, m3dp::sph::KernelType::wendland_c2);
  EXPECT_TRUE(scene.solver.gravity.isApprox(Vec3(0, 0, Real(-9.8))));
  EXPECT_FLOAT_EQ(scene.solver.cfl_factor, 0.4f);
  EXPECT_FLOAT_EQ(scene.solver.min_time_step, 1e-5f);
  EXPECT_FLOAT_EQ(scene.solver.max_time_step, 0.005f);
  EXPECT_FLOAT_EQ(scene.solver.density_tolerance, 0.0005f);
  EXPECT_EQ(scene.solver.max_density_iterations, 50);
  EXPECT_EQ(scene.solver.max_divergence_iterations, 50);
  EXPECT_FALSE(scene.solver.divergence_solver);
  EXPECT_TRUE(scene.solver.warm_start);
  EXPECT_TRUE(scene.solver.bounds.min.isApprox(Vec3(-1, -1, -1)));
  EXPECT_TRUE(scene.solver.bounds.max.isApprox(Vec3(1, 1, 1)));
  EXPECT_DOUBLE_EQ(scene.end_time, 2.0);

  ASSERT_EQ(scene.materials.size(), 1u);
  const auto* water = scene.find_material("water");
  ASSERT_NE(water, nullptr);
  EXPECT_EQ(scene.find_material("clay"), nullptr);
  EXPECT_FLOAT_EQ(water->material.density, 1000.0f);
  EXPECT_FLOAT_EQ(water->material.rheology.viscosity, 0.001f);  // 1 mPa*s
  EXPECT_FLOAT_EQ(water->material.boundary_viscosity, 0.002f); // 2 cP
  EXPECT_EQ(water->where.line, line_of(valid_scene(), "<material name=\"water\">"));

  ASSERT_EQ(scene.fluid_blocks.size(), 1u);
  EXPECT_TRUE(scene.fluid_blocks[0].box.max.isApprox(Vec3(Real(0.1), Real(0.1), Real(0.2))));
  EXPECT_TRUE(scene.fluid_blocks[0].initial_velocity.isApprox(Vec3(0, 0, Real(-0.01))));

  // World pose = model ∘ link ∘ collision: the model turns 90° about z, so the link's +y offset becomes -x.
  ASSERT_EQ(scene.bodies.size(), 1u);
  ASSERT_EQ(scene.bodies[0].collisions.size(), 2u);
  const auto& floor = scene.bodies[0].collisions[0];
  EXPECT_EQ(floor.name, "tank/walls/floor");
  EXPECT_LT((floor.pose.position - Vec3(0, 0, Real(-0.01))).norm(), 1e-6);
  EXPECT_LT((floor.pose.rotate(Vec3::UnitX()) - Vec3::UnitY()).norm(), 1e-6);
  ASSERT_TRUE(std::holds_alternative<m3dp::BoxShape>(floor.shape));
  EXPECT_TRUE(std::get<m3dp::BoxShape>(floor.shape).size.isApprox(Vec3(1, 1, Real(0.02))));
  const auto& ground = scene.bodies[0].collisions[1];
  ASSERT_TRUE(std::holds_alternative<m3dp::PlaneShape>(ground.shape));
  EXPECT_TRUE(std::get<m3dp::PlaneShape>(ground.shape).normal.isApprox(Vec3::UnitZ()));

  ASSERT_EQ(scene.print_heads.size(), 1u);
  const auto& head = scene.print_heads[0];
  EXPECT_FLOAT_EQ(head.inner_diameter, 0.01f);
  EXPECT_TRUE(head.direction.isApprox(Vec3(0, 0, -1)));
  EXPECT_DOUBLE_EQ(head.trajectory.start_time(), 0.5);
  EXPECT_GT(head.trajectory.end_time(), 0.5);

  ASSERT_TRUE(scene.output.particles_period.has_value());
  EXPECT_FLOAT_EQ(*scene.output.particles_period, 0.02f);
  EXPECT_TRUE(scene.output.write_particles);
}

TEST(Scene, OutputRecordsAndServes) {
  const std::string text = replaced(valid_scene(), "<particles>true</particles>", "<particles>true</particles><mcap>true</mcap><serve>0</serve>");
  const auto scene = load_scene_from_string(text, "scenes/valid.sdf");
  EXPECT_TRUE(scene.output.mcap);
  ASSERT_TRUE(scene.output.serve_port.has_value());
  EXPECT_EQ(*scene.output.serve_port, 0);
  EXPECT_FALSE(load_scene_from_string(valid_scene(), "scenes/valid.sdf").output.serve_port.has_value());
  expect_error_at(replaced(valid_scene(), "<particles>true</particles>", "<particles>true</particles>\n<serve>70000</serve>"),
                  "<serve>", "<serve> must be a whole number in [0, 65535], got 70000");
  expect_error_at(replaced(valid_scene(), "<particles>true</particles>", "<particles>true</particles>\n<mcap>yes</mcap>"),
                  "<mcap>", "<mcap> must be true or false (or 1 or 0), got 'yes'");
  EXPECT_EQ(load_scene_from_string(valid_scene(), "scenes/valid.sdf").output.checkpoint_period, 0.0);
  EXPECT_EQ(load_scene_from_string(replaced(valid_scene(), "<particles>true</particles>",
                                            "<particles>true</particles><checkpoint_period>0.5</checkpoint_period>"),
                                   "scenes/valid.sdf")
                .output.checkpoint_period,
            0.5);
  expect_error_at(replaced(valid_scene(), "<particles>true</particles>", "<particles>true</particles>\n<checkpoint_period>-1</checkpoint_period>"),
                  "<checkpoint_period>", "<checkpoint_period> must be >= 0 s, got -1");
}

TEST(Scene, CamerasInGazeboSyntaxAndInThePlugin) {
  // A Gazebo sensor in the static link (pose relative to the link, the link's to the model's), and a
  // plugin camera fixed in the world.
  std::string text = replaced(valid_scene(), R"(<inertial><mass>1</mass></inertial>)", R"(<inertial><mass>1</mass></inertial>
        <sensor name="overview" type="depth_camera">
          <pose>0.5 0 2 0 1.5708 0</pose>
          <update_rate unit="Hz">4</update_rate>
          <always_on>1</always_on>
          <camera>
            <horizontal_fov unit="deg">60</horizontal_fov>
            <image><width>640</width><height>480</height><format>R8G8B8</format></image>
            <clip><near>0.1</near><far>5</far></clip>
            <noise><type>gaussian</type><mean>0</mean><stddev>0.007</stddev></noise>
          </camera>
        </sensor>
        <sensor name="imu" type="imu"/>)");
  text = replaced(text, "<output>", R"(<camera name="side" type="camera"><pose>2 0 1 0 0 3.1416</pose><shadows>false</shadows></camera>
      <output>)");
  const auto scene = load_scene_from_string(text, "scenes/valid.sdf");
  ASSERT_EQ(scene.cameras.size(), 2u);
  const auto& overview = scene.cameras[0].settings;
  EXPECT_EQ(overview.name, "overview");
  EXPECT_EQ(overview.type, m3dp::sensors::CameraType::depth_camera);
  EXPECT_EQ(overview.width, 640);
  EXPECT_EQ(overview.height, 480);
  EXPECT_NEAR(overview.horizontal_fov, std::acos(-1.0) / 3, 1e-9);
  EXPECT_DOUBLE_EQ(overview.near, 0.1);
  EXPECT_DOUBLE_EQ(overview.far, 5);
  EXPECT_DOUBLE_EQ(overview.update_rate, 4);
  EXPECT_DOUBLE_EQ(overview.noise.stddev, 0.007);
  EXPECT_TRUE(overview.robot.empty());
  // The model at x = 1 turned 90° about z, the link 1 m along the model's y: the link at (0, 0, 0) … plus
  // the sensor's 0.5 m along the model's x, which is the world's y.
  EXPECT_TRUE(overview.pose.position.isApprox(Vec3(0, 0.5f, 2), 1e-5f)) << overview.pose.position.transpose();
  EXPECT_EQ(scene.cameras[1].settings.type, m3dp::sensors::CameraType::camera);
  EXPECT_FALSE(scene.cameras[1].settings.shadows);
  ASSERT_EQ(scene.warnings.size(), 1u);
  EXPECT_NE(scene.warnings[0].message.find("<sensor type=\"imu\">"), std::string::npos) << scene.warnings[0].message;

  expect_error_at(replaced(text, "<clip><near>0.1</near><far>5</far></clip>", "<clip><near>0.1</near>\n<far>0.05</far></clip>"), "<clip>",
                  "<far> (0.05 m) must be beyond <near> (0.1 m)");
  expect_error_at(replaced(text, R"(<camera name="side" type="camera">)", R"(<camera name="overview" type="camera">)"),
                  R"(<camera name="overview" type="camera">)", "a camera 'overview' is already defined at line");
  expect_error_at(replaced(text, R"(<camera name="side" type="camera">)", R"(<camera name="side" type="thermal">)"),
                  R"(<camera name="side" type="thermal">)", "camera type 'thermal' is not one M3DP renders");
  expect_error_at(replaced(text, "<type>gaussian</type>", "<type>gaussian_quantized</type>"), "<noise>",
                  "camera noise 'gaussian_quantized' is not simulated; expected gaussian (or none)");
}

TEST(Scene, NumbersBeyondWhatAFloatHoldsAreErrorsAtTheirLine) {
  // Checked in double then stored as float, these had become inf or 0 after the check.
  expect_error_at(replaced(valid_scene(), "<density>1000</density>", "<density>1e308</density>"), "<density>",
                  "<density> of 1e+308 kg/m^3 is beyond any density M3DP simulates (at most 100000 kg/m^3)");
  expect_error_at(replaced(valid_scene(), R"(<viscosity unit="mPa*s">1</viscosity>)", "<viscosity>1e308</viscosity>"), "<viscosity>",
                  "<viscosity> of 1e+308 Pa*s is beyond any dynamic viscosity M3DP simulates");
  expect_error_at(replaced(valid_scene(), R"(<particle_radius unit="mm">5</particle_radius>)", "<particle_radius>1e-300</particle_radius>"),
                  "<particle_radius>", "<particle_radius> of 1e-300 m is below the smallest length M3DP resolves (1e-07 m)");
  expect_error_at(replaced(valid_scene(), R"(<inner_diameter unit="cm">1</inner_diameter>)", "<inner_diameter>1e30</inner_diameter>"),
                  "<inner_diameter>", "<inner_diameter> of 1e+30 m is beyond any length M3DP simulates (at most 10000 m)");
  expect_error_at(replaced(valid_scene(), "<max>0.1 0.1 0.2</max>", "<max>0.1 0.1 1e39</max>"), "<max>0.1 0.1 1e39",
                  "<max> of 1e+39 m is beyond any length M3DP simulates");
  expect_error_at(replaced(valid_scene(), "<pose>0 1 0 0 0 0</pose>", "<pose>0 1e300 0 0 0 0</pose>"), "<pose>0 1e300",
                  "<pose> of 1e+300 m is beyond any length M3DP simulates");
  // Zero stays a value where the field allows it.
  EXPECT_NO_THROW(load_scene_from_string(replaced(valid_scene(), "<max>0.1 0.1 0.2</max>", "<max>0.1 0.1 0.2</max>"), "x.sdf"));
}

TEST(Scene, SizesAreEstimatedBeforeAnythingIsAllocated) {
  // A micrometre radius in a 10 cm block: ~10¹⁴ particles, refused at the block's line with the estimate.
  const std::string tiny = replaced(valid_scene(), "<particle_radius unit=\"mm\">5</particle_radius>",
                                    "<particle_radius>1e-6</particle_radius>");
  const std::string tiny_error = load_error(tiny).what();
  EXPECT_CONTAINS(tiny_error, location_of(tiny, "<fluid_block name=\"column\"") +
                                  " error: the scene would hold about 2.53e+14 particles at a particle radius of 1e-06 m, 2.5e+14 of them "
                                  "from <fluid_block name=\"column\"> (0.002 m³); at most ");
  EXPECT_CONTAINS(tiny_error, "GB of memory at about 2048 bytes a particle): use a larger <particle_radius>");
  // A kilometre nozzle: the print head's extrusion is the largest part.
  const std::string nozzle = replaced(valid_scene(), "<inner_diameter unit=\"cm\">1</inner_diameter>",
                                      "<inner_diameter>1000</inner_diameter>");
  EXPECT_CONTAINS(load_error(nozzle).what(), location_of(nozzle, "<print_head name=\"head\"") + " error: the scene would hold about");
  // The limit is a setting: this scene's 1,600 fluid and ~10⁵ extruded particles are more than 1,000.
  const std::string limited = replaced(valid_scene(), "<end_time>2</end_time>", "<end_time>2</end_time><max_particles>1000</max_particles>");
  EXPECT_CONTAINS(load_error(limited).what(), "at most 1e+03 fit (<max_particles>)");
  EXPECT_NO_THROW(load_scene_from_string(replaced(valid_scene(), "<end_time>2</end_time>",
                                                  "<end_time>2</end_time><max_particles>1e7</max_particles>"),
                                         "ok.sdf"));
  // A billion-layer wall is refused at <layers> before its path is made.
  const std::string wall = replaced(valid_scene(), "<line><start>0 0 0.1</start><end>0.1 0 0.1</end></line>",
                                    "<wall><corner>0 0 0</corner><size>0.1 0.1</size><layers>2000000000</layers>"
                                    "<layer_height unit=\"mm\">1</layer_height></wall>");
  EXPECT_CONTAINS(load_error(wall).what(), location_of(wall, "<layers>") + " error: a wall of 2000000000 layers is a path of 1e+10 points");
}

TEST(Scene, MisspelledSdfElementsAreWarnedWithTheClosestName) {
  // Outside the plugin a typo would drop a model, a link or a collision without a word.
  const auto expect_warning = [](const std::string& text, const std::string& message) {
    const auto scene = load_scene_from_string(text, "x.sdf");
    ASSERT_EQ(scene.warnings.size(), 1u) << message;
    EXPECT_EQ(scene.warnings[0].message, message);
    EXPECT_EQ(scene.warnings[0].location.file, "x.sdf");
  };
  std::string misspelled_model = replaced(valid_scene(), R"(<model name="tank">)", R"(<modle name="tank">)");
  misspelled_model = replaced(misspelled_model, "</model>", "</modle>");
  expect_warning(misspelled_model, "unknown element <modle> in <world>, ignored; did you mean <model>?");
  expect_warning(replaced(valid_scene(), R"(<collision name="floor">)", R"(<colision name="x"/><collision name="floor">)"),
                 "unknown element <colision> in <link>, ignored; did you mean <collision>?");
  expect_warning(replaced(valid_scene(), "<static>true</static>", "<static>true</static><stattic>true</stattic>"),
                 "unknown element <stattic> in <model>, ignored; did you mean <static>?");
  expect_warning(replaced(valid_scene(), "<pose>0 0 -0.01 0 0 0</pose>", "<pos>0 0 -0.01 0 0 0</pos>"),
                 "unknown element <pos> in <collision>, ignored; did you mean <pose>?");
  expect_warning(replaced(valid_scene(), "<light name=\"sun\" type=\"directional\"/>", "<rocket/>"),
                 "unknown element <rocket> in <world>, ignored: SDF has no such element there");
  // A dynamic model's link is checked too.
  expect_warning(replaced(replaced(valid_scene(), "<static>true</static>", "<static>false</static>"),
                          R"(<collision name="ground">
          <geometry><plane><normal>0 0 2</normal><size>2 2</size></plane></geometry>
        </collision>)", "<inertia/>"),
                 "unknown element <inertia> in <link>, ignored; did you mean <inertial>?");
}

TEST(Scene, UnknownElementListsWhatIsExpected) {
  const std::string text = replaced(valid_scene(), "<kernel>", "<colour>red</colour>\n        <kernel>");
  expect_error_at(text, "<colour>", "unknown element <colour> in <solver>; expected one of: particle_radius, kernel");
}

TEST(Scene, MissingRequiredValue) {
  const std::string text = replaced(valid_scene(), "<density>1000</density>", "");
  expect_error_at(text, "<material name=\"water\">", "missing required <density> in <material name=\"water\">");
}

TEST(Scene, KinematicUnitOnViscosity) {
  const std::string text = replaced(valid_scene(), R"(<viscosity unit="mPa*s">1</viscosity>)",
                                    R"(<viscosity unit="m^2/s">1e-6</viscosity>)");
  expect_error_at(text, "<viscosity", "<viscosity> is dynamic viscosity in Pa*s; 'm^2/s' is a kinematic viscosity "
                                      "unit (multiply by density to convert)");
}

TEST(Scene, UnitOfTheWrongDimension) {
  const std::string text = replaced(valid_scene(), R"(<particle_radius unit="mm">)", R"(<particle_radius unit="s">)");
  expect_error_at(text, "<particle_radius", "unit 's' on <particle_radius> is not a length unit; expected one of: m");
}

TEST(Scene, VectorWithATypo) {
  const std::string text = replaced(valid_scene(), "<max>0.1 0.1 0.2</max>", "<max>0.1 O.1 0.2</max>");
  expect_error_at(text, "<max>0.1 O.1", "expected 3 numbers (x y z) in <max>, got '0.1 O.1 0.2'");
}

TEST(Scene, UndefinedMaterial) {
  const std::string text = replaced(valid_scene(), R"(<fluid_block name="column" material="water">)",
                                    R"(<fluid_block name="column" material="clay">)");
  expect_error_at(text, "<fluid_block",
                  "material 'clay' used by <fluid_block name=\"column\"> is not defined; defined: water");
}

TEST(Scene, MaterialsMayDifferInDensity) {
  const std::string text = replaced(valid_scene(), "<fluid_block name=\"column\" material=\"water\">",
                                    "<material name=\"clay\"><density unit=\"g/cm^3\">1.8</density>"
                                    "<viscosity>10</viscosity></material>\n"
                                    "      <fluid_block name=\"column\" material=\"clay\">");
  const auto scene = load_scene_from_string(text, "two_materials.sdf");
  EXPECT_FLOAT_EQ(scene.find_material("clay")->material.density, 1800.0f);
}

TEST(Scene, NozzleNarrowerThanAParticle) {
  const std::string text = replaced(valid_scene(), R"(<inner_diameter unit="cm">1</inner_diameter>)",
                                    "<inner_diameter>0.004</inner_diameter>");
  expect_error_at(text, "<inner_diameter>", "the nozzle is narrower than one particle");
}

// A nozzle with walls: its bore and lip reach the engine in SI units, the material's bore slip is read,
// and a bore shorter than two particles, a lip inside the bore or an unknown slip are errors at their line.
TEST(Scene, NozzleBoreAndLipAreReadAndChecked) {
  const std::string bore = R"(<exit_speed>0.1</exit_speed>
          <bore_length unit="mm">20</bore_length>
          <outer_diameter unit="cm">3</outer_diameter>)";
  std::string text = replaced(valid_scene(), "<exit_speed>0.1</exit_speed>", bore);
  text = replaced(text, R"(<boundary_viscosity unit="cP">2</boundary_viscosity>)",
                  R"(<boundary_viscosity unit="cP">2</boundary_viscosity>
        <nozzle_wall>no_slip</nozzle_wall>)");
  const auto scene = load_scene_from_string(text, "bore.sdf");
  ASSERT_EQ(scene.print_heads.size(), 1u);
  EXPECT_FLOAT_EQ(scene.print_heads[0].bore_length, 0.02f);
  EXPECT_FLOAT_EQ(scene.print_heads[0].outer_diameter, 0.03f);
  EXPECT_TRUE(scene.find_material("water")->material.nozzle_no_slip);
  const m3dp::sph::Parameters parameters = m3dp::scene::solver_parameters(scene);
  EXPECT_FLOAT_EQ(parameters.nozzles[0].bore_length, 0.02f);
  EXPECT_FLOAT_EQ(parameters.nozzles[0].outer_diameter, 0.03f);
  EXPECT_FALSE(load_scene_from_string(valid_scene(), "plain.sdf").find_material("water")->material.nozzle_no_slip) << "free slip by default";

  expect_error_at(replaced(text, R"(<bore_length unit="mm">20</bore_length>)", "<bore_length>0.004</bore_length>"), "<bore_length>",
                  "<bore_length> must be 0 (no bore) or at least two particle diameters (0.02 m), got 0.004");
  expect_error_at(replaced(text, R"(<outer_diameter unit="cm">3</outer_diameter>)", "<outer_diameter>0.005</outer_diameter>"),
                  "<outer_diameter>", "<outer_diameter> 0.005 m must be larger than <inner_diameter> 0.01 m");
  expect_error_at(replaced(text, "<nozzle_wall>no_slip</nozzle_wall>", "<nozzle_wall>sticky</nozzle_wall>"), "<nozzle_wall>",
                  "<nozzle_wall> must be one of: free_slip, no_slip; got 'sticky'");
}

// A bed holds what is laid on it (issue 56): a printed material that sets no wall friction sticks to
// static walls and slips on moving bodies and the bore; a friction it sets (0 included), a material no
// head lays, and a preset's setting are kept as written.
TEST(Scene, PrintedMaterialSticksToStaticWallsByDefault) {
  using m3dp::material::Wall;
  // As the engine takes them (m3dp::scene::solver_parameters applies the default).
  const auto engine_material = [](const m3dp::scene::Scene& scene, const std::string& name) {
    return m3dp::scene::solver_parameters(scene).phases.at(scene.material_index(name));
  };
  const std::string unset = replaced(valid_scene(), R"(<boundary_viscosity unit="cP">2</boundary_viscosity>)", "");
  const auto printed = engine_material(load_scene_from_string(unset, "unset.sdf"), "water");
  EXPECT_TRUE(printed.sticks_to(Wall::static_wall));
  EXPECT_FALSE(printed.sticks_to(Wall::moving_body));
  EXPECT_FALSE(printed.sticks_to(Wall::nozzle_bore));
  EXPECT_FLOAT_EQ(printed.wall_viscosity(500, Wall::static_wall), 500) << "the material's own viscosity";
  EXPECT_FLOAT_EQ(printed.wall_viscosity(500, Wall::moving_body), 0) << "free slip on a moving body";
  EXPECT_TRUE(printed.has_wall_friction());

  const auto free_slip = engine_material(
      load_scene_from_string(replaced(valid_scene(), R"(<boundary_viscosity unit="cP">2</boundary_viscosity>)", "<boundary_viscosity>0</boundary_viscosity>"),
                             "free_slip.sdf"),
      "water");
  EXPECT_FALSE(free_slip.sticks_to(Wall::static_wall)) << "a written 0 is free slip";
  EXPECT_FALSE(free_slip.has_wall_friction());
  const auto navier = engine_material(load_scene_from_string(valid_scene(), "navier.sdf"), "water");
  EXPECT_FALSE(navier.sticks_to(Wall::static_wall));
  EXPECT_FLOAT_EQ(navier.wall_viscosity(500, Wall::static_wall), 0.002f) << "Navier slip as written";

  // Not laid by a head (the head prints another material): slips as before.
  std::string two = replaced(unset, R"(<print_head name="head" material="water">)", R"(<print_head name="head" material="paste">)");
  two = replaced(two, R"(<material name="water">)", R"(<material name="paste"><density>1800</density><viscosity>300</viscosity></material>
      <material name="water">)");
  const auto scene = load_scene_from_string(two, "two.sdf");
  EXPECT_FALSE(engine_material(scene, "water").sticks_to(Wall::static_wall)) << "water in a block slips";
  EXPECT_TRUE(engine_material(scene, "paste").sticks_to(Wall::static_wall));
}

TEST(Scene, DynamicModelsAreReadAndChecked) {
  // The tank made dynamic: its box moves, its plane cannot.
  const std::string dynamic = replaced(valid_scene(), "<static>true</static>", "<static>false</static>");
  expect_error_at(dynamic, "<geometry><plane>", "a <plane> cannot move: put it in a <static> model");
  const auto scene = load_scene_from_string(erased(dynamic, "<collision name=\"ground\">", "</collision>"), "dynamic.sdf");
  ASSERT_EQ(scene.dynamic_bodies.size(), 1u);
  EXPECT_TRUE(scene.bodies.empty());
  EXPECT_NEAR(scene.dynamic_bodies[0].mass, 1.0, 1e-12);
  ASSERT_EQ(scene.dynamic_bodies[0].collisions.size(), 1u);
  EXPECT_NEAR(scene.dynamic_bodies[0].collisions[0].pose.position.z(), -0.01, 1e-6);  // in the link frame
  EXPECT_NEAR(scene.dynamic_bodies[0].pose.position.x(), 0, 1e-6);  // model (1 0 0, yaw 90°) ∘ link (0 1 0)

  const std::string no_mass = erased(erased(dynamic, "<collision name=\"ground\">", "</collision>"), "<inertial>", "</inertial>");
  expect_error_at(no_mass, "<link name=\"walls\">",
                  "<link name=\"walls\"> of dynamic model 'tank' needs <inertial><mass>...</mass></inertial> (kg)");
}

namespace {
/// The valid scene with the project's UR10 included, set up and carrying the print head.
std::string robot_scene(const std::string& joint = "elbow_joint", const std::string& link = "tool0",
                        const std::string& uri = "model://ur10") {
  std::string text = replaced(valid_scene(), "<plugin name=\"other\"",
                              "<include><uri>" + uri + "</uri><name>arm</name><pose>0 0 0.5 0 0 0</pose></include>\n"
                              "    <plugin name=\"other\"");
  text = replaced(text, "<print_head name=\"head\" material=\"water\">",
                  "<robot name=\"arm\"><joint name=\"" + joint + "\" unit=\"deg\">90</joint></robot>\n"
                  "      <print_head name=\"head\" material=\"water\">\n"
                  "        <mount robot=\"arm\" link=\"" + link + "\"><pose>0 0 0.15 0 0 0</pose>"
                  "<barrel_radius unit=\"mm\">20</barrel_radius></mount>");
  return text;
}
}  // namespace

TEST(Scene, RobotIncludesAreReadAndChecked) {
  const auto scene = load_scene_from_string(robot_scene(), "robot.sdf");
  ASSERT_EQ(scene.robots.size(), 1u);
  const auto& robot = scene.robots[0];
  EXPECT_EQ(robot.name, "arm");
  EXPECT_EQ(robot.urdf_file.filename(), "ur10.urdf");
  EXPECT_EQ(robot.joint_names.size(), 6u);
  EXPECT_NEAR(robot.pose.position.z(), 0.5, 1e-6);
  ASSERT_EQ(robot.initial_joint_positions.size(), 1u);
  EXPECT_EQ(robot.initial_joint_positions[0].first, "elbow_joint");
  EXPECT_NEAR(robot.initial_joint_positions[0].second, 3.14159265 / 2, 1e-6);
  ASSERT_TRUE(scene.print_heads[0].mount.has_value());
  EXPECT_EQ(scene.print_heads[0].mount->link, "tool0");
  EXPECT_NEAR(scene.print_heads[0].mount->barrel_radius, 0.02, 1e-7);
  EXPECT_NEAR(scene.print_heads[0].mount->offset.position.z(), 0.15, 1e-7);

  expect_error_at(robot_scene("knee_joint"), "<joint name=\"knee_joint\"",
                  "robot 'arm' has no movable joint 'knee_joint'; its joints: shoulder_pan_joint, shoulder_lift_joint, "
                  "elbow_joint, wrist_1_joint, wrist_2_joint, wrist_3_joint");
  expect_error_at(robot_scene("elbow_joint", "gripper"), "<mount robot=\"arm\"",
                  "robot 'arm' has no link 'gripper'; its links: world, base_link");
  const std::string missing = robot_scene("elbow_joint", "tool0", "model://no_such_robot");
  const InputError error = load_error(missing);
  EXPECT_CONTAINS(error.what(), location_of(missing, "<uri>model://no_such_robot") +
                                    " error: 'model://no_such_robot' not found; looked for ");
  EXPECT_CONTAINS(error.what(), "no_such_robot/no_such_robot.urdf");
  // A name the file system refuses (longer than NAME_MAX) is not found, not an exception past the reader.
  const std::string long_name(300, 'r');
  const std::string too_long = robot_scene("elbow_joint", "tool0", long_name + ".urdf");
  expect_error_at(too_long, "<uri>" + long_name, "'" + long_name + ".urdf' not found (looked for ");
  expect_error_at(robot_scene("elbow_joint", "tool0", "model://" + long_name), "<uri>model://",
                  "'model://" + long_name + "' not found; looked for ");
  const std::string wheels = replaced(robot_scene(), "</robot>",
                                      "<mobile_base><left_wheel>wheel_left_joint</left_wheel><right_wheel>elbow_joint"
                                      "</right_wheel><wheel_radius unit=\"mm\">33</wheel_radius><wheel_separation>0.287"
                                      "</wheel_separation></mobile_base></robot>");
  expect_error_at(wheels, "<left_wheel>", "robot 'arm' has no movable joint 'wheel_left_joint' for a wheel; its joints: ");
  const std::string unknown = replaced(robot_scene(), "<robot name=\"arm\">", "<robot name=\"crane\">");
  EXPECT_CONTAINS(load_error(unknown).what(), location_of(unknown, "<robot name=\"crane\">") +
                                                  " error: <robot name=\"crane\">: no robot of that name is included in "
                                                  "the world (robots: arm)");
}

TEST(Scene, BrokenUrdfIsReportedAtItsOwnLine) {
  const auto folder = std::filesystem::temp_directory_path() / ("m3dp_broken_urdf_" + std::to_string(::getpid()));
  std::filesystem::create_directories(folder);
  {
    std::ofstream urdf(folder / "broken.urdf");
    urdf << "<?xml version=\"1.0\"?>\n<robot name=\"broken\">\n  <link name=\"a\">\n</robot>\n";
  }
  const std::string text = robot_scene("elbow_joint", "tool0", (folder / "broken.urdf").string());
  const InputError error = load_error(text);
  std::filesystem::remove_all(folder);
  EXPECT_CONTAINS(error.what(), (folder / "broken.urdf").string() + ":4: error: the URDF is not well-formed XML");
}

TEST(Scene, WhatDartsUrdfLoaderWouldRefuseOrDropIsAnErrorAtTheUrdfsLine) {
  // urdfdom's own messages name neither file nor line, and a missing mesh would only drop a shape.
  const auto folder = std::filesystem::temp_directory_path() / ("m3dp_bad_urdf_" + std::to_string(::getpid()));
  std::filesystem::create_directories(folder);
  std::ofstream(folder / "bad.urdf") << R"(<?xml version="1.0"?>
<robot name="bad">
  <link name="base">
    <collision><geometry><mesh filename="meshes/missing.stl"/></geometry></collision>
  </link>
  <link name="arm">
    <inertial><mass value="abc"/><inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
    <visual><geometry><box size="0.1 0 0.1"/></geometry></visual>
  </link>
  <joint name="j1" type="revolut">
    <parent link="base"/><child link="arms"/>
    <origin xyz="0 0 1e400"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="base"/><child link="base"/>
  </joint>
</robot>
)";
  const std::string text = robot_scene("elbow_joint", "tool0", (folder / "bad.urdf").string());
  const std::string errors = load_error(text).what();
  std::filesystem::remove_all(folder);
  const std::string file = (folder / "bad.urdf").string();
  for (const std::string& expected :
       {file + ":4: error: <mesh filename=\"meshes/missing.stl\">: not found (looked for " + (folder / "meshes/missing.stl").string() +
            "); the collision shape would be missing",
        file + ":7: error: <mass value=\"abc\">: 'abc' is not a finite number",
        file + ":8: error: <box size=\"0.1 0 0.1\">: must be > 0",
        file + ":10: error: <joint name=\"j1\" type=\"revolut\">: expected type revolute, continuous, prismatic, fixed, floating or planar",
        file + ":11: error: joint 'j1': no <link name=\"arms\"> in the robot",
        file + ":12: error: <origin xyz=\"0 0 1e400\">: '1e400' is not a finite number",
        file + ":14: error: revolute joint 'j2' needs a <limit lower upper effort velocity/>",
        file + ":3: error: link 'base' is its own ancestor: the joints form a loop"})
    EXPECT_CONTAINS(errors, expected);
}

TEST(Scene, ARobotOfOnlyTheWorldLinkIsAnErrorAtItsLine) {
  // Found by fuzz_urdf: DART loads it as a skeleton without bodies and asserts on its root.
  const auto folder = std::filesystem::temp_directory_path() / ("m3dp_world_urdf_" + std::to_string(::getpid()));
  std::filesystem::create_directories(folder);
  std::ofstream(folder / "world.urdf") << "<?xml version=\"1.0\"?>\n<robot name=\"ur10\">\n  <link name=\"world\"/>\n</robot>\n";
  const std::string errors = load_error(robot_scene("elbow_joint", "tool0", (folder / "world.urdf").string())).what();
  std::filesystem::remove_all(folder);
  EXPECT_CONTAINS(errors, (folder / "world.urdf").string() +
                              ":3: error: the robot's only <link> is \"world\", which stands for the world frame: it needs a link of its own");
}

TEST(Scene, UrdfColoursAreKeptForCameras) {
  // A two-link robot: one link coloured in its visual, one by a named material at the top level.
  const auto folder = std::filesystem::temp_directory_path() / ("m3dp_colour_urdf_" + std::to_string(::getpid()));
  std::filesystem::create_directories(folder);
  {
    std::ofstream urdf(folder / "painted.urdf");
    urdf << R"(<?xml version="1.0"?>
<robot name="painted">
  <material name="orange"><color rgba="1 0.5 0 1"/></material>
  <link name="base"><visual><geometry><box size="0.1 0.1 0.1"/></geometry><material name="grey"><color rgba="0.3 0.3 0.3 1"/></material></visual>
    <collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <link name="arm"><visual><geometry><box size="0.1 0.1 0.1"/></geometry><material name="orange"/></visual>
    <collision><geometry><box size="0.1 0.1 0.1"/></geometry></collision></link>
  <link name="tool0"/>
  <joint name="elbow_joint" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="10" velocity="1"/></joint>
  <joint name="tool" type="fixed"><parent link="arm"/><child link="tool0"/></joint>
</robot>
)";
  }
  const auto scene = load_scene_from_string(robot_scene("elbow_joint", "tool0", (folder / "painted.urdf").string()), "scenes/valid.sdf");
  std::filesystem::remove_all(folder);
  ASSERT_EQ(scene.robots.size(), 1u);
  const auto& colors = scene.robots[0].link_colors;
  ASSERT_EQ(colors.size(), 2u);
  EXPECT_EQ(colors[0].first, "base");
  EXPECT_FLOAT_EQ(colors[0].second[0], 0.3f);
  EXPECT_EQ(colors[1].first, "arm");
  EXPECT_FLOAT_EQ(colors[1].second[1], 0.5f);
}

TEST(Scene, MeshingBlockIsReadAndCheckedAtItsLine) {
  std::string text = valid_scene();
  text.replace(text.find("</plugin>\n  </world>"), 0,
               "  <meshing><method>zhu_bridson</method><period unit=\"ms\">250</period><format>stl</format>"
               "<voxel_size unit=\"mm\">2</voxel_size><material>water</material>"
               "<region><min>0 0 0</min><max>0.5 0.5 0.2</max></region></meshing>\n    ");
  const auto scene = load_scene_from_string(text, "meshing.sdf");
  EXPECT_TRUE(scene.meshing.enabled);
  EXPECT_EQ(scene.meshing.surface.method, m3dp::surface::Method::zhu_bridson);
  EXPECT_NEAR(scene.meshing.period, 0.25, 1e-7);
  EXPECT_EQ(scene.meshing.format, "stl");
  EXPECT_NEAR(scene.meshing.surface.voxel_size, 0.002, 1e-9);
  EXPECT_EQ(scene.meshing.material, "water");
  ASSERT_TRUE(scene.meshing.region.has_value());
  EXPECT_NEAR(scene.meshing.region->max.z(), 0.2, 1e-7);

  std::string bad = valid_scene();
  bad.replace(bad.find("</plugin>\n  </world>"), 0, "  <meshing><method>marching_cubes</method></meshing>\n    ");
  expect_error_at(bad, "<method>marching_cubes",
                  "<method> must be one of: spherical, sph_blobby, zhu_bridson, anisotropic; got 'marching_cubes'");
  std::string unknown = valid_scene();
  unknown.replace(unknown.find("</plugin>\n  </world>"), 0, "  <meshing><material>clay</material></meshing>\n    ");
  expect_error_at(unknown, "<material>clay", "material 'clay' used by <meshing> is not defined");
}

TEST(Scene, GcodePathIsReadRelativeToTheSceneWithWarningsAndErrorsAtTheirLines) {
  const fs::path folder = fs::temp_directory_path() / ("m3dp_test_gcode_scene_" + std::to_string(::getpid()));
  fs::create_directories(folder);
  std::ofstream(folder / "part.gcode") << "M104 S200\nG21\nG90\nM82\nG1 X10 Y10 Z0.3 F6000\nG1 X30 E1 F1200\nG4 S1\n";
  std::ofstream(folder / "bad.gcode") << "G1 X10\nG1 Y\"oops\"\n";
  auto scene_with = [&](const std::string& file) {
    std::string text = valid_scene();
    const std::size_t path_start = text.find("<path");
    const std::size_t path_end = text.find("</path>") + 7;
    text.replace(path_start, path_end - path_start,
                 "<path><gcode file=\"" + file + "\"><pose>1 0 0 0 0 0</pose>"
                 "<filament_diameter unit=\"mm\">2.85</filament_diameter></gcode></path>");
    return text;
  };
  const auto scene = load_scene_from_string(scene_with("part.gcode"), folder / "scene.sdf");
  const auto& trajectory = scene.print_heads.front().trajectory;
  // √200.09 mm of travel at 100 mm/s, 20 mm of printing at 20 mm/s, 1 s dwell.
  const double travel = std::sqrt(200.09) / 100;
  EXPECT_NEAR(trajectory.end_time() - trajectory.start_time(), travel + 1.0 + 1.0, 1e-5);
  const auto printing = trajectory.sample(trajectory.start_time() + travel + 0.5);
  EXPECT_TRUE(printing.extruding);
  EXPECT_NEAR(printing.position.x(), 1.020, 1e-5);  // halfway along X10 → X30, placed 1 m along x, mm → m
  // 1 mm of 2.85 mm filament over 1 s.
  EXPECT_NEAR(printing.volume_rate, m3dp::kPi * 1.425 * 1.425 * 1e-9, 1e-13);
  ASSERT_EQ(scene.warnings.size(), 1u);
  EXPECT_EQ(scene.warnings[0].location.str(), (folder / "part.gcode").string() + ":1");

  const std::string bad = scene_with("bad.gcode");
  try {
    (void)load_scene_from_string(bad, folder / "scene.sdf");
    ADD_FAILURE() << "bad G-code loaded";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), (folder / "bad.gcode").string() + ":2: error:");
  }
  EXPECT_CONTAINS(load_error(scene_with("missing.gcode")).what(), "G-code file 'missing.gcode' not found");
  fs::remove_all(folder);
}

TEST(Scene, MissingPlugin) {
  const std::string text = erased(valid_scene(), "<plugin name=\"m3dp\"", "</output>\n    </plugin>");
  expect_error_at(text, "<world", "missing <plugin name=\"m3dp\" filename=\"m3dp\">");
}

TEST(Scene, DuplicatePlugin) {
  const std::string text =
      replaced(valid_scene(), "  </world>", "    <plugin name=\"m3dp\" filename=\"m3dp\"/>\n  </world>");
  expect_error_at(text, "<plugin name=\"m3dp\" filename=\"m3dp\"/>", "more than one m3dp <plugin>");
}

TEST(Scene, NoFluid) {
  const std::string text = erased(valid_scene(), "<fluid_block", "</print_head>");
  const InputError error = load_error(text);
  EXPECT_CONTAINS(error.what(), "the scene has no fluid: add a <fluid_block> or a <print_head>");
}

TEST(Scene, MalformedXml) {
  const std::string text = replaced(valid_scene(), "</solver>", "</solvr>");
  const InputError error = load_error(text);
  ASSERT_EQ(error.diagnostics().size(), 1u);
  EXPECT_EQ(error.diagnostics()[0].location.line, line_of(text, "</solvr>"));
  EXPECT_CONTAINS(error.what(), "not well-formed XML");
}

TEST(Scene, EveryProblemIsReportedTogether) {
  std::string text = replaced(valid_scene(), R"(<particle_radius unit="mm">5</particle_radius>)",
                              "<particle_radius>-1</particle_radius>");
  text = replaced(text, "<density>1000</density>", "<density>0</density>");
  text = replaced(text, "<exit_speed>0.1</exit_speed>", "<exit_speed>fast</exit_speed>");
  const InputError error = load_error(text);
  EXPECT_GE(error.diagnostics().size(), 3u);
  EXPECT_CONTAINS(error.what(), location_of(text, "<particle_radius>") + " error: <particle_radius> must be > 0 m");
  EXPECT_CONTAINS(error.what(), location_of(text, "<density>") + " error: <density> must be > 0");
  EXPECT_CONTAINS(error.what(),
                  location_of(text, "<exit_speed>") + " error: expected a number in <exit_speed>, got 'fast'");
}

/// Mesh collision shapes are read relative to the scene file's folder and scaled.
class SceneWithMesh : public ::testing::Test {
 protected:
  void SetUp() override {
    std::random_device random;
    folder_ = fs::temp_directory_path() / ("m3dp_test_scene_" + std::to_string(random()));
    fs::create_directories(folder_ / "meshes");
    std::ofstream(folder_ / "meshes" / "triangle.obj") << "v 0 0 0\nv 1000 0 0\nv 0 1000 0\nf 1 2 3\n";
  }
  void TearDown() override {
    std::error_code ignored;
    fs::remove_all(folder_, ignored);
  }
  static std::string with_mesh(const std::string& uri) {
    return replaced(valid_scene(), "<plane><normal>0 0 2</normal><size>2 2</size></plane>",
                    "<mesh>\n            <uri>" + uri + "</uri>\n            <scale>0.001 0.001 0.001</scale>\n"
                    "          </mesh>");
  }
  fs::path folder_;
};

TEST_F(SceneWithMesh, RelativeUriIsReadAndScaled) {
  const auto scene = load_scene_from_string(with_mesh("meshes/triangle.obj"), folder_ / "scene.sdf");
  const auto& shape = scene.bodies.at(0).collisions.at(1).shape;
  ASSERT_TRUE(std::holds_alternative<m3dp::MeshShape>(shape));
  const auto& mesh = std::get<m3dp::MeshShape>(shape);
  EXPECT_EQ(fs::path(mesh.file), folder_ / "meshes" / "triangle.obj");
  ASSERT_EQ(mesh.mesh.vertices.size(), 3u);
  EXPECT_FLOAT_EQ(mesh.mesh.vertices[1].x(), 1.0f);
}

TEST_F(SceneWithMesh, MissingMeshAndModelUriAreReportedAtTheUri) {
  const std::string text = with_mesh("meshes/missing.stl");
  try {
    load_scene_from_string(text, folder_ / "bad.sdf");
    FAIL() << "the scene loaded without an error";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), location_of(text, "<uri>") + " error: cannot load mesh");
    EXPECT_CONTAINS(error.what(), "missing.stl");
  }
  const std::string model_uri = with_mesh("model://robot/meshes/part.stl");
  const InputError error = load_error(model_uri);
  EXPECT_CONTAINS(error.what(), "use a path relative to the scene file's folder");
}

}  // namespace

TEST(Scene, WallAndWaypointPathsAreRead) {
  const auto folder = std::filesystem::temp_directory_path() / ("m3dp_waypoints_" + std::to_string(::getpid()));
  std::filesystem::create_directories(folder);
  {
    std::ofstream csv(folder / "path.csv");
    csv << "x,y,z,speed,extrude\n0 0 0.1 0.1 0\n0.1 0 0.1 0.05 1\n";
    std::ofstream bad(folder / "bad.csv");
    bad << "0 0 0.1 0.1 0\n0.1 0 0.1 fast 1\n";
  }
  std::string text = replaced(valid_scene(), "<line><start>0 0 0.1</start><end>0.1 0 0.1</end></line>",
                              "<wall><corner>0 0 0.01</corner><size>0.2 0.1</size><layers>2</layers>"
                              "<layer_height unit=\"mm\">8</layer_height></wall>\n"
                              "          <waypoints file=\"" + (folder / "path.csv").string() + "\"><pose>0 0 0.5 0 0 0</pose></waypoints>");
  const auto scene = load_scene_from_string(text, "paths.sdf");
  const auto& trajectory = scene.print_heads.at(0).trajectory;
  // Starts at the wall's corner (after the start time) and the waypoints are lifted by the pose.
  EXPECT_TRUE(trajectory.sample(0.5).position.isApprox(Vec3(0, 0, Real(0.01))));
  EXPECT_GT(trajectory.end_time(), 0.5 + (2 * 0.6 + 0.008) / 0.05);

  std::string bad = replaced(text, "path.csv", "bad.csv");
  const InputError error = load_error(bad);
  std::filesystem::remove_all(folder);
  EXPECT_CONTAINS(error.what(), (folder / "bad.csv").string() + ":2: error: field 4 ('fast') is not a number");
  expect_error_at(replaced(valid_scene(), "<line><start>0 0 0.1</start><end>0.1 0 0.1</end></line>",
                           "<wall><corner>0 0 0</corner><size>0.2 0.1</size><layer_height>0.01</layer_height></wall>"),
                  "<wall>", "missing required <layers> in <wall>");
}

TEST(Scene, MissingSceneFileIsNamed) {
  try {
    m3dp::scene::load_scene("no_such_scene.sdf");
    FAIL() << "no error";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), "no_such_scene.sdf");
    EXPECT_CONTAINS(error.what(), "cannot read the scene (expected an SDF world file, e.g. scenes/dam_break.sdf): no such file");
  }
}

namespace {
/// The valid scene with its water replaced by `material` (which must be named "water").
std::string with_material(const std::string& material) {
  return replaced(valid_scene(), R"(<material name="water">
        <density>1000</density>
        <viscosity unit="mPa*s">1</viscosity>
        <boundary_viscosity unit="cP">2</boundary_viscosity>
      </material>)", material);
}
}  // namespace

TEST(SceneMaterials, RheologyAndAgeingAreReadInSiUnits) {
  const auto scene = load_scene_from_string(with_material(R"(<material name="water">
        <density>1800</density>
        <rheology model="herschel_bulkley">
          <yield_stress unit="kPa">1.5</yield_stress>
          <consistency>150</consistency>
          <flow_index>0.35</flow_index>
          <regularization unit="ms">500</regularization>
          <max_viscosity>2e5</max_viscosity>
        </rheology>
        <ageing>
          <structuration_rate unit="Pa/min">60</structuration_rate>
          <viscosity_growth unit="1/min">0.6</viscosity_growth>
        </ageing>
        <boundary_viscosity>no_slip</boundary_viscosity>
      </material>)"), "clay.sdf");
  const auto& material = scene.find_material("water")->material;
  EXPECT_EQ(material.rheology.model, m3dp::material::RheologyModel::herschel_bulkley);
  EXPECT_FLOAT_EQ(material.rheology.yield_stress, 1500.0f);
  EXPECT_FLOAT_EQ(material.rheology.consistency, 150.0f);
  EXPECT_FLOAT_EQ(material.rheology.flow_index, 0.35f);
  EXPECT_FLOAT_EQ(material.rheology.regularization, 0.5f);
  EXPECT_FLOAT_EQ(material.rheology.max_viscosity, 2e5f);
  EXPECT_FLOAT_EQ(material.ageing.structuration_rate, 1.0f);
  EXPECT_FLOAT_EQ(material.ageing.viscosity_growth, 0.01f);
  EXPECT_TRUE(material.sticks_to_walls);
  // The model itself: Herschel–Bulkley stress τ0 (1 − e^(−mγ̇)) + K γ̇ⁿ (Papanastasiou, m = 0.5 s).
  const Real rate = 10;
  const Real stress = material.rheology.effective_viscosity(rate, 1500, 1) * rate;
  EXPECT_NEAR(stress, 1500 * (1 - std::exp(-5.0)) + 150 * std::pow(10.0, 0.35), 1e-4 * stress);
}

TEST(SceneMaterials, SurfaceTensionAndAdhesionInNewtonsPerMetre) {
  const auto scene = load_scene_from_string(with_material(R"(<material name="water" preset="water">
        <adhesion unit="mN/m">145</adhesion>
      </material>)"), "wetting.sdf");
  const auto& material = scene.find_material("water")->material;
  EXPECT_FLOAT_EQ(material.surface_tension, 0.07274f);  // the preset's (IAPWS)
  EXPECT_FLOAT_EQ(material.adhesion, 0.145f);
  try {
    load_scene_from_string(with_material(R"(<material name="water">
        <density>1000</density>
        <viscosity>1</viscosity>
        <surface_tension>-0.07</surface_tension>
      </material>)"), "negative.sdf");
    FAIL() << "no error";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), "negative.sdf:");
    EXPECT_CONTAINS(error.what(), "surface_tension");
  }
}

TEST(SceneMaterials, TheContinuumSurfaceForceIsChosenInTheSolverAndHasNoAdhesion) {
  const std::string csf = replaced(valid_scene(), "<kernel>wendland_c2</kernel>",
                                   "<kernel>wendland_c2</kernel><surface_tension_model>brackbill1992</surface_tension_model>");
  const auto scene = load_scene_from_string(csf, "csf.sdf");
  EXPECT_EQ(scene.solver.surface_tension_model, m3dp::sph::SurfaceTensionModel::csf_brackbill1992);
  EXPECT_EQ(load_scene_from_string(valid_scene(), "default.sdf").solver.surface_tension_model,
            m3dp::sph::SurfaceTensionModel::akinci2013);
  const std::string wetting = replaced(csf, R"(<material name="water">
        <density>1000</density>
        <viscosity unit="mPa*s">1</viscosity>
        <boundary_viscosity unit="cP">2</boundary_viscosity>
      </material>)", R"(<material name="water" preset="water">
        <adhesion unit="mN/m">145</adhesion>
      </material>)");
  try {
    load_scene_from_string(wetting, "wetting.sdf");
    FAIL() << "no error";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), "wetting.sdf:");
    EXPECT_CONTAINS(error.what(), "<adhesion> needs the akinci2013 surface tension model");
  }
  try {
    load_scene_from_string(replaced(valid_scene(), "<kernel>wendland_c2</kernel>",
                                    "<kernel>wendland_c2</kernel><surface_tension_model>csf</surface_tension_model>"),
                           "typo.sdf");
    FAIL() << "no error";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), "typo.sdf:");
    EXPECT_CONTAINS(error.what(), "brackbill1992");
  }
}

TEST(SceneMaterials, PresetWithOverrides) {
  const auto scene = load_scene_from_string(with_material(R"(<material name="water" preset="printable_mortar">
        <rheology><yield_stress>800</yield_stress></rheology>
        <ageing><structuration_rate>2</structuration_rate></ageing>
      </material>)"), "mortar.sdf");
  const auto& material = scene.find_material("water")->material;
  EXPECT_EQ(material.preset, "printable_mortar");
  EXPECT_FLOAT_EQ(material.density, 2100.0f);             // the preset's
  EXPECT_EQ(material.rheology.model, m3dp::material::RheologyModel::bingham);
  EXPECT_FLOAT_EQ(material.rheology.viscosity, 10.0f);    // the preset's plastic viscosity
  EXPECT_FLOAT_EQ(material.rheology.yield_stress, 800.0f);  // overridden
  EXPECT_FLOAT_EQ(material.ageing.structuration_rate, 2.0f);
}

TEST(SceneMaterials, EveryPresetLoadsWithItsSource) {
  const auto presets = m3dp::scene::load_material_presets();
  std::vector<std::string> names;
  for (const auto& entry : presets) {
    names.push_back(entry.material.name);
    EXPECT_GT(entry.material.density, 900.0f) << entry.material.name;
    EXPECT_GT(entry.material.rheology.rest_viscosity(), 0.0f) << entry.material.name;
  }
  for (const char* expected : {"water", "honey", "clay_paste", "printable_mortar", "printable_concrete", "silicone"})
    EXPECT_NE(std::find(names.begin(), names.end(), expected), names.end()) << expected;
  // Each has a <source>: the data file is for looking values up.
  const std::string text = [] {
    std::ifstream file(m3dp::scene::material_presets_file());
    return std::string(std::istreambuf_iterator<char>(file), {});
  }();
  auto occurrences = [&](const std::string& needle) {
    int count = 0;
    for (auto at = text.find(needle); at != std::string::npos; at = text.find(needle, at + 1)) ++count;
    return count;
  };
  EXPECT_EQ(occurrences("<source>"), occurrences("<material name="));
}

TEST(SceneMaterials, MistakesAreReportedAtTheirLines) {
  const std::string unknown_preset = with_material(R"(<material name="water" preset="porridge"/>)");
  expect_error_at(unknown_preset, "preset=\"porridge\"", "unknown material preset 'porridge'; the presets (");
  EXPECT_CONTAINS(load_error(unknown_preset).what(), "water, honey, clay_paste, printable_mortar, printable_concrete, silicone");

  const std::string wrong_child = with_material(R"(<material name="water"><density>2000</density>
        <rheology model="bingham"><yield_stress>100</yield_stress><consistency>3</consistency></rheology></material>)");
  expect_error_at(wrong_child, "<consistency>", "unknown element <consistency> in <rheology>; expected one of: "
                                               "yield_stress, plastic_viscosity, regularization, max_viscosity");
  expect_error_at(wrong_child, "<rheology model=\"bingham\">",
                  "missing required <plastic_viscosity> in <rheology>");

  const std::string no_model = with_material(R"(<material name="water"><density>2000</density>
        <rheology><viscosity>3</viscosity></rheology></material>)");
  expect_error_at(no_model, "<rheology>", "missing required attribute model=\"...\" on <rheology>");

  const std::string unknown_model = with_material(R"(<material name="water"><density>2000</density>
        <rheology model="maxwell"/></material>)");
  expect_error_at(unknown_model, "<rheology model", "unknown rheology model 'maxwell'; expected one of: newtonian, "
                                                    "power_law, cross, carreau, bingham, herschel_bulkley");

  const std::string both = with_material(R"(<material name="water"><density>2000</density><viscosity>1</viscosity>
        <rheology model="newtonian"><viscosity>3</viscosity></rheology></material>)");
  expect_error_at(both, "<viscosity>1", "<material name=\"water\"> has both <viscosity> (a Newtonian fluid) and "
                                        "<rheology> (line");

  const std::string neither = with_material(R"(<material name="water"><density>2000</density></material>)");
  expect_error_at(neither, "<material name=\"water\">", "missing <viscosity> (Pa*s, a Newtonian fluid) or <rheology");

  const std::string bad_index = with_material(R"(<material name="water"><density>2000</density>
        <rheology model="power_law"><consistency>3</consistency><flow_index>-1</flow_index></rheology></material>)");
  expect_error_at(bad_index, "<flow_index>", "<flow_index> must be in (0, 2], got -1");

  const std::string bad_rate = with_material(R"(<material name="water"><density>2000</density><viscosity>1</viscosity>
        <ageing><structuration_rate unit="Pa*s">1</structuration_rate></ageing></material>)");
  expect_error_at(bad_rate, "<structuration_rate", "unit 'Pa*s' on <structuration_rate> is not a stress rate unit");
}

TEST(SceneMaterials, AWrongPresetFileIsReportedAtItsOwnLine) {
  const fs::path file = fs::temp_directory_path() / ("m3dp_presets_" + std::to_string(::getpid()) + ".xml");
  std::ofstream(file) << "<?xml version=\"1.0\"?>\n<materials>\n  <material name=\"paste\">\n"
                         "    <density>-5</density><viscosity>1</viscosity>\n  </material>\n</materials>\n";
  ::setenv("M3DP_MATERIALS", file.c_str(), 1);
  const InputError error = load_error(with_material(R"(<material name="water" preset="paste"/>)"));
  ::unsetenv("M3DP_MATERIALS");
  fs::remove(file);
  EXPECT_CONTAINS(error.what(), file.string() + ":4: error: <density> must be > 0 kg/m^3, got -5");
}

TEST(SceneMaterials, ViscositySolverAndRestSettings) {
  const std::string settings = replaced(valid_scene(), "<end_time>2</end_time>", R"(<end_time>2</end_time>
        <viscosity_solver>explicit</viscosity_solver>
        <max_viscosity_error unit="%">0.5</max_viscosity_error>
        <max_viscosity_iterations>40</max_viscosity_iterations>
        <xsph>0.05</xsph>
        <rest_detection>false</rest_detection>
        <rest_speed unit="mm/s">1</rest_speed>
        <rest_duration unit="ms">80</rest_duration>
        <wake_speed unit="mm/s">4</wake_speed>
        <wake_on_load>true</wake_on_load>
        <load_wake_duration unit="ms">500</load_wake_duration>)");
  const auto scene = load_scene_from_string(settings, "settings.sdf");
  EXPECT_EQ(scene.solver.viscosity_solver, m3dp::sph::ViscositySolver::explicit_morris1997);
  EXPECT_FLOAT_EQ(scene.solver.viscosity_tolerance, 0.005f);
  EXPECT_EQ(scene.solver.max_viscosity_iterations, 40);
  EXPECT_FLOAT_EQ(scene.solver.xsph_factor, 0.05f);
  EXPECT_FALSE(scene.solver.rest_detection);
  EXPECT_FLOAT_EQ(scene.solver.rest_speed, 0.001f);
  EXPECT_FLOAT_EQ(scene.solver.rest_duration, 0.08f);
  EXPECT_FLOAT_EQ(scene.solver.wake_speed, 0.004f);
  EXPECT_TRUE(scene.solver.wake_on_load);
  EXPECT_FLOAT_EQ(scene.solver.load_wake_duration, 0.5f);

  const std::string bad = replaced(valid_scene(), "<end_time>2</end_time>",
                                   "<end_time>2</end_time><viscosity_solver>implicit_weiler</viscosity_solver>");
  expect_error_at(bad, "<viscosity_solver>", "<viscosity_solver> must be one of: implicit (Weiler et al. 2018, any "
                                             "viscosity), explicit (Morris et al. 1997, water-like fluids); got "
                                             "'implicit_weiler'");
  const std::string bad_kernel = replaced(valid_scene(), "<kernel>wendland_c2</kernel>", "<kernel>gaussian</kernel>");
  expect_error_at(bad_kernel, "<kernel>", "<kernel> must be one of: cubic_spline, wendland_c2; got 'gaussian'");
}

TEST(SceneMaterials, GranularMaterialsAreReadAndMayNotMixWithFluids) {
  const auto scene = load_scene_from_string(with_material(R"(<material name="water">
        <density>1800</density>
        <viscosity>0</viscosity>
        <granular>
          <stiffness unit="N/mm">0.2</stiffness>
          <restitution>0.4</restitution>
          <friction>0.7</friction>
        </granular>
      </material>)"), "pellets.sdf");
  const auto& granular = scene.find_material("water")->material.granular;
  EXPECT_TRUE(granular.enabled);
  EXPECT_FLOAT_EQ(granular.stiffness, 200.0f);
  EXPECT_FLOAT_EQ(granular.restitution, 0.4f);
  EXPECT_FLOAT_EQ(granular.friction, 0.7f);
  try {
    load_scene_from_string(with_material(R"(<material name="water">
        <density>1000</density>
        <viscosity>0</viscosity>
        <granular><restitution>1.5</restitution></granular>
      </material>)"), "bouncy.sdf");
    FAIL() << "no error";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), "bouncy.sdf:");
    EXPECT_CONTAINS(error.what(), "restitution");
  }
}

TEST(SceneFiles, EverySceneShippedInScenesLoads) {
  int scenes = 0;
  for (const auto& entry : fs::directory_iterator(M3DP_SCENES)) {
    if (entry.path().extension() != ".sdf") continue;
    ++scenes;
    EXPECT_NO_THROW(m3dp::scene::load_scene(entry.path())) << entry.path();
  }
  EXPECT_GE(scenes, 10);
}

TEST(SceneAir, AnAirBlockSwitchesDragOnWithItsValues) {
  const auto scene = load_scene_from_string(replaced(valid_scene(), R"(<plugin name="m3dp" filename="m3dp">)",
                                                     R"(<plugin name="m3dp" filename="m3dp">
      <air>
        <density>1.1</density>
        <viscosity unit="mPa*s">0.019</viscosity>
        <velocity unit="mm/s">500 0 0</velocity>
      </air>)"),
                                            "windy.sdf");
  EXPECT_TRUE(scene.solver.air_drag);
  EXPECT_FLOAT_EQ(scene.solver.air_density, 1.1f);
  EXPECT_FLOAT_EQ(scene.solver.air_viscosity, 1.9e-5f);
  EXPECT_FLOAT_EQ(scene.solver.air_velocity.x(), 0.5f);
  EXPECT_FALSE(load_scene_from_string(valid_scene(), "still.sdf").solver.air_drag);
}

TEST(SceneMaterials, MicropolarBlockTurnsTheModelOn) {
  const auto scene = load_scene_from_string(with_material(R"(<material name="water" preset="water">
        <micropolar>
          <vortex_viscosity unit="mPa*s">5</vortex_viscosity>
          <microinertia unit="mm^2">0.5</microinertia>
        </micropolar>
      </material>)"), "vortices.sdf");
  const auto& micropolar = scene.find_material("water")->material.micropolar;
  EXPECT_TRUE(micropolar.enabled);
  EXPECT_FLOAT_EQ(micropolar.vortex_viscosity, 0.005f);
  EXPECT_FLOAT_EQ(micropolar.microinertia, 5e-7f);
  EXPECT_FLOAT_EQ(micropolar.angular_smoothing, 0.1f);  // the default
}

TEST(SceneMaterials, ElasticityInPascalsAndSeconds) {
  const auto scene = load_scene_from_string(with_material(R"(<material name="water" preset="clay_paste">
        <elasticity>
          <shear_modulus unit="kPa">20</shear_modulus>
          <poisson_ratio>0.4</poisson_ratio>
          <relaxation_time unit="ms">500</relaxation_time>
        </elasticity>
      </material>)"), "springy.sdf");
  const auto& elasticity = scene.find_material("water")->material.elasticity;
  EXPECT_TRUE(elasticity.enabled);
  EXPECT_FLOAT_EQ(elasticity.shear_modulus, 2e4f);
  EXPECT_FLOAT_EQ(elasticity.poisson_ratio, 0.4f);
  EXPECT_FLOAT_EQ(elasticity.relaxation_time, 0.5f);
  try {
    load_scene_from_string(with_material(R"(<material name="water" preset="clay_paste">
        <elasticity><poisson_ratio>0.5</poisson_ratio></elasticity>
      </material>)"), "rubber.sdf");
    FAIL() << "no error";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), "rubber.sdf:");
    EXPECT_CONTAINS(error.what(), "shear_modulus");
    EXPECT_CONTAINS(error.what(), "poisson_ratio");
  }
}

TEST(SceneMaterials, AnElasticMaterialNeedsTheImplicitSolver) {
  std::string text = replaced(valid_scene(), "<end_time>2</end_time>",
                              "<end_time>2</end_time><viscosity_solver>explicit</viscosity_solver>");
  text = replaced(text, R"(<material name="water">
        <density>1000</density>
        <viscosity unit="mPa*s">1</viscosity>
        <boundary_viscosity unit="cP">2</boundary_viscosity>
      </material>)", R"(<material name="water">
        <density>1000</density>
        <viscosity unit="mPa*s">1</viscosity>
        <elasticity><shear_modulus>1000</shear_modulus></elasticity>
      </material>)");
  expect_error_at(text, "<elasticity>", "<elasticity> needs the implicit viscosity solver");
}

TEST(SceneMaterials, TheEngineChecksAreReportedAtTheirLines) {
  // sph::check_parameters is the one check of engine rules; the scene names the line of each field.
  const std::string poisson = with_material(R"(<material name="water" preset="clay_paste">
        <elasticity>
          <poisson_ratio>0.6</poisson_ratio>
        </elasticity>
      </material>)");
  expect_error_at(poisson, "<poisson_ratio>", "<poisson_ratio> must be in [0, 0.49], got 0.6");
  // Fluids and discrete spheres in one scene: at the material that differs from the first one.
  std::string mixed = replaced(valid_scene(), R"(<material name="water">)", R"(<material name="pellets">
        <density>1500</density>
        <viscosity>0</viscosity>
        <granular/>
      </material>
      <material name="water">)");
  mixed = replaced(mixed, R"(<fluid_block name="column" material="water">)", R"(<fluid_block name="pile" material="pellets">
        <min>0.3 0.3 0.3</min><max>0.4 0.4 0.4</max>
      </fluid_block>
      <fluid_block name="column" material="water">)");
  expect_error_at(mixed, R"(<material name="water">)",
                  "material 'water' is a fluid but material 'pellets' is granular; one scene's materials are all fluids or "
                  "all granular for now");
  const InputError error = load_error(mixed);
  EXPECT_EQ(error.diagnostics().size(), 1u) << error.what();  // said once, not also by the scene reader
}

namespace {
std::string shared_print_scene() {
  std::ifstream file(fs::path(M3DP_SCENES) / "multi_robot_shared.sdf");
  return std::string(std::istreambuf_iterator<char>(file), {});
}
}  // namespace

TEST(Scene, ACoordinatorTakesItsSettingsAndPriorities) {
  const std::string text = shared_print_scene();
  const auto scene = load_scene_from_string(text, "scenes/multi_robot_shared.sdf");
  const auto& coordinator = scene.coordinator;
  EXPECT_TRUE(coordinator.enabled);
  EXPECT_DOUBLE_EQ(coordinator.period, 0.1);
  EXPECT_DOUBLE_EQ(coordinator.horizon, 1.5);
  EXPECT_EQ(coordinator.samples, 6);
  EXPECT_FLOAT_EQ(coordinator.robot_clearance, 0.03F);
  EXPECT_FLOAT_EQ(coordinator.print_clearance, 0.01F);
  EXPECT_EQ(coordinator.priority, (std::vector<std::string>{"turtlebot_1", "turtlebot_2", "turtlebot_3"}));
  EXPECT_FALSE(load_scene_from_string(replaced(text, "      <coordinator>", "      <coordinator enabled=\"false\">"), "x.sdf").coordinator.enabled);
  EXPECT_FALSE(load_scene_from_string(valid_scene(), "scenes/valid.sdf").coordinator.enabled);
}

TEST(Scene, ACoordinatorsMistakesAreErrorsAtTheirLine) {
  const std::string text = shared_print_scene();
  const std::string unknown = replaced(text, "<priority>turtlebot_1 turtlebot_2", "<priority>turtlebot_1 turtlebot_9");
  expect_error_at(unknown, "<priority>", "<priority>: no robot 'turtlebot_9' is included in the world; its robots: turtlebot_1, turtlebot_2, turtlebot_3");
  const std::string twice = replaced(text, "<priority>turtlebot_1 turtlebot_2", "<priority>turtlebot_1 turtlebot_1");
  expect_error_at(twice, "<priority>", "<priority>: robot 'turtlebot_1' is named twice");
  const std::string horizon = replaced(text, "<horizon>1.5</horizon>", "<horizon>-1</horizon>");
  EXPECT_CONTAINS(load_error(horizon).what(), location_of(horizon, "<horizon>") + " error: <horizon>");
  const std::string typo = replaced(text, "<horizon>", "<horizn>");
  EXPECT_CONTAINS(load_error(typo).what(), location_of(typo, "<horizn>"));
  // One robot has no one to make way for.
  const std::string alone = replaced(valid_scene(), "<output>", "<coordinator/><output>");
  expect_error_at(alone, "<coordinator/>", "<coordinator> coordinates robots: the world needs at least two");
}

TEST(Scene, MessagesNameTheElementWrittenAndSuggestTheClosestInThePluginBlock) {
  // The engine's field behind <max_volume_error> is volume_tolerance, behind <shifting>
  // shifting_factor: the messages name what the user wrote, at its line.
  const std::string solver_tail = "<max_time_step>0.005</max_time_step>";
  expect_error_at(replaced(valid_scene(), solver_tail, solver_tail + "\n<max_volume_error>2</max_volume_error>"), "<max_volume_error>",
                  "<max_volume_error> must be in [0, 1), got 2");
  expect_error_at(replaced(valid_scene(), solver_tail, solver_tail + "\n<shifting>20</shifting>"), "<shifting>",
                  "<shifting> must be in [0, 10], got 20");
  EXPECT_EQ(std::string(load_error(replaced(valid_scene(), solver_tail, solver_tail + "\n<max_volume_error>2</max_volume_error>")).what())
                .find("volume_tolerance"),
            std::string::npos);
  // A misspelling inside the plugin block gets the closest name, as SDF elements do.
  expect_error_at(replaced(valid_scene(), solver_tail, solver_tail + "\n<shiftng>2</shiftng>"), "<shiftng>",
                  "unknown element <shiftng> in <solver>; did you mean <shifting>? (expected one of: particle_radius, kernel");
  expect_error_at(replaced(valid_scene(), solver_tail, solver_tail + "\n<max_volum_error>0.5</max_volum_error>"), "<max_volum_error>",
                  "unknown element <max_volum_error> in <solver>; did you mean <max_volume_error>?");
}

TEST(Scene, EveryTableRowRefusesABadValueAtItsLineByItsOwnName) {
  // Each row of the scene table (schema.cpp) with a value to check is given one it must refuse, in
  // its block of the valid scene, and the error names the element at its line (this is the test of
  // each field's range: a negative radius, a zero density...).
  std::size_t checked = 0;
  for (const m3dp::scene::SchemaRow& row : m3dp::scene::schema_rows()) {
    using m3dp::scene::ValueKind;
    std::string bad;
    switch (row.kind) {
      case ValueKind::number:
      case ValueKind::integer:
        if (row.limits.greater_than) bad = fmt::format("{:g}", *row.limits.greater_than);
        else if (row.limits.at_least) bad = fmt::format("{:g}", *row.limits.at_least - 1);
        else if (row.limits.less_than) bad = fmt::format("{:g}", *row.limits.less_than);
        else if (row.limits.at_most) bad = fmt::format("{:g}", *row.limits.at_most + 1);
        break;
      case ValueKind::boolean: bad = "maybe"; break;
      case ValueKind::keyword: bad = "no_such_word"; break;
      case ValueKind::structure: break;
    }
    if (bad.empty()) continue;
    const std::string element = fmt::format("<{0}>{1}</{0}>", row.name, bad);
    std::string text = valid_scene();
    // The block's element, put in its parent's (in the scene's first) where the scene has none: a
    // rheology model in place of the material's <viscosity>, a robot by a name.
    auto opening = [](std::string_view block) {
      if (block.starts_with("rheology ")) return fmt::format("rheology model=\"{}\"", block.substr(9));
      if (block == "robot") return std::string("robot name=\"arm\"");
      return std::string(block);
    };
    auto tag_of = [](std::string_view block) { return std::string(block.substr(0, block.find(' '))); };
    auto parent_of = [](std::string_view block) {
      for (const auto& candidate : m3dp::scene::schema_blocks())
        if (candidate.name == block) return candidate.parent;
      return std::string_view("plugin");
    };
    std::function<void(std::string_view)> ensure = [&](std::string_view block) {
      const std::string tag = tag_of(block);
      if (text.find("<" + tag + ">") != std::string::npos || text.find("<" + tag + " ") != std::string::npos) return;
      const std::string_view parent = parent_of(block);
      ensure(parent);
      if (tag == "rheology") text = replaced(text, "<viscosity unit=\"mPa*s\">1</viscosity>", "");
      const std::string element = fmt::format("<{}></{}>", opening(block), tag);
      if (parent == "plugin")
        text = replaced(text, "<output>", element + "\n      <output>");
      else
        text.insert(text.find(">", text.find("<" + tag_of(parent) + (parent == "material" ? " " : ""))) + 1, element);
    };
    ensure(row.block);
    const std::string block = tag_of(row.block);
    // The element first in its block (replacing one the scene has: no duplicate).
    const std::size_t open = text.find(">", text.find("<" + block)) + 1;
    const std::string existing = fmt::format("<{}>", row.name);
    const std::size_t close_block = text.find("</" + block + ">", open);
    if (const std::size_t at = text.find(existing, open); at != std::string::npos && at < close_block)
      text.erase(at, text.find(fmt::format("</{}>", row.name), at) + row.name.size() + 3 - at);
    text.insert(open, "\n" + element);
    // A number's whole message, its range in SI as the reference gives it ("<density> must be > 0
    // kg/m^3, got 0"); the other kinds' first words.
    const std::string expected =
        row.kind == ValueKind::number    ? fmt::format("<{}> must be {}, got {}", row.name,
                                                       row.limits.describe(m3dp::scene::quantity_info(row.quantity).si_symbol), bad)
        : row.kind == ValueKind::keyword ? fmt::format("<{}> must be one of:", row.name)
        : row.kind == ValueKind::boolean ? fmt::format("<{}> must be true or false", row.name)
                                         : fmt::format("<{}> must be a whole number", row.name);
    SCOPED_TRACE(fmt::format("<{}> in <{}> = {}", row.name, row.block, bad));
    expect_error_at(text, element, expected);
    ++checked;
  }
  EXPECT_GE(checked, 85u);
}

// ---- values replaced by their path (studies, the Python API) ----

m3dp::scene::Scene load_with(const std::vector<m3dp::scene::SceneOverride>& overrides) {
  const std::string text = valid_scene();
  return load_scene_from_string(m3dp::scene::apply_overrides(text, "valid.sdf", overrides), "valid.sdf");
}

std::string override_error(const std::vector<m3dp::scene::SceneOverride>& overrides) {
  try {
    load_with(overrides);
  } catch (const InputError& error) {
    return error.what();
  }
  ADD_FAILURE() << "the overrides were accepted";
  return {};
}

TEST(Scene, OverridesReplaceValuesByTheirPathCheckedAsIfWritten) {
  // An element with a unit (5 mm: the unit goes, the value is SI), a material's by its name, an
  // attribute (the path's speed), an element not written (added), a world element.
  const auto scene = load_with({{"solver.particle_radius", "0.004"},
                                {"material[water].density", "1100"},
                                {"print_head[head].path.speed", "0.07"},
                                {"solver.max_time_step", "0.004"},
                                {"fluid_block[column].max", "0.1 0.1 0.3"},
                                {"gravity", "0 0 -9.81"}});
  EXPECT_FLOAT_EQ(scene.solver.particle_radius, 0.004f);
  EXPECT_FLOAT_EQ(scene.materials[0].material.density, 1100.0f);
  EXPECT_FLOAT_EQ(scene.solver.max_time_step, 0.004f);
  EXPECT_FLOAT_EQ(scene.fluid_blocks[0].box.max.z(), 0.3f);
  EXPECT_FLOAT_EQ(scene.solver.gravity.z(), -9.81f);
  // Lines of the rest of the file stay where they were: an error later in it names its own line.
  const std::string text = replaced(valid_scene(), "<exit_speed>0.1</exit_speed>", "<exit_speed>-1</exit_speed>");
  try {
    load_scene_from_string(m3dp::scene::apply_overrides(text, "valid.sdf", std::vector<m3dp::scene::SceneOverride>{{"solver.particle_radius", "0.004"}}),
                           "valid.sdf");
    ADD_FAILURE() << "a negative exit speed was accepted";
  } catch (const InputError& error) {
    EXPECT_CONTAINS(error.what(), replaced(location_of(text, "<exit_speed>-1"), "bad.sdf", "valid.sdf"));
  }

  // A value out of range is the reader's message for that element; a path that leads nowhere says where it stopped.
  EXPECT_CONTAINS(override_error({{"solver.particle_radius", "-1"}}), "<particle_radius> must be > 0 m, got -1");
  EXPECT_CONTAINS(override_error({{"material[mortar].density", "1"}}),
                  "the value of 'material[mortar].density': <plugin name=\"m3dp\"> has no <material name=\"mortar\"> (its <material>: water)");
  EXPECT_CONTAINS(override_error({{"solver.particle_radus", "0.1"}}), "unknown element <particle_radus> in <solver>; did you mean <particle_radius>?");
  EXPECT_CONTAINS(override_error({{"solver.bounds", "1"}}), "the value of 'solver.bounds': <bounds> holds elements, not a value");
  EXPECT_CONTAINS(override_error({{"solver..cfl_factor", "1"}}), "the value of 'solver..cfl_factor': an empty step at character 8");
}
