#pragma once
// The world as the outputs that draw it see it (world.pvd, run.mcap, live streams): every body
// with its shapes as triangles in its own frame, each nozzle, each path, once (WorldLayout); and
// where the bodies and nozzles are at a time (WorldPoses). One description, so that every way out
// shows the same scene.
#include <optional>
#include <string>
#include <vector>

#include "m3dp/core/geometry.hpp"
#include "m3dp/sim/simulation.hpp"
#include "m3dp/toolpath/parametric.hpp"

namespace m3dp::sim {

enum class BodyKind { static_body, free_body, robot_link };
[[nodiscard]] const char* body_kind_name(BodyKind kind);  // "static", "body", "link"

struct BodyView {
  std::string name;                       // "ur10/forearm_link", a body's or a static shape's name
  BodyKind kind = BodyKind::static_body;
  std::optional<world::LinkIndex> link;   // where it moves (none: it does not)
  std::string robot;                      // the robot it belongs to, if a link
  TriangleMesh triangles;                 // its collision shapes, in its own frame (m)
  Pose fixed_pose;                        // its frame in the world, when it does not move
  /// Whether it is drawn in a frame of its own (a link or a free body; a static shape is in the world's).
  [[nodiscard]] bool own_frame() const { return kind != BodyKind::static_body; }
};

struct NozzleView {
  std::string name;                       // the print head's
  std::string parent_frame;               // the body it is fixed to, or "world"
  Real inner_diameter = 0;                // m
  TriangleMesh triangles;                 // a short tube above the exit, in the exit frame
};

struct PathView {
  std::string name;                       // the print head's, or the mobile robot's
  bool base_path = false;                 // a mobile base's path (else a nozzle's toolpath)
  std::vector<toolpath::PathVertex> vertices;
  std::size_t index = 0;                  // of the print head, or the robot, in scene order
};

struct WorldLayout {
  std::vector<BodyView> bodies;
  std::vector<NozzleView> nozzles;        // one per print head, in scene order
  std::vector<PathView> paths;
};

/// What does not change during the run. Arcs of paths in chords of at most `max_chord` (m).
[[nodiscard]] WorldLayout world_layout(const Simulation& simulation, Real max_chord = Real(0.002));

struct WorldPoses {
  double time = 0;                                   // s
  std::vector<Pose> bodies;                          // each layout body's frame in the world
  std::vector<Simulation::NozzleState> nozzles;      // each print head's
  std::vector<double> path_times;                    // s: where each layout path is sampled now (its robot's plan clock)
};
[[nodiscard]] WorldPoses world_poses(const Simulation& simulation, const WorldLayout& layout);

/// The part of a path printed by `time` (the path's own: WorldPoses::path_times): each run of extruding moves as a polyline, the last one
/// ending where the path is at `time` when it is extruding then.
[[nodiscard]] std::vector<std::vector<Vec3>> printed_runs(const PathView& path, double time);

}  // namespace m3dp::sim
