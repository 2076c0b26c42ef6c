// meshes/mesh_NNNNNN.EXT: the printed material's surface meshes, which the simulation makes every
// <meshing><period> and puts into the world (printed_body.hpp) whether or not a run writes them; this
// output has them written into the run folder, and the final state's too, and reports them.
#include "m3dp/core/error.hpp"
#include "m3dp/sim/outputs/outputs.hpp"
#include "m3dp/sim/printed_body.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim::outputs {

namespace {

class PrintedMesh final : public RunObserver {
 public:
  [[nodiscard]] std::string_view name() const override { return "the printed-material meshes"; }
  PrintedMesh(PrintedBody& body, const RunOptions& options) : body_(body) {
    // Where the meshes go, and whether the solver waits for each (a reproducible run) or steps on.
    body_.set_output(options.output_directory / "meshes", options.wait_for_meshes || options.hash);
  }
  [[nodiscard]] double period() const override { return 0; }
  void start(const Simulation& /*simulation*/) override {}
  void observe(const Simulation& /*simulation*/, const StepReport& /*report*/) override {}
  // The meshes so far are in the simulation's checkpoint.
  void save(StateWriter& /*out*/) override {}
  void resume(const Simulation& /*simulation*/, StateReader& /*in*/) override {}

  void finish(const Simulation& simulation, RunSummary& summary) override {
    // The final state is always meshed (after the mesh in progress): nothing printed goes unmeshed.
    body_.mesh_now(simulation);
    summary.meshes = body_.meshes();
    summary.meshes_written = summary.meshes.size();
    summary.meshes_skipped = body_.skipped();
    summary.meshes_inserted = simulation.printed_mesh_version();
    // A mesh that could not be made or written leaves a gap in meshes/: the run did not do all it was asked.
    // It is thrown, so that the run names this output and says the simulation completed.
    if (!body_.error().empty()) throw Error(body_.error());
  }

 private:
  PrintedBody& body_;
};

}  // namespace

std::unique_ptr<RunObserver> make_printed_mesh(Simulation& simulation, const RunOptions& options) {
  if (options.output_directory.empty() || !simulation.printed_body()) return nullptr;
  return std::make_unique<PrintedMesh>(*simulation.printed_body(), options);
}

}  // namespace m3dp::sim::outputs
