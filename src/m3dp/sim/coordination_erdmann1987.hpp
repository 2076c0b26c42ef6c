#pragma once
// Several robots that share a print: prioritized coordination after M. Erdmann, T. Lozano-Pérez,
// "On multiple moving objects", Algorithmica 2 (1987) 477–521 — robots are planned one at a time in
// priority order, each avoiding the ones planned before it as moving obstacles — with each robot
// keeping its path and only its speed along it chosen (the path–velocity decomposition of K. Kant,
// S. Zucker, IJRR 5(3) 1986), as chunk-by-chunk cooperative printers wait for the chunk beside them.
//
// Every period, for each robot in priority order: the largest rate of its plan clock among 1, ½, ¼
// and 0 whose predicted configurations over the horizon (base and tools where its paths put them at
// that rate, the arm by IK) keep robot_clearance from every robot planned before it (at their
// chosen rates) and every robot after it (where it stands now), and print_clearance from the
// printed material (boxes around its particles, fresh or already meshed: the world's mesh is made
// of the same particles, and FCL's mesh distances cost ten times more). Where two
// are closer than a clearance already, a prediction passes if it comes no closer. A stopped robot
// extrudes nothing; a slowed one extrudes in proportion, so its bead keeps its section.
#include <cstdint>
#include <limits>
#include <vector>

#include "m3dp/core/geometry.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/robots.hpp"

namespace m3dp {
class StateWriter;
class StateReader;
}  // namespace m3dp

namespace m3dp::sim {

class Simulation;

/// What the coordinator did for one robot, over the run so far.
struct CoordinationReport {
  double waiting_time = 0;          // s of simulated time stopped before its paths' end
  double slowed_time = 0;           // s at a rate between 0 and 1
  std::uint64_t decisions = 0;      // decisions taken for it
  std::uint64_t conflicts = 0;      // decisions at which full speed would have come too close
  std::uint64_t blocked = 0;        // decisions at which not even standing kept the clearances
  double least_robot_distance = std::numeric_limits<double>::infinity();  // m, to another robot, at decisions
  double least_print_distance = std::numeric_limits<double>::infinity();  // m, to the printed material, at decisions
  double rate = 1;                  // the plan clock's rate now
};

class PrioritizedCoordination {
 public:
  explicit PrioritizedCoordination(const scene::CoordinatorSettings& settings, const scene::Scene& scene);
  /// Decides every robot's clock rate when a period has passed since the last decision (the first
  /// at once). Robots under external control are not decided for; others keep clear of them.
  void update(Simulation& simulation, std::vector<PlanClock>& clocks);
  /// One per scene robot, in scene order.
  [[nodiscard]] const std::vector<CoordinationReport>& reports() const { return reports_; }
  [[nodiscard]] const scene::CoordinatorSettings& settings() const { return settings_; }
  void save(StateWriter& out) const;
  void load(StateReader& in);

 private:
  /// Whether robot `robot` at `rate` keeps its clearances over the horizon, the robots decided
  /// before it at this decision moving at their chosen rates.
  bool keeps_clear(Simulation& simulation, const std::vector<PlanClock>& clocks, std::size_t robot, double rate);
  /// Puts robot `robot` where its paths have it at plan time `plan_time` (s).
  void place(Simulation& simulation, std::size_t robot, double plan_time);
  /// Boxes around every fluid particle, for the world's print_distance.
  void update_print_boxes(Simulation& simulation);

  scene::CoordinatorSettings settings_;
  std::vector<std::size_t> order_;     // scene robots, highest priority first
  std::vector<CoordinationReport> reports_;
  std::vector<double> distance_now_;   // m, robot pairs (row-major, scene order) at this decision
  std::vector<double> print_distance_now_;
  double next_decision_ = 0, last_decision_ = -1;  // s
  std::vector<std::size_t> decided_;   // this decision's robots so far, in priority order
  std::vector<std::pair<world::ToolIndex, world::ToolTarget>> tool_targets_;  // scratch of place
  std::vector<std::int64_t> cell_keys_;  // scratch of update_print_boxes
  std::vector<Aabb> print_boxes_;     // boxes around the particles
};

}  // namespace m3dp::sim
