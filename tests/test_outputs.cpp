// The run folder: particle frames (.vtu + .pvd), timing.csv and summary.json, no leftovers.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <map>
#include <sstream>

#include "m3dp/core/progress.hpp"
#include "m3dp/core/state_io.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/io/vtk_writer.hpp"
#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/run.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/sim/world_view.hpp"
#include "m3dp/surface/mesh_tools.hpp"
#include "m3dp/surface/surface.hpp"

using namespace m3dp;
namespace fs = std::filesystem;

namespace {
std::string read_text(const fs::path& file) {
  std::ifstream stream(file, std::ios::binary);
  std::stringstream buffer;
  buffer << stream.rdbuf();
  return buffer.str();
}
fs::path fresh_directory(const std::string& name) {
  const fs::path directory = fs::temp_directory_path() / ("m3dp_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(directory);
  return directory;
}

sim::RunSummary run_into(sim::Simulation& simulation, const fs::path& directory) {
  sim::RunOptions options;
  options.output_directory = directory;
  options.show_progress = false;
  return sim::run_simulation(simulation, options);
}
}  // namespace

TEST(Outputs, RunFolderHasFramesTimingAndSummary) {
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.005);
  setup.end_time = 0.1;
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.output.particles_period = Real(0.025);
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("outputs");
  const auto summary = run_into(simulation, directory);
  EXPECT_EQ(summary.status, sim::RunStatus::completed);

  // Frames at t = 0, 0.025, ..., 0.1.
  const std::string pvd = read_text(directory / "particles.pvd");
  std::size_t datasets = 0;
  for (std::size_t at = pvd.find("<DataSet"); at != std::string::npos; at = pvd.find("<DataSet", at + 1)) ++datasets;
  EXPECT_EQ(datasets, 5u);
  EXPECT_EQ(summary.frames_written, 5u);
  EXPECT_NE(pvd.find("file=\"particles/particles_000004.vtu\""), std::string::npos);
  const std::string vtu = read_text(directory / "particles" / "particles_000004.vtu");
  EXPECT_NE(vtu.find("NumberOfPoints=\"" + std::to_string(summary.particles) + "\""), std::string::npos);
  EXPECT_NE(vtu.find("Name=\"velocity\""), std::string::npos);
  EXPECT_EQ(vtu.substr(vtu.size() - 11), "</VTKFile>\n");

  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  EXPECT_EQ(json["status"], "completed");
  EXPECT_EQ(json["particles"].get<std::size_t>(), summary.particles);
  EXPECT_EQ(json["steps"].get<std::int64_t>(), summary.steps);
  EXPECT_NEAR(json["simulated_time_s"].get<double>(), 0.1, 0.01);
  EXPECT_GT(json["real_time_factor"].get<double>(), 0);
  EXPECT_NEAR(json["mass_final_kg"].get<double>(), json["mass_initial_kg"].get<double>(), 1e-9);
  // The tank's walls: every boundary particle static, 12 + 12 + 4 bytes of positions and velocity, 4 of
  // volume, 4 of body and 1 of slip each at least.
  const std::size_t walls = simulation.solver().state().boundary.size();
  EXPECT_GT(walls, 500u);
  EXPECT_EQ(json["boundary"]["particles"].get<std::size_t>(), walls);
  EXPECT_EQ(json["boundary"]["static_particles"].get<std::size_t>(), walls);
  EXPECT_GE(json["boundary"]["megabytes"].get<double>(), 1e-6 * 45 * double(walls));

