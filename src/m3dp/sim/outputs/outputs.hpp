#pragma once
// The run folder's outputs: each an observer (observer.hpp) in a file of its own, made by its
// factory; run.cpp's kOutputs lists them in the order they observe and finish. A new output is a new
// file here and one row there.
#include <memory>

#include "m3dp/sim/observer.hpp"

namespace m3dp::sim::outputs {

/// s between particle frames in this run (0: none): the scene's, or chosen for the run's length.
[[nodiscard]] double frame_period(const Simulation& simulation, const RunOptions& options);

/// The output's observer for a run, or null where the scene or the options leave it out.
using MakeOutput = std::unique_ptr<RunObserver> (*)(Simulation& simulation, const RunOptions& options);

std::unique_ptr<RunObserver> make_density_check(Simulation& simulation, const RunOptions& options);    // the measured density (always)
std::unique_ptr<RunObserver> make_particle_frames(Simulation& simulation, const RunOptions& options);  // particles/*.vtu, particles.pvd
std::unique_ptr<RunObserver> make_world_frames(Simulation& simulation, const RunOptions& options);     // world/*.vtm, world.pvd
std::unique_ptr<RunObserver> make_run_messages(Simulation& simulation, const RunOptions& options);     // run.mcap, the live stream
std::unique_ptr<RunObserver> make_pace(Simulation& simulation, const RunOptions& options);             // no faster than RunOptions::pace
std::unique_ptr<RunObserver> make_camera_files(Simulation& simulation, const RunOptions& options);     // cameras/NAME/
std::unique_ptr<RunObserver> make_printed_mesh(Simulation& simulation, const RunOptions& options);     // meshes/, the world's printed body
std::unique_ptr<RunObserver> make_quality_report(Simulation& simulation, const RunOptions& options);    // quality.json (the print against its design)
std::unique_ptr<RunObserver> make_state_hash(Simulation& simulation, const RunOptions& options);       // hashes.csv (--hash)
std::unique_ptr<RunObserver> make_timing_table(Simulation& simulation, const RunOptions& options);     // timing.csv
std::unique_ptr<RunObserver> make_run_figures(Simulation& simulation, const RunOptions& options);      // the summary's figures (always)
std::unique_ptr<RunObserver> make_progress_bar(Simulation& simulation, const RunOptions& options);     // the terminal's progress line
std::unique_ptr<RunObserver> make_summary_file(Simulation& simulation, const RunOptions& options);     // summary.json, scene.sdf

}  // namespace m3dp::sim::outputs
