#pragma once
// What the particle engine is given: solver settings, the materials (phases) and the nozzles. Plain
// data that the scene reader and tests fill; compile_model (model.hpp) checks it and derives every
// constant the stages use. Nothing here knows the engine's state.
#include <cstdint>
#include <string>
#include <vector>

#include "m3dp/core/types.hpp"
#include "m3dp/material/material.hpp"
#include "m3dp/sph/kernels.hpp"

namespace m3dp::sph {

/// A fluid as the solver sees it: a material (density, rheology, ageing, boundary viscosity).
/// Phases may differ in rest density: every particle has the rest volume d³ (its mass is its phase's
/// rest density × d³), and the solver works with volumes (see pressure/dfsph_bender2017.cpp).
using FluidPhase = material::Material;

/// How surface tension is modelled.
enum class SurfaceTensionModel {
  // Akinci et al. 2013 cohesion, curvature and wall adhesion: robust down to single particles and
  // with any wetting, but σ sets only its scale (a droplet oscillates 2.6–3× too fast).
  akinci2013,
  // Continuum surface force (Brackbill et al. 1992) with curvature fitted to the surface: the physical
  // σ (Rayleigh's droplet within 3 %), for surfaces resolved by ~10 particles per radius of curvature;
  // walls are wetted at 90° (no adhesion setting).
  csf_brackbill1992,
};

/// How viscous forces are integrated.
enum class ViscositySolver {
  implicit_weiler2018,  // Weiler et al. 2018: stable at any viscosity and time step (conjugate gradients)
  explicit_morris1997,  // Morris et al. 1997: cheaper for water, but Δt ≤ 0.125 d²ρ/μ
};

struct SolverSettings {
  Real particle_radius = Real(0.01);          // m; rest spacing is 2 × radius
  KernelType kernel = KernelType::cubic_spline;
  Real support_radius_factor = 4;             // support radius = factor × particle radius
  Real boundary_spacing_factor = Real(1.0);   // boundary particle spacing = factor × diameter (volumes and
                                              // the wall calibration follow it; 0.5 gives smoother walls)
  Vec3 gravity = Vec3(0, 0, Real(-9.81));     // m/s²
  Real cfl_factor = Real(0.5);                // dt = cfl · 0.4 · diameter / v_max
  Real min_time_step = Real(1e-5);            // s
  Real max_time_step = Real(5e-3);            // s
  Real density_tolerance = Real(0.0005);      // mean relative density error of the density solve
  // The compression the volume correction leaves (a fraction of ρ0): after the viscosity solve, what
  // a particle would be compressed beyond this is taken out of the positions (correct_volume).
  Real volume_tolerance = Real(0.01);
  // The least distance between two particles the volume correction leaves, in particle diameters.
  Real minimum_spacing = Real(0.7);
  // Tension in viscous material (pressure/projection_cummins_rudman1999.cpp): after the implicit
  // viscosity a two-sided projection takes the velocities' divergence out (pushing and pulling, the air
  // beyond a free surface at p = 0, and the dilation of the material's interior), and its pressure is
  // kept and applied again before the next step's viscosity solve, so that a stretched thread thins as
  // an incompressible one does instead of dilating and cracking. Off by default until its extensional
  // stress is right (docs/decisions.md, "Tension in viscous material"); false: the solves only push.
  bool tension = false;
  int max_tension_iterations = 100;           // conjugate-gradient iterations of the projection
  // Particle shifting of viscous materials' moving particles (shift_particles): Skillen et al.'s A
  // (they use 1 to 6); 0 leaves the particles where the solves put them.
  Real shifting_factor = Real(4);
  Real divergence_tolerance = Real(0.001);    // mean relative density change per step of the divergence solve
  int min_density_iterations = 2;
  int max_density_iterations = 100;
  int max_divergence_iterations = 100;
  // The divergence solve stops at once when its warm start already meets the tolerance (the usual
  // case for a settled flow).
  int min_divergence_iterations = 0;
  bool divergence_solver = true;
  bool warm_start = true;                     // the solves start from the last step's solution (false: cold, v* and κ = 0)
  Aabb bounds;                                // particles leaving it are removed (m)
  Real max_speed = 100;                       // m/s; faster means the state exploded
  int reorder_interval = 32;                  // steps between Z-order reorderings
  // Neighbour lists kept across steps (SkinnedNeighborSearch) with this skin, a fraction of the support
  // radius, while the material is slow: each step the solver predicts from the speeds whether they
  // would last, and returns to a search every step where they did not (a splash). 0: never.
  Real neighbor_skin = Real(0.1);
  ViscositySolver viscosity_solver = ViscositySolver::implicit_weiler2018;
  Real viscosity_tolerance = Real(1e-2);      // implicit viscosity: relative residual ‖b − Av‖/‖b‖ of the solve
  int max_viscosity_iterations = 300;
  // The share of the implicit viscosity taken by the stress form (viscosity/weiler2018_stress.cpp:
  // the velocity gradient, then the divergence of μ(∇v + ∇vᵀ), isotropic on the rest lattice) instead of
  // the pair form, whose normal stress along a lattice axis is twice the isotropic one at a support
  // of four radii. 0: the pair form alone; at most 0.95 (the pair form damps the stress form's
  // particle-scale modes, which it does not see).
  Real stress_form_viscosity = 0;
  Real xsph_factor = 0;                       // XSPH velocity smoothing ε (Monaghan 1989), 0 = none
  SurfaceTensionModel surface_tension_model = SurfaceTensionModel::akinci2013;
  // Material at rest costs nothing: a particle of a yield-stress material that has moved slower than
  // rest_speed, below its yield stress, for rest_duration leaves the solve and stays where it is as a
  // fixed neighbour of the material still moving. It wakes when a moving neighbour (fluid faster than
  // wake_speed, or a moving body's surface) comes within a support radius.
  bool rest_detection = true;
  // Buildability: resting material also wakes when the weight above it (checked every
  // rest_duration/2) has grown since it came to rest by a tenth of its yield stress and exceeds
  // Roussel's unconfined bound √3 τ0, and is then simulated for load_wake_duration. Off by default:
  // a print nearing its bound then costs what it costs without rest detection.
  bool wake_on_load = false;
  // Air drag on the material's surface (Gissler et al. 2017), off by default: still air exerts
  // ½ ρ_air C_D A v² on each exposed particle; wind is air_velocity.
  bool air_drag = false;
  Real air_density = Real(1.204);             // kg/m³, dry air at 20 °C
  Real air_viscosity = Real(1.825e-5);        // Pa·s, dry air at 20 °C
  Vec3 air_velocity = Vec3::Zero();           // m/s
  Real rest_speed = Real(2e-3);               // m/s
  // Resting material compressed beyond this fraction of ρ0 wakes (moving material was pressed
  // against it), and material does not come to rest so compressed. Resting paste sits about 1 %
  // above ρ0 (the volume correction's floor), the odd particle 2-3 %.
  Real rest_compression = Real(0.03);
  Real rest_duration = Real(0.05);            // s
  Real wake_speed = Real(5e-3);               // m/s
  Real load_wake_duration = 1;                // s: material woken by load is simulated at least this long
                                              // (a collapse starts slowly)
};

/// A circular nozzle that emits whole disc layers of particles (volume flux π D²/4 · U).
struct NozzleSettings {
  std::string name;
  Real inner_diameter = Real(0.01);   // m
  Real exit_speed = Real(0.1);        // m/s, mean speed of material leaving the nozzle
  std::uint16_t phase = 0;
  // A nozzle with walls: the bore's inner wall over `bore_length` above the exit and the flat tip, an
  // annulus out to `outer_diameter` (the lip that presses a bead), as boundary particles moving with
  // the nozzle. Material enters at the bore's top, driven at the commanded flow by a piston zone (a
  // pump: the flow is imposed, the pressure follows), and leaves pushed by the material behind it.
  // bore_length 0: no walls, the exit plane is a velocity inlet one particle deep.
  Real bore_length = 0;               // m
  Real outer_diameter = 0;            // m; below inner_diameter + 2 particle diameters: that (a thin wall)
};

/// Everything the engine is given.
struct Parameters {
  SolverSettings settings;
  std::vector<FluidPhase> phases;
  std::vector<NozzleSettings> nozzles;
};

/// Rest volume of every fluid particle (m³): the particle diameter cubed.
inline Real particle_rest_volume(Real particle_radius) { return 8 * particle_radius * particle_radius * particle_radius; }

}  // namespace m3dp::sph