  const std::string timing = read_text(directory / "timing.csv");
  EXPECT_EQ(timing.rfind("step,time_s,dt_s,particles", 0), 0u);
  // Which limit set each step (column 10): for water settling in a tank, gravity's (a particle moves
  // at most 1 % of a spacing a step from rest) or the CFL condition's, never the smallest step.
  EXPECT_NE(timing.find(",density_error,dt_set_by,"), std::string::npos);
  std::map<std::string, int> set_by;
  std::stringstream rows(timing);
  std::string row;
  std::getline(rows, row);
  while (std::getline(rows, row)) {
    std::stringstream cells(row);
    std::string cell;
    for (int column = 0; column < 10; ++column) std::getline(cells, cell, ',');
    ++set_by[cell];
  }
  for (const auto& [limit, steps] : set_by) std::printf("steps set by %s: %d\n", limit.c_str(), steps);
  EXPECT_GT(set_by["gravity"] + set_by["cfl"], 0);
  EXPECT_EQ(set_by["gravity"] + set_by["cfl"] + set_by["largest"], summary.steps);
  EXPECT_EQ(static_cast<std::int64_t>(std::count(timing.begin(), timing.end(), '\n')), summary.steps + 1);

  for (const auto& entry : fs::recursive_directory_iterator(directory)) {
    const std::string name = entry.path().filename().string();
    EXPECT_EQ(name.find(".tmp"), std::string::npos) << name;
    EXPECT_EQ(name.find(".partial"), std::string::npos) << name;
  }
  fs::remove_all(directory);
}

namespace {
/// A small water tank meshed every `period` seconds (blobby field), no particle frames.
scene::Scene meshed_tank(double end_time, Real period) {
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.005);
  setup.end_time = end_time;
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.output.write_particles = false;
  scene.meshing.enabled = true;
  scene.meshing.period = period;
  scene.meshing.surface.method = surface::Method::sph_blobby;
  return scene;
}

}  // namespace

TEST(Outputs, ParticleFramesKeepALongRunsFolderReasonableAndZeroSaysNone) {
  // Without <particles_period>: 0.02 s for a run of up to 10 s, else the next 1, 2 or 5 × 10^k s that
  // keeps it to 500 frames (a 15-minute print: one every 2 s, 450 frames, not 45,000).
  const scene::OutputSettings unset;
  for (const auto& [end_time, period] : std::vector<std::pair<double, double>>{
           {1, 0.02}, {10, 0.02}, {12, 0.05}, {31, 0.1}, {60, 0.2}, {900, 2}, {3600, 10}, {86400, 200}})
    EXPECT_DOUBLE_EQ(scene::particle_frame_period(unset, end_time), period) << end_time << " s";
  scene::OutputSettings given;
  given.particles_period = Real(0.5);
  EXPECT_FLOAT_EQ(float(scene::particle_frame_period(given, 900)), 0.5f);

  // A short run chosen for, and a run with <particles_period>0: the summary says which, and why.
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.005);
  setup.end_time = 0.06;
  for (const std::optional<Real> period : {std::optional<Real>(), std::optional<Real>(Real(0))}) {
    scene::Scene scene = sim::hydrostatic_scene(setup);
    scene.output.particles_period = period;
    sim::Simulation simulation(scene);
    const fs::path directory = fresh_directory("frame_period");
    const auto summary = run_into(simulation, directory);
    const std::string text = sim::format_summary(summary, directory);
    const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
    if (!period) {
      EXPECT_EQ(summary.frames_written, 4u);  // 0, 0.02, 0.04, 0.06
      EXPECT_NE(text.find("4 particle frames, one every 0.02 s (chosen for a 0.06 s run: at most 500 frames; "
                          "<output><particles_period> sets it)"),
                std::string::npos)
          << text;
      EXPECT_TRUE(json["particle_frame_period_chosen"].get<bool>());
    } else {
      EXPECT_EQ(summary.frames_written, 0u);
      EXPECT_FALSE(fs::exists(directory / "particles.pvd"));
      EXPECT_NE(text.find("(no particle frames: <output><particles_period> is 0)"), std::string::npos) << text;
      EXPECT_EQ(json["particle_frame_period_s"].get<double>(), 0.0);
    }
  }
}

