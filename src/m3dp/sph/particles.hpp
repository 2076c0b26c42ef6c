#pragma once
// Particle state as structure-of-arrays. Every per-particle field is declared once, in
// for_each_field, so resizing, reordering and removal can never forget one.
#include <cstdint>
#include <utility>
#include <string>
#include <vector>

#include "m3dp/core/types.hpp"
#include "m3dp/material/material.hpp"

namespace m3dp::sph {

/// Mutable state of the fluid particles (n = size()).
struct FluidParticles {
  std::vector<Vec3> position;            // (n) m
  std::vector<Vec3> velocity;            // (n) m/s
  std::vector<Vec3> acceleration;        // (n) m/s², non-pressure forces of this step
  std::vector<Real> mass;                // (n) kg
  std::vector<Real> density;             // (n) kg/m³, SPH sum incl. boundary
  std::vector<Real> dfsph_factor;        // (n) α_i (m²), Bender & Koschier 2017 eq. 11
  std::vector<Real> density_advected;    // (n) predicted ρ*/ρ0 (density solve) or divergence (1/s)
  std::vector<Real> kappa_density;       // (n) Σκ of the density solve (m²/s², κ = ρ0 p/ρ²): warm start, pressure
  std::vector<Real> kappa_divergence;    // (n) Σκ of the divergence solve (m²/s²)
  std::vector<Real> kappa_tension;       // (n) κ of the tension projection (m²/s², < 0 pulls), kept across steps
  std::vector<std::uint16_t> phase;      // (n) index into Parameters::phases
  std::vector<std::uint16_t> neighbor_count;  // (n) fluid neighbours + boundary ones weighted as fluid, this step
  std::vector<std::uint64_t> id;         // (n) stable id for tracking across reorders
  std::vector<Real> birth_time;          // (n) s, simulated time the particle appeared
  std::vector<std::int32_t> print_layer; // (n) the layer of its nozzle's path it was emitted in (0 first);
                                         //     -1: not printed by a path (blocks, material set up)
  std::vector<Real> viscosity;           // (n) Pa·s, effective dynamic viscosity of this step (rheology, age)
  std::vector<Real> shear_rate;          // (n) 1/s, √(2 D:D) of this step (non-Newtonian phases only)
  std::vector<Vec3> viscous_change;      // (n) m/s, last step's velocity change by the implicit viscosity (warm start)
  std::vector<Vec3> viscous_velocity;    // (n) m/s, the velocity the last implicit viscosity solve ended with (warm start)
  std::vector<Real> rest_time;           // (n) s the particle has been at rest (see SolverSettings::rest_detection);
                                         //     negative: woken by load, held awake that much longer
  std::vector<Real> rest_load;           // (n) Pa, weight per area above it when it came to rest (< 0: not yet measured)
  std::vector<Vec3> angular_velocity;    // (n) rad/s, micro-rotation ω (micropolar materials; zero otherwise)
  std::vector<Vec3> reference_position;  // (n) m, where the particle sits in the unstrained shape (elastic materials)

  [[nodiscard]] std::size_t size() const { return position.size(); }

  template <class Visit>
  void for_each_field(Visit&& visit) {
    visit(position);
    visit(velocity);
    visit(acceleration);
    visit(mass);
    visit(density);
    visit(dfsph_factor);
    visit(density_advected);
    visit(kappa_density);
    visit(kappa_divergence);
    visit(kappa_tension);
    visit(phase);
    visit(neighbor_count);
    visit(id);
    visit(birth_time);
    visit(print_layer);
    visit(viscosity);
    visit(shear_rate);
    visit(viscous_change);
    visit(viscous_velocity);
    visit(rest_time);
    visit(rest_load);
    visit(angular_velocity);
    visit(reference_position);
  }
  void reserve(std::size_t capacity) {
    for_each_field([&](auto& field) { field.reserve(capacity); });
  }
  void resize(std::size_t count) {
    if (count < watched_end) watched_touched = touched_overflow = true;
    for_each_field([&](auto& field) { field.resize(count); });
  }
  /// Moves particle `from` into slot `to` (used by swap-removal).
  void move(std::size_t from, std::size_t to) {
    note_touched(from);
    note_touched(to);
    for_each_field([&](auto& field) { field[to] = field[from]; });
  }
  /// Exchanges two particles (keeps the active ones first, see State::active_count).
  void swap(std::size_t a, std::size_t b) {
    note_touched(a);
    note_touched(b);
    for_each_field([&](auto& field) { std::swap(field[a], field[b]); });
  }

  // Watched slots: the neighbour stage keeps a grid of the settled resting particles, slots
  // [watched_begin, watched_end); any swap, move or resize that reaches them marks them touched
  // (what keeps its own structure of them, cameras, builds it again). The touched slots are listed,
  // up to kMostTouched, so that the neighbour stage takes those few out of its grid instead of
  // sorting every resting particle again (a wall's interface wakes a few particles most steps);
  // more, or a resize, overflow the list.
  static constexpr std::size_t kMostTouched = 1024;
  std::size_t watched_begin = 0, watched_end = 0;
  bool watched_touched = false;
  bool touched_overflow = false;
  std::vector<Index> touched_slots;  // each touch once or more, in order
  void watch_slots(std::size_t begin, std::size_t end) {
    watched_begin = begin;
    watched_end = end;
    watched_touched = touched_overflow = false;
    touched_slots.clear();
    touched_slots.reserve(kMostTouched);
  }

 private:
  void note_touched(std::size_t slot) {
    if (slot < watched_begin || slot >= watched_end) return;
    watched_touched = true;
    if (touched_slots.size() < kMostTouched) touched_slots.push_back(static_cast<Index>(slot));
    else touched_overflow = true;
  }
};

/// Akinci et al. 2012 boundary particles of every rigid body, in one set.
struct BoundaryParticles {
  std::vector<Vec3> local_position;  // (nb) m, in the body frame
  std::vector<Vec3> position;        // (nb) m, world
  std::vector<Vec3> velocity;        // (nb) m/s, world
  std::vector<Real> volume;          // (nb) m³, Ψ/ρ0 = 1 / Σ_k W_bk over the same body
  std::vector<Index> body;           // (nb) owning body
  std::vector<material::Wall> wall_kind;  // (nb) static wall, moving body or a nozzle's bore: which slip the material takes there

  [[nodiscard]] std::size_t size() const { return position.size(); }
};

/// A rigid body seen by the fluid: its boundary particles and its motion, set by the caller.
struct BoundaryBody {
  std::string name;
  bool is_static = true;
  Index first_particle = 0;
  Index particle_count = 0;
  Pose pose;                                  // body frame in world
  Aabb local_bounds;                          // of its boundary particles, body frame
  bool near_fluid = true;                     // moving bodies: its particles took part in the last step
  Vec3 linear_velocity = Vec3::Zero();        // m/s of the body-frame origin
  Vec3 angular_velocity = Vec3::Zero();       // rad/s, world frame
  Vec3 fluid_force = Vec3::Zero();            // N, fluid on body during the last step (world)
  Vec3 fluid_torque = Vec3::Zero();           // N·m, about pose.position (world)
};

}  // namespace m3dp::sph
