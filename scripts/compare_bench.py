#!/usr/bin/env python3
"""Compares two m3dp binaries' speed on one benchmark by alternating runs in one sitting.

This machine's speed swings by 10-30 % between phases; alternating old and new runs puts both
binaries in the same phases. Prints, per binary, the minimum and median of the figure over the
runs and the ratio new/old of both.

  scripts/compare_bench.py OLD_M3DP NEW_M3DP [--runs 6] [--figure ms_per_step|ratio|...] -- bench ARGS

The figure is read from `m3dp bench` output: "X ms/step" (dam_break, clay_print), "(Y ms/step" from
ur10_wall's summary line, or the wall_layers cost ratio.
"""
import argparse
import re
import statistics
import subprocess
import sys

PATTERNS = {
    "ms_per_step": re.compile(r"([0-9.]+) ms/step"),
    "cost_ratio": re.compile(r"cost of a step at layer \d+ / at layer 2: ([0-9.]+)"),
    "real_time_factor": re.compile(r"real-time factor ([0-9.e+-]+)"),
    "wall_seconds": re.compile(r"simulated in ([0-9.]+) s wall"),
}


def figure(binary, bench_args, name):
    output = subprocess.run([binary, "bench", *bench_args], capture_output=True, text=True, check=True).stdout
    match = PATTERNS[name].search(output)
    if not match:
        sys.exit(f"no '{name}' in the output of {binary}:\n{output}")
    return float(match.group(1))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("old")
    parser.add_argument("new")
    parser.add_argument("--runs", type=int, default=6)
    parser.add_argument("--figure", default="ms_per_step", choices=sorted(PATTERNS))
    split = sys.argv.index("--") if "--" in sys.argv else len(sys.argv)
    arguments = parser.parse_args(sys.argv[1:split])
    bench_args = sys.argv[split + 1:]
    values = {"old": [], "new": []}
    for run in range(arguments.runs):
        for label in ("old", "new") if run % 2 == 0 else ("new", "old"):
            values[label].append(figure(getattr(arguments, label), bench_args, arguments.figure))
    for label in ("old", "new"):
        print(f"{label}: min {min(values[label]):.3f}, median {statistics.median(values[label]):.3f}  "
              f"({', '.join(f'{v:.3f}' for v in values[label])})")
    print(f"new/old: min {min(values['new']) / min(values['old']):.3f}, "
          f"median {statistics.median(values['new']) / statistics.median(values['old']):.3f}")


if __name__ == "__main__":
    main()