TEST(Outputs, MeshesAreMadeDuringTheRunAndOfTheFinalState) {
  scene::Scene scene = meshed_tank(0.1, Real(0.04));
  scene.meshing.format = "stl";
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("meshing");
  const auto summary = run_into(simulation, directory);
  ASSERT_EQ(summary.status, sim::RunStatus::completed);
  EXPECT_TRUE(summary.error.empty()) << summary.error;

  // Requested at 0.04 and 0.08 (either may be skipped while the mesher is busy), plus the final state.
  EXPECT_EQ(summary.meshes_written + summary.meshes_skipped, 3u);
  EXPECT_GE(summary.meshes_written, 2u);
  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  ASSERT_EQ(json["meshes"].size(), summary.meshes_written);
  const auto& last = json["meshes"].back();
  EXPECT_NEAR(last["time_s"].get<double>(), summary.simulated_time, 1e-9);
  EXPECT_EQ(last["particles"].get<std::size_t>(), summary.particles);
  // The file is where the summary says, relative to the run folder, and holds the triangles it lists.
  const fs::path file = directory / last["file"].get<std::string>();
  ASSERT_TRUE(fs::exists(file)) << file;
  EXPECT_EQ(fs::file_size(file), 84 + 50 * last["triangles"].get<std::uintmax_t>());  // binary STL
  fs::remove_all(directory);
}

TEST(Outputs, AMeshThatCannotBeWrittenFailsTheRun) {
  // A directory where the second mesh goes: the first is written, the second (and the final state's,
  // which takes its name) fail, and the run says failed (exit 3 from m3dp run), not completed.
  scene::Scene scene = meshed_tank(0.1, Real(0.04));
  scene.meshing.format = "stl";
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("mesh_fails");
  fs::create_directories(directory / "meshes" / "mesh_000001.stl");
  sim::RunOptions options;
  options.output_directory = directory;
  options.show_progress = false;
  options.wait_for_meshes = true;
  const auto summary = sim::run_simulation(simulation, options);
  EXPECT_EQ(summary.status, sim::RunStatus::failed);
  EXPECT_NE(summary.error.find("mesh at t = 0.08"), std::string::npos) << summary.error;
  // It names the output that failed, and that the simulation itself completed.
  EXPECT_NE(summary.error.find("the printed-material meshes failed: "), std::string::npos) << summary.error;
  EXPECT_NE(summary.error.find("the simulation completed; every other output was written"), std::string::npos) << summary.error;
  EXPECT_NE(summary.error.find("mesh_000001.stl"), std::string::npos) << summary.error;
  EXPECT_NEAR(summary.simulated_time, 0.1, 0.01);  // the simulation itself went on to the end
  EXPECT_EQ(summary.meshes_written, 1u);           // t = 0.04 only
  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  EXPECT_EQ(json["status"], "failed");
  EXPECT_EQ(json["error"], summary.error);
  EXPECT_NE(sim::format_summary(summary, directory).find("Run failed"), std::string::npos);
  fs::remove_all(directory);
}

