#pragma once
// One strand laid by a nozzle with a bore (sph::NozzleSettings::bore_length; or the exit-plane inlet)
// along x over a floor or over a strand of the same material laid before, and its steady section
// measured: the deposition tests (test_deposition), the grid study (tests/deposition_grid) and
// `m3dp bench strand` share it.
// D = nozzle bore, g = gap from the exit to the surface below, U = mean extrusion speed, V = travel speed.
#include <string>

#include "m3dp/material/material.hpp"

namespace m3dp::sim::deposition {

struct StrandCase {
  std::string label;
  material::Material material;
  double diameter = 0.01;            // m, D
  double gap_ratio = 0.5;            // g/D
  double speed_ratio = 1;            // V/U
  double exit_speed = 0.05;          // m/s, U
  double outer_ratio = 3;            // the tip's outer diameter / D
  double bore_ratio = 2;             // bore length / D; 0: no bore (the exit plane is the inlet)
  double particles_across = 8;       // D / particle diameter
  double length = 0.2;               // m of line; the middle 60 % is measured
  bool on_layer = false;             // laid on a strand printed before (same material, pressed at g = D/2)
  double viscosity_cap = 0;          // Pa·s; 0: the material's own
  bool rest_detection = true;
  bool tension = false;              // the tension projection (SolverSettings::tension)
  double stress_form = 0;            // the implicit viscosity's stress-form share (SolverSettings::stress_form_viscosity)
  std::string particles_csv;         // where to write the particles at the end (x, y, z, id, at rest, of the strand
                                     // measured or the layer below); empty: nowhere
};

struct StrandResult {
  double area = 0;           // m², the section of the particles' surface (union of spheres of 1.31 r), steady part
  double least_area = 0, greatest_area = 0;  // m², the smallest and largest of the stations' sections there
  double counted_area = 0;   // m², the particles' volume per length there
  double width = 0;          // m, mean over the stations that hold material
  double height = 0;         // m, at the centreline: the material's volume per footprint (see lay_strand)
  double top = 0;            // m, the highest particles' tops over the surface below (the same stations)
  double landed = 0;         // fraction of the steady part whose bottom lies on the surface below (within d)
  // The same steady part measured by the quality module (quality/sections.hpp) against the line as
  // designed: its sections' mean width, height (the material's extent up) and area.
  double quality_width = 0, quality_height = 0, quality_area = 0;
  double extrusion_pressure = 0;  // Pa, mean over the steady part
  double bottom = 0;         // m, the surface below
  double seconds = 0;        // wall time
  unsigned long long steps = 0, blocked_layers = 0;
  double particle_steps = 0;  // Σ over steps of the particles simulated (moving)
  double step_seconds = 0;    // wall time in the solver's steps
  std::size_t particles = 0;
};

/// The demo's printable mortar (data/materials.xml: Bingham, τ0 = 1 kPa, μp = 10 Pa·s, 10 Pa·s against
/// walls), capped at 10⁴ Pa·s as the demo caps it.
material::Material printable_mortar();
/// A stiff Newtonian paste (a clay-like 10⁴ Pa·s, 1800 kg/m³) that flows little over the seconds
/// measured and sticks to the bed (the nozzle's bore and lip slip: Material::nozzle_no_slip is off).
material::Material stiff_newtonian_paste();

/// Lays the strand and measures it.
StrandResult lay_strand(const StrandCase& strand);

/// The reference section's area (U/V)·πD²/4 (m²).
double nominal_area(const StrandCase& strand);
/// The rounded box's width for a pressed strand (g ≤ D, U/V ≥ (g/D)²), m: w/D = (π/4)(U/V)/(g/D) + (g/D)(1 − π/4).
double rounded_box_width(const StrandCase& strand);
/// Whether the nozzle presses the strand: g/D ≤ 1 and U/V ≥ (g/D)².
bool pressed(const StrandCase& strand);

}  // namespace m3dp::sim::deposition
