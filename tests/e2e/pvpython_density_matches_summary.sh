#!/usr/bin/env bash
# End to end: the density error that summary.json reports is the one in the written frames. ParaView's
# reader (pvpython) opens the last particle frame, computes rho/rho0 - 1 from its density and material
# arrays (rest densities from summary.json's materials) over all particles, and the mean, median,
# 99th percentile (numpy's) and max agree with the summary's last check within 0.1 percentage points.
set -euo pipefail
source "$(dirname "$0")/pvpython_errors.sh"
m3dp=$1 scene=$2 out=$3 until=$4
rm -rf "$out"
"$m3dp" run "$scene" -o "$out" --until "$until" --quiet
report=$(pvpython --force-offscreen-rendering - "$out/particles.pvd" "$out/summary.json" <<'PY' 2>"$out/pvpython.err" | tail -n 1
import json, sys
import numpy as np
from paraview.simple import PVDReader, UpdatePipeline, servermanager
from vtk.util.numpy_support import vtk_to_numpy
summary = json.load(open(sys.argv[2]))
reader = PVDReader(FileName=sys.argv[1])
last_time = reader.TimestepValues[-1]
UpdatePipeline(time=last_time, proxy=reader)
data = servermanager.Fetch(reader)
density = vtk_to_numpy(data.GetPointData().GetArray("density")).astype(float)
material = vtk_to_numpy(data.GetPointData().GetArray("material")).astype(int)
rest = np.array([m["rest_density_kg_m3"] for m in summary["materials"]])
error = density / rest[material] - 1
last = summary["density_error"]["last"]
assert abs(last["time_s"] - last_time) < 1e-6, (last["time_s"], last_time)
assert last["particles"] == len(error), (last["particles"], len(error))
measured = {"mean": error.mean(), "median": np.median(error), "p99": np.percentile(error, 99), "max": error.max()}
worst = max(abs(measured[k] - last[k]) for k in measured)
print(" ".join(f"{k} {100 * measured[k]:+.4f}/{100 * last[k]:+.4f} %" for k in measured),
      f"particles {len(error)} t {last_time:.3f} worst_difference_pp {100 * worst:.5f}")
PY
) || pvpython_failed "$out/pvpython.err"
check_pvpython_errors "$out/pvpython.err"
echo "frame (pvpython) / summary.json: $report (tolerance 0.1 percentage points)"
difference=${report##* }
python3 -c "import sys; sys.exit(0 if float(sys.argv[1]) < 0.1 else 1)" "$difference" || { echo "FAIL: differ by $difference pp"; exit 1; }
echo "PASS"
