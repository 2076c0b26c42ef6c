#!/usr/bin/env bash
# End to end: `m3dp run` writes a run folder; ParaView's own reader (pvpython) opens the .pvd as a
# time series and reads the same particle count that summary.json reports.
set -euo pipefail
source "$(dirname "$0")/pvpython_errors.sh"
m3dp=$1 scene=$2 out=$3
rm -rf "$out"
"$m3dp" run "$scene" -o "$out" --until 0.05 --quiet
test -f "$out/particles.pvd" && test -f "$out/summary.json" && test -f "$out/timing.csv"
expected=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['particles'])" "$out/summary.json")
frames=$(grep -c '<DataSet' "$out/particles.pvd")
read_back=$(pvpython --force-offscreen-rendering - "$out/particles.pvd" <<'PY' 2>"$out/pvpython.err" | tail -n 1
import sys
from paraview.simple import PVDReader, UpdatePipeline, servermanager
reader = PVDReader(FileName=sys.argv[1])
times = reader.TimestepValues
UpdatePipeline(time=times[-1], proxy=reader)
data = servermanager.Fetch(reader)
names = [data.GetPointData().GetArrayName(i) for i in range(data.GetPointData().GetNumberOfArrays())]
assert "velocity" in names and "density" in names and "pressure" in names, names
print(len(times), data.GetNumberOfPoints())
PY
) || pvpython_failed "$out/pvpython.err"
check_pvpython_errors "$out/pvpython.err"
echo "summary.json: $expected particles, $frames frames; pvpython read back: $read_back (frames points)"
[ "$read_back" = "$frames $expected" ] || { echo "FAIL: pvpython read '$read_back', expected '$frames $expected'"; exit 1; }
echo "PASS"
