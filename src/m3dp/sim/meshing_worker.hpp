#pragma once
// Surface meshes during a run (issue 4): the run loop hands a copy of the particle positions to a
// worker thread and steps on; the worker reconstructs the surface and writes meshes/mesh_NNNNNN.EXT.
// While the worker is busy, a new request is skipped (and counted), never queued: the solver
// does not wait, and meshes never fall further and further behind. Material at rest is meshed
// incrementally: its field is kept between meshes (surface::IncrementalSurface).
#include <condition_variable>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "m3dp/core/geometry.hpp"
#include "m3dp/surface/surface.hpp"

namespace m3dp::sim {

class MeshingWorker {
 public:
  struct Mesh {
    double time = 0;                 // s, simulated time of the particles it was made from
    std::filesystem::path file;
    std::size_t particles = 0, triangles = 0;
    double volume = 0;               // m³ the mesh encloses (surface::signed_volume)
    std::size_t reused_particles = 0;  // resting particles whose field was kept from earlier meshes
    std::size_t tiles = 0, remeshed_tiles = 0;  // mesh tiles (32 voxels), and those meshed again
    double seconds = 0;              // wall time to reconstruct and write
  };

  /// `settings` must have the particle radius; `format` is obj, ply or stl; an empty `folder`: the
  /// meshes are made, not written.
  MeshingWorker(surface::SurfaceSettings settings, std::filesystem::path folder, std::string format);
  ~MeshingWorker();
  MeshingWorker(const MeshingWorker&) = delete;
  MeshingWorker& operator=(const MeshingWorker&) = delete;

  /// Copies the particles for a mesh at `time`: those still moving, and those at rest with their
  /// stable ids. Returns false (and counts a skip) if the worker is busy.
  bool submit(double time, std::span<const Vec3> moving, std::span<const Vec3> resting = {},
              std::span<const std::uint64_t> resting_ids = {});
  /// Blocks until the worker is idle.
  void wait_idle();
  /// Waits, then drops the resting particles' field kept between meshes: the next mesh is made whole
  /// (at a checkpoint, as a resumed run's first one is).
  void forget_kept_field();
  /// A resumed run's worker: the meshes made before the checkpoint, the skips, and the newest mesh.
  void resume(std::vector<Mesh> meshes, std::size_t skipped, std::shared_ptr<const TriangleMesh> latest);

  [[nodiscard]] std::vector<Mesh> meshes() const;
  [[nodiscard]] std::size_t skipped() const;
  /// The newest mesh (null before the first): for consumers such as the world's collision bodies.
  [[nodiscard]] std::shared_ptr<const TriangleMesh> latest_mesh() const;
  /// The first error the worker met (a mesh it could not write), empty if none.
  [[nodiscard]] std::string error() const;

 private:
  void run();

  surface::SurfaceSettings settings_;
  std::filesystem::path folder_;
  std::string format_;

  mutable std::mutex mutex_;
  std::condition_variable work_ready_, work_done_;
  bool busy_ = false, stopping_ = false;
  double pending_time_ = 0;
  // Filled by submit, swapped out by the worker.
  std::vector<Vec3> pending_moving_, pending_resting_;
  std::vector<std::uint64_t> pending_resting_ids_;
  std::unique_ptr<surface::IncrementalSurface> surface_;   // used by the worker thread only (or while idle)
  std::vector<Mesh> meshes_;
  std::size_t skipped_ = 0;
  std::shared_ptr<const TriangleMesh> latest_;
  std::string error_;
  std::thread thread_;                    // last: starts after every member above exists
};

}  // namespace m3dp::sim
