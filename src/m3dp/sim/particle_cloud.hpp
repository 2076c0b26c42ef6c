#pragma once
// The fluid as one foxglove.PointCloud (what run.mcap and the live stream send on /particles):
// per particle 56 bytes, position, velocity, measured density, pressure, viscosity, shear rate,
// rest time and birth time as float32, id as uint32 and material as uint16, in the world frame.
#include <string>

namespace m3dp::sim {

class Simulation;

/// Writes the message into `out` (its capacity reused), packing the points in parallel.
void encode_particle_cloud(const Simulation& simulation, std::string& out);

}  // namespace m3dp::sim
