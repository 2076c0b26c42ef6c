#!/usr/bin/env python3
"""Draws the deposition grid (build/tests/deposition_grid -o grid.csv) as Xu et al. 2022 collapse it:
W/D and H/g against (D/g)(U/V), pressed and free strands of each material, with the pressed
rounded box's closed form W/D = (pi/4)(U/V)/(g/D) + (g/D)(1 - pi/4) at each point.
    python3 scripts/plot_deposition.py grid.csv out.png
"""
import csv
import math
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) != 3:
        sys.exit(f"usage: {sys.argv[0]} GRID.csv OUT.png")
    with open(sys.argv[1], newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        sys.exit(f"{sys.argv[1]}: no rows")
    figure, (width_axes, height_axes) = plt.subplots(1, 2, figsize=(11, 4.5))
    styles = {("bingham_mortar", "pressed"): ("o", "tab:orange"), ("newtonian_paste", "pressed"): ("s", "tab:blue"),
              ("bingham_mortar", "free"): ("^", "tab:red")}
    for (material, regime), (marker, colour) in styles.items():
        for surface, fill in (("floor", colour), ("layer", "none")):
            chosen = [r for r in rows if r["material"] == material and r["regime"] == regime and r["surface"] == surface]
            if not chosen:
                continue
            x = [(1 / float(r["g_over_D"])) / float(r["V_over_U"]) for r in chosen]
            diameter_mm = 10.0
            w = [float(r["width_mm"]) / diameter_mm for r in chosen]
            h = [float(r["height_mm"]) / (float(r["g_over_D"]) * diameter_mm) for r in chosen]
            label = f"{material.replace('_', ' ')}, {regime}, on the {surface}"
            width_axes.scatter(x, w, marker=marker, facecolors=fill, edgecolors=colour, label=label)
            height_axes.scatter(x, h, marker=marker, facecolors=fill, edgecolors=colour, label=label)
    pressed = [r for r in rows if r["regime"] == "pressed"]
    x = [(1 / float(r["g_over_D"])) / float(r["V_over_U"]) for r in pressed]
    box = [float(r["reference_width_mm"]) / 10.0 for r in pressed]
    width_axes.scatter(x, box, marker="_", s=200, color="black", label="rounded box (pressed)")
    for axes, name in ((width_axes, "W/D"), (height_axes, "H/g")):
        axes.set_xscale("log")
        axes.set_xlabel("(D/g)(U/V)")
        axes.set_ylabel(name)
        axes.grid(True, which="both", alpha=0.3)
    height_axes.axhline(1, color="black", lw=0.8)
    width_axes.legend(fontsize=7)
    figure.suptitle("M3DP strands from a nozzle with a bore (D = 10 mm, 8 particles across)")
    figure.tight_layout()
    figure.savefig(sys.argv[2], dpi=120)


if __name__ == "__main__":
    main()
