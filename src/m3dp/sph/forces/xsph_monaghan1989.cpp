// XSPH velocity smoothing after J. J. Monaghan, "On the problem of penetration in particle methods",
// J. Comput. Phys. 82(1), 1–15, 1989: v_i += ε Σ_j V_j (v_j − v_i) W_ij (stage "viscosity", off by default).
#include <algorithm>

#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void apply_xsph(const Model& model, State& state, Workspace& workspace) {
  const Real factor = model.settings.xsph_factor;
  if (factor <= 0) return;
  auto& fluid = state.fluid;
  const std::size_t count = state.active_count;
  auto& smoothed = workspace.scratch_vec3;
  smoothed.resize(count);
  with_kernel(model.settings.kernel, model.support_radius, [&](const auto& kernel) {
    parallel_for_each_index(count, [&](std::size_t i) {
      Vec3 change = Vec3::Zero();
      for (const Index j : workspace.fluid_neighbors.of(i))
        change += (fluid.mass[j] / fluid.density[j] * kernel.W((fluid.position[i] - fluid.position[j]).norm())) *
                  (fluid.velocity[j] - fluid.velocity[i]);
      smoothed[i] = fluid.velocity[i] + factor * change;
    }, 256);
  });
  std::copy(smoothed.begin(), smoothed.end(), fluid.velocity.begin());
}

}  // namespace m3dp::sph::stages
