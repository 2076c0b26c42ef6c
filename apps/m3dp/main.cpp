// m3dp — command-line front end.
//   m3dp run SCENE [-o DIR] [--until SECONDS] [--threads N] [--record] [--no-coordinator] [--serve [PORT]] [--pace F] [--checkpoint-period S]
//   m3dp run --resume RUN_DIR
//   m3dp validate SCENE
//   m3dp bench [--particles N] [--steps S] ...
//   m3dp mesh INPUT -o OUT [--method M] ...
//   m3dp render RUN_DIR [--time T] [--camera NAME | --eye X Y Z --target X Y Z] -o image.png
//   m3dp view RUN_DIR [--port N]
//   m3dp quality RUN_DIR [--spacing M]
//   m3dp study FILE -o DIR [--scheduler tcp://host:8786] [--workers N] [--report]
#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <atomic>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <cerrno>
#include <filesystem>
#include <string>
#include <vector>

#include <unistd.h>

#include "bench_command.hpp"
#include "mesh_command.hpp"
#include "m3dp/scene/schema.hpp"
#include "quality_command.hpp"
#include "render_command.hpp"
#include "view_command.hpp"
#include "viewer_files.hpp"
#include "m3dp/quality/design.hpp"
#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/checkpoint.hpp"
#include "m3dp/sim/robots.hpp"
#include "m3dp/sim/run.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/world/world.hpp"

