#include "m3dp/quality/sections.hpp"
#include "m3dp/sim/strand_deposition.hpp"

#include <algorithm>
#include <chrono>
#include <limits>
#include <fstream>
#include <cmath>
#include <vector>

#include "m3dp/core/types.hpp"
#include "m3dp/sph/boundary_sampling.hpp"
#include "m3dp/sph/solver.hpp"
#include "m3dp/surface/mesh_tools.hpp"
#include "m3dp/surface/surface.hpp"

namespace m3dp::sim::deposition {

material::Material printable_mortar() {
  material::Material mortar = material::newtonian("mortar", 2100, 10, 10);
  mortar.rheology.model = material::RheologyModel::bingham;
  mortar.rheology.yield_stress = 1000;
  mortar.rheology.max_viscosity = 1e4;
  return mortar;
}

material::Material stiff_newtonian_paste() {
  material::Material paste = material::newtonian("paste", 1800, 1e4, 0);
  paste.sticks_to_walls = true;
  return paste;
}

double nominal_area(const StrandCase& strand) { return kPi * strand.diameter * strand.diameter / 4 / strand.speed_ratio; }

double rounded_box_width(const StrandCase& strand) {
  const double flow_ratio = 1 / strand.speed_ratio, gap = strand.gap_ratio;
  return strand.diameter * (kPi / 4 * flow_ratio / gap + gap * (1 - kPi / 4));
}

bool pressed(const StrandCase& strand) {
  return strand.gap_ratio <= 1 + 1e-9 && 1 / strand.speed_ratio >= strand.gap_ratio * strand.gap_ratio - 1e-9;
}

namespace {

/// Moves the nozzle along x at height `exit_height` from x = `from` to `to` at `speed` (m/s),
/// extruding, then `settle` s more without; `each_step` sees every step while extruding.
template <typename EachStep>
void print_line(sph::Solver& solver, double from, double to, double exit_height, double speed, double settle, EachStep&& each_step,
                StrandResult* cost = nullptr) {
  const double start = solver.time(), duration = std::abs(to - from) / speed;
  const double direction = to > from ? 1 : -1;
  while (solver.time() < start + duration + settle) {
    const double elapsed = std::min(solver.time() - start, duration);
    const bool extruding = solver.time() - start < duration;
    Pose pose;
    pose.position = Vec3(Real(from + direction * elapsed * speed), 0, Real(exit_height));
    solver.set_nozzle(0, pose, extruding ? Vec3(Real(direction * speed), 0, 0) : Vec3::Zero(), extruding);
    const auto step_start = std::chrono::steady_clock::now();
    solver.step();
    if (cost) {
      cost->step_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - step_start).count();
      cost->particle_steps += double(solver.state().active_count);
    }
    if (extruding) each_step(pose.position.x());
  }
}

/// The time a nozzle takes to rise or move to a new start without extruding (s): 0.2 s.
void move_nozzle(sph::Solver& solver, const Vec3& from, const Vec3& to, double duration) {
  const double start = solver.time();
  while (solver.time() < start + duration) {
    const double s = std::min(1.0, (solver.time() - start) / duration);
    Pose pose;
    pose.position = from + Real(s) * (to - from);
    solver.set_nozzle(0, pose, (to - from) / Real(duration), false);
    solver.step();
  }
}

}  // namespace

