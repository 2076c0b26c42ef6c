// particles/particles_NNNNNN.vtu every <output><particles_period> of simulated time (and at the
// start), listed in particles.pvd: a ParaView time series.
#include <fmt/format.h>

#include "m3dp/io/vtk_writer.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

class ParticleFrames final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the particle frames (particles.pvd)"; }
  ParticleFrames(const std::filesystem::path& output_directory, double period)
      : folder_(output_directory / "particles"), collection_(output_directory / "particles.pvd"), period_(period) {
    std::filesystem::create_directories(folder_);
  }
  [[nodiscard]] double period() const override { return period_; }
  void start(const Simulation& simulation) override { write(simulation); }
  void observe(const Simulation& simulation, const StepReport& /*report*/) override { write(simulation); }
  void finish(const Simulation& /*simulation*/, RunSummary& summary) override { summary.frames_written = collection_.size(); }
  // The frames after the checkpoint are written again under the same numbers.
  void save(StateWriter& out) override { collection_.save(out); }
  void resume(const Simulation& /*simulation*/, StateReader& in) override { collection_.load(in); }

 private:
  void write(const Simulation& simulation) {
    const auto& solver = simulation.solver();
    const auto& fluid = solver.fluid();
    // The density measured where the particles are written (the density pass's own values are from
    // before the step moved them, and stale for resting particles).
    const auto& density = simulation.measured_density().density;
    pressure_.resize(fluid.size());
    for (std::size_t i = 0; i < fluid.size(); ++i) pressure_[i] = solver.pressure(i);
    const auto file = folder_ / fmt::format("particles_{:06}.vtu", collection_.size());
    io::write_vtu(file, fluid.position,
                  {io::PointArray::of("velocity", fluid.velocity), io::PointArray::of("density", density),
                   io::PointArray::of("pressure", pressure_), io::PointArray::of("material", fluid.phase),
                   io::PointArray::of("id", fluid.id), io::PointArray::of("birth_time", fluid.birth_time),
                   io::PointArray::of("layer", fluid.print_layer),
                   io::PointArray::of("viscosity", fluid.viscosity), io::PointArray::of("shear_rate", fluid.shear_rate),
                   io::PointArray::of("rest_time", fluid.rest_time),
                   io::PointArray::of("angular_velocity", fluid.angular_velocity)},
                  {{"particle_radius", solver.parameters().settings.particle_radius}, {"time", solver.time()}});
    collection_.add(solver.time(), file);
  }

  std::filesystem::path folder_;
  io::PvdCollection collection_;
  double period_;
  std::vector<Real> pressure_;
};

}  // namespace

double frame_period(const Simulation& simulation, const RunOptions& options) {
  return scene::particle_frame_period(simulation.scene().output, options.until.value_or(simulation.scene().end_time));
}

std::unique_ptr<RunObserver> make_particle_frames(Simulation& simulation, const RunOptions& options) {
  const auto& output = simulation.scene().output;
  const double period = frame_period(simulation, options);
  if (options.output_directory.empty() || !output.write_particles || !(period > 0)) return nullptr;
  return std::make_unique<ParticleFrames>(options.output_directory, period);
}

}  // namespace m3dp::sim::outputs
