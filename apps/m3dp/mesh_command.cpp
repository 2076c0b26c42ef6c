// m3dp mesh: saved particle frames → surface meshes (offline surface reconstruction).
#include "mesh_command.hpp"

#include <fmt/format.h>

#include <chrono>
#include <memory>

#include "m3dp/core/error.hpp"
#include "m3dp/core/parallel.hpp"
#include "m3dp/core/progress.hpp"
#include "m3dp/io/mesh_io.hpp"
#include "m3dp/io/particle_reader.hpp"
#include "m3dp/surface/mesh_tools.hpp"

namespace m3dp::app {

namespace fs = std::filesystem;

void add_mesh_options(CLI::App& command, MeshOptions& options) {
  command.add_option("input", options.input, "Particle frame (.vtu, .vtp, .ply) or sequence (.pvd)")
      ->required()
      ->check(CLI::ExistingFile);
  command.add_option("-o,--output", options.output,
                     fmt::format("Mesh file ({}) or, for a .pvd sequence or --format sdf, a folder", io::mesh_format_names()))
      ->required();
  command.add_option("--method", options.method, surface::method_names())->capture_default_str();
  command.add_option("--format", options.format,
                     fmt::format("{} or sdf (a Gazebo model folder); default from -o, else obj", io::mesh_format_names()));
  command.add_option("--particle-radius", options.particle_radius,
                     "Particle radius r in m (default: read from the file, as m3dp run writes it)")
      ->check(CLI::PositiveNumber);
  command.add_option("--voxel-size", options.voxel_size, "Grid spacing in m (default r)")
      ->check(CLI::PositiveNumber);
  command.add_option("--kernel-radius", options.kernel_radius, "Kernel support in m (default 4 r)")->check(CLI::PositiveNumber);
  command.add_option("--sphere-radius", options.sphere_radius, "spherical: sphere radius in m (default 1.5 r)")
      ->check(CLI::PositiveNumber);
  command.add_option("--iso", options.iso_level, "sph_blobby, anisotropic: volume fraction on the surface")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 1.0));
  command.add_option("--smooth", options.smoothing_iterations, "Taubin smoothing iterations (0 = none)")
      ->check(CLI::NonNegativeNumber);
  command.add_option("--threads", options.threads, "Worker threads (default: all cores)")->check(CLI::NonNegativeNumber);
  command.add_flag("-q,--quiet", options.quiet, "No progress bar");
}

namespace {

std::string format_of(const MeshOptions& options, bool sequence) {
  if (!options.format.empty()) {
    if (options.format != "sdf" && !io::find_mesh_format(options.format))
      throw Error(fmt::format("--format '{}': expected {} or sdf", options.format, io::mesh_format_names()));
    return options.format;
  }
  if (const io::MeshFormat* format = io::mesh_format_of(options.output); format && !sequence) return std::string(format->name);
  return "obj";
}

surface::SurfaceSettings settings_of(const MeshOptions& options, const io::ParticleFrame& frame, const fs::path& file) {
  surface::SurfaceSettings settings;
  const auto method = surface::parse_method(options.method);
  if (!method) throw Error(fmt::format("--method '{}': expected one of {}", options.method, surface::method_names()));
  settings.method = *method;
  settings.particle_radius = static_cast<Real>(options.particle_radius);
  if (settings.particle_radius <= 0) {
    if (!frame.particle_radius)
      throw Error(fmt::format("{}: the file does not say its particle radius (FieldData 'particle_radius'); pass "
                              "--particle-radius",
                              file.string()));
    settings.particle_radius = *frame.particle_radius;
  }
  settings.voxel_size = static_cast<Real>(options.voxel_size);
  settings.kernel_radius = static_cast<Real>(options.kernel_radius);
  settings.sphere_radius = static_cast<Real>(options.sphere_radius);
  settings.iso_level = static_cast<Real>(options.iso_level);
  settings.smoothing_iterations = options.smoothing_iterations;
  return settings;
}

struct MeshedFrame {
  std::string line;  // what to print
  std::size_t particles = 0;
};

/// Meshes one frame and writes it. `incremental`, for a sequence, keeps the field of particles that
/// have not moved since the previous frame (frames with particle ids only, as m3dp run writes them).
MeshedFrame mesh_one(const MeshOptions& options, const fs::path& input, const fs::path& output, const std::string& format,
                     std::unique_ptr<surface::IncrementalSurface>* incremental = nullptr) {
  const io::ParticleFrame frame = io::read_particle_frame(input);
  const surface::SurfaceSettings settings = settings_of(options, frame, input);
  surface::SurfaceStats stats;
  const bool reuse = incremental && frame.ids.size() == frame.positions.size();
  if (reuse && !*incremental) *incremental = std::make_unique<surface::IncrementalSurface>(settings);
  const TriangleMesh mesh = reuse ? (*incremental)->reconstruct_frame(frame.positions, frame.ids, &stats)
                                  : surface::reconstruct_surface(frame.positions, settings, &stats);
  if (format == "sdf") {
    io::write_sdf_model(output, output.filename().string(), mesh);
  } else {
    if (output.has_parent_path()) fs::create_directories(output.parent_path());
    io::write_triangle_mesh(output, mesh);
  }
  return {fmt::format("{} → {}: {} particles{}, {} triangles, {} pieces, volume {:.6g} m³ ({} method, {:.3f} s field + {:.3f} s mesh, "
                      "{:.1f} MB grid)",
                      input.string(), output.string(), frame.positions.size(),
                      reuse ? fmt::format(" ({} meshed from a kept field: unmoved since earlier frames; {} of {} mesh tiles made again)",
                                          stats.reused_particles, stats.remeshed_tiles, stats.mesh_tiles)
                            : std::string(),
                      mesh.triangles.size(), surface::connected_components(mesh), surface::signed_volume(mesh),
                      surface::method_name(settings.method), stats.field_seconds, stats.mesh_seconds, stats.grid_bytes / 1e6),
          frame.positions.size()};
}

}  // namespace

int mesh_command(const MeshOptions& options) {
  ThreadLimit thread_limit(options.threads);
  const bool sequence = options.input.extension() == ".pvd";
  const std::string format = format_of(options, sequence);
  if (!sequence) {
    fmt::print("{}\n", mesh_one(options, options.input, options.output, format).line);
    return 0;
  }
  const auto entries = io::read_pvd(options.input);
  if (entries.empty()) throw Error(fmt::format("{}: the collection lists no datasets", options.input.string()));
  fs::create_directories(options.output);
  ProgressBar progress(stderr, !options.quiet);
  const auto start = std::chrono::steady_clock::now();
  ProgressSample sample;
  sample.end_time_s = entries.back().time;
  std::unique_ptr<surface::IncrementalSurface> incremental;  // the frames' resting material is meshed once
  for (std::size_t n = 0; n < entries.size(); ++n) {
    const std::string name = fmt::format("mesh_{:06}", n);
    const fs::path output = format == "sdf" ? options.output / name : options.output / (name + "." + format);
    const MeshedFrame meshed = mesh_one(options, entries[n].file, output, format, &incremental);
    if (options.quiet) fmt::print("{}\n", meshed.line);
    sample.particles = static_cast<long long>(meshed.particles);
    sample.simulated_time_s = entries[n].time;
    sample.steps = static_cast<long long>(n + 1);
    sample.wall_time_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    progress.update(sample);
  }
  progress.finish(sample);
  fmt::print("{} frames of {} → {} ({} files)\n", entries.size(), options.input.string(), options.output.string(), format);
  return 0;
}

}  // namespace m3dp::app
