// The scene language's table (schema.hpp): units, ranges and the plugin's elements, and the
// reference page made from them.
#include "m3dp/scene/schema.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>
#include <type_traits>

#include "m3dp/material/material.hpp"
#include "m3dp/scene/scene.hpp"

namespace m3dp::scene {

QuantityInfo quantity_info(Quantity quantity) {
  static constexpr Unit kLength[] = {{"m", 1}, {"cm", 1e-2}, {"mm", 1e-3}};
  static constexpr Unit kTime[] = {{"s", 1}, {"ms", 1e-3}};
  static constexpr Unit kSpeed[] = {{"m/s", 1}, {"mm/s", 1e-3}};
  static constexpr Unit kAcceleration[] = {{"m/s^2", 1}, {"m/s2", 1}};
  static constexpr Unit kDensity[] = {{"kg/m^3", 1}, {"kg/m3", 1}, {"g/cm^3", 1e3}, {"g/cm3", 1e3}};
  static constexpr Unit kDynamicViscosity[] = {{"Pa*s", 1},      {"Pa.s", 1},      {"Pa·s", 1},
                                               {"mPa*s", 1e-3},  {"mPa.s", 1e-3},  {"mPa·s", 1e-3},
                                               {"cP", 1e-3},     {"P", 0.1}};
  static constexpr Unit kFraction[] = {{"1", 1}, {"%", 1e-2}};
  static constexpr Unit kAngle[] = {{"rad", 1}, {"deg", kRadiansPerDegree}};
  static constexpr Unit kMass[] = {{"kg", 1}, {"g", 1e-3}};
  static constexpr Unit kStress[] = {{"Pa", 1}, {"kPa", 1e3}};
  static constexpr Unit kStressRate[] = {{"Pa/s", 1}, {"Pa/min", 1.0 / 60}};
  static constexpr Unit kRate[] = {{"1/s", 1}, {"Hz", 1}, {"1/min", 1.0 / 60}, {"1/h", 1.0 / 3600}};
  static constexpr Unit kConsistency[] = {{"Pa*s^n", 1}, {"Pa.s^n", 1}, {"Pa·s^n", 1}};
  static constexpr Unit kSurfaceTension[] = {{"N/m", 1}, {"mN/m", 1e-3}, {"J/m^2", 1}, {"J/m2", 1}};
  static constexpr Unit kStiffness[] = {{"N/m", 1}, {"N/mm", 1e3}, {"kN/m", 1e3}};
  static constexpr Unit kArea[] = {{"m^2", 1}, {"m2", 1}, {"mm^2", 1e-6}, {"mm2", 1e-6}};
  switch (quantity) {
    case Quantity::mass: return {"mass", "kg", kMass};
    case Quantity::length: return {"length", "m", kLength};
    case Quantity::time: return {"time", "s", kTime};
    case Quantity::speed: return {"speed", "m/s", kSpeed};
    case Quantity::acceleration: return {"acceleration", "m/s^2", kAcceleration};
    case Quantity::density: return {"density", "kg/m^3", kDensity};
    case Quantity::dynamic_viscosity: return {"dynamic viscosity", "Pa*s", kDynamicViscosity};
    case Quantity::fraction: return {"fraction", "", kFraction};
    case Quantity::angle: return {"angle", "rad", kAngle};
    case Quantity::stress: return {"stress", "Pa", kStress};
    case Quantity::stress_rate: return {"stress rate", "Pa/s", kStressRate};
    case Quantity::rate: return {"rate", "1/s", kRate};
    case Quantity::consistency: return {"consistency", "Pa*s^n", kConsistency};
    case Quantity::surface_tension: return {"surface tension", "N/m", kSurfaceTension};
    case Quantity::stiffness: return {"stiffness", "N/m", kStiffness};
    case Quantity::area: return {"area", "m^2", kArea};
    case Quantity::plain_number: break;
  }
  return {"plain number", "", {}};
}

Magnitude magnitude(Quantity quantity) {
  switch (quantity) {
    case Quantity::length: return {1e-7, 1e4};            // 0.1 µm to 10 km
    case Quantity::time: return {1e-9, 1e7};              // 1 ns to four months
    case Quantity::speed: return {1e-9, 1e3};             // m/s
    case Quantity::acceleration: return {1e-9, 1e5};      // m/s²
    case Quantity::density: return {1e-3, 1e5};           // kg/m³: thin gases to past osmium
    case Quantity::dynamic_viscosity: return {1e-9, 1e12};  // Pa·s
    case Quantity::mass: return {1e-12, 1e7};             // kg
    case Quantity::stress: return {1e-9, 1e12};           // Pa
    case Quantity::stress_rate: return {1e-12, 1e9};      // Pa/s
    case Quantity::rate: return {1e-12, 1e9};             // 1/s
    case Quantity::consistency: return {1e-9, 1e12};      // Pa·sⁿ
    case Quantity::surface_tension: return {1e-9, 1e4};   // N/m
    case Quantity::stiffness: return {1e-9, 1e15};        // N/m
    case Quantity::area: return {1e-14, 1e8};             // m²
    case Quantity::angle: return {1e-12, 1e4};            // rad
    case Quantity::fraction:
    case Quantity::plain_number: return {1e-12, 1e12};
  }
  return {1e-12, 1e12};
}

std::string Limits::describe(std::string_view unit) const {
  const std::string suffix = unit.empty() ? "" : fmt::format(" {}", unit);
  const std::optional<double> lower = greater_than ? greater_than : at_least;
  const std::optional<double> upper = less_than ? less_than : at_most;
  if (lower && upper) return fmt::format("in {}{}, {}{}{}", greater_than ? "(" : "[", *lower, *upper, less_than ? ")" : "]", suffix);
  if (greater_than) return fmt::format("> {}{}", *greater_than, suffix);
  if (at_least) return fmt::format(">= {}{}", *at_least, suffix);
  if (at_most) return fmt::format("<= {}{}", *at_most, suffix);
  if (less_than) return fmt::format("< {}{}", *less_than, suffix);
  return "any number";
}

namespace {

using Row = SchemaRow;

/// A number that shows as written in the reference: 0.005, 1e-05, 300.
std::string number_text(double value) { return fmt::format("{:g}", value); }
std::string bool_text(bool value) { return value ? "true" : "false"; }

/// The type a setter fills: its first parameter, without const and reference.
template <class F>
struct TargetOf : TargetOf<decltype(&F::operator())> {};
template <class C, class R, class A, class... Rest>
struct TargetOf<R (C::*)(A, Rest...) const> {
  using type = std::remove_cvref_t<A>;
};

/// A row's setter and show from ones of the block's own target type.
template <class Set>
std::function<void(const SchemaTarget&, double)> bind_set(Set set) {
  using Target = typename TargetOf<Set>::type;
  return [set](const SchemaTarget& target, double value) { set(*std::get<Target*>(target), value); };
}
template <class Show>
std::function<std::string(const SchemaTarget&)> bind_show(Show show) {
  using Target = typename TargetOf<Show>::type;
  return [show](const SchemaTarget& target) { return show(*std::get<Target*>(target)); };
}
/// Set and show of a plain number member (Real, double or int) of a block's target.
template <class Target, class Value>
auto member_set(Value Target::*member) {
  return [member](Target& target, double value) { target.*member = Value(value); };
}
template <class Target, class Value>
auto member_show(Value Target::*member) {
  return [member](const Target& target) { return number_text(double(target.*member)); };
}
#define M3DP_MEMBER(Type, member) member_set(&Type::member), member_show(&Type::member)

std::vector<SchemaRow> make_rows() {
  std::vector<SchemaRow> rows;
  auto add = [&](std::string_view block, std::string_view name, ValueKind kind, std::string_view doc) -> Row& {
    Row row;
    row.block = block, row.name = name, row.kind = kind, row.doc = doc;
    rows.push_back(std::move(row));
    return rows.back();
  };
  auto number = [&](std::string_view block, std::string_view name, Quantity quantity, Limits limits, std::string_view doc, auto set,
                    auto show, std::string_view field = {}) -> Row& {
    Row& row = add(block, name, ValueKind::number, doc);
    row.quantity = quantity, row.limits = limits, row.field = field;
    row.set = bind_set(set), row.show = bind_show(show);
    return row;
  };
  auto integer = [&](std::string_view block, std::string_view name, Limits limits, std::string_view doc, auto set, auto show) -> Row& {
    Row& row = add(block, name, ValueKind::integer, doc);
    row.limits = limits, row.set = bind_set(set), row.show = bind_show(show);
    return row;
  };
  auto boolean = [&](std::string_view block, std::string_view name, std::string_view doc, auto set, auto get) -> Row& {
    Row& row = add(block, name, ValueKind::boolean, doc);
    row.set = bind_set([set](typename TargetOf<decltype(set)>::type& target, double value) { set(target, value != 0); });
    row.show = bind_show([get](const typename TargetOf<decltype(get)>::type& target) { return bool_text(get(target)); });
    return row;
  };
  auto keyword = [&](std::string_view block, std::string_view name, std::vector<std::string_view> words, std::string_view hint,
                     std::string_view doc, auto set, auto get) -> Row& {
    Row& row = add(block, name, ValueKind::keyword, doc);
    row.words = std::move(words), row.hint = hint;
    row.set = bind_set([set](typename TargetOf<decltype(set)>::type& target, double index) { set(target, std::size_t(index)); });
    row.show = bind_show([get, words = row.words](const typename TargetOf<decltype(get)>::type& target) {
      return std::string(words[get(target)]);
    });
    return row;
  };
  auto structure = [&](std::string_view block, std::string_view name, std::string_view doc, bool required = false,
                       bool repeated = false) -> Row& {
    Row& row = add(block, name, ValueKind::structure, doc);
    row.required = required, row.repeated = repeated;
    return row;
  };

  // Valid SDF 1.9 children of an element that M3DP accepts and leaves alone (an unknown one is a warning).
  auto accepted = [&](std::string_view block, std::initializer_list<std::string_view> names) {
    for (const std::string_view name : names) add(block, name, ValueKind::structure, "valid SDF, not used").ignored = true;
  };

  // ---- SDF (sdformat.org, 1.9): what M3DP reads of the world outside its plugin ----
  structure("world", "gravity", "gravity (x y z, m/s²); default 0 0 −9.81");
  structure("world", "model", "a body: `<static>true</static>` a wall, floor or mould; otherwise one link that the material pushes",
            false, true);
  structure("world", "include", "a URDF robot: the block below", false, true);
  structure("world", "plugin",
            "`<plugin name=\"m3dp\" filename=\"m3dp\">`, M3DP's own block (below; exactly one); other plugins are left alone", true,
            true);
  accepted("world", {"audio", "wind", "magnetic_field", "atmosphere", "gui", "physics", "scene", "light", "frame", "actor", "road",
                     "spherical_coordinates", "state", "population", "joint"});
  structure("include", "uri", "the URDF: model://NAME (NAME/NAME.urdf or NAME/model.urdf in M3DP_MODEL_PATH, then models/) or a path "
            "(file:// or relative to the scene)", true);
  structure("include", "name", "the robot's name (what <robot>, <mount> and cameras call it); default the URDF's <robot name>");
  structure("include", "pose", "where its base stands (x y z roll pitch yaw; m, rad)");
  accepted("include", {"static", "placement_frame", "plugin"});
  rows.back().repeated = true;
  structure("model", "static", "true: a fixed boundary of boxes, spheres, cylinders, planes and meshes; false (the default): a "
            "rigid body of one link the material pushes and that pushes it");
  structure("model", "pose", "the model's frame in the world (x y z roll pitch yaw; m, rad)");
  structure("model", "link", "a link: the block below (a dynamic model has exactly one)", false, true);
  structure("model", "include", "nested includes: not supported yet (an error)", false, true);
  structure("model", "model", "nested models: not supported yet (an error)", false, true);
  accepted("model", {"self_collide", "allow_auto_disable", "enable_wind", "frame", "joint", "plugin", "gripper"});
  structure("link", "pose", "the link's frame in the model's (x y z roll pitch yaw; m, rad)");
  structure("link", "inertial", "a dynamic link's `<mass>` (kg, required) and `<inertia>` (`<ixx>` … `<izz>`, kg·m² about the link "
            "origin; default its first shape's at uniform density); the centre of mass is the link origin");
  structure("link", "collision", "a shape the material and the world collide with: the block below", false, true);
  structure("link", "sensor", "a camera on the link: `<sensor type=\"…\">` of type camera, depth_camera or rgbd_camera, with SDF's `<camera>` "
            "(its <image>, <clip>, <noise>, <horizontal_fov> as in the camera block below) and `<update_rate>`", false, true);
  accepted("link", {"gravity", "enable_wind", "self_collide", "kinematic", "must_be_base_link", "velocity_decay", "visual", "projector",
                    "audio_sink", "audio_source", "battery", "light", "particle_emitter", "frame"});
  structure("collision", "geometry", "one shape: `<box><size>` (x y z, m), `<sphere><radius>`, `<cylinder><radius><length>` (along "
            "z), `<plane><normal><size>` (a finite patch; static only) or `<mesh><uri><scale>` (STL, OBJ or PLY)", true);
  structure("collision", "pose", "the shape's frame in the link's (x y z roll pitch yaw; m, rad)");
  accepted("collision", {"laser_retro", "max_contacts", "surface"});

  // ---- <plugin name="m3dp">: its blocks ----
  structure("plugin", "solver", "the SPH solver: the block below", true);
  structure("plugin", "air", "the air around the print: the block below");
  structure("plugin", "material", "a material, named, that fluid blocks and print heads use: the block below", false, true);
  structure("plugin", "fluid_block", "material at the start, in a box or a cylinder: the block below", false, true);
  structure("plugin", "print_head", "a nozzle moved along a path: the block below", false, true);
  structure("plugin", "robot", "settings of a robot <include>d in the world (by its name): the block below", false, true);
  structure("plugin", "output", "what a run writes: the block below");
  structure("plugin", "meshing", "surface meshes of the material during the run: the block below");
  structure("plugin", "camera", "a camera in the world or on a robot: the block below (SDF <sensor type=\"camera\"> in a static "
                                "model's link works too)", false, true);
  structure("plugin", "coordinator", "several robots sharing a workspace: the block below");

#define M3DP_SOLVER_REAL(member) \
  [](Scene& scene, double value) { scene.solver.member = Real(value); }, [](const Scene& scene) { return number_text(scene.solver.member); }

  // ---- <solver> ----
  number("solver", "particle_radius", Quantity::length, Limits::positive(),
         "the particles' radius; their rest spacing is twice it, and the kernel's support four times it", M3DP_SOLVER_REAL(particle_radius))
      .required = true;
  keyword("solver", "kernel", {"cubic_spline", "wendland_c2"}, {}, "the SPH kernel",
          [](Scene& scene, std::size_t word) { scene.solver.kernel = word == 0 ? sph::KernelType::cubic_spline : sph::KernelType::wendland_c2; },
          [](const Scene& scene) { return std::size_t(scene.solver.kernel == sph::KernelType::cubic_spline ? 0 : 1); });
  number("solver", "cfl_factor", Quantity::plain_number, Limits::positive_up_to(2),
         "the time step is this × 0.4 × the particle diameter over the fastest particle's speed", M3DP_SOLVER_REAL(cfl_factor));
  number("solver", "min_time_step", Quantity::time, Limits::positive(), "the shortest time step", M3DP_SOLVER_REAL(min_time_step));
  number("solver", "max_time_step", Quantity::time, Limits::positive(), "the longest time step (at least <min_time_step>)",
         M3DP_SOLVER_REAL(max_time_step));
  number("solver", "max_density_error", Quantity::fraction, Limits::positive_up_to(0.1),
         "the density solve's tolerance: the mean relative density error it leaves", M3DP_SOLVER_REAL(density_tolerance), "density_tolerance");
  number("solver", "max_divergence_error", Quantity::fraction, Limits::positive_up_to(1),
         "the divergence solve's tolerance: the mean relative density change per step it leaves", M3DP_SOLVER_REAL(divergence_tolerance),
         "divergence_tolerance");
  integer("solver", "max_iterations", Limits{std::nullopt, 1.0, std::nullopt, std::nullopt},
          "the most iterations of the density and the divergence solves a step",
          [](Scene& scene, double value) {
            scene.solver.max_density_iterations = scene.solver.max_divergence_iterations = int(value);
            scene.solver.min_density_iterations = std::min(scene.solver.min_density_iterations, int(value));
          },
          [](const Scene& scene) { return std::to_string(scene.solver.max_density_iterations); });
  boolean("solver", "divergence_solver", "whether the divergence-free solve runs (DFSPH's second solve)",
          [](Scene& scene, bool value) { scene.solver.divergence_solver = value; }, [](const Scene& scene) { return scene.solver.divergence_solver; });
  boolean("solver", "warm_start", "whether the solves start from the last step's solution",
          [](Scene& scene, bool value) { scene.solver.warm_start = value; }, [](const Scene& scene) { return scene.solver.warm_start; });
  number("solver", "end_time", Quantity::time, Limits::positive(), "simulated time a run goes to (m3dp run --until overrides it)",
         [](Scene& scene, double value) { scene.end_time = value; }, [](const Scene& scene) { return number_text(scene.end_time); });
  structure("solver", "bounds",
            "the box the simulation lives in (`<min>x y z</min> <max>x y z</max>`, m); material leaving it is removed and counted", true);
  keyword("solver", "viscosity_solver", {"implicit", "explicit"},
          "implicit (Weiler et al. 2018, any viscosity), explicit (Morris et al. 1997, water-like fluids)", "how viscosity is solved",
          [](Scene& scene, std::size_t word) {
            scene.solver.viscosity_solver = word == 0 ? sph::ViscositySolver::implicit_weiler2018 : sph::ViscositySolver::explicit_morris1997;
          },
          [](const Scene& scene) { return std::size_t(scene.solver.viscosity_solver == sph::ViscositySolver::implicit_weiler2018 ? 0 : 1); });
  number("solver", "max_viscosity_error", Quantity::fraction, Limits::positive_up_to(0.1),
         "the implicit viscosity solve's tolerance (relative residual)", M3DP_SOLVER_REAL(viscosity_tolerance), "viscosity_tolerance");
  integer("solver", "max_viscosity_iterations", Limits{std::nullopt, 1.0, std::nullopt, std::nullopt},
          "the most iterations of the implicit viscosity solve a step",
          [](Scene& scene, double value) { scene.solver.max_viscosity_iterations = int(value); },
          [](const Scene& scene) { return std::to_string(scene.solver.max_viscosity_iterations); });
  number("solver", "xsph", Quantity::plain_number, Limits::between(0, 1), "XSPH velocity smoothing ε (Monaghan 1989); 0: none",
         M3DP_SOLVER_REAL(xsph_factor), "xsph_factor");
  boolean("solver", "rest_detection",
          "whether material at rest (below <rest_speed> and its yield stress for <rest_duration>) leaves the solve until something "
          "moves near it",
          [](Scene& scene, bool value) { scene.solver.rest_detection = value; }, [](const Scene& scene) { return scene.solver.rest_detection; });
  number("solver", "rest_speed", Quantity::speed, Limits::positive(), "the speed below which material may come to rest",
         M3DP_SOLVER_REAL(rest_speed));
  number("solver", "rest_duration", Quantity::time, Limits::positive(), "how long material stays slow before it rests",
         M3DP_SOLVER_REAL(rest_duration));
  number("solver", "wake_speed", Quantity::speed, Limits::positive(), "a neighbour this fast wakes resting material",
         M3DP_SOLVER_REAL(wake_speed));
  boolean("solver", "wake_on_load",
          "whether resting layers wake when the weight printed on them passes Roussel's bound (a buildability study)",
          [](Scene& scene, bool value) { scene.solver.wake_on_load = value; }, [](const Scene& scene) { return scene.solver.wake_on_load; });
  number("solver", "load_wake_duration", Quantity::time, Limits::non_negative(),
         "how long material woken by load is simulated at least; 0: until it rests again", M3DP_SOLVER_REAL(load_wake_duration));
  number("solver", "rest_compression", Quantity::fraction, Limits::positive(),
         "the compression (of the rest density) resting material may keep", M3DP_SOLVER_REAL(rest_compression));
  keyword("solver", "surface_tension_model", {"akinci2013", "brackbill1992"},
          "akinci2013 (cohesion and adhesion, robust, σ as a scale), brackbill1992 (continuum surface force, the physical σ on "
          "resolved surfaces, walls wetted at 90°)",
          "how the materials' <surface_tension> acts",
          [](Scene& scene, std::size_t word) {
            scene.solver.surface_tension_model = word == 0 ? sph::SurfaceTensionModel::akinci2013 : sph::SurfaceTensionModel::csf_brackbill1992;
          },
          [](const Scene& scene) { return std::size_t(scene.solver.surface_tension_model == sph::SurfaceTensionModel::akinci2013 ? 0 : 1); });
  number("solver", "max_volume_error", Quantity::fraction, Limits{std::nullopt, 0.0, std::nullopt, 1.0},
         "the compression the volume correction leaves after the viscosity solve; 0: none left", M3DP_SOLVER_REAL(volume_tolerance),
         "volume_tolerance");
  number("solver", "minimum_spacing", Quantity::plain_number, Limits::between(0, 1),
         "the least distance of two particles the volume correction leaves, in particle diameters; 0: none kept",
         M3DP_SOLVER_REAL(minimum_spacing));
  number("solver", "shifting", Quantity::plain_number, Limits::between(0, 10),
         "particle shifting of viscous materials' moving particles (Skillen et al.'s A, 1 to 6 there); 0: none",
         M3DP_SOLVER_REAL(shifting_factor), "shifting_factor");
  boolean("solver", "tension",
          "whether viscous material holds tension: a two-sided projection after the viscosity solve, zero at the free surface, so "
          "that a stretched thread thins instead of cracking (with <viscous_stress_form> 0.9 for its extensional stress)",
          [](Scene& scene, bool value) { scene.solver.tension = value; }, [](const Scene& scene) { return scene.solver.tension; });
  number("solver", "viscous_stress_form", Quantity::plain_number, Limits::between(0, 0.95),
         "the share of the implicit viscosity taken by the stress form (the renormalised velocity gradient, then the divergence of "
         "mu (grad v + grad v^T)), isotropic where the pair form's normal stress along a lattice axis is twice the isotropic one; "
         "0: the pair form alone; 0.9 for threads with <tension>",
         M3DP_SOLVER_REAL(stress_form_viscosity), "stress_form_viscosity");
  structure("solver", "max_particles",
            "the most particles the scene may hold (> 0); default: what 80 % of this machine's memory holds at 2 kB a particle");
#undef M3DP_SOLVER_REAL

  // ---- <air> ----
  boolean("air", "drag", "whether the air drags the material's surface (Gissler et al. 2017); on when the <air> block is there",
          [](Scene& scene, bool value) { scene.solver.air_drag = value; }, [](const Scene&) { return true; });
  number("air", "density", Quantity::density, Limits::positive(), "the air's density (dry air at 20 °C by default)",
         [](Scene& scene, double value) { scene.solver.air_density = Real(value); },
         [](const Scene& scene) { return number_text(scene.solver.air_density); }, "air.density");
  number("air", "viscosity", Quantity::dynamic_viscosity, Limits::positive(), "the air's dynamic viscosity",
         [](Scene& scene, double value) { scene.solver.air_viscosity = Real(value); },
         [](const Scene& scene) { return number_text(scene.solver.air_viscosity); }, "air.viscosity");
  structure("air", "velocity", "the wind (x y z, m/s); default still air");

  // ---- <output> ----
  number("output", "particles_period", Quantity::time, Limits::non_negative(),
         "simulated time between particle frames (particles.pvd, world.pvd, run.mcap); 0: none; unset: 0.02 s for a run of up to "
         "10 s, else the next 1, 2 or 5 × 10ⁿ s that keeps it to 500 frames",
         [](Scene& scene, double value) { scene.output.particles_period = Real(value); },
         [](const Scene& scene) {
           return scene.output.particles_period ? number_text(*scene.output.particles_period) : std::string("chosen for the run's length");
         });
  boolean("output", "particles", "whether particle frames are written at all",
          [](Scene& scene, bool value) { scene.output.write_particles = value; }, [](const Scene& scene) { return scene.output.write_particles; });
  boolean("output", "mcap", "whether the run is recorded to run.mcap (also m3dp run --record)",
          [](Scene& scene, bool value) { scene.output.mcap = value; }, [](const Scene& scene) { return scene.output.mcap; });
  integer("output", "serve", Limits::between(0, 65535), "stream the run live on this TCP port (Foxglove WebSocket); 0: any free port",
          [](Scene& scene, double value) { scene.output.serve_port = std::uint16_t(value); },
          [](const Scene& scene) { return scene.output.serve_port ? std::to_string(*scene.output.serve_port) : std::string("none"); });
  number("output", "checkpoint_period", Quantity::time, Limits::non_negative(),
         "simulated time between checkpoints (m3dp run --resume); 0: none",
         [](Scene& scene, double value) { scene.output.checkpoint_period = value; },
         [](const Scene& scene) { return number_text(scene.output.checkpoint_period); });
  number("output", "quality_period", Quantity::time, Limits::non_negative(),
         "simulated time between the in-run quality report's looks at the printed height; 0: no in-run report",
         [](Scene& scene, double value) { scene.output.quality_period = value; },
         [](const Scene& scene) { return number_text(scene.output.quality_period); });

  // ---- <meshing> ----
  structure("meshing", "method", "the surface method: spherical, sph_blobby, zhu_bridson, anisotropic (Yu and Turk), …");
  number("meshing", "period", Quantity::time, Limits::positive(), "simulated time between meshes of the material",
         [](Scene& scene, double value) { scene.meshing.period = Real(value); },
         [](const Scene& scene) { return number_text(scene.meshing.period); });
  structure("meshing", "format", "the meshes' file format: ply, obj, stl, …");
  structure("meshing", "material", "mesh only this material (its name); default all");
  structure("meshing", "region", "mesh only the particles in this box (<min>, <max>, m)");
  number("meshing", "voxel_size", Quantity::length, Limits::positive(), "the field's grid spacing; default the particle radius",
         [](Scene& scene, double value) { scene.meshing.surface.voxel_size = Real(value); },
         [](const Scene& scene) { return scene.meshing.surface.voxel_size > 0 ? number_text(scene.meshing.surface.voxel_size) : std::string("r"); });
  number("meshing", "kernel_radius", Quantity::length, Limits::positive(), "the field kernel's support; default 4 particle radii",
         [](Scene& scene, double value) { scene.meshing.surface.kernel_radius = Real(value); },
         [](const Scene& scene) {
           return scene.meshing.surface.kernel_radius > 0 ? number_text(scene.meshing.surface.kernel_radius) : std::string("4 r");
         });
  number("meshing", "iso_level", Quantity::fraction, Limits{0.0, std::nullopt, std::nullopt, 1.0},
         "the volume fraction on the surface (sph_blobby, anisotropic)",
         [](Scene& scene, double value) { scene.meshing.surface.iso_level = Real(value); },
         [](const Scene& scene) { return number_text(scene.meshing.surface.iso_level); });
  integer("meshing", "smoothing_iterations", Limits::non_negative(), "Laplacian smoothing passes over the mesh; 0: none",
          [](Scene& scene, double value) { scene.meshing.surface.smoothing_iterations = int(value); },
          [](const Scene& scene) { return std::to_string(scene.meshing.surface.smoothing_iterations); });

  // ---- <coordinator> ----
  number("coordinator", "period", Quantity::time, Limits::positive(), "simulated time between the coordinator's decisions",
         [](Scene& scene, double value) { scene.coordinator.period = value; },
         [](const Scene& scene) { return number_text(scene.coordinator.period); });
  number("coordinator", "horizon", Quantity::time, Limits::positive(), "how far ahead it predicts the robots",
         [](Scene& scene, double value) { scene.coordinator.horizon = value; },
         [](const Scene& scene) { return number_text(scene.coordinator.horizon); });
  integer("coordinator", "samples", Limits{std::nullopt, 1.0, std::nullopt, std::nullopt}, "predicted configurations over the horizon",
          [](Scene& scene, double value) { scene.coordinator.samples = int(value); },
          [](const Scene& scene) { return std::to_string(scene.coordinator.samples); });
  number("coordinator", "robot_clearance", Quantity::length, Limits::non_negative(), "the least distance kept between two robots",
         [](Scene& scene, double value) { scene.coordinator.robot_clearance = Real(value); },
         [](const Scene& scene) { return number_text(scene.coordinator.robot_clearance); });
  number("coordinator", "print_clearance", Quantity::length, Limits::non_negative(), "the least distance a robot keeps from the print",
         [](Scene& scene, double value) { scene.coordinator.print_clearance = Real(value); },
         [](const Scene& scene) { return number_text(scene.coordinator.print_clearance); });
  structure("coordinator", "priority", "robot names, highest priority first; those not named follow in scene order");
  // ---- <material> and its parts: these fill a material (a preset's values under a scene's) ----
#define M3DP_MATERIAL_REAL(member) \
  [](material::Material& material, double value) { material.member = Real(value); }, \
      [](const material::Material& material) { return number_text(material.member); }
  number("material", "density", Quantity::density, Limits::positive(), "the material's density at rest",
                  M3DP_MATERIAL_REAL(density))
      .show = [](const SchemaTarget&) { return std::string("required unless a preset= gives it"); };
  structure("material", "viscosity", "a Newtonian material's dynamic viscosity (Pa·s, ≥ 0); or give <rheology>");
  structure("material", "rheology", "a non-Newtonian material: model= power_law, cross, carreau, bingham or herschel_bulkley, and its "
                                    "parameters (README, \"Materials\")");
  structure("material", "ageing", "structural build-up with age (Roussel 2006): the block below");
  structure("material", "boundary_viscosity",
            "friction against walls, bodies and the nozzle: a viscosity (Pa·s, Navier slip; 0: free slip), or no_slip (the "
            "material sticks); default: a material a print head lays sticks to static walls (a bed, a floor hold what is "
            "laid on them) and slips on moving bodies, any other slips everywhere");
  keyword("material", "nozzle_wall", {"free_slip", "no_slip"}, {},
          "the slip of a nozzle's bore (El Abbaoui et al. 2024 found free slip matches printed concrete better)",
          [](material::Material& material, std::size_t word) { material.nozzle_no_slip = word != 0; },
          [](const material::Material& material) { return std::size_t(material.nozzle_no_slip ? 1 : 0); });
  number("material", "surface_tension", Quantity::surface_tension, Limits::non_negative(), "σ against air; 0: none",
                  M3DP_MATERIAL_REAL(surface_tension));
  number("material", "adhesion", Quantity::surface_tension, Limits::non_negative(),
                  "the work of adhesion to walls, σ(1 + cos θ) (akinci2013 only); 0: none", M3DP_MATERIAL_REAL(adhesion));
  structure("material", "granular", "discrete spheres instead of a fluid (Cundall and Strack 1979): the block below");
  structure("material", "micropolar", "micro-rotation of the particles (Bender et al. 2017): the block below");
  structure("material", "elasticity", "an elastic or viscoelastic solid (Peer et al. 2018): the block below");
  structure("material", "source", "where the values come from (a paper, a data sheet): text, not read");
  structure("material", "color", "the colour cameras see it in (r g b, 0 to 1)");

  number("ageing", "structuration_rate", Quantity::stress_rate, Limits::non_negative(),
                  "A_thix: the yield stress grows by this each second of a particle's age (Roussel 2006); 0: none",
                  M3DP_MATERIAL_REAL(ageing.structuration_rate));
  number("ageing", "viscosity_growth", Quantity::rate, Limits::non_negative(),
                  "the viscosity parameter's relative growth per second of age; 0: none", M3DP_MATERIAL_REAL(ageing.viscosity_growth));

  number("granular", "stiffness", Quantity::stiffness, Limits::positive(),
                  "the contacts' normal spring; unset: derived from the particle size", M3DP_MATERIAL_REAL(granular.stiffness));
  number("granular", "restitution", Quantity::plain_number, Limits{0.0, std::nullopt, 1.0, std::nullopt},
                  "the normal coefficient of restitution of a binary collision", M3DP_MATERIAL_REAL(granular.restitution),
                  "granular.restitution");
  number("granular", "friction", Quantity::plain_number, Limits::non_negative(), "the Coulomb friction coefficient",
                  M3DP_MATERIAL_REAL(granular.friction));

  number("micropolar", "vortex_viscosity", Quantity::dynamic_viscosity, Limits::positive(),
                  "μ_t, the coupling of micro-rotation and vorticity", M3DP_MATERIAL_REAL(micropolar.vortex_viscosity));
  number("micropolar", "microinertia", Quantity::area, Limits::positive(),
                  "Θ; unset: that of the sphere of one particle's volume, (2/5) R²", M3DP_MATERIAL_REAL(micropolar.microinertia));
  number("micropolar", "angular_smoothing", Quantity::fraction, Limits::between(0, 1),
                  "smoothing of the micro-rotation towards its neighbours' per step", M3DP_MATERIAL_REAL(micropolar.angular_smoothing));

  number("elasticity", "shear_modulus", Quantity::stress, Limits::positive(), "G; Young's modulus is 2G(1 + ν)",
                  M3DP_MATERIAL_REAL(elasticity.shear_modulus), "elasticity.shear_modulus")
      .required = true;
  number("elasticity", "poisson_ratio", Quantity::plain_number, Limits::between(0, 0.49),
                  "ν; soft pastes and gels are nearly incompressible", M3DP_MATERIAL_REAL(elasticity.poisson_ratio), "elasticity.poisson_ratio");
  number("elasticity", "relaxation_time", Quantity::time, Limits::non_negative(),
                  "τ of the stress relaxation (a Maxwell fluid); 0: none, an elastic solid", M3DP_MATERIAL_REAL(elasticity.relaxation_time));
#undef M3DP_MATERIAL_REAL

  // ---- <print_head><nozzle> ----
  number("nozzle", "inner_diameter", Quantity::length, Limits::positive(), "the bore D (at least a particle diameter)",
         M3DP_MEMBER(PrintHead, inner_diameter))
      .required = true;
  number("nozzle", "exit_speed", Quantity::speed, Limits::positive(),
         "the material's mean speed U out of the exit: the flow is π D²/4 · U (a G-code's E replaces it)", M3DP_MEMBER(PrintHead, exit_speed))
      .required = true;
  structure("nozzle", "direction", "the unit vector the material leaves along (x y z); default straight down, 0 0 -1");
  number("nozzle", "bore_length", Quantity::length, Limits::non_negative(),
         "the bore's walls above the exit (at least two diameters); 0: none, the exit is the inlet", M3DP_MEMBER(PrintHead, bore_length));
  number("nozzle", "outer_diameter", Quantity::length, Limits::positive(),
         "the tip's lip, an annulus from the bore out to this (more than <inner_diameter>); unset: a wall one particle thick",
         M3DP_MEMBER(PrintHead, outer_diameter));

  // ---- <print_head>: its parts, and where it is carried ----
  structure("print_head", "nozzle", "the nozzle: the block below", true);
  structure("print_head", "path", "where it goes and when it extrudes: <line>, <polyline>, <circle>, <helix>, <wall>, <waypoints> or "
                                  "<gcode> (README, \"Print paths\")", true);
  structure("print_head", "mount", "on a robot: the block below; unset: an ideal gantry moves the nozzle exactly along the path");
  structure("mount", "pose", "the nozzle exit's frame in the link's frame (x y z roll pitch yaw; z the way material leaves)");
  number("mount", "barrel_radius", Quantity::length, Limits::non_negative(),
         "a cylinder from the link to the exit that collides with and displaces the material; 0: none", M3DP_MEMBER(NozzleMount, barrel_radius));

  // ---- <fluid_block> ----
  structure("fluid_block", "min", "the box's lower corner (x y z, m); with <max>, or give <cylinder>");
  structure("fluid_block", "max", "the box's upper corner (x y z, m)");
  structure("fluid_block", "velocity", "the material's velocity at the start (x y z, m/s); default at rest");
  structure("fluid_block", "cylinder", "a vertical cylinder instead of a box (a slump test's mould): the block below");
  structure("cylinder", "base", "the centre of its bottom (x y z, m)", true);
  number("cylinder", "radius", Quantity::length, Limits::positive(), "its radius",
         [](FluidBlock& block, double value) { block.cylinder_radius = Real(value); },
         [](const FluidBlock& block) { return block.cylinder_radius ? number_text(*block.cylinder_radius) : std::string("—"); })
      .required = true;
  number("cylinder", "height", Quantity::length, Limits::positive(), "its height", M3DP_MEMBER(FluidBlock, cylinder_height)).required = true;

  // ---- <rheology model="...">: each model's parameters (Rheology, material/rheology/generalized_newtonian.hpp) ----
  const Limits flow_index_limits = Limits::positive_up_to(2);
  auto max_viscosity = [&](std::string_view block) {
    number(block, "max_viscosity", Quantity::dynamic_viscosity, Limits::positive(),
           "the cap of the viscosity (at rest, in the plug): the stiffest the solver sees", M3DP_MEMBER(material::Rheology, max_viscosity));
  };
  auto yield_stress = [&](std::string_view block) {
    number(block, "yield_stress", Quantity::stress, Limits::non_negative(), "τ0: below it the material stands (before ageing raises it)",
           M3DP_MEMBER(material::Rheology, yield_stress))
        .required = true;
  };
  auto regularization = [&](std::string_view block) {
    number(block, "regularization", Quantity::time, Limits::positive(),
           "Papanastasiou's m: the unyielded material's viscosity is about τ0·m", M3DP_MEMBER(material::Rheology, regularization));
  };
  auto consistency = [&](std::string_view block) {
    number(block, "consistency", Quantity::consistency, Limits::positive(), "K: the viscosity is K γ̇ⁿ⁻¹ (plus τ0/γ̇ with a yield stress)",
           M3DP_MEMBER(material::Rheology, consistency))
        .required = true;
  };
  auto flow_index = [&](std::string_view block) {
    number(block, "flow_index", Quantity::plain_number, flow_index_limits, "n: below 1 shear-thinning, above 1 shear-thickening",
           M3DP_MEMBER(material::Rheology, flow_index))
        .required = true;
  };
  number("rheology newtonian", "viscosity", Quantity::dynamic_viscosity, Limits::non_negative(), "μ (the same as the material's <viscosity>)",
         M3DP_MEMBER(material::Rheology, viscosity))
      .required = true;
  consistency("rheology power_law");
  flow_index("rheology power_law");
  max_viscosity("rheology power_law");
  for (const std::string_view block : {"rheology cross", "rheology carreau"}) {
    number(block, "zero_shear_viscosity", Quantity::dynamic_viscosity, Limits::positive(), "μ0, the viscosity at rest",
           M3DP_MEMBER(material::Rheology, viscosity), "viscosity")
        .required = true;
    number(block, "infinite_shear_viscosity", Quantity::dynamic_viscosity, Limits::non_negative(),
           "μ∞, the viscosity at high shear rates (at most μ0)", M3DP_MEMBER(material::Rheology, infinite_shear_viscosity));
    number(block, "time_constant", Quantity::time, Limits::positive(), "λ: the thinning sets in near a shear rate of 1/λ",
           M3DP_MEMBER(material::Rheology, time_constant))
        .required = true;
    flow_index(block);
    max_viscosity(block);
  }
  yield_stress("rheology bingham");
  number("rheology bingham", "plastic_viscosity", Quantity::dynamic_viscosity, Limits::positive(), "μp, the viscosity once yielded",
         M3DP_MEMBER(material::Rheology, viscosity), "viscosity")
      .required = true;
  regularization("rheology bingham");
  max_viscosity("rheology bingham");
  yield_stress("rheology herschel_bulkley");
  consistency("rheology herschel_bulkley");
  flow_index("rheology herschel_bulkley");
  regularization("rheology herschel_bulkley");
  max_viscosity("rheology herschel_bulkley");

  // ---- <robot name="..."> ----
  structure("robot", "joint", "a joint's position at the start: `<joint name=\"…\">value</joint>`, rad or m (unit=\"deg\" too)", false, true);
  structure("robot", "mobile_base", "a differential-drive base: the block below");
  structure("mobile_base", "left_wheel", "the left wheel's joint (its name)", true);
  structure("mobile_base", "right_wheel", "the right wheel's joint (its name)", true);
  number("mobile_base", "wheel_radius", Quantity::length, Limits::positive(), "the wheels' radius", M3DP_MEMBER(MobileBase, wheel_radius))
      .required = true;
  number("mobile_base", "wheel_separation", Quantity::length, Limits::positive(), "the distance between the wheels' contact points",
         M3DP_MEMBER(MobileBase, wheel_separation))
      .required = true;
  structure("mobile_base", "path", "a path for the base to follow, as a print head's (z ignored)");

  // ---- <camera>, and the intrinsics it shares with SDF's <sensor><camera> ----
  number("camera", "update_rate", Quantity::rate, Limits::positive(), "images per second of simulated time",
         M3DP_MEMBER(sensors::CameraSettings, update_rate));
  number("camera", "horizontal_fov", Quantity::angle, Limits::positive_up_to(3.1), "the horizontal field of view",
         M3DP_MEMBER(sensors::CameraSettings, horizontal_fov));
  structure("camera", "image", "the picture's size: the block below");
  structure("camera", "clip", "what it sees: the block below");
  structure("camera", "noise", "noise on its colour and depth: the block below");
  boolean("camera", "shadows", "whether the key light casts shadows (one more ray a pixel)",
          [](sensors::CameraSettings& camera, bool value) { camera.shadows = value; },
          [](const sensors::CameraSettings& camera) { return camera.shadows; });
  structure("camera", "point_cloud", "true: a point cloud of each depth image (a depth_camera or rgbd_camera), in frame=\"optical\" "
                                     "(the default) or frame=\"world\" (a scan that adds up)");
  structure("camera", "mount", "on a robot: <mount robot=\"…\" link=\"…\"> with the camera's <pose> in the link's frame inside it");
  structure("camera", "pose", "where it is in the world, when not mounted (x y z roll pitch yaw; x forward, z up)");
  const Limits pixels = Limits::between(1, 8192);
  integer("image", "width", pixels, "pixels across", M3DP_MEMBER(sensors::CameraSettings, width));
  integer("image", "height", pixels, "pixels down", M3DP_MEMBER(sensors::CameraSettings, height));
  structure("image", "format", "accepted as SDF writes it; colour images are 8-bit RGB, depth 32-bit float (m)");
  structure("image", "anti_aliasing", "accepted as SDF writes it; not used");
  number("clip", "near", Quantity::length, Limits::positive(), "nothing nearer is seen", M3DP_MEMBER(sensors::CameraSettings, near));
  number("clip", "far", Quantity::length, Limits::positive(), "nothing farther is seen (beyond <near>)",
         M3DP_MEMBER(sensors::CameraSettings, far));
  structure("noise", "type", "gaussian (or none); also as a type=\"…\" attribute");
  number("noise", "mean", Quantity::plain_number, Limits::any(), "the noise's mean, in colour levels of 0 to 1 (and m of depth)",
         [](sensors::CameraSettings& camera, double value) { camera.noise.mean = value; },
         [](const sensors::CameraSettings& camera) { return number_text(camera.noise.mean); });
  number("noise", "stddev", Quantity::plain_number, Limits::non_negative(), "its standard deviation, in the same units",
         [](sensors::CameraSettings& camera, double value) { camera.noise.stddev = value; },
         [](const sensors::CameraSettings& camera) { return number_text(camera.noise.stddev); });
  integer("noise", "seed", Limits::between(0, 9007199254740991.0),
          "which noise: two seeds give two independent noises (a study's repeats set it); the same seed, the same noise",
          [](sensors::CameraSettings& camera, double value) { camera.noise.seed = std::uint64_t(value); },
          [](const sensors::CameraSettings& camera) { return std::to_string(camera.noise.seed); });
  return rows;
}

}  // namespace

std::span<const SchemaRow> schema_rows() {
  static const std::vector<SchemaRow> rows = make_rows();
  return rows;
}

const SchemaRow& schema_row(std::string_view block, std::string_view name) {
  for (const SchemaRow& row : schema_rows())
    if (row.block == block && row.name == name) return row;
  throw std::logic_error(fmt::format("the scene table has no <{}> in block '{}'", name, block));
}

std::vector<const SchemaRow*> schema_block(std::string_view block) {
  std::vector<const SchemaRow*> rows;
  for (const SchemaRow& row : schema_rows())
    if (row.block == block) rows.push_back(&row);
  return rows;
}

/// A default target of one kind, for the reference's defaults.
template <class Target>
SchemaTarget default_of() {
  static Target target{};
  return &target;
}

std::span<const SchemaBlock> schema_blocks() {
  static const SchemaBlock kBlocks[] = {
      {"world", "<world name=\"…\">",
       "An SDF world: what M3DP reads of it. The rest of SDF is accepted and left alone; an element SDF does not have there is a "
       "warning with the closest name.",
       "", default_of<Scene>},
      {"include", "<world><include>", "A robot from a URDF file, by DART's URDF loader.", "world", default_of<Scene>},
      {"model", "<world><model name=\"…\">", "A body of the world: a static boundary or a rigid body.", "world", default_of<Scene>},
      {"link", "<model><link name=\"…\">", "A link of a model.", "model", default_of<Scene>},
      {"collision", "<link><collision name=\"…\">", "A collision shape of a link.", "link", default_of<Scene>},
      {"plugin", "<world><plugin name=\"m3dp\" filename=\"m3dp\">", "Everything M3DP adds to an SDF world, in the world's plugin element.",
       "world",
       default_of<Scene>},
      {"solver", "<plugin><solver>", "The SPH solver (DFSPH): resolution, time steps, tolerances, rest detection. Required.", "plugin",
       default_of<Scene>},
      {"air", "<plugin><air>", "The air around the print: its drag on the material's surface, on when the block is there.", "plugin",
       default_of<Scene>},
      {"output", "<plugin><output>", "What a run writes beside summary.json and timing.csv.", "plugin", default_of<Scene>},
      {"meshing", "<plugin><meshing>", "Surface meshes of the material during the run (also the printed body the world collides with).",
       "plugin", default_of<Scene>},
      {"coordinator", "<plugin><coordinator enabled=\"true\">", "Several robots sharing a workspace (Erdmann and Lozano-Pérez 1987).",
       "plugin", default_of<Scene>},
      {"material", "<plugin><material name=\"…\" preset=\"…\">", "A material, from scratch or over a preset of data/materials.xml.",
       "plugin", default_of<material::Material>},
      {"rheology newtonian", "<material><rheology model=\"newtonian\">", "A Newtonian fluid: μ(γ̇) = μ.", "material",
       default_of<material::Rheology>},
      {"rheology power_law", "<material><rheology model=\"power_law\">", "A power-law fluid: μ = K γ̇ⁿ⁻¹, capped at rest.", "material",
       default_of<material::Rheology>},
      {"rheology cross", "<material><rheology model=\"cross\">", "Cross (1965): μ = μ∞ + (μ0 − μ∞) / (1 + (λγ̇)ⁿ).", "material",
       default_of<material::Rheology>},
      {"rheology carreau", "<material><rheology model=\"carreau\">", "Carreau (1972): μ = μ∞ + (μ0 − μ∞)(1 + (λγ̇)²)^((n−1)/2).",
       "material", default_of<material::Rheology>},
      {"rheology bingham", "<material><rheology model=\"bingham\">",
       "A Bingham plastic (a fresh mortar): μ = μp + τ0 (1 − e^(−mγ̇))/γ̇ (Papanastasiou 1987).", "material", default_of<material::Rheology>},
      {"rheology herschel_bulkley", "<material><rheology model=\"herschel_bulkley\">",
       "Herschel–Bulkley: μ = K γ̇ⁿ⁻¹ + τ0 (1 − e^(−mγ̇))/γ̇; over a preset of the same model, every parameter is optional.", "material",
       default_of<material::Rheology>},
      {"ageing", "<material><ageing>", "Structural build-up of a printable mortar or concrete.", "material", default_of<material::Material>},
      {"granular", "<material><granular>", "Discrete spheres: every material of the scene granular, or none.", "material",
       default_of<material::Material>},
      {"micropolar", "<material><micropolar>", "Micro-rotation of the particles: their spin and the fluid's vorticity coupled.", "material",
       default_of<material::Material>},
      {"elasticity", "<material><elasticity>", "An elastic solid, or with a relaxation time a viscoelastic (Maxwell) fluid.", "material",
       default_of<material::Material>},
      {"fluid_block", "<plugin><fluid_block name=\"…\" material=\"…\">", "Material at the start: a box, or a vertical cylinder.",
       "plugin", default_of<FluidBlock>},
      {"cylinder", "<fluid_block><cylinder>", "A vertical cylinder of material (a slump test's mould).", "fluid_block",
       default_of<FluidBlock>},
      {"print_head", "<plugin><print_head name=\"…\" material=\"…\">", "A nozzle moved along a path, extruding where the path says.",
       "plugin", default_of<PrintHead>},
      {"nozzle", "<print_head><nozzle>", "A print head's nozzle: a bore fed at the commanded flow.", "print_head", default_of<PrintHead>},
      {"mount", "<print_head><mount robot=\"…\" link=\"…\">", "The nozzle carried on a robot's link.", "print_head",
       default_of<NozzleMount>},
      {"robot", "<plugin><robot name=\"…\">", "Settings of a robot the world includes (`<include><uri>model://…</uri></include>` of a URDF).",
       "plugin", default_of<Scene>},
      {"mobile_base", "<robot><mobile_base>", "A differential-drive base carrying the robot.", "robot", default_of<MobileBase>},
      {"camera", "<plugin><camera name=\"…\" type=\"camera|depth_camera|rgbd_camera\">",
       "A simulated camera (colour, depth or both), fixed in the world or on a robot's link.", "plugin",
       default_of<sensors::CameraSettings>},
      {"image", "<camera><image>", "The picture's size (also in SDF's <sensor><camera>).", "camera", default_of<sensors::CameraSettings>},
      {"clip", "<camera><clip>", "The nearest and farthest a camera sees (also in SDF's <sensor><camera>).", "camera",
       default_of<sensors::CameraSettings>},
      {"noise", "<camera><noise>", "Gaussian noise on each colour channel and the depth (also in SDF's <sensor><camera>).", "camera",
       default_of<sensors::CameraSettings>},
  };
  return kBlocks;
}

/// `doc` with every <element> in it as code, so that Markdown shows it rather than taking it for HTML;
/// what the doc already puts in backticks (an example of several elements) is kept as it is.
std::string markdown_doc(std::string_view doc) {
  std::string text;
  for (std::size_t i = 0; i < doc.size(); ++i) {
    const char closing = doc[i] == '<' ? '>' : doc[i] == '`' ? '`' : '\0';
    const std::size_t close = closing ? doc.find(closing, i + 1) : std::string_view::npos;
    if (close == std::string_view::npos) {
      text += doc[i];
      continue;
    }
    text += closing == '`' ? std::string(doc.substr(i, close - i + 1)) : fmt::format("`{}`", doc.substr(i, close - i + 1));
    i = close;
  }
  return text;
}

std::string schema_reference() {
  std::string text =
      "# Scene reference\n\n"
      "Generated by `m3dp schema` from the scene reader's own table (src/m3dp/scene/schema.cpp); a test fails when this page\n"
      "is stale (regenerate it with `build/apps/m3dp/m3dp schema > docs/scene_reference.md`). Every value is SI unless a\n"
      "`unit=\"...\"` attribute says otherwise; the units each value takes are listed. Defaults are the engine's own.\n\n"
      "The world around the plugin (models, links, collisions, includes of URDF robots) is SDF's (sdformat.org): its first\n"
      "blocks below say what M3DP reads of it. The print paths (`<line>`, `<polyline>`, `<circle>`, `<helix>`, `<wall>`,\n"
      "`<waypoints>`, `<gcode>`) are described in the README.\n";
  for (const SchemaBlock& block : schema_blocks()) {
    const SchemaTarget defaults = block.defaults();
    text += fmt::format("\n## `{}`\n\n{}\n\n| element | value | unit (also) | range | default | meaning |\n|---|---|---|---|---|---|\n",
                        block.path, markdown_doc(block.doc));
    std::string ignored;
    for (const SchemaRow* row : schema_block(block.name)) {
      if (row->ignored) {
        ignored += fmt::format("{}`<{}>`", ignored.empty() ? "" : ", ", row->name);
        continue;
      }
      std::string value, units, range = "", shown = row->show ? row->show(defaults) : std::string();
      switch (row->kind) {
        case ValueKind::number: {
          const QuantityInfo info = quantity_info(row->quantity);
          value = std::string(info.name);
          std::string also;
          for (const Unit& unit : info.units)
            if (unit.symbol != info.si_symbol) also += (also.empty() ? "" : ", ") + std::string(unit.symbol);
          units = info.si_symbol.empty() ? (also.empty() ? "—" : fmt::format("({})", also))
                                         : fmt::format("{}{}", info.si_symbol, also.empty() ? "" : fmt::format(" ({})", also));
          range = row->limits.describe("");
          break;
        }
        case ValueKind::integer: value = "whole number", units = "—", range = row->limits.describe(""); break;
        case ValueKind::boolean: value = "true or false", units = "—", range = "—"; break;
        case ValueKind::keyword: {
          value = "one of: ";
          for (std::size_t w = 0; w < row->words.size(); ++w) value += (w ? ", " : "") + fmt::format("`{}`", row->words[w]);
          units = "—", range = "—";
          break;
        }
        case ValueKind::structure: value = row->repeated ? "see meaning; may repeat" : "see meaning", units = "—", range = "—"; break;
      }
      if (row->required) shown = "required";
      if (shown.empty()) shown = "—";
      text += fmt::format("| `<{}>` | {} | {} | {} | {} | {}{} |\n", row->name, value, units, range, shown, markdown_doc(row->doc),
                          row->field.empty() ? "" : fmt::format(" (the engine's `{}`)", row->field));
    }
    if (!ignored.empty()) text += fmt::format("\nAlso valid SDF here, accepted and not used: {}.\n", ignored);
  }
  return text;
}

}  // namespace m3dp::scene
