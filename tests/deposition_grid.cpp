// The deposition grid of issue 38, one command: strands from a nozzle with a bore over g/D × V/U for a
// Newtonian paste and a Bingham mortar (pressed where g/D ≤ 1 and U/V ≥ (g/D)², free elsewhere),
// each against mass conservation and its reference section. Prints a CSV table (stdout or -o FILE)
// that scripts/plot_deposition.py draws; not in CI (about a minute a point on two cores).
//   build/tests/deposition_grid [-o FILE] [--quick] [--cap PA_S] [--across N] [--gap G/D --speed V/U]
//                               [--no-rest] [--particles PREFIX] [--bore L/D (0: the exit-plane inlet)]
//                               [--material bingham|newtonian] [--yield-stress PA] [--plastic-viscosity PA_S]
//                               [--surface floor|layer] [--viscosity PA_S] [--tension] [--stress-form SHARE]
// (--gap and --speed: that one point of the grid only; --particles: each strand's particles at the
// end as PREFIX_MATERIAL_G_V_SURFACE.csv; --material newtonian with --gap/--speed lays a free
// Newtonian rope too; --yield-stress and --plastic-viscosity change the mortar's Bingham figures,
// --viscosity the Newtonian paste's; --tension and --stress-form turn on the tension projection and the
// implicit viscosity's stress form, issue 55. least_area and greatest_area are the smallest and largest
// stations' sections over the nominal one: a torn rope has a station near 0.)
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "m3dp/sim/strand_deposition.hpp"
#include "m3dp/core/types.hpp"

using namespace m3dp;
namespace deposition = m3dp::sim::deposition;

