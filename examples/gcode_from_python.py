#!/usr/bin/env python3
"""Slice, load, print and read back, all from Python.

PrusaSlicer (Debian's prusa-slicer, its default printer and print settings) slices a 6 mm cube into
G-code; a scene made here prints that G-code ten times larger with printable mortar (a 60 mm cube
of 3 mm layers, a 4 mm nozzle: construction scale); the simulation runs for a few seconds; and the
deposited volume is read back from the particles and compared with what the G-code's E asked for.

    PYTHONPATH=build/python python3 examples/gcode_from_python.py [--until 4] [--out DIR]
"""
import argparse
import pathlib
import subprocess
import tempfile

import m3dp

PART = pathlib.Path("/usr/share/PrusaSlicer/shapes/box.stl")  # a 30 mm cube, shipped with the slicer
PARTICLE_RADIUS = 0.001  # m

SCENE = """<?xml version="1.0"?>
<sdf version="1.9">
  <world name="gcode_from_python">
    <model name="build_plate">
      <static>true</static>
      <link name="plate">
        <collision name="plate">
          <pose>0 0 -0.005 0 0 0</pose>
          <geometry><box><size>0.3 0.3 0.01</size></box></geometry>
        </collision>
      </link>
    </model>
    <plugin name="m3dp" filename="m3dp">
      <solver>
        <particle_radius>{radius}</particle_radius>
        <max_time_step>0.002</max_time_step>
        <end_time>{until}</end_time>
        <bounds><min>-1.2 -1.2 -0.05</min><max>0.3 0.3 0.3</max></bounds>
      </solver>
      <material name="mortar" preset="printable_mortar">
        <rheology><max_viscosity>1e4</max_viscosity></rheology>
      </material>
      <print_head name="gantry" material="mortar">
        <nozzle>
          <inner_diameter unit="mm">4</inner_diameter>
          <exit_speed>0.1</exit_speed>
        </nozzle>
        <path>
          <!-- The slicer centred the part at (100, 100) mm; ten times larger that is (1, 1) m. -->
          <gcode file="{gcode}">
            <pose>-1 -1 0 0 0 0</pose>
            <scale>10</scale>
          </gcode>
        </path>
      </print_head>
    </plugin>
  </world>
</sdf>
"""


def slice_part(folder):
    """PrusaSlicer's G-code of the cube at a fifth of its size, in 0.3 mm layers."""
    gcode = folder / "cube.gcode"
    subprocess.run(["prusa-slicer", "--export-gcode", "--scale", "0.2", "--center", "100,100", "--layer-height", "0.3",
                    "--first-layer-height", "0.3", "--output", str(gcode), str(PART)],
                   check=True, capture_output=True, text=True)
    return gcode


def print_gcode(gcode, until, out=None, threads=2):
    """Prints the G-code for `until` simulated seconds; returns the volume the particles hold and the
    run's summary (with the volume the G-code commanded), m³."""
    scene = SCENE.format(radius=PARTICLE_RADIUS, until=until, gcode=gcode.name)
    sim = m3dp.Simulation.from_string(scene, name=str(gcode.parent / "scene.sdf"), threads=threads)
    if out:
        sim.record(out)
    sim.step_to(until)
    # Every particle stands for a cube of its diameter at the material's rest density.
    deposited = sim.particle_count * (2 * PARTICLE_RADIUS) ** 3
    summary = sim.close()
    return deposited, summary


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--until", type=float, default=4.0, help="simulated seconds to print")
    parser.add_argument("--out", help="a run folder to record (particles.pvd, world.pvd, summary.json)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        gcode = slice_part(pathlib.Path(folder))
        print(f"sliced {PART.name} at 0.2 scale: {sum(1 for _ in gcode.open())} lines of G-code")
        deposited, summary = print_gcode(gcode, args.until, args.out)
    commanded, lost = summary["volume_m3"]["commanded"], summary["volume_m3"]["lost_at_nozzles"]
    print(f"printed {args.until:g} s: {deposited * 1e6:.2f} cm³ deposited, {commanded * 1e6:.2f} cm³ commanded by the G-code "
          f"({100 * (deposited / commanded - 1):+.2f} %); {lost * 1e6:.2f} cm³ could not leave the nozzle "
          f"while the layer below blocked it")


if __name__ == "__main__":
    main()