StrandResult lay_strand(const StrandCase& strand) {
  const auto wall_start = std::chrono::steady_clock::now();
  const double D = strand.diameter, d = D / strand.particles_across;
  const double gap = strand.gap_ratio * D, travel_speed = strand.speed_ratio * strand.exit_speed;
  const double length = strand.length;
  sph::Parameters parameters;
  parameters.settings.particle_radius = Real(d / 2);
  parameters.settings.max_time_step = Real(2e-3);
  parameters.settings.rest_detection = strand.rest_detection;
  parameters.settings.tension = strand.tension;
  parameters.settings.stress_form_viscosity = Real(strand.stress_form);
  parameters.settings.bounds.min = Vec3(Real(-0.1), Real(-0.1), Real(-0.05));
  parameters.settings.bounds.max = Vec3(Real(length + 0.1), Real(0.1), Real(0.1));
  material::Material material = strand.material;
  if (strand.viscosity_cap > 0) material.rheology.max_viscosity = Real(strand.viscosity_cap);
  parameters.phases.push_back(material);
  sph::NozzleSettings nozzle{"nozzle", Real(D), Real(strand.exit_speed), 0};
  nozzle.bore_length = Real(strand.bore_ratio * D);
  nozzle.outer_diameter = strand.bore_ratio > 0 ? Real(strand.outer_ratio * D) : Real(0);
  parameters.nozzles.push_back(nozzle);
  sph::Solver solver(parameters);
  // The bed's top at z = 0, 5 cm beyond the line each way.
  const Real bed_length = Real(length + 0.1);
  solver.add_body("bed", sph::sample_box_surface(BoxShape{Vec3(bed_length, Real(0.12), Real(4 * d))}, Real(d), Real(-d / 2)).points,
                  Pose{Vec3(Real(length / 2), 0, Real(-2 * d)), Quat::Identity()}, true);
  solver.reserve(static_cast<std::size_t>(3 * nominal_area(strand) * (length + 0.1) / (d * d * d)) + 20000);

  const double low = 0.2 * length, high = 0.8 * length;
  constexpr int kStations = 31;
  auto station_of = [&](double x) { return static_cast<int>(std::floor((x - low) / (high - low) * kStations)); };

  double bottom = 0;  // the surface below the strand measured
  std::uint64_t first_id = 0;
  if (strand.on_layer) {
    // The layer below: the same material pressed at g = D/2, V/U = 1 (a rounded box D/2 high), along +x.
    print_line(solver, 0, length, D / 2, strand.exit_speed, 0.3, [](Real) {});
    // Its top, station by station in the window.
    std::vector<double> tops(kStations, 0);
    for (const Vec3& p : solver.fluid().position) {
      const int s = station_of(p.x());
      if (s >= 0 && s < kStations) tops[s] = std::max(tops[s], double(p.z()) + d / 2);
    }
    for (const double top : tops) bottom += top / kStations;
    // Up and back to the start above the layer, without extruding; the strand runs along +x again.
    const Vec3 end(Real(length), 0, Real(D / 2));
    const Vec3 raised(Real(length), 0, Real(bottom + gap + D));
    move_nozzle(solver, end, raised, 0.2);
    move_nozzle(solver, raised, Vec3(0, 0, Real(bottom + gap + D)), 0.5);
    move_nozzle(solver, Vec3(0, 0, Real(bottom + gap + D)), Vec3(0, 0, Real(bottom + gap)), 0.2);
    first_id = solver.state().next_particle_id;
  }
  double pressure_sum = 0;
  std::size_t pressure_samples = 0;
  StrandResult result;
  print_line(
      solver, 0, length, bottom + gap, travel_speed, 0.3,
      [&](Real x) {
        if (x < low || x > high) return;
        pressure_sum += solver.state().nozzles[0].extrusion_pressure;
        ++pressure_samples;
      },
      &result);

  // The strand's particles in the window, station by station.
  const auto& fluid = solver.fluid();
  std::vector<Vec3> strand_points;
  struct Station {
    double y_min = 1, y_max = -1, top = -1, lowest = 1, y_sum = 0, column = 0;
  };
  std::vector<Station> stations(kStations);
  std::size_t count = 0;
  for (std::size_t i = 0; i < fluid.size(); ++i) {
    if (fluid.id[i] < first_id) continue;
    const Vec3& p = fluid.position[i];
    strand_points.push_back(p);
    const int s = station_of(p.x());
    if (s < 0 || s >= kStations) continue;
    ++count;
    Station& station = stations[s];
    station.y_min = std::min(station.y_min, double(p.y()));
    station.y_max = std::max(station.y_max, double(p.y()));
    station.top = std::max(station.top, double(p.z()));
    station.lowest = std::min(station.lowest, double(p.z()));
    station.y_sum += p.y();
  }
  // The strand's height at its centreline: the material's volume (d³ a particle) per footprint in a
  // band two spacings wide about the section's middle, which does not depend on how the particles pack
  // against the walls (pressed, the first layer sits up to 0.4 d into the floor's Akinci particles,
  // so the highest particle's top overstates the height by about that).
  for (std::size_t i = 0; i < fluid.size(); ++i) {
    if (fluid.id[i] < first_id) continue;
    const Vec3& p = fluid.position[i];
    const int s = station_of(p.x());
    if (s < 0 || s >= kStations) continue;
    Station& station = stations[s];
    const double middle = (station.y_min + station.y_max) / 2;
    if (std::abs(p.y() - middle) < d) station.column += 1;
  }
  if (!strand.particles_csv.empty()) {
    std::ofstream csv(strand.particles_csv);
    csv << "x,y,z,id,resting,strand\n";
    for (std::size_t i = 0; i < fluid.size(); ++i)
      csv << fluid.position[i].x() << ',' << fluid.position[i].y() << ',' << fluid.position[i].z() << ',' << fluid.id[i] << ','
          << (i >= solver.state().active_count) << ',' << (fluid.id[i] >= first_id) << '\n';
  }
  result.bottom = bottom;
  int landed = 0, filled = 0;
  for (const Station& station : stations) {
    result.height += station.column * d * d * d / (2 * d * (high - low) / kStations) / kStations;
    if (station.y_max < station.y_min) continue;  // empty: a torn rope's gap (no width, no top)
    ++filled;
    result.width += station.y_max - station.y_min + d;
    result.top += station.top + d / 2 - bottom;
    // On the surface: its lowest particle's centre no more than a particle diameter above it.
    if (station.lowest - d / 2 <= bottom + d / 2) ++landed;
  }
  result.landed = double(landed) / kStations;
  result.width /= std::max(filled, 1);
  result.top /= std::max(filled, 1);
  result.counted_area = double(count) * d * d * d / (high - low);
  // The section of the particles' surface, the union of spheres of radius 1.31 r (the fair surface of
  // their volume: see test_materials' strands), at the stations' centres.
  surface::SurfaceSettings spheres;
  spheres.particle_radius = Real(d / 2);
  spheres.method = surface::Method::spherical;
  spheres.sphere_radius = Real(1.31 * d / 2);
  const TriangleMesh mesh = surface::reconstruct_surface(strand_points, spheres);
  result.least_area = std::numeric_limits<double>::infinity();
  for (int k = 0; k < kStations; ++k) {
    const double area = surface::cross_section_area(mesh, 0, low + (high - low) * (k + 0.5) / kStations);
    result.area += area / kStations;
    result.least_area = std::min(result.least_area, area);
    result.greatest_area = std::max(result.greatest_area, area);
  }
  // The quality module on the same strand: its design is the printed line, its sections those in the window.
  toolpath::PathSegment line;
  line.curve = toolpath::LineCurve{Vec3(0, 0, Real(bottom + gap)), Vec3(Real(length), 0, Real(bottom + gap))};
  line.speed = Real(travel_speed);
  const quality::Design design = quality::design_of(toolpath::Trajectory({line}, 0), quality::Nozzle{D, strand.exit_speed, bottom});
  const auto sections = quality::measure_sections(design, quality::Printed{strand_points, {}, d}, (high - low) / kStations);
  std::size_t measured = 0;
  for (const auto& section : sections) {
    if (section.at.x() < low || section.at.x() > high || section.particles == 0) continue;
    result.quality_width += section.width;
    result.quality_height += section.height;
    result.quality_area += section.area;
    ++measured;
  }
  if (measured > 0) {
    result.quality_width /= double(measured);
    result.quality_height /= double(measured);
    result.quality_area /= double(measured);
  }
  result.extrusion_pressure = pressure_samples > 0 ? pressure_sum / double(pressure_samples) : 0;
  result.steps = static_cast<unsigned long long>(solver.state().step);
  result.blocked_layers = solver.state().nozzles[0].blocked_layers;
  result.particles = fluid.size();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
  return result;
}

}  // namespace m3dp::sim::deposition
