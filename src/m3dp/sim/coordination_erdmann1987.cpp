#include "m3dp/sim/coordination_erdmann1987.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "m3dp/core/state_io.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

namespace {
constexpr std::array<double, 4> kRates = {1.0, 0.5, 0.25, 0.0};
/// A prediction already closer than its clearance passes if it comes no closer than this (m) more.
constexpr double kDistanceTolerance = 1e-4;

/// Where a clearance check draws its line: the clearance, or the distance now where that is less.
double threshold(double clearance, double distance_now) {
  return std::min(clearance, distance_now - kDistanceTolerance);
}
}  // namespace

PrioritizedCoordination::PrioritizedCoordination(const scene::CoordinatorSettings& settings, const scene::Scene& scene)
    : settings_(settings), reports_(scene.robots.size()) {
  for (const auto& name : settings.priority)
    for (std::size_t r = 0; r < scene.robots.size(); ++r)
      if (scene.robots[r].name == name) order_.push_back(r);
  for (std::size_t r = 0; r < scene.robots.size(); ++r)
    if (std::find(order_.begin(), order_.end(), r) == order_.end()) order_.push_back(r);
  distance_now_.assign(scene.robots.size() * scene.robots.size(), std::numeric_limits<double>::infinity());
  print_distance_now_.assign(scene.robots.size(), std::numeric_limits<double>::infinity());
}

void PrioritizedCoordination::place(Simulation& simulation, std::size_t robot, double plan_time) {
  const scene::Scene& scene = simulation.scene();
  world::World& world = simulation.world();
  const world::RobotIndex index = simulation.robots()[robot];
  std::optional<Vec3> base;
  if (const auto& base_path = simulation.base_path(robot)) {
    const auto sample = base_path->sample(plan_time);
    // The base faces the way its path goes; where the path stands still, the way it faces now.
    double heading = world.base_x_y_heading(index).z();
    if (sample.velocity.head<2>().norm() > 1e-9) heading = std::atan2(sample.velocity.y(), sample.velocity.x());
    base = Vec3(sample.position.x(), sample.position.y(), Real(heading));
  }
  tool_targets_.clear();
  for (std::size_t h = 0; h < scene.print_heads.size(); ++h) {
    if (simulation.robot_of_head(h) != robot || !simulation.print_head_tool(h)) continue;
    const auto& head = scene.print_heads[h];
    tool_targets_.emplace_back(*simulation.print_head_tool(h),
                               world::ToolTarget{simulation.head_path(h).sample(plan_time).position, head.direction.normalized()});
  }
  world.place_robot(index, base, tool_targets_);
}

bool PrioritizedCoordination::keeps_clear(Simulation& simulation, const std::vector<PlanClock>& clocks, std::size_t robot,
                                          double rate) {
  world::World& world = simulation.world();
  const auto& robots = simulation.robots();
  const std::size_t count = robots.size();
  const double now = simulation.time();
  bool clear = true;
  for (int k = 1; k <= settings_.samples && clear; ++k) {
    const double ahead = settings_.horizon * k / settings_.samples;  // s of world time
    for (const std::size_t other : decided_) place(simulation, other, clocks[other].at(now) + clocks[other].rate * ahead);
    place(simulation, robot, clocks[robot].at(now) + rate * ahead);
    for (std::size_t other = 0; other < count && clear; ++other) {
      if (other == robot) continue;
      const double line = threshold(settings_.robot_clearance, distance_now_[robot * count + other]);
      clear = world.robot_distance(robots[robot], robots[other], line) > line;  // FCL returns the bound itself when it finds less
    }
    if (clear) {
      const double line = threshold(settings_.print_clearance, print_distance_now_[robot]);
      clear = world.print_distance(robots[robot], line) > line;
    }
  }
  world.restore_robots();
  return clear;
}

