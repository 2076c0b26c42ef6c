// The viscous threads of tension_cases.hpp at any resolution (not a test): the fine table of
// docs/validation.md. Usage:
//   tension_cases filament|column|bingham [--radius PARTICLE_RADIUS_M] [--length L0_M] [--no-tension]
//                 [--cap MAX_VISCOSITY_PA_S] [--support SUPPORT_IN_PARTICLE_RADII]
//                 [--stress-form SHARE]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "tension_cases.hpp"

int main(int argc, char** argv) {
  using namespace m3dp;
  const std::string which = argc > 1 ? argv[1] : "filament";
  bool tension = true;
  double particle_radius = 0, length = 0, cap = 1e5, support = 4, stress_form = 0;
  for (int a = 2; a < argc; ++a) {
    const std::string flag = argv[a];
    const bool has_value = a + 1 < argc;
    if (flag == "--no-tension") tension = false;
    else if (flag == "--radius" && has_value) particle_radius = std::atof(argv[++a]);
    else if (flag == "--length" && has_value) length = std::atof(argv[++a]);
    else if (flag == "--cap" && has_value) cap = std::atof(argv[++a]);
    else if (flag == "--support" && has_value) support = std::atof(argv[++a]);
    else if (flag == "--stress-form" && has_value) stress_form = std::atof(argv[++a]);
    else {
      std::fprintf(stderr, "tension_cases: unknown argument '%s'\n", argv[a]);
      return 2;
    }
  }
  if (which == "filament") {
    tension::FilamentCase filament;
    filament.tension = tension;
    if (particle_radius > 0) filament.particle_radius = Real(particle_radius);
    if (length > 0) filament.length = Real(length);
    filament.support_radius_factor = Real(support);
    filament.stress_form_viscosity = Real(stress_form);
    tension::stretch_filament(filament);
    return 0;
  }
  if (which == "column" || which == "bingham") {
    tension::ColumnCase column;
    column.tension = tension;
    if (particle_radius > 0) column.particle_radius = Real(particle_radius);
    if (length > 0) column.length = Real(length);
    column.support_radius_factor = Real(support);
    column.stress_form_viscosity = Real(stress_form);
    if (which == "column") {
      tension::hang_column(column, tension::stokes_break_time(column));
      return 0;
    }
    column.material = tension::bingham_paste(Real(cap));
    const double critical = tension::critical_length(column.material);
    const auto result = tension::hang_column(column, tension::bingham_break_time(column), Real(critical));
    std::printf("bingham: the part below L_c = %.1f mm stretched %.2f %%\n", 1e3 * critical, 100 * result.lower_part_strain);
    return 0;
  }
  std::fprintf(stderr, "tension_cases: unknown case '%s' (filament, column, bingham)\n", which.c_str());
  return 2;
}
