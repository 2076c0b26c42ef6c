#!/usr/bin/env bash
# End to end: `m3dp run --record` writes run.mcap, and readers we did not write read all of it
# (tests/e2e/mcap_reads_run.js: @mcap/core with CRCs and indexes, every message decoded against
# @foxglove/schemas). Then a run killed with SIGKILL mid-print: its run.mcap still reads up to the
# last frame written.
set -euo pipefail
m3dp=$1 scene=$2 urdf=$3 out=$4
here=$(dirname "$0")
rm -rf "$out"
"$m3dp" run "$scene" -o "$out/whole" --until 2.5 --record --quiet > /dev/null
node "$here/mcap_reads_run.js" "$out/whole" "$urdf"

# Killed: wait until the print has begun (22 particle frames, 2.1 s; each frame ends a chunk), then
# SIGKILL; the run must still be going.
"$m3dp" run "$scene" -o "$out/killed" --record --quiet --pace 4 > /dev/null 2>&1 &
pid=$!
for _ in $(seq 1 600); do
  frames=$(grep -c '<DataSet' "$out/killed/particles.pvd" 2>/dev/null || true)
  [ "${frames:-0}" -ge 22 ] && break
  sleep 0.05
done
kill -0 $pid 2>/dev/null || { echo "FAIL: the run ended before it could be killed"; exit 1; }
kill -KILL $pid
wait $pid 2>/dev/null || true
grep -q '"status": "running"' "$out/killed/summary.json" || { echo "FAIL: a killed run's summary.json does not say it was running"; exit 1; }
node "$here/mcap_reads_run.js" "$out/killed" "$urdf" --killed
echo "PASS"