TEST(Outputs, APourInPlaceIsNotMeasuredAndTheRunCompletes) {
  // A nozzle that pours where it stands (its path 1 mm long over 1 s, 0.3 mm of it laid by the end):
  // the commanded flow over the path's speed designs a bead 0.64 m wide (213 m for the bench's 0.3 m
  // nozzle), whose fill grid threw std::bad_alloc at the end of the run and failed it (issue 56). The
  // report says why it measures nothing, and the run completes.
  const scene::Scene scene = scene::load_scene_from_string(R"(<?xml version="1.0"?>
<sdf version="1.9"><world name="pour">
  <model name="floor"><static>true</static><link name="floor"><collision name="floor">
    <pose>0 0 -0.01 0 0 0</pose><geometry><box><size>0.3 0.3 0.02</size></box></geometry>
  </collision></link></model>
  <plugin name="m3dp" filename="m3dp">
    <solver><particle_radius unit="mm">2</particle_radius><end_time>0.3</end_time>
      <bounds><min>-0.15 -0.15 -0.05</min><max>0.15 0.15 0.2</max></bounds></solver>
    <material name="paste"><density>1500</density><viscosity>100</viscosity></material>
    <print_head name="nozzle" material="paste">
      <nozzle><inner_diameter unit="mm">20</inner_diameter><exit_speed>0.1</exit_speed></nozzle>
      <path speed="0.001"><line><start>0 0 0.05</start><end>0.001 0 0.05</end></line></path>
    </print_head>
  </plugin>
</world></sdf>)", "pour.sdf");
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("pour_in_place");
  const auto summary = run_into(simulation, directory);
  EXPECT_EQ(summary.status, sim::RunStatus::completed) << summary.error;
  ASSERT_TRUE(summary.quality.has_value());
  EXPECT_TRUE(summary.quality->file.empty());
  EXPECT_NE(summary.quality->note.find("head 'nozzle' extrudes along 0.301 mm of path, less than its bead is wide (0.639 m"), std::string::npos)
      << summary.quality->note;
  EXPECT_NE(summary.quality->note.find("a pour in place"), std::string::npos) << summary.quality->note;
  EXPECT_FALSE(fs::exists(directory / "quality.json"));
  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  EXPECT_EQ(json["status"], "completed");
  EXPECT_EQ(json["quality"]["note"], summary.quality->note);
  EXPECT_NE(sim::format_summary(summary, directory).find("quality     not measured: head 'nozzle'"), std::string::npos);
  fs::remove_all(directory);
}

TEST(Outputs, AFrameThatCannotBeWrittenStopsTheRunAndTheOutputsStillFinish) {
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.005);
  setup.end_time = 0.1;
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.output.particles_period = Real(0.025);
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("frame_fails");
  fs::create_directories(directory / "particles" / "particles_000002.vtu");
  sim::RunOptions options;
  options.output_directory = directory;
  options.show_progress = false;
  const auto summary = sim::run_simulation(simulation, options);
  EXPECT_EQ(summary.status, sim::RunStatus::failed);
  EXPECT_NE(summary.error.find("particles_000002.vtu"), std::string::npos) << summary.error;
  EXPECT_NEAR(summary.simulated_time, 0.05, 0.005);
  // The frames before it are listed and the summary and timing table are whole.
  const std::string pvd = read_text(directory / "particles.pvd");
  EXPECT_NE(pvd.find("particles_000001.vtu"), std::string::npos);
  EXPECT_EQ(pvd.find("particles_000002.vtu"), std::string::npos);
  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  EXPECT_EQ(json["status"], "failed");
  const std::string timing = read_text(directory / "timing.csv");
  EXPECT_EQ(static_cast<std::int64_t>(std::count(timing.begin(), timing.end(), '\n')), summary.steps + 1);
  fs::remove_all(directory);
}

TEST(Outputs, MeshingRegionSelectsTheParticlesInside) {
  scene::Scene scene = meshed_tank(0.02, Real(1));  // only the final state is meshed
  scene.meshing.material = scene.materials.front().material.name;
  scene.meshing.region = Aabb{Vec3(-1, -1, -1), Vec3(1, 1, Real(0.05))};  // the lower half of the column
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("meshing_region");
  const auto summary = run_into(simulation, directory);
  ASSERT_EQ(summary.meshes_written, 1u);
  std::size_t below = 0;
  for (const Vec3& p : simulation.solver().fluid().position) below += p.z() < Real(0.05) ? 1 : 0;
  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  EXPECT_EQ(json["meshes"][0]["particles"].get<std::size_t>(), below);
  EXPECT_LT(below, summary.particles);
  fs::remove_all(directory);
}

TEST(Outputs, StopRequestEndsCleanlyWithSummary) {
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.005);
  scene::Scene scene = sim::hydrostatic_scene(setup);
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("stop");
  std::atomic<bool> stop{true};
  sim::RunOptions options;
  options.output_directory = directory;
  options.show_progress = false;
  options.stop_requested = &stop;
  const auto summary = sim::run_simulation(simulation, options);
  EXPECT_EQ(summary.status, sim::RunStatus::interrupted);
  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  EXPECT_EQ(json["status"], "interrupted");
  EXPECT_TRUE(fs::exists(directory / "timing.csv"));
  fs::remove_all(directory);
}

