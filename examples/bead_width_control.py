#!/usr/bin/env python3
"""Closed-loop bead width control: a depth camera above a printed wall measures the width of each
layer as it is finished, and a controller sets the next layer's flow so that the beads come out as
wide as designed.

The material's real flow is 15 % below the nominal one (a paste stiffer than the pump was
calibrated for: the robot asks for a flow, the nozzle delivers 0.85 of it). The nozzle presses each
bead to the layer height, so the missing material makes the bead narrower, not lower: open loop
every layer is about 12 % narrow. Closed loop, the controller takes the width as proportional to
the flow (a bead pressed to the layer height H at speed U is Q / (U H) wide) and corrects the flow
asked by the ratio of the width wanted to the width measured:

    next flow asked = flow asked · (design width / measured width)

Run from the project folder (the module from the build tree):

    PYTHONPATH=build/python python3 examples/bead_width_control.py

Scored over flow errors from -20 % to +20 % as a study (its `control` function is the study's controller):

    m3dp study examples/bead_width_study.toml -o out/bead_width_study

Scene: examples/bead_width_wall.sdf (a UR10 prints six 6 mm layers of mortar, 0.2 m long, with a
12 mm nozzle; the camera "top" looks straight down with its point cloud in the world frame).
"""
import argparse
import math
import pathlib

import numpy as np

import m3dp

SCENE = pathlib.Path(__file__).resolve().with_name("bead_width_wall.sdf")
LAYER_HEIGHT = 0.006  # m, the nozzle's rise per layer
LAYERS = 6
WALL_X = 0.72  # m: the wall runs along y at this x
NOZZLE_DIAMETER, EXIT_SPEED, PRINT_SPEED = 0.012, 0.1, 0.1  # m, m/s, m/s: the scene's
# The design: the nominal flow over the print speed, pressed to the layer height (18.8 mm).
DESIGN_WIDTH = math.pi / 4 * NOZZLE_DIAMETER**2 * EXIT_SPEED / PRINT_SPEED / LAYER_HEIGHT
DESIGN_VOLUME = DESIGN_WIDTH * LAYER_HEIGHT * 0.2 * LAYERS  # m³: six layers 0.2 m long


def layer_width(sim, layer):
    """The width (m) of layer `layer` (1 first) as the top camera sees it: per centimetre of the
    wall, the span across it of the material it sees in that layer's upper half; the median along
    the middle 0.16 m (the arm hides parts of the ends)."""
    image = sim.camera("top")
    material = [segment for segment, entry in sim.camera_legend().items() if entry["kind"] == "material"]
    points = image["points"][np.isin(image["point_segments"], material)]
    top = layer * LAYER_HEIGHT
    upper = points[(points[:, 2] > top - 0.5 * LAYER_HEIGHT) & (np.abs(points[:, 1]) < 0.08)]
    spans = []
    for start in np.arange(-0.08, 0.08, 0.01):
        across = upper[(upper[:, 1] >= start) & (upper[:, 1] < start + 0.01), 0]
        if len(across) > 20:
            spans.append(across.max() - across.min())
    return float(np.median(spans)) if spans else float("nan")


class WidthController:
    """The loop of one print: when a layer ends, measures it and sets the next layer's flow. `real_flow`
    is the fraction of the asked flow the nozzle delivers (the disturbance)."""

    def __init__(self, sim, closed_loop=True, real_flow=0.85, verbose=False):
        self.closed_loop, self.real_flow, self.verbose = closed_loop, real_flow, verbose
        self.asked = [1.0]  # the flow asked of each layer, as a fraction of the nominal
        self.widths = []
        self.was_extruding = False
        sim.set_extrusion("nozzle", flow_scale=real_flow * self.asked[-1])

    def update(self, sim):
        """Called as the print goes (every step, or every period of a study's controller)."""
        extruding = sim.nozzle("nozzle")["extruding"]
        if self.was_extruding and not extruding:  # a layer has ended: measure it, then set the next one's flow
            self.widths.append(layer_width(sim, len(self.widths) + 1))
            if len(self.widths) < LAYERS:
                wanted = self.asked[-1] * DESIGN_WIDTH / self.widths[-1] if self.closed_loop else 1.0
                self.asked.append(min(max(wanted, 0.5), 2.0))
                sim.set_extrusion("nozzle", flow_scale=self.real_flow * self.asked[-1])
            if self.verbose:
                print(f"  t = {sim.time:5.2f} s  layer {len(self.widths)}: {self.widths[-1] * 1000:5.2f} mm wide "
                      f"(design {DESIGN_WIDTH * 1000:.2f} mm)"
                      + (f", next layer's flow asked {self.asked[-1]:.3f}" if len(self.widths) < LAYERS else ""))
        self.was_extruding = extruding


def print_wall(closed_loop, real_flow=0.85, threads=2, verbose=False):
    """Prints the wall; returns each layer's measured width (m), the flow asked of each layer and
    the run's summary."""
    sim = m3dp.Simulation(SCENE, threads=threads)
    controller = WidthController(sim, closed_loop, real_flow, verbose)
    while sim.time < sim.end_time:
        sim.step()
        controller.update(sim)
    summary = sim.close()
    return controller.widths, controller.asked, summary


_study_controllers = {}


def control(sim, run):
    """The loop as a study's controller (examples/bead_width_study.toml): the study's flow_scale is the
    real flow (the disturbance); called every period, it returns the run's score so far: the last
    layer's width off the design (relative), and the flow it asked."""
    real_flow = float(run["parameters"].get("flow_scale", 1.0))
    if id(sim) not in _study_controllers:
        _study_controllers[id(sim)] = WidthController(sim, True, real_flow)
    controller = _study_controllers[id(sim)]
    controller.update(sim)
    if not controller.widths:
        return None
    return {"layers": len(controller.widths), "width_error": controller.widths[-1] / DESIGN_WIDTH - 1,
            "flow_asked": controller.asked[-1]}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--real-flow", type=float, default=0.85, help="the flow the nozzle delivers over the one asked")
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    errors = {}
    for closed_loop in (False, True):
        print(f"{'closed' if closed_loop else 'open'} loop, real flow {args.real_flow:.2f} of the nominal:")
        widths, asked, summary = print_wall(closed_loop, args.real_flow, args.threads, verbose=True)
        errors[closed_loop] = abs(widths[-1] - DESIGN_WIDTH)
        print(f"  last layer {widths[-1] * 1000:.2f} mm wide against {DESIGN_WIDTH * 1000:.2f} mm: "
              f"error {errors[closed_loop] * 1000:.2f} mm; material laid {summary['volume_m3']['emitted'] * 1e6:.1f} cm³ "
              f"of the {DESIGN_VOLUME * 1e6:.1f} cm³ designed\n")
    print(f"width error of the last layer: open loop {errors[False] * 1000:.2f} mm, closed loop "
          f"{errors[True] * 1000:.2f} mm ({errors[False] / max(errors[True], 1e-9):.1f}x smaller)")


if __name__ == "__main__":
    main()
