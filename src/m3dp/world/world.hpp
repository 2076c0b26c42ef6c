#pragma once
// The rigid-body world (DART): static geometry, free rigid bodies, and printed-material meshes
// added at run time as static collision bodies. DART stays inside world.cpp (pimpl), so the rest
// of M3DP never includes its headers. Robots, controllers and the two-way coupling with the fluid
// come with the robots issue; this is the part the surface meshes need.
#include <memory>
#include <string>
#include <vector>

#include "m3dp/core/geometry.hpp"
#include "m3dp/core/types.hpp"

namespace m3dp::world {

struct WorldSettings {
  Vec3 gravity = Vec3(0, 0, Real(-9.81));  // m/s²
  double time_step = 1e-3;                 // s, fixed; the world sub-steps to the fluid's clock
};

/// A handle to a body of the world: its index in the order bodies were added.
using BodyIndex = std::size_t;

class World {
 public:
  explicit World(const WorldSettings& settings = {});
  ~World();
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  /// A body fixed in the world with one collision shape at `pose` (m, world frame).
  BodyIndex add_static_shape(const std::string& name, const Shape& shape, const Pose& pose);
  /// A free rigid body: mass (kg) and its inertia from the shape, uniform density.
  BodyIndex add_rigid_body(const std::string& name, const Shape& shape, double mass, const Pose& pose);
  /// Sets (first call) or replaces (later calls) the static collision mesh called `name`, e.g. the
  /// newest surface of the printed material. An empty mesh removes it.
  void set_static_mesh(const std::string& name, const TriangleMesh& mesh);

  /// Steps at the fixed time step until the world's clock reaches `time` (s).
  void step_to(double time);

  [[nodiscard]] double time() const;
  [[nodiscard]] Pose pose(BodyIndex body) const;
  [[nodiscard]] Vec3 linear_velocity(BodyIndex body) const;  // m/s of the body's origin, world frame
  /// Contacts found by the last world step.
  [[nodiscard]] std::size_t contact_count() const;
  /// How many times set_static_mesh replaced a mesh (0 after the first insertion).
  [[nodiscard]] std::size_t mesh_replacements() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace m3dp::world
