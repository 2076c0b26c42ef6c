// The zhu_bridson method after Y. Zhu, R. Bridson, "Animating sand as a fluid", ACM Transactions on
// Graphics 24(3), 965–972, 2005: φ = |x − x̄(x)| − r̄, x̄ the kernel-weighted mean of nearby centres,
// r̄ the mean radius; the surface is at φ = 0. Not a sum over particles: made whole every time.
#include <openvdb/tree/LeafManager.h>
#include <tbb/parallel_for.h>

#include "m3dp/surface/field.hpp"

namespace m3dp::surface {

namespace {

/// Zhu & Bridson 2005: φ(x) = |x − x̄| − r̄, x̄ = Σ k_i x_i / Σ k_i, k(s) = max(0, 1 − s²)³, s = |x − x_i| / R.
openvdb::FloatGrid::Ptr zhu_bridson_field(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                          const openvdb::math::Transform::Ptr& transform, SurfaceStats& stats,
                                          const FieldInputs& /*inputs*/) {
  const Real support = settings.kernel_radius;
  const Real voxel = settings.voxel_size;
  const Vec3 half_extent = Vec3::Constant(support);
  const DeepRegion region = find_deep_region(positions, support, settings.particle_radius);
  stats.surface_particles += region.contributing.size();
  const std::vector<Index>& order = region.contributing;
  // x̄ needs Σk and Σk·x: a float grid and a Vec3 grid (OpenVDB registers no Vec4 float grid).
  const Eigen::Matrix3f to_unit = Eigen::Matrix3f::Identity() / support;
  auto splat_weight = [&](Index particle, openvdb::FloatGrid::Accessor& accessor) {
    for_each_voxel_in_ellipsoid(positions[particle], to_unit, half_extent, voxel, [&](const openvdb::Coord& ijk, Real q) {
      const Real one_minus = 1 - q * q;
      const float weight = one_minus * one_minus * one_minus;
      accessor.modifyValue(ijk, [weight](float& value) { value += weight; });
    });
  };
  auto splat_moment = [&](Index particle, openvdb::Vec3SGrid::Accessor& accessor) {
    const Vec3 centre = positions[particle];
    for_each_voxel_in_ellipsoid(centre, to_unit, half_extent, voxel, [&](const openvdb::Coord& ijk, Real q) {
      const Real one_minus = 1 - q * q;
      const Real weight = one_minus * one_minus * one_minus;
      const openvdb::Vec3s moment(weight * centre.x(), weight * centre.y(), weight * centre.z());
      accessor.modifyValue(ijk, [&moment](openvdb::Vec3s& value) { value += moment; });
    });
  };
  auto weight = splat_particles<openvdb::FloatGrid>(order, transform, 0.f, splat_weight);
  auto moment = splat_particles<openvdb::Vec3SGrid>(order, transform, openvdb::Vec3s(0, 0, 0), splat_moment);

  const float outside = static_cast<float>(support);
  stats.grid_bytes = weight->memUsage() + moment->memUsage();
  auto phi = openvdb::FloatGrid::create(outside);
  phi->setTransform(transform);
  phi->setTree(std::make_shared<openvdb::FloatTree>(weight->tree(), outside, openvdb::TopologyCopy()));
  openvdb::tree::LeafManager<openvdb::FloatTree> leaves(phi->tree());
  const Real mean_radius = settings.zhu_bridson_radius;
  tbb::parallel_for(leaves.leafRange(), [&](const openvdb::tree::LeafManager<openvdb::FloatTree>::LeafRange& range) {
    for (auto leaf = range.begin(); leaf; ++leaf) {
      const auto* weight_leaf = weight->tree().probeConstLeaf(leaf->origin());
      const auto* moment_leaf = moment->tree().probeConstLeaf(leaf->origin());
      for (auto value = leaf->beginValueOn(); value; ++value) {
        const auto offset = value.pos();
        const float weight_sum = weight_leaf->getValue(offset);
        const openvdb::Coord ijk = value.getCoord();
        if (!(weight_sum > 0) || moment_leaf == nullptr) {
          value.setValue(outside);
          continue;
        }
        const openvdb::Vec3s mean = moment_leaf->getValue(offset) / weight_sum;
        const Vec3 x(ijk.x() * voxel, ijk.y() * voxel, ijk.z() * voxel);
        value.setValue(static_cast<float>((x - Vec3(mean.x(), mean.y(), mean.z())).norm() - mean_radius));
      }
    }
  });
  fill_interior(*phi, region, voxel, static_cast<float>(-mean_radius));
  return phi;
}

}  // namespace

extern const FieldMethod kZhuBridsonMethod{Method::zhu_bridson, false, false, false, false, zhu_bridson_field};

}  // namespace m3dp::surface
