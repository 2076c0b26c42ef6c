#pragma once
// Reference set-ups built in code (no file): used by tests, benchmarks and `m3dp bench`.
#include "m3dp/scene/scene.hpp"

namespace m3dp::sim {

/// Martin & Moyce 1952 dam break: a water column of width a and height 2a at the left wall of a
/// tank 5a long, released at t = 0. Depth (y) spans the tank between two side walls.
struct DamBreakSetup {
  Real column_width = Real(0.1);  // a (m)
  Real depth = Real(0.05);        // tank depth (m)
  Real particle_radius = Real(0.004);
  Real tank_length_factor = 5;    // tank length / a
  double end_time = 0.25;         // s
  Real viscosity = Real(1e-3);    // Pa·s
  sph::KernelType kernel = sph::KernelType::cubic_spline;
};

/// Particle radius that gives about `particle_count` fluid particles for a column with depth = depth_ratio · a.
Real dam_break_radius_for_count(std::size_t particle_count, Real column_width, Real depth);

scene::Scene dam_break_scene(const DamBreakSetup& setup);

/// A tank of water at rest: width × width footprint, fluid height `height`; the floor is its own body.
struct HydrostaticSetup {
  Real width = Real(0.1);
  Real height = Real(0.1);
  Real particle_radius = Real(0.005);
  double end_time = 1.0;
};

scene::Scene hydrostatic_scene(const HydrostaticSetup& setup);

/// High-viscosity printing: a nozzle lays a clay strand along a slab of already printed clay
/// (the clay_paste preset, Herschel–Bulkley, implicit viscosity) on a floor.
struct ClayPrintSetup {
  std::size_t slab_particles = 20000;   // the printed clay already there
  Real particle_radius = Real(0.00125);
  Real max_viscosity = Real(1e4);       // Pa·s: cap of the effective viscosity (the preset's unyielded 10⁶ is far stiffer)
  Real time_step = Real(1e-3);          // s, the largest step the solver may take
  double end_time = 100;
};

scene::Scene clay_print_scene(const ClayPrintSetup& setup);

/// A square wall printed layer on layer by a gantry nozzle, in clay: the case for "material at rest
/// costs nothing" (the cost of a step at the top layer against the second).
struct WallPrintSetup {
  int layers = 20;
  Real side = Real(0.04);              // m, square wall's side
  Real layer_height = Real(0.008);     // m
  Real nozzle_diameter = Real(0.008);  // m
  Real nozzle_speed = Real(0.1);       // m/s
  Real particle_radius = Real(0.001);
  Real max_viscosity = Real(1e4);      // Pa·s cap of the clay's effective viscosity
};

scene::Scene wall_print_scene(const WallPrintSetup& setup);

/// A test paste: Bingham, 150 Pa yield stress, 5 Pa·s, 1500 kg/m³, sticking to walls. It holds a
/// 1 cm bead (τ0 ≥ ρ g h/√3 ≈ 85 Pa).
material::Material bingham_test_paste();

/// A slab of bingham_test_paste() on a floor: it settles and comes to rest within about 0.2 s. The slab is centred on the origin and sits on z = 0.
struct PasteSlabSetup {
  Real half_width = Real(0.06);  // m, the slab's half side
  Real height = Real(0.03);      // m
  Real particle_radius = Real(0.0025);
  double end_time = 1.0;
};

scene::Scene paste_slab_scene(const PasteSlabSetup& setup);

}  // namespace m3dp::sim