int main(int argc, char** argv) {
  std::string output, particles_csv, only_material, only_surface;
  bool quick = false, rest_detection = true, tension = false;
  double stress_form = 0, newtonian_viscosity = 0;
  double cap = 0, across = 8, only_gap = 0, only_speed = 0, bore = 2, yield_stress = 0, plastic_viscosity = 0;
  for (int k = 1; k < argc; ++k) {
    if (!std::strcmp(argv[k], "-o") && k + 1 < argc) output = argv[++k];
    else if (!std::strcmp(argv[k], "--quick")) quick = true;
    else if (!std::strcmp(argv[k], "--material") && k + 1 < argc) only_material = argv[++k];
    else if (!std::strcmp(argv[k], "--no-rest")) rest_detection = false;
    else if (!std::strcmp(argv[k], "--bore") && k + 1 < argc) bore = std::atof(argv[++k]);
    else if (!std::strcmp(argv[k], "--cap") && k + 1 < argc) cap = std::atof(argv[++k]);
    else if (!std::strcmp(argv[k], "--across") && k + 1 < argc) across = std::atof(argv[++k]);
    else if (!std::strcmp(argv[k], "--gap") && k + 1 < argc) only_gap = std::atof(argv[++k]);
    else if (!std::strcmp(argv[k], "--particles") && k + 1 < argc) particles_csv = argv[++k];
    else if (!std::strcmp(argv[k], "--speed") && k + 1 < argc) only_speed = std::atof(argv[++k]);
    else if (!std::strcmp(argv[k], "--surface") && k + 1 < argc) only_surface = argv[++k];
    else if (!std::strcmp(argv[k], "--yield-stress") && k + 1 < argc) yield_stress = std::atof(argv[++k]);
    else if (!std::strcmp(argv[k], "--plastic-viscosity") && k + 1 < argc) plastic_viscosity = std::atof(argv[++k]);
    else if (!std::strcmp(argv[k], "--viscosity") && k + 1 < argc) newtonian_viscosity = std::atof(argv[++k]);
    else if (!std::strcmp(argv[k], "--tension")) tension = true;
    else if (!std::strcmp(argv[k], "--stress-form") && k + 1 < argc) stress_form = std::atof(argv[++k]);
    else {
      std::fprintf(stderr, "usage: %s [-o FILE] [--quick] [--cap PA_S] [--across PARTICLES_PER_BORE] [--gap G_OVER_D --speed V_OVER_U] [--no-rest] [--particles PREFIX] [--bore LENGTH_OVER_D] [--material bingham|newtonian] [--yield-stress PA] [--plastic-viscosity PA_S] [--surface floor|layer] [--viscosity PA_S] [--tension] [--stress-form SHARE]\n",
                   argv[0]);
      return 2;
    }
  }
  if (!only_surface.empty() && only_surface != "floor" && only_surface != "layer") {
    std::fprintf(stderr, "%s: --surface is floor or layer, got %s\n", argv[0], only_surface.c_str());
    return 2;
  }
  std::FILE* out = output.empty() ? stdout : std::fopen(output.c_str(), "w");
  if (!out) {
    std::fprintf(stderr, "cannot write %s\n", output.c_str());
    return 1;
  }
  std::fprintf(out, "material,regime,surface,g_over_D,V_over_U,area_ratio,least_area,greatest_area,height_mm,reference_height_mm,width_mm,reference_width_mm,"
                    "landed,extrusion_pressure_Pa,blocked_steps,particles,seconds\n");
  std::vector<double> gaps = quick ? std::vector<double>{0.5, 1.5} : std::vector<double>{0.25, 0.5, 0.75, 1.0, 1.5, 2.0};
  std::vector<double> speeds = quick ? std::vector<double>{1} : std::vector<double>{0.5, 1, 1.5, 2};
  if (only_gap > 0) gaps = {only_gap};
  if (only_speed > 0) speeds = {only_speed};
  for (const bool bingham : {true, false}) {
    if (!only_material.empty() && only_material != (bingham ? "bingham" : "newtonian")) continue;
    for (const double gap : gaps)
      for (const double speed : speeds)
        for (const bool on_layer : {false, true}) {
          if (!only_surface.empty() && only_surface != (on_layer ? "layer" : "floor")) continue;
          deposition::StrandCase strand;
          strand.material = bingham ? deposition::printable_mortar() : deposition::stiff_newtonian_paste();
          if (bingham && yield_stress > 0) strand.material.rheology.yield_stress = Real(yield_stress);
          if (bingham && plastic_viscosity > 0) strand.material.rheology.viscosity = Real(plastic_viscosity);
          if (!bingham && newtonian_viscosity > 0) strand.material.rheology.viscosity = Real(newtonian_viscosity);
          strand.tension = tension;
          strand.stress_form = stress_form;
          strand.gap_ratio = gap;
          strand.speed_ratio = speed;
          strand.particles_across = across;
          strand.viscosity_cap = cap;
          strand.on_layer = on_layer;
          strand.rest_detection = rest_detection;
          strand.bore_ratio = bore;
          if (!particles_csv.empty())
            strand.particles_csv = particles_csv + "_" + (bingham ? "bingham" : "newtonian") + "_" + std::to_string(gap) + "_" +
                                   std::to_string(speed) + (on_layer ? "_layer" : "_floor") + ".csv";
          const bool pressed = deposition::pressed(strand);
          if (on_layer && pressed) continue;   // pressed strands: on the floor
          // Free ropes: the mortar that holds its shape, unless a Newtonian one is asked for alone.
          if (!bingham && !pressed && !(only_material == "newtonian" && only_gap > 0)) continue;
          const auto result = deposition::lay_strand(strand);
          const double round = strand.diameter * std::sqrt(1 / speed);
          const double reference_height = pressed ? gap * strand.diameter : round;
          const double reference_width = pressed ? deposition::rounded_box_width(strand) : round;
          std::fprintf(out, "%s,%s,%s,%.2f,%.2f,%.4f,%.4f,%.4f,%.3f,%.3f,%.3f,%.3f,%.3f,%.1f,%llu,%zu,%.1f\n", bingham ? "bingham_mortar" : "newtonian_paste",
                       pressed ? "pressed" : "free", on_layer ? "layer" : "floor", gap, speed, result.area / deposition::nominal_area(strand),
                       result.least_area / deposition::nominal_area(strand), result.greatest_area / deposition::nominal_area(strand),
                       1e3 * result.height, 1e3 * reference_height, 1e3 * result.width, 1e3 * reference_width, result.landed,
                       result.extrusion_pressure, result.blocked_layers, result.particles, result.seconds);
          std::fflush(out);
        }
  }
  if (out != stdout) std::fclose(out);
  return 0;
}
