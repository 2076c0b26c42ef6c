#pragma once
// Surface reconstruction: particles → implicit field on a sparse OpenVDB grid → triangle mesh.
// OpenVDB stays inside reconstruct_openvdb.cpp (slow to compile); this header is plain C++.
//
// Methods (every length defaults to a multiple of the particle radius r, see SurfaceSettings):
//  spherical    union of spheres (the narrow-band level set OpenVDB's ParticlesToLevelSet makes,
//               gathered per leaf node), surface at the spheres' skin.
//  sph_blobby   volume fraction Σ_j V_j W(x − x_j) with the SPH cubic spline; surface at iso_level.
//  zhu_bridson  Zhu & Bridson 2005, "Animating sand as a fluid": φ = |x − x̄(x)| − r̄, x̄ the
//               kernel-weighted mean of nearby centres, r̄ the mean radius; surface at φ = 0.
//  anisotropic  Yu & Turk 2013, "Reconstructing surfaces of particle-based fluids using
//               anisotropic kernels": smoothed centres and one ellipsoidal kernel per particle from
//               its neighbourhood's covariance; volume fraction, surface at iso_level.
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "m3dp/core/geometry.hpp"
#include "m3dp/core/types.hpp"

namespace m3dp::surface {

enum class Method { spherical, sph_blobby, zhu_bridson, anisotropic };

[[nodiscard]] std::string_view method_name(Method method);
[[nodiscard]] std::optional<Method> parse_method(std::string_view name);
/// "spherical, sph_blobby, zhu_bridson, anisotropic" (for error messages and --help).
[[nodiscard]] std::string method_names();

/// What to reconstruct and how. Every length left at 0 is derived from particle_radius when the
/// mesh is made; resolved() returns the settings with those values filled in.
struct SurfaceSettings {
  Method method = Method::anisotropic;
  Real particle_radius = 0;   // m, r: half the rest spacing of the particles (required)
  Real voxel_size = 0;        // m, grid spacing of the field; 0 = r (finer costs ~8x per halving)
  Real kernel_radius = 0;     // m, support of the field's kernel; 0 = 4 r (the SPH support)
  Real sphere_radius = 0;     // m, spherical: radius of each sphere; 0 = 1.5 r, the smallest
                              // round number that closes a lattice's faces (√2 r) so the union is solid
  Real iso_level = Real(0.5); // sph_blobby and anisotropic: volume fraction on the surface (0..1)
  Real zhu_bridson_radius = 0;  // m, zhu_bridson: r̄; 0 = calibrated so a flat lattice block's
                                // surface sits a radius beyond its last layer of centres
  // Yu & Turk 2013 (their names in brackets):
  Real anisotropy_neighborhood = 0;  // m, covariance and smoothing radius [r_i]; 0 = 1.5 × kernel_radius
  Real centre_smoothing = Real(0.05);  // [λ] 0 = raw centres, 1 = neighbourhood means. Yu & Turk's
                                      // 0.9 sinks a flat face with this neighbourhood, so the
                                      // default only smooths noise
  Real max_anisotropy = 4;            // [k_r] largest ratio of the ellipsoid's axes
  int min_neighbors = 10;             // [N_ε] fewer neighbours: isotropic kernel of scale sparse_scale.
                                      // Yu & Turk's 25 in a neighbourhood of 2h, scaled to this 1.5h
                                      // one (25·0.75³ ≈ 10): a strand 2 particles across stays anisotropic
  Real sparse_scale = Real(0.5);      // [k_n] kernel scale of particles with few neighbours
  // Mesh post-processing: Taubin λ|μ smoothing (shrinks far less than Laplacian smoothing).
  int smoothing_iterations = 0;
  Real smoothing_lambda = Real(0.5);
  Real smoothing_mu = Real(-0.53);

