#!/usr/bin/env bash
# Ctrl-C (SIGINT) stops a run cleanly: summary.json says "interrupted", every file is complete
# (ParaView reads every frame listed) and no temporary file is left.
set -euo pipefail
source "$(dirname "$0")/pvpython_errors.sh"
m3dp=$1 scene=$2 out=$3
rm -rf "$out"
"$m3dp" run "$scene" -o "$out" --quiet &
pid=$!
# Wait for at least two frames, then interrupt.
for _ in $(seq 1 600); do
  if [ -f "$out/particles.pvd" ] && [ "$(grep -c '<DataSet' "$out/particles.pvd")" -ge 2 ]; then break; fi
  sleep 0.1
done
kill -INT $pid
set +e
wait $pid
status=$?
set -e
[ $status -eq 130 ] || { echo "FAIL: exit status $status, expected 130"; exit 1; }
grep -q '"status": "interrupted"' "$out/summary.json" || { echo "FAIL: summary.json does not say interrupted"; exit 1; }
leftovers=$(find "$out" -name '*.tmp*' -o -name '*.partial' | wc -l)
[ "$leftovers" -eq 0 ] || { echo "FAIL: $leftovers temporary files left"; exit 1; }
pvpython --force-offscreen-rendering - "$out/particles.pvd" <<'PY' 2>"$out/pvpython.err" || pvpython_failed "$out/pvpython.err"
import sys
from paraview.simple import PVDReader, UpdatePipeline, servermanager
reader = PVDReader(FileName=sys.argv[1])
for t in reader.TimestepValues:
    UpdatePipeline(time=t, proxy=reader)
    assert servermanager.Fetch(reader).GetNumberOfPoints() > 0, t
print("all", len(reader.TimestepValues), "frames readable")
PY
check_pvpython_errors "$out/pvpython.err"
echo "PASS"
