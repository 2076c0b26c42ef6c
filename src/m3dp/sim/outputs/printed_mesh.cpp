// meshes/mesh_NNNNNN.EXT every <meshing><period> of simulated time, made on a worker thread while the
// solver steps on (MeshingWorker), and the final state's at the end. The newest mesh goes back into
// the world as the printed material's collision body: the one way an output feeds the run, through
// the Simulation the factory was given (the observer itself only reads).
#include <array>

#include "m3dp/core/error.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

class PrintedMesh final : public RunObserver {
 public:
  PrintedMesh(Simulation& simulation, const RunOptions& options)
      : simulation_(simulation), settings_(simulation.scene().meshing), wait_(options.wait_for_meshes || options.hash),
        worker_(surface_settings(simulation), options.output_directory / "meshes", settings_.format) {
    // The particles the meshing block asks for: one material, one region, or all.
    for (std::size_t m = 0; m < simulation.scene().materials.size(); ++m)
      if (simulation.scene().materials[m].material.name == settings_.material) phase_ = static_cast<std::uint16_t>(m);
  }

  // Every step: a finished mesh joins the world as soon as it is there. Meshes are asked for at the
  // meshing period (next_time_), which the run's schedule does not see.
  void start(const Simulation& simulation) override {
    next_time_ = settings_.period * (std::floor((simulation.time() + 1e-12) / settings_.period) + 1);
  }

  void observe(const Simulation& simulation, const StepReport& /*report*/) override {
    const double time = simulation.time();
    if (time + 1e-12 >= next_time_) {
      if (wait_) worker_.wait_idle();
      if (submit(simulation)) last_meshed_time_ = time;
      if (wait_) worker_.wait_idle();
      while (next_time_ <= time + 1e-12) next_time_ += settings_.period;
    }
    auto newest = worker_.latest_mesh();
    if (newest && newest != inserted_) {
      simulation_.set_printed_mesh(newest);
      inserted_ = std::move(newest);
      ++inserted_count_;
    }
  }

  // A checkpoint: the mesh in progress joins the world first, and the kept field is dropped, so that
  // the run goes on as a resumed one will (its first mesh made whole).
  void save(StateWriter& out) override {
    worker_.wait_idle();
    auto newest = worker_.latest_mesh();
    if (newest && newest != inserted_) {
      simulation_.set_printed_mesh(newest);
      inserted_ = std::move(newest);
      ++inserted_count_;
    }
    worker_.forget_kept_field();
    if (!worker_.error().empty()) throw Error(worker_.error());
    out.put(next_time_);
    out.put(last_meshed_time_);
    out.put(static_cast<std::uint64_t>(inserted_count_));
    out.put(static_cast<std::uint64_t>(worker_.skipped()));
    const auto meshes = worker_.meshes();
    out.put(static_cast<std::uint64_t>(meshes.size()));
    for (const auto& mesh : meshes) {
      out.put(mesh.file.string());
      out.put(std::array<double, 3>{mesh.time, mesh.volume, mesh.seconds});
      out.put(std::array<std::uint64_t, 5>{mesh.particles, mesh.triangles, mesh.reused_particles, mesh.tiles, mesh.remeshed_tiles});
    }
  }
  void resume(const Simulation& simulation, StateReader& in) override {
    in.get(next_time_);
    in.get(last_meshed_time_);
    inserted_count_ = in.get<std::uint64_t>();
    const auto skipped = in.get<std::uint64_t>();
    const auto count = in.get<std::uint64_t>();
    if (count > in.remaining()) in.fail("more meshes than the file holds");
    std::vector<MeshingWorker::Mesh> meshes(count);
    for (auto& mesh : meshes) {
      std::string file;
      in.get(file);
      mesh.file = file;
      const auto times = in.get<std::array<double, 3>>();
      mesh.time = times[0], mesh.volume = times[1], mesh.seconds = times[2];
      const auto counts = in.get<std::array<std::uint64_t, 5>>();
      mesh.particles = counts[0], mesh.triangles = counts[1], mesh.reused_particles = counts[2];
      mesh.tiles = counts[3], mesh.remeshed_tiles = counts[4];
    }
    inserted_ = simulation.printed_mesh();
    worker_.resume(std::move(meshes), skipped, inserted_);
  }

  void finish(const Simulation& simulation, RunSummary& summary) override {
    // The final state is always meshed (after the mesh in progress): nothing printed goes unmeshed.
    worker_.wait_idle();
    if (last_meshed_time_ < simulation.time() && simulation.solver().fluid().size() > 0) {
      submit(simulation);
      worker_.wait_idle();
    }
    summary.meshes = worker_.meshes();
    summary.meshes_written = summary.meshes.size();
    summary.meshes_skipped = worker_.skipped();
    summary.meshes_inserted = inserted_count_;
    // A mesh that could not be made or written leaves a gap in meshes/: the run did not do all it was asked.
    if (!worker_.error().empty()) summary.fail(worker_.error());
  }

 private:
  static surface::SurfaceSettings surface_settings(const Simulation& simulation) {
    surface::SurfaceSettings surface = simulation.scene().meshing.surface;
    surface.particle_radius = simulation.solver().parameters().settings.particle_radius;
    return surface;
  }

  /// Hands the worker the meshed particles: the moving and the resting apart (it keeps the resting
  /// ones' field between meshes).
  bool submit(const Simulation& simulation) {
    const auto& fluid = simulation.solver().fluid();
    const std::size_t active = simulation.solver().state().active_count;
    moving_.clear();
    resting_.clear();
    resting_ids_.clear();
    for (std::size_t i = 0; i < fluid.size(); ++i) {
      if ((phase_ && fluid.phase[i] != *phase_) || (settings_.region && !settings_.region->contains(fluid.position[i]))) continue;
      if (i < active) {
        moving_.push_back(fluid.position[i]);
      } else {
        resting_.push_back(fluid.position[i]);
        resting_ids_.push_back(fluid.id[i]);
      }
    }
    return worker_.submit(simulation.time(), moving_, resting_, resting_ids_);
  }

  Simulation& simulation_;
  const scene::MeshingSettings& settings_;
  bool wait_;
  MeshingWorker worker_;
  std::optional<std::uint16_t> phase_;
  double next_time_ = 0, last_meshed_time_ = -1;
  std::shared_ptr<const TriangleMesh> inserted_;
  std::size_t inserted_count_ = 0;
  std::vector<Vec3> moving_, resting_;
  std::vector<std::uint64_t> resting_ids_;
};

}  // namespace

std::unique_ptr<RunObserver> make_printed_mesh(Simulation& simulation, const RunOptions& options) {
  if (options.output_directory.empty() || !simulation.scene().meshing.enabled) return nullptr;
  return std::make_unique<PrintedMesh>(simulation, options);
}

}  // namespace m3dp::sim::outputs
