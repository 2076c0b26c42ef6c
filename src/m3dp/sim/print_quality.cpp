#include "m3dp/sim/print_quality.hpp"

#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

std::vector<quality::HeadDesign> head_designs(const scene::Scene& scene, std::span<const toolpath::Trajectory> paths) {
  std::vector<quality::HeadDesign> designs;
  for (std::size_t h = 0; h < scene.print_heads.size(); ++h) {
    const auto& head = scene.print_heads[h];
    designs.push_back({head.name, quality::design_of(paths[h], quality::Nozzle{head.inner_diameter, head.exit_speed, 0})});
  }
  return designs;
}

quality::Report print_quality(const Simulation& simulation, double spacing) {
  std::vector<toolpath::Trajectory> paths;
  for (std::size_t h = 0; h < simulation.scene().print_heads.size(); ++h) paths.push_back(simulation.head_path(h));
  const auto& fluid = simulation.solver().fluid();
  const quality::Printed printed{fluid.position, fluid.print_layer, double(simulation.solver().particle_diameter())};
  return quality::measure(head_designs(simulation.scene(), paths), printed, spacing, simulation.time());
}

}  // namespace m3dp::sim
