#include "m3dp/sim/meshing_worker.hpp"

#include <fmt/format.h>

#include <chrono>

#include "m3dp/io/mesh_io.hpp"

namespace m3dp::sim {

MeshingWorker::MeshingWorker(surface::SurfaceSettings settings, std::filesystem::path folder, std::string format)
    : settings_(settings.resolved()), folder_(std::move(folder)), format_(std::move(format)) {
  std::filesystem::create_directories(folder_);
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

bool MeshingWorker::submit(double time, std::span<const Vec3> positions) {
  {
    std::lock_guard lock(mutex_);
    if (busy_) {
      ++skipped_;
      return false;
    }
    pending_positions_.assign(positions.begin(), positions.end());
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

std::shared_ptr<const TriangleMesh> MeshingWorker::latest_mesh() const {
  std::lock_guard lock(mutex_);
  return latest_;
}

std::string MeshingWorker::error() const {
  std::lock_guard lock(mutex_);
  return error_;
}

void MeshingWorker::run() {
  std::vector<Vec3> positions;
  for (;;) {
    double time = 0;
    std::size_t index = 0;
    {
      std::unique_lock lock(mutex_);
      work_ready_.wait(lock, [this] { return busy_ || stopping_; });
      if (!busy_) return;  // stopping with nothing to do
      positions.swap(pending_positions_);
      time = pending_time_;
      index = meshes_.size();
    }
    const auto start = std::chrono::steady_clock::now();
    Mesh mesh;
    mesh.time = time;
    mesh.particles = positions.size();
    mesh.file = folder_ / fmt::format("mesh_{:06}.{}", index, format_);
    std::shared_ptr<TriangleMesh> surface;
    std::string failure;
    try {
      surface = std::make_shared<TriangleMesh>(surface::reconstruct_surface(positions, settings_));
      io::write_triangle_mesh(mesh.file, *surface);
      mesh.triangles = surface->triangles.size();
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
