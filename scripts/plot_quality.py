#!/usr/bin/env python3
"""Draws a print's quality report (m3dp quality RUN_DIR writes quality.json and quality.csv, then runs
this): per head, each layer's measured bead width and height (mean, with the range of its sections)
against the design, the printed height against the design's over time (did each head's part stand?),
the histogram of every section's width and top off the design, and that of the
printed surface's distance to the designed one (its mesh's vertices).
    python3 scripts/plot_quality.py RUN_DIR/quality.json RUN_DIR/quality.csv OUT.png
"""
import csv
import json
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402


def main():
    if len(sys.argv) != 4:
        sys.exit(f"usage: {sys.argv[0]} quality.json quality.csv OUT.png")
    with open(sys.argv[1]) as f:
        report = json.load(f)
    with open(sys.argv[2], newline="") as f:
        rows = [r for r in csv.DictReader(f) if int(r["particles"]) > 0]
    heads = report["heads"]
    if not heads:
        sys.exit(f"{sys.argv[1]}: no print heads")
    surface = report.get("surface_deviation_m")
    figure, grid = plt.subplots(2, 3, figsize=(15, 8))
    width_axes, height_axes, time_axes = grid[0]
    histogram_axes, surface_axes, text_axes = grid[1]
    axes = [width_axes, height_axes, time_axes, histogram_axes] + ([surface_axes] if surface else [])
    if not surface:
        surface_axes.axis("off")
    for index, head in enumerate(heads):
        layers = [layer for layer in head["layers"] if layer["stations"] > layer["stations_empty"]]
        numbers = [layer["layer"] + 0.12 * index for layer in layers]
        for axes_, key, label in ((width_axes, "width", "width"), (height_axes, "height", "height")):
            means = [1e3 * layer[f"{key}_m"] for layer in layers]
            low = [m - 1e3 * layer[f"{key}_min_m"] for m, layer in zip(means, layers)]
            high = [1e3 * layer[f"{key}_max_m"] - m for m, layer in zip(means, layers)]
            axes_.errorbar(numbers, means, yerr=[low, high], fmt="o", capsize=3, label=f"{head['name']}: printed")
            axes_.plot(numbers, [1e3 * layer[f"design_{key}_m"] for layer in layers], "k_", markersize=18, label=f"{head['name']}: design")
            axes_.set_xlabel("layer")
            axes_.xaxis.set_major_locator(MaxNLocator(integer=True))
            last_layer = max((layer["layer"] for h in heads for layer in h["layers"]), default=0)
            axes_.set_xlim(-0.5, last_layer + 0.5)
            axes_.set_ylabel(f"bead {label} (mm)")
            axes_.set_title(f"bead {label} per layer")
    designs = {(h["name"], layer["layer"]): layer for h in heads for layer in h["layers"]}
    width_off = [1e3 * (float(r["width_m"]) - designs[(r["head"], int(r["layer"]))]["design_width_m"]) for r in rows]
    top_off = [1e3 * float(r["offset_up_m"]) for r in rows]
    histogram_axes.hist([width_off, top_off], bins=30, label=["width - design", "top - designed top"])
    histogram_axes.set_xlabel("deviation (mm)")
    histogram_axes.set_ylabel("sections")
    histogram_axes.set_title("sections off the design")
    verdicts = []
    for index, head in enumerate(heads):
        height = head.get("height")
        if not height:
            continue
        times = [row[0] for row in height["history"]]
        color = f"C{index}"
        time_axes.plot(times, [1e3 * row[3] for row in height["history"]], color=color, label=f"{head['name']}: printed")
        time_axes.plot(times, [1e3 * row[2] for row in height["history"]], color=color, linestyle="--", linewidth=0.8,
                       label=f"{head['name']}: design")
        shortfall = height["shortfall"]
        if shortfall:
            time_axes.plot([shortfall["time_s"]], [1e3 * shortfall["printed_m"]], "x", color=color, markersize=10)
            verdicts.append(f"{head['name']}: fell short at layer {shortfall['layer']} ({shortfall['time_s']:.2f} s)")
        else:
            verdicts.append(f"{head['name']}: stood")
    time_axes.set_xlabel("time (s)")
    time_axes.set_ylabel("height (mm)")
    time_axes.set_title("printed height against the design (x: fell short)")
    if surface:
        edges = [1e3 * edge for edge in surface["histogram"]["edges_m"]]
        counts = surface["histogram"]["counts"]
        surface_axes.stairs(counts, edges, fill=True, label=f"p95 {1e3 * surface['p95']:.2f} mm, mean {1e3 * surface['mean']:+.2f} mm")
        surface_axes.axvline(0, color="k", linewidth=0.8)
        surface_axes.set_xlabel("distance to the design (mm, < 0 inside)")
        surface_axes.set_ylabel("mesh vertices")
        surface_axes.set_title("printed surface off the design")
    text_axes.axis("off")
    lines = verdicts + ([f"warning: {report['resolution_warning']}"] if report.get("resolution_warning") else [])
    text_axes.text(0, 1, "\n".join(lines), va="top", fontsize=10, wrap=True)
    for axes_ in axes:
        axes_.legend(fontsize=8)
        axes_.grid(alpha=0.3)
    fill = report["fill_m3"]
    figure.suptitle(f"t = {report['time_s']:.2f} s: {1e6 * fill['printed']:.1f} of {1e6 * fill['designed']:.1f} cm³ designed; "
                    f"over-fill {1e6 * fill['over']:.1f} cm³, under-fill {1e6 * fill['under']:.1f} cm³")
    figure.tight_layout()
    figure.savefig(sys.argv[3], dpi=110)


if __name__ == "__main__":
    main()