  /// Copy with every derived length filled in. Throws m3dp::Error for a non-positive radius.
  [[nodiscard]] SurfaceSettings resolved() const;
};

struct SurfaceStats {
  std::size_t particles = 0;
  std::size_t surface_particles = 0;  // particles near enough to the surface to be splatted
  std::size_t active_voxels = 0;
  std::size_t grid_bytes = 0;     // memory of the field grid(s) at their largest
  double field_seconds = 0;       // particles → grid
  double mesh_seconds = 0;        // grid → triangles (+ smoothing)
  // IncrementalSurface only:
  std::size_t reused_particles = 0;  // resting particles whose field was kept from earlier frames
  std::size_t added_particles = 0;   // resting particles added to that field in this frame
  std::size_t refreshed_kernels = 0; // anisotropic: kept kernels remade because their neighbours changed
  bool rebuilt = false;              // the kept field was dropped (a resting particle woke or moved)
  std::size_t mesh_tiles = 0;        // tiles of 32 voxels the mesh is made of
  std::size_t remeshed_tiles = 0;    // of those, meshed again because the field around them changed
};

/// Reconstructs the surface of the particles at `positions` (m). Returns a closed, outward-oriented
/// mesh (empty for no particles). Runs in parallel (TBB).
[[nodiscard]] TriangleMesh reconstruct_surface(std::span<const Vec3> positions, const SurfaceSettings& settings,
                                               SurfaceStats* stats = nullptr);

namespace detail {
/// For tests: the spherical method's union of spheres as M3DP rasterises it, compared voxel by voxel
/// with OpenVDB's ParticlesToLevelSet (the reference it replaced for speed).
struct SphericalFieldComparison {
  std::size_t active_voxels = 0, reference_active_voxels = 0;
  std::size_t activity_mismatches = 0;  // voxels active in one grid and not in the other
  double max_difference = 0;            // m, largest difference of a voxel's value
};
[[nodiscard]] SphericalFieldComparison compare_spherical_field_with_openvdb(std::span<const Vec3> centres, Real sphere_radius,
                                                                            Real voxel_size);
}  // namespace detail

/// Meshes a sequence of frames in which printed material comes to rest (issue 4, incremental
/// meshing). The field of the resting particles is kept between frames: each frame adds the
/// particles that came to rest since the last one and the field of the moving ones, so the field's
/// cost follows what changed, not the whole print. The mesh is made by tiles of 32 voxels, and a
/// tile is meshed again only when the field around it changed (a hash of its values); joining
/// the tiles' triangles and hashing them still walks the whole surface, at a few ns a triangle.
/// A resting particle keeps its id and position; if one wakes up, moves or leaves, the kept field
/// is rebuilt from the current resting set.
///  spherical, sph_blobby  the result is the whole frame's (a union and a sum split into parts).
///  anisotropic            the same too: Yu & Turk's kernels depend on the neighbours, so a kept
///                         particle near material that arrived or moved gets its kernel remade and
///                         swapped in the kept field (a flat kernel under a new layer turns round).
///  zhu_bridson            not a sum of contributions: every frame is reconstructed whole.
class IncrementalSurface {
 public:
  explicit IncrementalSurface(const SurfaceSettings& settings);
  ~IncrementalSurface();
  IncrementalSurface(const IncrementalSurface&) = delete;
  IncrementalSurface& operator=(const IncrementalSurface&) = delete;

  /// The surface of `moving` ∪ `resting` (m); `resting_ids` are the resting particles' stable ids.
  [[nodiscard]] TriangleMesh reconstruct(std::span<const Vec3> moving, std::span<const Vec3> resting,
                                         std::span<const std::uint64_t> resting_ids, SurfaceStats* stats = nullptr);
  /// For saved frames, where rest is not recorded: a particle whose id and position are those it had
  /// in the previous call's frame counts as resting (a resting particle is frozen, bit for bit).
  [[nodiscard]] TriangleMesh reconstruct_frame(std::span<const Vec3> positions, std::span<const std::uint64_t> ids,
                                               SurfaceStats* stats = nullptr);

 private:
  struct Cache;
  std::unique_ptr<Cache> cache_;
};

}  // namespace m3dp::surface
