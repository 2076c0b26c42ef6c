#include "m3dp/world/statistics.hpp"

#include <algorithm>
#include <cmath>

namespace m3dp::world {

void TrackingError::add(double distance) {
  squared_sum += distance * distance;
  ++count;
  max = std::max(max, distance);
}

void RobotContacts::add(ContactWith with) {
  switch (with) {
    case ContactWith::robot: ++with_robots; break;
    case ContactWith::printed_material: ++with_printed_material; break;
    case ContactWith::other: ++with_other; break;
  }
}

double TrackingError::rms() const { return count ? std::sqrt(squared_sum / static_cast<double>(count)) : 0.0; }

}  // namespace m3dp::world