TEST(Outputs, ExplodingStateStopsWithAReport) {
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.005);
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.solver.max_speed = Real(0.05);  // gravity alone exceeds this within a few steps once the block drops
  scene.fluid_blocks[0].box.min.z() += Real(0.05);
  scene.fluid_blocks[0].box.max.z() += Real(0.05);
  sim::Simulation simulation(scene);
  const auto summary = sim::run_simulation(simulation, {});
  EXPECT_EQ(summary.status, sim::RunStatus::failed);
  EXPECT_NE(summary.error.find("unstable at t = "), std::string::npos) << summary.error;
  EXPECT_NE(summary.error.find("particle"), std::string::npos);
  EXPECT_LT(summary.simulated_time, 0.1);
}

TEST(Outputs, MaterialLeavingTheBoundsFailsTheRun) {
  // No floor under the block: it falls out of the bounds within a few tenths of a second, which
  // must not end "completed" (a run where nearly every particle left once did).
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.005);
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.bodies.clear();
  scene.solver.bounds.min.z() = Real(-0.05);
  sim::Simulation simulation(scene);
  const auto summary = sim::run_simulation(simulation, {});
  EXPECT_EQ(summary.status, sim::RunStatus::failed);
  EXPECT_NE(summary.error.find("% of the material, left the bounds"), std::string::npos) << summary.error;
  EXPECT_NE(summary.error.find("<bounds>"), std::string::npos) << summary.error;
  // It stops when more than half has gone, not at the first particle out.
  EXPECT_GT(summary.mass_lost, 0.5 * summary.mass_initial);
  EXPECT_LT(summary.mass_lost, 0.9 * summary.mass_initial);
  EXPECT_LT(summary.simulated_time, 0.5);
}

TEST(Outputs, ProgressLineShowsTimeSpeedParticlesAndEta) {
  ProgressSample sample;
  sample.simulated_time_s = 0.5;
  sample.end_time_s = 2.0;
  sample.steps = 100;
  sample.particles = 1234;
  sample.wall_time_s = 10.0;
  const std::string line = ProgressBar::format_line(sample, 20);
  EXPECT_NE(line.find("25.0%"), std::string::npos) << line;
  EXPECT_NE(line.find("t=0.500/2.000 s"), std::string::npos) << line;
  EXPECT_NE(line.find("10 steps/s"), std::string::npos) << line;
  EXPECT_NE(line.find("RTF 0.05"), std::string::npos) << line;
  EXPECT_NE(line.find("1234 particles"), std::string::npos) << line;
  EXPECT_NE(line.find("ETA 00:30"), std::string::npos) << line;
  EXPECT_EQ(line.find("rho/rho0"), std::string::npos) << "no density measured yet: none shown: " << line;
  sample.density_error_p99 = 0.0123;
  sample.density_error_max = -0.004;
  const std::string with_density = ProgressBar::format_line(sample, 20);
  EXPECT_NE(with_density.find("rho/rho0-1 p99 +1.23% max -0.40%"), std::string::npos) << with_density;
}