namespace {

// The only global: a signal handler can reach nothing else.
std::atomic<bool> g_stop_requested{false};

extern "C" void request_stop(int) { g_stop_requested.store(true); }

/// m3dp study: the study runner is Python (Dask is), so this hands its arguments to Debian's python3
/// (or $M3DP_PYTHON) running m3dp_study, from the build tree's python/ when there, else installed.
int study_command(const std::vector<std::string>& arguments) {
  const char* chosen = std::getenv("M3DP_PYTHON");
  const std::string python = chosen && *chosen ? chosen : "/usr/bin/python3";
  if (std::filesystem::exists(M3DP_BUILD_PYTHON "/m3dp_study")) {
    const char* path = std::getenv("PYTHONPATH");
    const std::string joined = std::string(M3DP_BUILD_PYTHON) + (path && *path ? std::string(":") + path : "");
    ::setenv("PYTHONPATH", joined.c_str(), 1);
  }
  std::vector<std::string> words{python, "-m", "m3dp_study"};
  words.insert(words.end(), arguments.begin(), arguments.end());
  std::vector<char*> argv;
  for (std::string& word : words) argv.push_back(word.data());
  argv.push_back(nullptr);
  ::execv(python.c_str(), argv.data());
  fmt::print(stderr, "m3dp: error: study: cannot start {} (set M3DP_PYTHON to a Python 3 with Dask): {}\n", python, std::strerror(errno));
  return 1;
}

/// `m3dp run`: `options` holds what the command line set (until, progress, record, live stream, pace).
/// `coordinate`: none as the scene says; false switches its <coordinator> off (`--no-coordinator`).
int run_command(const std::filesystem::path& scene_file, std::filesystem::path output, int threads, m3dp::sim::RunOptions options,
                bool coordinate) {
  using namespace m3dp;
  ThreadLimit thread_limit(threads);
  scene::Scene scene = scene::load_scene(scene_file);
  if (!coordinate) scene.coordinator.enabled = false;
  for (const auto& warning : scene.warnings) fmt::print(stderr, "{}: warning: {}\n", warning.location.str(), warning.message);
  if (output.empty()) output = std::filesystem::path("out") / scene_file.stem();
  fmt::print(stderr, "m3dp: {} → {} ({} threads){}\n", scene_file.string(), output.string(), ThreadLimit::active_threads(),
             options.resume ? " resumed from its checkpoint" : "");
  sim::Simulation simulation(scene);
  fmt::print(stderr, "m3dp: {} fluid particles, {} boundary particles in {} bodies, particle radius {} m\n",
             simulation.solver().fluid().size(), simulation.solver().boundary().size(), simulation.solver().bodies().size(),
             scene.solver.particle_radius);

  std::signal(SIGINT, request_stop);
  std::signal(SIGTERM, request_stop);
  options.output_directory = output;
  options.stop_requested = &g_stop_requested;
  const sim::RunSummary summary = sim::run_simulation(simulation, options);
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
  fmt::print("{}", sim::format_summary(summary, output));
  if (summary.status == sim::RunStatus::failed) return 3;
  if (summary.status == sim::RunStatus::interrupted) return 130;
  return 0;
}

int validate_command(const std::filesystem::path& scene_file) {
  const m3dp::scene::Scene scene = m3dp::scene::load_scene(scene_file);
  for (const auto& warning : scene.warnings) fmt::print(stderr, "{}: warning: {}\n", warning.location.str(), warning.message);
  // Robots as a run loads them: DART's URDF loader may reject what the XML check let through, and a
  // mobile base or a mount may name what the robot does not have.
  m3dp::world::World world;
  const std::vector<m3dp::sim::PlanClock> clocks(scene.robots.size());
  const auto head_paths = m3dp::sim::scene_head_paths(scene);
  const auto base_paths = m3dp::sim::scene_base_paths(scene);
  const auto robots = m3dp::sim::add_scene_robots(scene, world, clocks, base_paths);
  m3dp::sim::add_print_head_tools(scene, world, robots, 2 * scene.solver.particle_radius, clocks, head_paths);
  std::size_t collisions = 0;
  for (const auto& body : scene.bodies) collisions += body.collisions.size();
  fmt::print("{}: OK — world '{}', {} static bodies ({} collision shapes), {} dynamic bodies, {} robots, {} materials, {} fluid "
             "blocks, {} print heads, {} s\n",
             scene_file.string(), scene.world_name, scene.bodies.size(), collisions, scene.dynamic_bodies.size(),
             scene.robots.size(), scene.materials.size(), scene.fluid_blocks.size(), scene.print_heads.size(), scene.end_time);
  // What each head's path asks for (the designed print: quality/design.hpp), before anything runs.
  for (const auto& head : scene.print_heads) {
    const auto summary = m3dp::quality::summarize(head.trajectory, m3dp::quality::Nozzle{head.inner_diameter, head.exit_speed, 0});
    fmt::print("  print head '{}': {:.2f} s from {:.2f} s, {:.3f} m extruding and {:.3f} m travelling, {} layer{}, {:.2f} cm3 "
               "commanded",
               head.name, summary.duration, head.trajectory.start_time(), summary.extruding_length, summary.travel_length,
               summary.layers, summary.layers == 1 ? "" : "s", 1e6 * summary.commanded_volume);
    if (summary.commanded_volume > 0)
      fmt::print("; designed bead {:.2f}-{:.2f} mm wide, {:.2f}-{:.2f} mm high", 1e3 * summary.width_min, 1e3 * summary.width_max,
                 1e3 * summary.height_min, 1e3 * summary.height_max);
    fmt::print("\n");
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"M3DP — simulator for robotic and mobile 3D printing"};
  app.require_subcommand(1);

  std::filesystem::path scene_file, output;
  int threads = 0;
  bool quiet = false;
  m3dp::sim::RunOptions run_options;
  std::optional<int> serve_port;
  auto* run = app.add_subcommand("run", "Run a scene and write its results folder");
  run->add_option("scene", scene_file, "Scene file (.sdf)")->check(CLI::ExistingFile);
  std::filesystem::path resume_folder;
  run->add_option("--resume", resume_folder,
                  "Go on with the run in this folder from its last checkpoint, with the scene and options it was started with")
      ->check(CLI::ExistingDirectory);
  run->add_option("--checkpoint-period", run_options.checkpoint_period,
                  "Simulated seconds between checkpoints (checkpoint.bin; default the scene's <output><checkpoint_period>, 0: none)")
      ->check(CLI::NonNegativeNumber);
  run->add_option("-o,--output", output, "Output folder (default out/<scene name>)");
  run->add_option("--until", run_options.until, "Stop at this simulated time in seconds (default: the scene's end_time)")
      ->check(CLI::PositiveNumber);
  run->add_option("--threads", threads, "Worker threads (default: all cores)")->check(CLI::NonNegativeNumber);
  run->add_flag("-q,--quiet", quiet, "No progress bar");
  run->add_flag("--record", run_options.record, "Also write run.mcap: the run in Foxglove's messages (Foxglove, Lichtblick, Rerun)");
  run->add_option("--serve", serve_port, "Stream the run live: a Foxglove WebSocket server on localhost at PORT (default 8765; 0: any free port)")
      ->expected(0, 1)
      ->default_str("8765")
      ->check(CLI::Range(0, 65535));
  bool view_live = false;
  run->add_flag("--view", view_live, "Watch the run in the browser while it runs: --serve, and the viewer's page on the same port");
  run->add_option("--live-rate", run_options.live_rate, "Frames per second the live stream sends at most (default 20)")
      ->check(CLI::PositiveNumber);
  run->add_flag("--hash", run_options.hash,
                "Print a hash of the state after every step (also hashes.csv): the same scene gives the same hashes at a "
                "fixed thread count; meshes then join the world at the step they were asked for");
  bool no_coordinator = false;
  run->add_flag("--no-coordinator", no_coordinator,
                "Switch the scene's <coordinator> off: every robot follows its paths at full speed, whatever it meets");
  run->add_option("--pace", run_options.pace, "Run at most this many times real time (1: real time, to watch it live)")
      ->check(CLI::PositiveNumber);

  std::filesystem::path validate_file;
  auto* validate = app.add_subcommand("validate", "Check a scene file and list every problem with file:line");
  validate->add_option("scene", validate_file, "Scene file (.sdf)")->required()->check(CLI::ExistingFile);

  m3dp::app::BenchOptions bench_options;
  auto* bench = app.add_subcommand("bench", "Measure speed: the solver on a dam break, or the whole ur10_wall print");
  m3dp::app::add_bench_options(*bench, bench_options);

  m3dp::app::MeshOptions mesh_options;
  auto* mesh = app.add_subcommand("mesh", "Turn saved particle frames (.vtu/.ply, or a .pvd sequence) into surface meshes");
  m3dp::app::add_mesh_options(*mesh, mesh_options);

  m3dp::app::ViewOptions view_options;
  auto* view = app.add_subcommand("view", "Watch a recorded run in the browser (or Foxglove): its run.mcap played back");
  m3dp::app::add_view_options(*view, view_options);

  m3dp::app::RenderOptions render_options;
  auto* render = app.add_subcommand("render", "A picture of a saved run at a time, from one of its cameras or any eye point");
  m3dp::app::add_render_options(*render, render_options);

  m3dp::app::QualityOptions quality_options;
  auto* quality = app.add_subcommand("quality", "Measure a finished run's print against its design: quality.json, quality.csv");
  m3dp::app::add_quality_options(*quality, quality_options);

  auto* schema = app.add_subcommand("schema", "Print the scene reference (Markdown): every element the table has, its unit, range, default "
                                              "and meaning, as docs/scene_reference.md holds it");

  auto* study = app.add_subcommand("study", "Run a study of many runs (a TOML file: values to vary, figures to collect) on a local or "
                                            "remote Dask cluster; m3dp study --help for its options");
  // Everything after `study` is the study runner's (its own --help included).
  study->prefix_command();
  study->allow_extras();
  study->set_help_flag();

  CLI11_PARSE(app, argc, argv);
  if (study->parsed()) return study_command(study->remaining());
  try {
    if (run->parsed()) {
      run_options.show_progress = !quiet;
      if (run->count("--serve") > 0 || view_live) run_options.serve_port = static_cast<std::uint16_t>(serve_port.value_or(8765));
      if (run_options.serve_port) run_options.http = m3dp::app::viewer_file;  // the viewer's page on the stream's port
      if (!resume_folder.empty()) {
        // The scene and options the run was started with; a different thread count is allowed but
        // ends differently (bit for bit) from a run never stopped.
        if (!scene_file.empty() || !output.empty() || run_options.until || run_options.checkpoint_period || run_options.record || run_options.hash)
          throw m3dp::Error("--resume takes the scene, the output folder and the options from the checkpoint: give only the folder "
                            "(and --threads, -q, --serve, --view, --pace)");
        const m3dp::sim::CheckpointRun saved = m3dp::sim::read_checkpoint_run(resume_folder);
        if (run->count("--threads") > 0 && threads != saved.threads)
          fmt::print(stderr, "m3dp: warning: the run was checkpointed with --threads {}; with {} it will not end bit for bit as it would have\n",
                     saved.threads, threads);
        else
          threads = saved.threads;
        scene_file = saved.scene_file;
        output = resume_folder;
        run_options.until = saved.until;
        run_options.hash = saved.hash;
        run_options.record = saved.record;
        run_options.wait_for_meshes = saved.wait_for_meshes;
        run_options.checkpoint_period = saved.checkpoint_period;
        run_options.live_rate = saved.live_rate;
        run_options.resume = true;
        fmt::print(stderr, "m3dp: resuming {} at {:.4f} s (step {})\n", resume_folder.string(), saved.time, saved.step);
      } else if (scene_file.empty()) {
        throw m3dp::Error("run: give a scene file (or --resume RUN_DIR)");
      }
      run_options.threads = threads;
      return run_command(scene_file, output, threads, run_options, !no_coordinator);
    }
    if (validate->parsed()) return validate_command(validate_file);
    if (schema->parsed()) {
      fmt::print("{}", m3dp::scene::schema_reference());
      return 0;
    }
    if (bench->parsed()) return m3dp::app::bench_command(bench_options);
    if (mesh->parsed()) return m3dp::app::mesh_command(mesh_options);
    if (quality->parsed()) return m3dp::app::quality_command(quality_options);
    if (render->parsed()) return m3dp::app::render_command(render_options);
    if (view->parsed()) {
      std::signal(SIGINT, request_stop);
      std::signal(SIGTERM, request_stop);
      return m3dp::app::view_command(view_options, g_stop_requested);
    }
  } catch (const m3dp::InputError& error) {
    fmt::print(stderr, "{}\n", error.what());
    fmt::print(stderr, "m3dp: {} problem(s) found\n", error.diagnostics().size());
    return 2;
  } catch (const std::exception& error) {
    fmt::print(stderr, "m3dp: error: {}\n", error.what());
    return 1;
  }
  return 0;
}
