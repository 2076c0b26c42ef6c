#pragma once
// The compiled model: the parameters as given and every constant derived from them, computed once
// (MuJoCo's mjModel). compile_model is the one place that checks engine parameters; its problems
// name the phase, nozzle or setting and the field, so the scene reader can point at file:line.
#include <cstddef>
#include <string>
#include <vector>

#include "m3dp/core/error.hpp"
#include "m3dp/sph/settings.hpp"

namespace m3dp::sph {

/// Factors on the viscosity sums that make them exact on the rest lattice (see model.cpp).
struct ViscosityCalibration {
  Real fluid = 1;     // on fluid–fluid pairs
  Real boundary = 1;  // on fluid–boundary pairs: no slip at the geometric surface
  Real fluid_gradient = 1;     // on the velocity gradient's fluid sum
  Real boundary_gradient = 1;  // on its wall sum
  // 1/m²: on the rest lattice, Σ_j |c_ij| r_ij² = Δt μ/ρ0 × coupling (c_ij the implicit solve's pair
  // coefficients): how strongly the viscous term couples a particle to its neighbours in a step.
  Real coupling = 0;
};

/// Surface tension (Akinci et al. 2013) coefficients per unit of the material's physical values:
/// γ = cohesion_per_tension × σ / (ρ0_i ρ0_j), β = adhesion_per_work × W_a / ρ0_i² (σ, W_a in N/m); see
/// surface_tension/akinci2013.cpp.
struct SurfaceTensionCalibration {
  Real cohesion_per_tension = 0;
  Real adhesion_per_work = 0;
  Real layer_kernel_sum = 0;  // CSF: d² Σ_j W_fit over a flat layer of the rest lattice (m² · kernel units)
};

/// A granular phase's contact law as the solver uses it.
struct GranularContact {
  Real stiffness = 0;      // N/m, normal spring
  Real damping_ratio = 0;  // ζ of the normal dashpot, from the restitution
  Real friction = 0;       // Coulomb μ
};

/// A nozzle's disc of sample offsets and its layer period.
struct NozzleGeometry {
  std::vector<Vec3> disc_offsets;  // in the nozzle frame, z = 0
  double layer_period = 0;         // s between layers at the set exit speed
  double flux = 0;                 // m³/s: π D²/4 · U, the flow at flow scale 1
  // A nozzle with a bore (NozzleSettings::bore_length > 0): its walls in the nozzle frame (exit plane
  // z = 0, the bore above it), the body that carries them (set by the Solver), and the depth below
  // the bore's top where the piston drives the material.
  std::vector<Vec3> bore_points;
  std::vector<Vec3> piston_points;  // the lid over the bore, a spacing above where discs come in
  std::int32_t bore_body = -1, piston_body = -1;
  Real piston_depth = 0;           // m
  [[nodiscard]] bool has_bore() const { return !bore_points.empty(); }
};

/// One thing wrong with the parameters. `field` is the setting's or material's field as the scene
/// file names it ("particle_radius", "elasticity.poisson_ratio"); `index` the phase or nozzle.
struct ParameterProblem {
  enum class Subject { settings, phase, nozzle };
  Subject subject = Subject::settings;
  std::size_t index = 0;
  std::string field;
  std::string message;  // what is wrong and what was expected, e.g. "must be > 0 m"
  [[nodiscard]] std::string str(const Parameters& parameters) const;  // "material 'clay': elasticity.poisson_ratio must be ..."
};

/// Every problem of the parameters that ties fields together (empty when they are fine); each field's
/// own range is the scene table's (scene/schema.hpp), which every scene is read through.
[[nodiscard]] std::vector<ParameterProblem> check_parameters(const Parameters& parameters);

/// Thrown by compile_model for parameters check_parameters does not accept.
class ParameterError : public Error {
 public:
  ParameterError(std::vector<ParameterProblem> problems, const Parameters& parameters);
  [[nodiscard]] const std::vector<ParameterProblem>& problems() const { return problems_; }

 private:
  std::vector<ParameterProblem> problems_;
};

struct Model : Parameters {
  // Lengths and volumes of one particle.
  Real particle_radius = 0;        // m (settings.particle_radius)
  Real particle_diameter = 0;      // m: the rest spacing d
  Real particle_volume = 0;        // m³: d³
  Real support_radius = 0;         // m: settings.support_radius_factor × radius
  Real wall_spacing = 0;           // m: spacing of the boundary particles
  std::vector<Real> particle_mass; // kg per phase: rest density × d³
  int full_neighbourhood = 1;      // neighbours of an interior particle on the rest lattice
  Real widest_nozzle = 0;          // m, largest inner diameter

  // Kernel calibrations on the rest lattice.
  Real boundary_volume_scale = 1;     // on Akinci's boundary volumes (a fluid one spacing from a wall at rest density)
  Real boundary_share_at_surface = 1; // Σ_b V_b W a tenth of a radius in front of a flat wall's geometric surface
  ViscosityCalibration viscosity_calibration;
  SurfaceTensionCalibration surface_tension_calibration;

  // What the phases need, together.
  Real largest_surface_tension = 0;   // N/m (capillary time-step limit)
  Real lightest_rest_density = 0;     // kg/m³
  bool any_elastic = false;
  bool any_shear_rate = false;        // some phase's viscosity depends on its shear rate or age
  bool any_wall_friction = false;     // some phase has a boundary viscosity or sticks
  bool granular = false;              // every phase is granular: discrete spheres, no fluid stages
  std::vector<Real> microinertia;     // m² per phase (micropolar)
  std::vector<GranularContact> granular_contacts;  // per phase (granular mode)
  Real granular_time_step = 0;        // s, a tenth of the shortest contact duration
  std::vector<NozzleGeometry> nozzle_geometry;     // per nozzle
};

/// Checks `parameters` (throws ParameterError listing every problem) and derives the model.
[[nodiscard]] Model compile_model(Parameters parameters);

// Calibrations computed by their method's file.
/// The mean-field surface energy of Akinci's cohesion and adhesion forces on the rest lattice.
SurfaceTensionCalibration calibrated_surface_tension(KernelType kernel_type, Real support_radius, Real fluid_spacing,
                                                     Real wall_spacing, Real boundary_volume_scale);
/// The CSF's area scale: d² Σ_j W over a flat layer of the rest lattice with the curvature fit's kernel, so
/// that a layer particle's area is this over its kernel sum. See surface_tension/brackbill1992.cpp.
Real csf_layer_kernel_sum(KernelType kernel_type, Real support_radius, Real spacing);
/// Drag coefficient of a sphere at Reynolds number Re (Schiller & Naumann 1933; 0.44 from Re = 1000).
Real sphere_drag_coefficient(Real reynolds_number);
/// Neighbours (excluding itself) of a particle on the rest lattice of spacing `spacing`.
int full_neighbourhood_count(Real support_radius, Real spacing);

}  // namespace m3dp::sph
