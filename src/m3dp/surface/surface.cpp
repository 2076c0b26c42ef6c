#include "m3dp/surface/surface.hpp"

#include <array>
#include <cmath>
#include <utility>

#include "m3dp/core/error.hpp"

namespace m3dp::surface {

namespace {
/// Every method's name (what scenes and `m3dp mesh --method` say), in Method's order.
constexpr std::array<std::pair<Method, std::string_view>, 4> kMethodNames{{{Method::spherical, "spherical"},
                                                                           {Method::sph_blobby, "sph_blobby"},
                                                                           {Method::zhu_bridson, "zhu_bridson"},
                                                                           {Method::anisotropic, "anisotropic"}}};
/// r̄ that puts the Zhu–Bridson surface of a flat cubic-lattice block (spacing 2r) one radius beyond
/// its last layer of centres, i.e. on the block's geometric face. Averaged over points above a
/// lattice site, an edge midpoint and a cell centre.
Real calibrated_zhu_bridson_radius(Real particle_radius, Real support) {
  const Real spacing = 2 * particle_radius;
  const int reach = static_cast<int>(std::ceil(support / spacing)) + 1;
  const std::array<Vec3, 3> queries{Vec3(0, 0, particle_radius), Vec3(particle_radius, 0, particle_radius),
                                    Vec3(particle_radius, particle_radius, particle_radius)};
  double total = 0;
  for (const Vec3& query : queries) {
    double weight_sum = 0;
    Eigen::Vector3d moment = Eigen::Vector3d::Zero();
    for (int i = -reach; i <= reach; ++i)
      for (int j = -reach; j <= reach; ++j)
        for (int k = -reach; k <= 0; ++k) {
          const Vec3 centre(i * spacing, j * spacing, k * spacing);
          const double s2 = (query - centre).squaredNorm() / (support * support);
          if (s2 >= 1) continue;
          const double weight = (1 - s2) * (1 - s2) * (1 - s2);
          weight_sum += weight;
          moment += weight * centre.cast<double>();
        }
    total += (query.cast<double>() - moment / weight_sum).norm();
  }
  return static_cast<Real>(total / queries.size());
}
}  // namespace

SurfaceSettings SurfaceSettings::resolved() const {
  if (!(particle_radius > 0)) throw Error("surface reconstruction: particle_radius must be > 0 m");
  if (voxel_size < 0 || kernel_radius < 0 || sphere_radius < 0 || zhu_bridson_radius < 0 || anisotropy_neighborhood < 0)
    throw Error("surface reconstruction: lengths must be >= 0 m (0 = derived from the particle radius)");
  if (!(iso_level > 0 && iso_level < 1)) throw Error("surface reconstruction: iso_level must lie between 0 and 1");
  if (!(max_anisotropy >= 1)) throw Error("surface reconstruction: max_anisotropy must be >= 1");
  if (!(sparse_scale > 0)) throw Error("surface reconstruction: sparse_scale must be > 0");
  if (centre_smoothing < 0 || centre_smoothing > 1) throw Error("surface reconstruction: centre_smoothing must lie in [0, 1]");
  if (smoothing_iterations < 0) throw Error("surface reconstruction: smoothing_iterations must be >= 0");
  SurfaceSettings out = *this;
  const Real r = particle_radius;
  if (out.voxel_size == 0) out.voxel_size = r;
  if (out.kernel_radius == 0) out.kernel_radius = 4 * r;
  if (out.sphere_radius == 0) out.sphere_radius = Real(1.5) * r;
  if (out.anisotropy_neighborhood == 0) out.anisotropy_neighborhood = Real(1.5) * out.kernel_radius;
  if (out.zhu_bridson_radius == 0) out.zhu_bridson_radius = calibrated_zhu_bridson_radius(r, out.kernel_radius);
  return out;
}

std::string_view method_name(Method method) {
  for (const auto& [entry, name] : kMethodNames)
    if (entry == method) return name;
  return "unknown";
}

std::optional<Method> parse_method(std::string_view name) {
  for (const auto& [method, entry] : kMethodNames)
    if (entry == name) return method;
  return std::nullopt;
}

std::string method_names() {
  std::string names;
  for (const auto& [method, name] : kMethodNames) names += (names.empty() ? "" : ", ") + std::string(name);
  return names;
}

}  // namespace m3dp::surface
