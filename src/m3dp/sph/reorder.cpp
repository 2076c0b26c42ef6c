// Stage "reorder": every few steps the active particles are sorted along a Z-order (Morton) curve
// of their cells, so that neighbours sit near in memory.
#include "m3dp/core/parallel.hpp"
#include "m3dp/sph/stages.hpp"

namespace m3dp::sph::stages {

void reorder_particles(const Model& model, State& state, Workspace& workspace) {
  const int interval = model.settings.reorder_interval;
  if (interval <= 0 || state.step % interval != 0) return;
  // Only the active particles: resting ones do not move, so their order stays good.
  auto& fluid = state.fluid;
  const std::size_t count = state.active_count;
  if (count < 2) return;
  sort_by_cell(fluid.position, count, model.support_radius, workspace.sort_keys, workspace.permutation);
  auto gather = [&](auto& field, auto& scratch) {
    scratch.resize(count);
    parallel_for_each_index(count, [&](std::size_t i) { scratch[i] = field[workspace.permutation[i]]; }, 2048);
    std::copy(scratch.begin(), scratch.begin() + static_cast<std::ptrdiff_t>(count), field.begin());
  };
  fluid.for_each_field([&](auto& field) {
    using Element = typename std::decay_t<decltype(field)>::value_type;
    if constexpr (std::is_same_v<Element, Vec3>) gather(field, workspace.scratch_vec3);
    else if constexpr (std::is_same_v<Element, Real>) gather(field, workspace.scratch_real);
    else if constexpr (std::is_same_v<Element, std::uint16_t>) gather(field, workspace.scratch_u16);
    else if constexpr (std::is_same_v<Element, std::uint64_t>) gather(field, workspace.scratch_u64);
    else if constexpr (std::is_same_v<Element, std::int32_t>) gather(field, workspace.scratch_i32);
    else static_assert(sizeof(Element) == 0, "add a scratch buffer for this field type");
  });
}

}  // namespace m3dp::sph::stages
