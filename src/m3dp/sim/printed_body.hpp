#pragma once
// The printed material as a collision body of the rigid world: its surface mesh, remade every
// <meshing><period> on a worker thread (MeshingWorker), joins the world as "printed_material". The
// simulation owns it, so robots meet their print whether or not the run writes anything; a run with
// an output folder only has the meshes written there too (outputs/printed_mesh.cpp).
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <vector>

#include "m3dp/core/periodic.hpp"
#include "m3dp/core/state_io.hpp"
#include "m3dp/scene/scene.hpp"
#include "m3dp/sim/meshing_worker.hpp"

namespace m3dp::sim {

class Simulation;

class PrintedBody {
 public:
  explicit PrintedBody(const Simulation& simulation);

  /// Meshes are written into `folder` from now on (empty: made, not written); `wait`: the solver waits
  /// for each, which then joins the world at the step it was asked for (reproducible), rather than
  /// when it is ready. The meshes listed so far are those of the folder before.
  void set_output(const std::filesystem::path& folder, bool wait);
  /// After a step: asks for a mesh when the period is due. Returns the newest finished mesh when it
  /// is new (for the world), else null.
  std::shared_ptr<const TriangleMesh> after_step(const Simulation& simulation);
  /// Meshes the state now unless it was meshed at this time, and waits: a run's final state, written
  /// but kept out of the world (when a run ends must not change what a simulation that goes on meets).
  void mesh_now(const Simulation& simulation);
  /// Waits for the mesh in progress and drops the field kept between meshes, so that the run goes on
  /// as one resumed from a checkpoint here will. Returns the newest mesh when it is new.
  std::shared_ptr<const TriangleMesh> settle();

  /// The newest finished mesh, mesh_now's (the final state's) included; null before the first.
  [[nodiscard]] std::shared_ptr<const TriangleMesh> newest() const { return worker_->latest_mesh(); }
  [[nodiscard]] std::vector<MeshingWorker::Mesh> meshes() const { return worker_->meshes(); }
  [[nodiscard]] std::size_t skipped() const { return worker_->skipped(); }
  [[nodiscard]] std::string error() const { return worker_->error(); }

  void save(StateWriter& out) const;
  /// `inserted`: the mesh the world holds (the checkpoint's).
  void load(StateReader& in, std::shared_ptr<const TriangleMesh> inserted);

 private:
  /// Hands the worker the meshed particles: the moving and the resting apart (it keeps the resting
  /// ones' field between meshes).
  bool submit(const Simulation& simulation);
  std::shared_ptr<const TriangleMesh> take_newest();

  const scene::MeshingSettings& settings_;
  surface::SurfaceSettings surface_;
  std::optional<std::uint16_t> phase_;  // the material meshed; none: all
  bool wait_ = true;
  std::unique_ptr<MeshingWorker> worker_;
  Periodic due_;                  // the next mesh
  double last_meshed_time_ = -1;  // s
  std::shared_ptr<const TriangleMesh> inserted_;
  std::shared_ptr<const TriangleMesh> written_only_;  // mesh_now's: not for the world
  std::vector<Vec3> moving_, resting_;
  std::vector<std::uint64_t> resting_ids_;
};

}  // namespace m3dp::sim