void PrioritizedCoordination::update_print_boxes(Simulation& simulation) {
  // The cells (at least a centimetre, so a print's thousands of particles make hundreds) that hold a
  // particle, each row of neighbouring cells along x merged into one box: a strand is a few boxes.
  const auto& positions = simulation.solver().state().fluid.position;
  const double cell = std::max(0.01, 2.0 * static_cast<double>(simulation.solver().particle_diameter()));
  constexpr std::int64_t kSpan = 1 << 20;  // cells per axis a key tells apart (10 km at 1 cm)
  auto cell_index = [&](Real coordinate) {
    return std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor(coordinate / cell)) + kSpan / 2, 0, kSpan - 1);
  };
  cell_keys_.clear();
  for (const Vec3& position : positions)  // z, then y, then x: a row along x is a run of keys
    cell_keys_.push_back((cell_index(position.z()) * kSpan + cell_index(position.y())) * kSpan + cell_index(position.x()));
  std::sort(cell_keys_.begin(), cell_keys_.end());
  cell_keys_.erase(std::unique(cell_keys_.begin(), cell_keys_.end()), cell_keys_.end());
  print_boxes_.clear();
  auto coordinate = [&](std::int64_t index) { return Real(cell * static_cast<double>(index - kSpan / 2)); };
  for (std::size_t first = 0; first < cell_keys_.size();) {
    std::size_t last = first;
    while (last + 1 < cell_keys_.size() && cell_keys_[last + 1] == cell_keys_[last] + 1 && cell_keys_[last + 1] % kSpan != 0) ++last;
    const std::int64_t key = cell_keys_[first];
    const std::int64_t x = key % kSpan, y = (key / kSpan) % kSpan, z = key / (kSpan * kSpan);
    const std::int64_t x_end = cell_keys_[last] % kSpan + 1;
    print_boxes_.push_back(Aabb{Vec3(coordinate(x), coordinate(y), coordinate(z)), Vec3(coordinate(x_end), coordinate(y + 1), coordinate(z + 1))});
    first = last + 1;
  }
  simulation.world().set_print_boxes(print_boxes_);
}

void PrioritizedCoordination::update(Simulation& simulation, std::vector<PlanClock>& clocks) {
  const double now = simulation.time();
  if (now + 1e-12 < next_decision_) return;
  const scene::Scene& scene = simulation.scene();
  world::World& world = simulation.world();
  const auto& robots = simulation.robots();
  const std::size_t count = robots.size();
  // What the rates since the last decision did.
  if (last_decision_ >= 0) {
    const double elapsed = now - last_decision_;
    for (std::size_t r = 0; r < count; ++r) {
      double path_end = -1;
      if (const auto& base_path = simulation.base_path(r)) path_end = base_path->end_time();
      for (std::size_t h = 0; h < scene.print_heads.size(); ++h)
        if (simulation.robot_of_head(h) == r) path_end = std::max(path_end, simulation.head_path(h).end_time());
      if (clocks[r].rate <= 0 && clocks[r].at(now) < path_end) reports_[r].waiting_time += elapsed;
      if (clocks[r].rate > 0 && clocks[r].rate < 1) reports_[r].slowed_time += elapsed;
    }
  }
  last_decision_ = now;
  next_decision_ = now + settings_.period;

  update_print_boxes(simulation);
  for (std::size_t a = 0; a < count; ++a) {
    for (std::size_t b = a + 1; b < count; ++b) {
      const double distance = world.robot_distance(robots[a], robots[b], 0);
      distance_now_[a * count + b] = distance_now_[b * count + a] = distance;
      reports_[a].least_robot_distance = std::min(reports_[a].least_robot_distance, distance);
      reports_[b].least_robot_distance = std::min(reports_[b].least_robot_distance, distance);
    }
    print_distance_now_[a] = world.print_distance(robots[a], 0);
    reports_[a].least_print_distance = std::min(reports_[a].least_print_distance, print_distance_now_[a]);
  }

  decided_.clear();
  for (const std::size_t robot : order_) {
    if (world.external_control(robots[robot])) continue;  // commanded from outside: an obstacle standing where it is
    CoordinationReport& report = reports_[robot];
    ++report.decisions;
    double chosen = -1;
    for (const double rate : kRates)
      if (keeps_clear(simulation, clocks, robot, rate)) {
        chosen = rate;
        break;
      }
    if (chosen < 0) {
      ++report.blocked;
      chosen = 0;
    }
    if (chosen < 1) ++report.conflicts;
    if (chosen != clocks[robot].rate) clocks[robot].set_rate(now, chosen);
    report.rate = chosen;
    decided_.push_back(robot);
  }
}

void PrioritizedCoordination::save(StateWriter& out) const {
  out.section("coordination");
  out.put(next_decision_);
  out.put(last_decision_);
  out.put(reports_);
}

void PrioritizedCoordination::load(StateReader& in) {
  in.section("coordination");
  next_decision_ = in.get<double>();
  last_decision_ = in.get<double>();
  const std::size_t robots = reports_.size();
  in.get(reports_);
  if (reports_.size() != robots) in.fail("a coordination checkpoint for another number of robots");
}

}  // namespace m3dp::sim
