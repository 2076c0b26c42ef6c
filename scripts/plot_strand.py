#!/usr/bin/env python3
"""Side views and middle sections of strands that deposition_grid --particles PREFIX wrote
(PREFIX_MATERIAL_G_V_SURFACE.csv): each file a row, the strand measured in red, the layer below in grey.
    python3 scripts/plot_strand.py OUT.png PARTICLES.csv [PARTICLES.csv ...]
"""
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main():
    if len(sys.argv) < 3:
        sys.exit(f"usage: {sys.argv[0]} OUT.png PARTICLES.csv [PARTICLES.csv ...]")
    files = sys.argv[2:]
    figure, axes = plt.subplots(len(files), 2, figsize=(14, 2.6 * len(files)), gridspec_kw={"width_ratios": [5, 1]}, squeeze=False)
    for row, name in enumerate(files):
        with open(name, newline="") as f:
            particles = [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]
        if not particles:
            sys.exit(f"{name}: no particles")
        xs = [p["x"] for p in particles]
        middle = (min(xs) + max(xs)) / 2
        side, section = axes[row]
        for strand, colour in ((0, "tab:grey"), (1, "tab:red")):
            chosen = [p for p in particles if p["strand"] == strand and abs(p["y"]) < 0.0015]
            side.scatter([1e3 * p["x"] for p in chosen], [1e3 * p["z"] for p in chosen], s=2, color=colour)
            cut = [p for p in particles if p["strand"] == strand and abs(p["x"] - middle) < 0.002]
            section.scatter([1e3 * p["y"] for p in cut], [1e3 * p["z"] for p in cut], s=6, color=colour)
        side.set_title(f"{os.path.basename(name)}: side, |y| < 1.5 mm", fontsize=9)
        section.set_title(f"section at x = {1e3 * middle:.0f} mm", fontsize=9)
        for axes_ in (side, section):
            axes_.set_aspect("equal")
            axes_.set_xlabel("mm")
    figure.tight_layout()
    figure.savefig(sys.argv[1], dpi=90)


if __name__ == "__main__":
    main()
