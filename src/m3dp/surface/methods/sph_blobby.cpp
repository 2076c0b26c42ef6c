// The sph_blobby method: the SPH volume fraction Σ_j V_j W(x − x_j) with the cubic spline of the
// kernel radius; the surface is at iso_level.
#include "m3dp/sph/kernels.hpp"
#include "m3dp/surface/field.hpp"

namespace m3dp::surface {

namespace {

/// −Σ_j V_j W(x − x_j): negative inside, so the mesher's "inside = below the iso-value" holds.
openvdb::FloatGrid::Ptr blobby_field(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                     const openvdb::math::Transform::Ptr& transform, SurfaceStats& stats, const FieldInputs& /*inputs*/) {
  const Real spacing = 2 * settings.particle_radius;
  const Real volume = spacing * spacing * spacing;
  const sph::CubicSplineKernel kernel(settings.kernel_radius);
  const Real voxel = settings.voxel_size;
  const Vec3 half_extent = Vec3::Constant(settings.kernel_radius);
  const DeepRegion region = find_deep_region(positions, settings.kernel_radius, settings.particle_radius);
  stats.surface_particles += region.contributing.size();
  const Eigen::Matrix3f to_unit = Eigen::Matrix3f::Identity() / settings.kernel_radius;
  auto splat = [&](Index particle, openvdb::FloatGrid::Accessor& accessor) {
    for_each_voxel_in_ellipsoid(positions[particle], to_unit, half_extent, voxel, [&](const openvdb::Coord& ijk, Real q) {
      const float weight = volume * kernel.W(q * settings.kernel_radius);
      accessor.modifyValue(ijk, [weight](float& value) { value -= weight; });
    });
  };
  auto grid = splat_particles<openvdb::FloatGrid>(region.contributing, transform, 0.f, splat);
  fill_interior(*grid, region, voxel, -1.f);
  return grid;
}

}  // namespace

extern const FieldMethod kSphBlobbyMethod{Method::sph_blobby, true, true, false, false, blobby_field};

}  // namespace m3dp::surface