TEST(Outputs, RobotRunsReportRobotsNozzlesAndWorldTimes) {
  // The first 3 s of the demo: the UR10 travels to the wall's corner and starts laying material.
  scene::Scene scene = scene::load_scene(fs::path(M3DP_SCENES) / "ur10_wall.sdf");
  scene.output.write_particles = false;
  scene.meshing.enabled = false;
  scene.end_time = 3;
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("robot_run");
  const auto summary = run_into(simulation, directory);
  ASSERT_EQ(summary.status, sim::RunStatus::completed);
  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  ASSERT_EQ(json["robots"].size(), 1u);
  const auto& robot = json["robots"][0];
  EXPECT_EQ(robot["name"], "ur10");
  EXPECT_EQ(robot["contacts_with_robots"].get<std::uint64_t>(), 0u);
  EXPECT_GT(robot["nozzle_tracking_max_m"].get<double>(), 0.0);
  EXPECT_LT(robot["nozzle_tracking_rms_m"].get<double>(), 1e-3);
  EXPECT_FALSE(robot.contains("base"));  // a fixed arm has no mobile base report
  ASSERT_EQ(json["nozzles"].size(), 1u);
  EXPECT_EQ(json["nozzles"][0]["particles_emitted"].get<std::uint64_t>(), summary.particles_emitted);
  EXPECT_GT(summary.particles_emitted, 0u);
  // The robot's stages have their own columns in the timing table.
  const std::string timing = read_text(directory / "timing.csv");
  EXPECT_NE(timing.find(",ms_coupling,ms_world,"), std::string::npos);
  fs::remove_all(directory);
}

TEST(Outputs, MaterialAtRestIsMeshedIncrementallyAndGivesTheWholeFramesMesh) {
  // A slab of yield-stress paste settles and comes to rest; it is meshed every 0.05 s. Once at rest
  // its field is kept between meshes, and the last mesh is the one the whole frame gives.
  sim::PasteSlabSetup setup;
  setup.half_width = Real(0.03);
  setup.end_time = 0.3;
  scene::Scene scene = sim::paste_slab_scene(setup);
  scene.meshing.enabled = true;
  scene.meshing.period = Real(0.05);
  scene.meshing.format = "obj";
  scene.meshing.surface.method = surface::Method::sph_blobby;
  sim::Simulation simulation(scene);
  const fs::path directory = fresh_directory("incremental_meshing");
  sim::RunOptions options;
  options.output_directory = directory;
  options.show_progress = false;
  options.wait_for_meshes = true;
  const auto summary = sim::run_simulation(simulation, options);
  ASSERT_EQ(summary.status, sim::RunStatus::completed);
  ASSERT_GT(summary.particles_at_rest, summary.particles * 9 / 10);

  const auto json = nlohmann::json::parse(read_text(directory / "summary.json"));
  const auto& meshes = json["meshes"];
  ASSERT_GE(meshes.size(), 5u);
  std::printf("particles reused from the kept field, mesh by mesh:");
  for (const auto& mesh : meshes) std::printf(" %zu/%zu", mesh["reused_particles"].get<std::size_t>(), mesh["particles"].get<std::size_t>());
  std::printf("\ntiles meshed again, mesh by mesh:");
  for (const auto& mesh : meshes) std::printf(" %zu/%zu", mesh["remeshed_tiles"].get<std::size_t>(), mesh["tiles"].get<std::size_t>());
  std::printf("\n");
  const auto& last = meshes.back();
  EXPECT_GT(last["reused_particles"].get<std::size_t>(), summary.particles * 9 / 10);
  // Nothing moves at the end: the last mesh reuses every tile's triangles.
  EXPECT_GT(last["tiles"].get<std::size_t>(), 0u);
  EXPECT_EQ(last["remeshed_tiles"].get<std::size_t>(), 0u);
  const TriangleMesh written = io::read_triangle_mesh(directory / last["file"].get<std::string>());
  surface::SurfaceSettings settings = scene.meshing.surface;
  settings.particle_radius = scene.solver.particle_radius;
  const TriangleMesh whole = surface::reconstruct_surface(simulation.solver().fluid().position, settings);
  EXPECT_EQ(written.triangles.size(), whole.triangles.size());
  EXPECT_NEAR(surface::signed_volume(written), surface::signed_volume(whole), 1e-4 * surface::signed_volume(whole));
  fs::remove_all(directory);
}

