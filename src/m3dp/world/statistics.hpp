#pragma once
// What the world counts while it steps: how far tools and bases were from their targets, and what
// each robot touched.
#include <cstddef>
#include <cstdint>

namespace m3dp::world {

/// Distances (m) of something from its target, one a sample.
struct TrackingError {
  double squared_sum = 0, max = 0;
  std::size_t count = 0;
  void add(double distance);
  [[nodiscard]] double rms() const;
};

/// What a robot's link touched in a contact.
enum class ContactWith { robot, printed_material, other };

/// Contacts of one robot, summed over every world step so far.
struct RobotContacts {
  std::uint64_t with_robots = 0;           // contact points with another robot's links
  std::uint64_t with_printed_material = 0; // with a printed-material mesh
  std::uint64_t with_other = 0;            // static shapes, rigid bodies
  std::uint64_t steps_in_contact = 0;      // world steps with at least one contact
  void add(ContactWith with);              // one contact point
};

}  // namespace m3dp::world
