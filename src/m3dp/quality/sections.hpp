#pragma once
// The printed material measured against its design (issue 39): sections across each designed bead
// at stations along it (width, height, area, how far the bead sits off its path), and the volumes
// printed where nothing was designed (over-fill) and designed where nothing was printed
// (under-fill). Measured on geometry, not on SPH density (low at a free surface): each particle
// stands for a cube of its diameter, its volume at rest.
#include <cstdint>
#include <span>
#include <vector>

#include "m3dp/quality/design.hpp"

namespace m3dp::quality {

/// The printed material: particle centres (m), each the cube of `particle_diameter` about it, and
/// the layer of its head's path each was printed in (empty: the layers are not known, and a section
/// takes every particle in its bead's box).
struct Printed {
  std::span<const Vec3> positions;
  std::span<const std::int32_t> layers;
  double particle_diameter = 0;  // m
};

struct Section {
  std::size_t bead = 0;                   // index in Design::beads
  std::int32_t layer = 0;
  Vec3d at = Vec3d::Zero();               // m, the station on the path
  double width = 0;                       // m, across the bead (horizontal)
  double height = 0;                      // m: its top's rise over the top of the layers under it (on the bed: its extent)
  double extent = 0;                      // m, its particles' bottom to top (reaching into the layer below where it sags)
  double area = 0;                        // m², the material's volume per length there
  double offset_across = 0;               // m, the section's middle off the path, to the left of travel
  double offset_up = 0;                   // m, its top off the designed top (the nozzle's path)
  std::size_t particles = 0;              // in the station's slab; 0: nothing printed there
};

/// Sections every `spacing` (m) along each bead, from half its width past its ends (corners mix two
/// beads); a slab two particle diameters thick about each station.
[[nodiscard]] std::vector<Section> measure_sections(const Design& design, const Printed& printed, double spacing);

struct Fill {
  double designed = 0, printed = 0;    // m³
  double over = 0, under = 0;          // m³: printed outside the design, designed and not printed
};
/// Over- and under-fill on a grid of half the particle diameter: printed where the particles' volume
/// fraction is at least a half (each particle's volume spread by a tent of half-width d).
[[nodiscard]] Fill measure_fill(const Design& design, const Printed& printed);

}  // namespace m3dp::quality