TEST(Checkpoint, ASimulationLoadedFromItsStateStepsOnBitForBit) {
  // A gantry nozzle printing clay: emission, implicit viscosity with its warm starts, material coming
  // to rest, kept neighbour lists. One simulation saves its state (and drops its caches, as a run
  // that writes a checkpoint does), another made from the same scene loads it: they step on the same.
  sim::WallPrintSetup setup;
  setup.layers = 2;
  setup.particle_radius = Real(0.002);
  const scene::Scene scene = sim::wall_print_scene(setup);
  sim::Simulation original(scene);
  while (original.solver().fluid().size() < 300) original.step();
  StateWriter saved;
  original.save_state(saved);
  original.drop_caches();
  sim::Simulation resumed(scene);
  StateReader reader(saved.bytes(), "test checkpoint");
  resumed.load_state(reader);
  EXPECT_EQ(reader.remaining(), 0u);
  ASSERT_GT(original.solver().state().active_count, 0u);
  EXPECT_EQ(resumed.time(), original.time());
  for (int step = 0; step < 150; ++step) {
    original.step();
    resumed.step();
  }
  const auto& a = original.solver().fluid();
  const auto& b = resumed.solver().fluid();
  ASSERT_EQ(a.size(), b.size());
  EXPECT_GT(a.size(), 300u);  // printing went on
  EXPECT_EQ(std::memcmp(a.position.data(), b.position.data(), a.size() * sizeof(Vec3)), 0);
  EXPECT_EQ(std::memcmp(a.velocity.data(), b.velocity.data(), a.size() * sizeof(Vec3)), 0);
  EXPECT_EQ(a.id, b.id);
  EXPECT_EQ(original.solver().state().active_count, resumed.solver().state().active_count);
  EXPECT_EQ(original.time(), resumed.time());
}

TEST(Checkpoint, PathsTargetsAndCommandsGivenAtRunTimeAreInTheCheckpoint) {
  // A gantry head given a new path (a circle) and then a target with extrusion commanded: a
  // simulation loaded from its state follows the same new plans bit for bit, where one made from
  // the scene alone would follow the scene's path.
  sim::WallPrintSetup setup;
  setup.layers = 2;
  setup.particle_radius = Real(0.002);
  const scene::Scene scene = sim::wall_print_scene(setup);
  sim::Simulation original(scene);
  while (original.solver().fluid().size() < 200) original.step();
  const Vec3 here = original.nozzle_state(0).pose.position;
  toolpath::PathSegment circle;
  circle.curve = toolpath::CircleCurve{here + Vec3(0, Real(0.02), Real(0.004)), Real(0.02), Real(-kPi / 2), Real(0.5)};
  circle.speed = Real(0.05);
  original.set_head_path(0, {circle}, 0.05, false);
  for (int step = 0; step < 40; ++step) original.step();
  original.command_head_target(0, world::ToolTarget{original.nozzle_state(0).pose.position + Vec3(0, 0, Real(0.01)), Vec3(0, 0, -1)},
                               world::MotionLimits{0.05, 0.5});
  original.command_head(0, sim::Simulation::HeadCommand{true, Real(0.5)});
  for (int step = 0; step < 10; ++step) original.step();
  StateWriter saved;
  original.prepare_checkpoint();
  original.save_state(saved);
  original.drop_caches();
  sim::Simulation resumed(scene);
  StateReader reader(saved.bytes(), "test checkpoint");
  resumed.load_state(reader);
  EXPECT_EQ(reader.remaining(), 0u);
  EXPECT_EQ(resumed.head_control(0), sim::Simulation::HeadControl::external);
  EXPECT_EQ(resumed.head_command(0).flow_scale, Real(0.5));
  EXPECT_EQ(resumed.head_path(0).end_time(), original.head_path(0).end_time());
  EXPECT_NE(resumed.head_path(0).end_time(), scene.print_heads[0].trajectory.end_time());  // the scene keeps its own
  for (int step = 0; step < 100; ++step) {
    original.step();
    resumed.step();
  }
  EXPECT_EQ(original.nozzle_state(0).pose.position, resumed.nozzle_state(0).pose.position);
  const auto& a = original.solver().fluid();
  const auto& b = resumed.solver().fluid();
  ASSERT_EQ(a.size(), b.size());
  EXPECT_EQ(std::memcmp(a.position.data(), b.position.data(), a.size() * sizeof(Vec3)), 0);
  // Released, the head goes back to its (new) path in both.
  original.release_head(0);
  resumed.release_head(0);
  for (int step = 0; step < 300; ++step) {
    original.step();
    resumed.step();
  }
  EXPECT_EQ(original.head_control(0), resumed.head_control(0));
  EXPECT_EQ(original.nozzle_state(0).pose.position, resumed.nozzle_state(0).pose.position);
}

