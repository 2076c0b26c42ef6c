#include "m3dp/sim/particle_cloud.hpp"

#include <cstddef>
#include <cstring>
#include <vector>

#include "m3dp/core/parallel.hpp"
#include "m3dp/record/foxglove_messages.hpp"
#include "m3dp/sim/simulation.hpp"

namespace m3dp::sim {

namespace {

struct PackedParticle {
  float x, y, z, vx, vy, vz, density, pressure, viscosity, shear_rate, rest_time, birth_time;
  std::uint32_t id;
  std::uint16_t material;
  std::uint16_t padding;
};
static_assert(sizeof(PackedParticle) == 56);

const std::vector<record::PointField>& particle_fields() {
  static const std::vector<record::PointField> fields = [] {
    using Type = record::PointField::Type;
    std::vector<record::PointField> list;
    const char* names[] = {"x", "y", "z", "vx", "vy", "vz", "density", "pressure", "viscosity", "shear_rate", "rest_time", "birth_time"};
    for (std::uint32_t f = 0; f < 12; ++f) list.push_back({names[f], 4 * f, Type::float32});
    list.push_back({"id", offsetof(PackedParticle, id), Type::uint32});
    list.push_back({"material", offsetof(PackedParticle, material), Type::uint16});
    return list;
  }();
  return fields;
}

}  // namespace

void encode_particle_cloud(const Simulation& simulation, std::string& out) {
  const auto& solver = simulation.solver();
  const auto& fluid = solver.fluid();
  const auto& density = simulation.measured_density().density;
  const std::size_t count = fluid.size();
  record::encode_point_cloud(simulation.time(), "world", particle_fields(), sizeof(PackedParticle), count, [&](char* bytes) {
    parallel_for_each_index(count, [&](std::size_t i) {
      const PackedParticle point{static_cast<float>(fluid.position[i].x()), static_cast<float>(fluid.position[i].y()),
                                 static_cast<float>(fluid.position[i].z()), static_cast<float>(fluid.velocity[i].x()),
                                 static_cast<float>(fluid.velocity[i].y()), static_cast<float>(fluid.velocity[i].z()),
                                 static_cast<float>(density[i]),            static_cast<float>(solver.pressure(i)),
                                 static_cast<float>(fluid.viscosity[i]),    static_cast<float>(fluid.shear_rate[i]),
                                 static_cast<float>(fluid.rest_time[i]),    static_cast<float>(fluid.birth_time[i]),
                                 static_cast<std::uint32_t>(fluid.id[i]),   fluid.phase[i],
                                 0};
      std::memcpy(bytes + i * sizeof(PackedParticle), &point, sizeof(PackedParticle));
    }, 4096);
  }, out);
}

}  // namespace m3dp::sim
