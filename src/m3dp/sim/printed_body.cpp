#include "m3dp/sim/printed_body.hpp"

#include <array>
#include <cmath>

#include "m3dp/core/error.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

PrintedBody::PrintedBody(const Simulation& simulation) : settings_(simulation.scene().meshing), surface_(settings_.surface) {
  surface_.particle_radius = simulation.solver().parameters().settings.particle_radius;
  // The particles the meshing block asks for: one material, one region, or all.
  for (std::size_t m = 0; m < simulation.scene().materials.size(); ++m)
    if (simulation.scene().materials[m].material.name == settings_.material) phase_ = static_cast<std::uint16_t>(m);
  worker_ = std::make_unique<MeshingWorker>(surface_, std::filesystem::path(), settings_.format);
  due_.start(simulation.time(), settings_.period);
}

void PrintedBody::set_output(const std::filesystem::path& folder, bool wait) {
  worker_->wait_idle();
  worker_ = std::make_unique<MeshingWorker>(surface_, folder, settings_.format);
  wait_ = wait;
}

std::shared_ptr<const TriangleMesh> PrintedBody::take_newest() {
  auto newest = worker_->latest_mesh();
  if (!newest || newest == inserted_ || newest == written_only_) return nullptr;
  inserted_ = newest;
  return newest;
}

std::shared_ptr<const TriangleMesh> PrintedBody::after_step(const Simulation& simulation) {
  const double time = simulation.time();
  if (due_.take(time, settings_.period)) {
    if (wait_) worker_->wait_idle();
    if (submit(simulation)) last_meshed_time_ = time;
    if (wait_) worker_->wait_idle();
  }
  return take_newest();
}

void PrintedBody::mesh_now(const Simulation& simulation) {
  worker_->wait_idle();
  if (last_meshed_time_ < simulation.time() && simulation.solver().fluid().size() > 0) {
    if (submit(simulation)) last_meshed_time_ = simulation.time();
    worker_->wait_idle();
    if (auto newest = worker_->latest_mesh(); newest != inserted_) written_only_ = std::move(newest);
  }
}

std::shared_ptr<const TriangleMesh> PrintedBody::settle() {
  worker_->wait_idle();
  auto newest = take_newest();
  worker_->forget_kept_field();
  if (!worker_->error().empty()) throw Error(worker_->error());
  return newest;
}

bool PrintedBody::submit(const Simulation& simulation) {
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
  return worker_->submit(simulation.time(), moving_, resting_, resting_ids_);
}

void PrintedBody::save(StateWriter& out) const {
  out.put(due_.next_time);
  out.put(last_meshed_time_);
  out.put(static_cast<std::uint64_t>(worker_->skipped()));
  const auto meshes = worker_->meshes();
  out.put(static_cast<std::uint64_t>(meshes.size()));
  for (const auto& mesh : meshes) {
    out.put(mesh.file.string());
    out.put(std::array<double, 3>{mesh.time, mesh.volume, mesh.seconds});
    out.put(std::array<std::uint64_t, 5>{mesh.particles, mesh.triangles, mesh.reused_particles, mesh.tiles, mesh.remeshed_tiles});
  }
}

void PrintedBody::load(StateReader& in, std::shared_ptr<const TriangleMesh> inserted) {
  in.get(due_.next_time);
  in.get(last_meshed_time_);
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
  inserted_ = std::move(inserted);
  worker_->resume(std::move(meshes), skipped, inserted_);
}

}  // namespace m3dp::sim