TEST(Checkpoint, DamagedOrForeignCheckpointsAreErrorsThatNameTheFile) {
  sim::HydrostaticSetup setup;
  setup.particle_radius = Real(0.01);
  const scene::Scene scene = sim::hydrostatic_scene(setup);
  sim::Simulation simulation(scene);
  simulation.step();
  StateWriter saved;
  simulation.save_state(saved);
  auto error_loading = [&](std::string_view bytes) -> std::string {
    sim::Simulation other(scene);
    StateReader reader(bytes, "run/checkpoint.bin");
    try {
      other.load_state(reader);
    } catch (const InputError& error) {
      return error.what();
    }
    return "no error";
  };
  const std::string& bytes = saved.bytes();
  EXPECT_NE(error_loading(std::string_view(bytes).substr(0, bytes.size() / 2)).find("run/checkpoint.bin: error: damaged checkpoint: "),
            std::string::npos);
  using namespace std::string_view_literals;
  EXPECT_EQ(error_loading("\x0a\0\0\0\0\0\0\0simulaXion"sv).find("run/checkpoint.bin: error: not a checkpoint this version of m3dp can continue"),
            0u);
  // Another scene's state: another number of bodies.
  sim::HydrostaticSetup wider = setup;
  wider.width = Real(0.2);
  sim::Simulation other_scene(sim::hydrostatic_scene(wider));
  other_scene.step();
  StateWriter foreign;
  other_scene.save_state(foreign);
  const std::string mismatch = error_loading(foreign.bytes());
  EXPECT_NE(mismatch.find("run/checkpoint.bin: error: damaged checkpoint"), std::string::npos) << mismatch;
}

TEST(Outputs, APathSlowedByTheCoordinatorIsDrawnPrintedAsFarAsItsNozzleGot) {
  // multi_robot_shared at 9 s: turtlebot_2 has been slowed and stopped for turtlebot_1's arm since
  // 6.9 s, so its nozzle is behind where its path would be at 9 s. What world.pvd and run.mcap draw
  // as printed (and the nozzle's tracking error they report) follow the robot's plan clock, not the
  // world's: the printed run ends at the nozzle.
  const auto scene = scene::load_scene(std::filesystem::path(M3DP_SCENES) / "multi_robot_shared.sdf");
  sim::Simulation simulation(scene);
  while (simulation.time() < 9) simulation.step();
  const std::size_t head = 1;  // nozzle_2, on turtlebot_2
  ASSERT_LT(simulation.plan_clock(1).at(simulation.time()), simulation.time() - 0.5);
  const sim::WorldLayout layout = sim::world_layout(simulation);
  const sim::WorldPoses poses = sim::world_poses(simulation, layout);
  const auto runs = sim::printed_runs(layout.paths[head], poses.path_times[head]);
  ASSERT_FALSE(runs.empty());
  const Vec3 printed_end = runs.back().back();
  const Vec3 nozzle = simulation.nozzle_state(head).pose.position;
  std::printf("nozzle_2 at x = %.4f m, printed to x = %.4f m (at world time: %.4f m)\n", nozzle.x(), printed_end.x(),
              sim::printed_runs(layout.paths[head], simulation.time()).back().back().x());
  EXPECT_NEAR(printed_end.x(), nozzle.x(), 0.002);
  EXPECT_LT(sim::printed_runs(layout.paths[head], simulation.time()).back().back().x(), nozzle.x() - 0.02);
}
