#include "m3dp/sim/meshing_worker.hpp"

#include <fmt/format.h>

#include <chrono>

#include "m3dp/core/error.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/surface/mesh_tools.hpp"

namespace m3dp::sim {

MeshingWorker::MeshingWorker(surface::SurfaceSettings settings, std::filesystem::path folder, std::string format)
    : settings_(settings.resolved()), folder_(std::move(folder)), format_(std::move(format)), surface_(std::make_unique<surface::IncrementalSurface>(settings_)) {
  if (!folder_.empty()) std::filesystem::create_directories(folder_);
  thread_ = std::thread([this] { run(); });
}

MeshingWorker::~MeshingWorker() {
  {
    std::lock_guard lock(mutex_);
    stopping_ = true;
  }
  work_ready_.notify_one();
  thread_.join();
}

bool MeshingWorker::submit(double time, std::span<const Vec3> moving, std::span<const Vec3> resting,
                           std::span<const std::uint64_t> resting_ids) {
  if (resting.size() != resting_ids.size()) throw Error("meshing: one id per resting particle is needed");
  {
    std::lock_guard lock(mutex_);
    if (busy_) {
      ++skipped_;
      return false;
    }
    pending_moving_.assign(moving.begin(), moving.end());
    pending_resting_.assign(resting.begin(), resting.end());
    pending_resting_ids_.assign(resting_ids.begin(), resting_ids.end());
    pending_time_ = time;
    busy_ = true;
  }
  work_ready_.notify_one();
  return true;
}

void MeshingWorker::wait_idle() {
  std::unique_lock lock(mutex_);
  work_done_.wait(lock, [this] { return !busy_; });
}

std::vector<MeshingWorker::Mesh> MeshingWorker::meshes() const {
  std::lock_guard lock(mutex_);
  return meshes_;
}

std::size_t MeshingWorker::skipped() const {
  std::lock_guard lock(mutex_);
  return skipped_;
}

void MeshingWorker::forget_kept_field() {
  wait_idle();
  surface_ = std::make_unique<surface::IncrementalSurface>(settings_);
}

void MeshingWorker::resume(std::vector<Mesh> meshes, std::size_t skipped, std::shared_ptr<const TriangleMesh> latest) {
  wait_idle();
  std::lock_guard lock(mutex_);
  meshes_ = std::move(meshes);
  skipped_ = skipped;
  latest_ = std::move(latest);
}

std::shared_ptr<const TriangleMesh> MeshingWorker::latest_mesh() const {
  std::lock_guard lock(mutex_);
  return latest_;
}

std::string MeshingWorker::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

void MeshingWorker::run() {
  std::vector<Vec3> moving, resting;
  std::vector<std::uint64_t> resting_ids;
  for (;;) {
    double time = 0;
    std::size_t index = 0;
    {
      std::unique_lock lock(mutex_);
      work_ready_.wait(lock, [this] { return busy_ || stopping_; });
      if (!busy_) return;  // stopping with nothing to do
      moving.swap(pending_moving_);
      resting.swap(pending_resting_);
      resting_ids.swap(pending_resting_ids_);
      time = pending_time_;
      index = meshes_.size();
    }
    const auto start = std::chrono::steady_clock::now();
    Mesh mesh;
    mesh.time = time;
    mesh.particles = moving.size() + resting.size();
    if (!folder_.empty()) mesh.file = folder_ / fmt::format("mesh_{:06}.{}", index, format_);
    std::shared_ptr<TriangleMesh> surface;
    std::string failure;
    try {
      surface::SurfaceStats stats;
      surface = std::make_shared<TriangleMesh>(surface_->reconstruct(moving, resting, resting_ids, &stats));
      mesh.reused_particles = stats.reused_particles;
      mesh.tiles = stats.mesh_tiles;
      mesh.remeshed_tiles = stats.remeshed_tiles;
      if (!mesh.file.empty()) io::write_triangle_mesh(mesh.file, *surface);
      mesh.triangles = surface->triangles.size();
      mesh.volume = surface::signed_volume(*surface);
    } catch (const std::exception& error) {
      failure = fmt::format("mesh at t = {:.4f} s: {}", time, error.what());
    }
    mesh.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    {
      std::lock_guard lock(mutex_);
      if (failure.empty()) {
        meshes_.push_back(mesh);
        latest_ = surface;
      } else if (error_.empty()) {
        error_ = failure;
      }
      busy_ = false;
    }
    work_done_.notify_all();
  }
}

}  // namespace m3dp::sim
