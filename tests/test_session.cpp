// The session a caller drives (sim::Session, under the Python API): lifecycle, names, the summary,
// commands by name and their refusals.
#include <gtest/gtest.h>

#include <unistd.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "m3dp/sim/presets.hpp"
#include "m3dp/sim/session.hpp"

using namespace m3dp;
namespace fs = std::filesystem;

namespace {
const fs::path kDemo = fs::path(M3DP_SCENES) / "ur10_wall.sdf";
const fs::path kStrand = fs::path(M3DP_SCENES) / "strand.sdf";

template <class Call>
std::string error_of(Call&& call) {
  try {
    call();
  } catch (const Error& error) {
    return error.what();
  }
  return "";
}
}  // namespace

TEST(Session, ThreadsMustBeZeroOrMore) {
  const scene::Scene scene = sim::hydrostatic_scene({});
  EXPECT_NE(error_of([&] { sim::Session session(scene, -1); }).find("threads = -1: expected 0 (every core)"), std::string::npos);
}

TEST(Session, NamesAreLookedUpWithTheSceneNamesInTheError) {
  sim::Session session(scene::load_scene(kDemo), 2);
  EXPECT_EQ(session.robot("ur10"), 0u);
  EXPECT_EQ(session.head("nozzle"), 0u);
  EXPECT_EQ(session.robot_head(0, std::nullopt), 0u);
  EXPECT_EQ(error_of([&] { (void)session.robot("ur5"); }), "no robot 'ur5' in the scene (robots: ur10)");
  EXPECT_EQ(error_of([&] { (void)session.head("extruder"); }), "no print head 'extruder' in the scene (print heads: nozzle)");
  EXPECT_EQ(error_of([&] { (void)session.camera("top"); }), "no camera 'top' in the scene (cameras: overview, wrist)");
  EXPECT_EQ(error_of([&] { session.set_external_control("turtle", true); }),
            "set_external_control: no robot or print head 'turtle' in the scene (robots: ur10; print heads: nozzle)");
  EXPECT_EQ(error_of([&] { session.set_external_control("nozzle", true); }), "print head 'nozzle' is on robot 'ur10': switch the robot");
}

TEST(Session, CloseGivesSummaryJsonOnceAndAgainAndRefusesCommandsAfter) {
  const fs::path folder = fs::temp_directory_path() / ("m3dp_test_session_" + std::to_string(::getpid()));
  fs::remove_all(folder);
  sim::Session session(scene::load_scene(kDemo), 2);
  while (session.simulation().time() < 0.05) session.step();
  session.record(folder, false);
  while (session.simulation().time() < 0.1) session.step();
  EXPECT_FALSE(session.closed());
  const std::string text = session.close();
  EXPECT_TRUE(session.closed());
  EXPECT_EQ(session.close(), text);  // the same, not empty
  std::ifstream file(folder / "summary.json");
  std::stringstream on_disk;
  on_disk << file.rdbuf();
  EXPECT_EQ(nlohmann::json::parse(text), nlohmann::json::parse(on_disk.str()));
  EXPECT_EQ(nlohmann::json::parse(text)["status"], "completed");
  EXPECT_EQ(error_of([&] { session.step(); }), "step: the simulation is closed");
  EXPECT_EQ(error_of([&] { session.record(folder / "again", false); }), "record: the simulation is closed");
  EXPECT_EQ(error_of([&] { session.set_external_control("ur10", true); }), "set_external_control: the simulation is closed");
  EXPECT_EQ(error_of([&] { (void)session.command("set_extrusion"); }), "set_extrusion: the simulation is closed");
  fs::remove_all(folder);
}

TEST(Session, AGantryHeadIsHeldAndReleasedByName) {
  sim::Session session(scene::load_scene(kStrand), 2);
  while (session.simulation().time() < 0.2) session.step();
  const std::size_t even = session.head("even");
  session.set_external_control("even", true);
  EXPECT_EQ(session.simulation().head_control(even), sim::Simulation::HeadControl::external);
  const Vec3 held = session.simulation().nozzle_state(even).pose.position;
  for (int step = 0; step < 50; ++step) session.step();
  EXPECT_EQ(session.simulation().nozzle_state(even).pose.position, held);
  EXPECT_FALSE(session.simulation().nozzle_state(even).extruding);
  session.set_external_control("even", false);
  session.step();
  EXPECT_EQ(session.simulation().head_control(even), sim::Simulation::HeadControl::rejoining);
  while (session.simulation().time() < 1.0) session.step();
  EXPECT_EQ(session.simulation().head_control(even), sim::Simulation::HeadControl::path);
}

TEST(Session, AFailedStepFailsTheRunAndLaterStepsRefuse) {
  sim::HydrostaticSetup setup;
  scene::Scene scene = sim::hydrostatic_scene(setup);
  scene.bodies.clear();  // nothing under the water: it falls out of the bounds
  scene.solver.bounds.min.z() = Real(-0.05);
  sim::Session session(scene, 1);
  std::string failure;
  for (int step = 0; step < 10000 && failure.empty(); ++step) failure = error_of([&] { session.step(); });
  EXPECT_NE(failure.find("left the bounds"), std::string::npos) << failure;
  EXPECT_NE(error_of([&] { session.step(); }).find("the run failed and cannot go on"), std::string::npos);
  const auto summary = nlohmann::json::parse(session.close());
  EXPECT_EQ(summary["status"], "failed");
  EXPECT_NE(summary["error"].get<std::string>().find("left the bounds"), std::string::npos);
}
