#!/usr/bin/env bash
# Checkpoints: ur10_wall to 4.5 s with a checkpoint every simulated second (a mesh joins the world
# at 4 s), once without stopping and once killed with SIGKILL at several points, each time resumed
# with `m3dp run --resume`. The resumed run must end bit for bit as the one never stopped: the same
# state hash at every step, the same particle, world, mesh and camera files byte for byte, the same
# messages in run.mcap (read by @mcap/core, its indexes whole), the same summary and timing rows
# apart from wall-clock figures. After every kill, the files in the folder are valid as they are,
# and what a writer killed mid-file left is cleared by the resume.
# Also: a folder without a checkpoint, and a scene changed since, are refused with the reason.
set -euo pipefail
m3dp=$1 scene=$2 urdf=$3 out=$4
here=$(dirname "$0")
rm -rf "$out"
mkdir -p "$out"
run=(run "$scene" --until 4.5 --hash --record --checkpoint-period 1 --threads 2 --quiet)
"$m3dp" "${run[@]}" -o "$out/whole" > "$out/whole.log"

# Kill points (steps in hashes.csv): about 405 steps a simulated second, so after the first
# checkpoint, after the second (written by a resumed run), just after the third, and again before
# the fourth (the same checkpoint twice).
killed="$out/killed"
first=1
for steps in 600 1000 1230 1260; do
  if [ $first = 1 ]; then
    "$m3dp" "${run[@]}" -o "$killed" > /dev/null 2>&1 &
    first=0
  else
    "$m3dp" run --resume "$killed" --quiet > /dev/null 2>&1 &
  fi
  pid=$!
  for _ in $(seq 1 3000); do
    lines=$({ wc -l < "$killed/hashes.csv.partial"; } 2>/dev/null || echo 0)
    [ "$lines" -gt "$steps" ] && break
    sleep 0.01
  done
  kill -0 $pid 2>/dev/null || { echo "FAIL: the run ended before it could be killed at step $steps"; exit 1; }
  kill -KILL $pid
  wait $pid 2>/dev/null || true
  /usr/bin/python3 - "$killed" "$steps" <<'PY'
# The folder of a killed run: every file under its real name is whole.
import json, os, sys, xml.etree.ElementTree as ET
folder, steps = sys.argv[1], sys.argv[2]
summary = json.load(open(f"{folder}/summary.json"))
assert summary["status"] == "running", summary
for series in ("particles.pvd", "world.pvd"):
    for dataset in ET.parse(f"{folder}/{series}").getroot().iter("DataSet"):
        file = os.path.join(folder, dataset.get("file"))
        assert os.path.getsize(file) > 0, f"{series} lists {file}, which is empty"
        ET.parse(file)  # whole XML
assert not os.path.exists(f"{folder}/timing.csv"), "a killed run has timing.csv under its real name"
print(f"killed after step {steps}: summary says running at {summary['simulated_time_s']:.3f} s; every frame listed is whole")
PY
done
# What a writer killed mid-file leaves (its temporary name): the resumed run clears it.
echo "half a frame" > "$killed/particles/particles_000045.vtu.tmp99999"
"$m3dp" run --resume "$killed" --quiet > "$out/resumed.log"
grep -q "Run completed" "$out/resumed.log" || { cat "$out/resumed.log"; echo "FAIL: the resumed run did not complete"; exit 1; }

cmp "$out/whole/hashes.csv" "$killed/hashes.csv" || { echo "FAIL: the state hashes differ"; exit 1; }
# Every file byte for byte, but those with wall-clock figures, compared below.
[ ! -f "$out/whole/checkpoint.bin" ] && [ ! -f "$killed/checkpoint.bin" ] || { echo "FAIL: a completed run left its checkpoint"; exit 1; }
diff -r -q -x timing.csv -x summary.json -x run.mcap "$out/whole" "$killed"
node "$here/mcap_same_messages.js" "$out/whole/run.mcap" "$killed/run.mcap"
node "$here/mcap_reads_run.js" "$killed" "$urdf" > /dev/null
/usr/bin/python3 - "$out/whole" "$killed" <<'PY'
import csv, json, sys
whole, resumed = sys.argv[1:]
simulated = ["step", "time_s", "dt_s", "particles", "moving_particles", "density_iterations", "divergence_iterations", "viscosity_iterations", "density_error"]
rows = [[[row[c] for c in simulated] for row in csv.DictReader(open(f"{folder}/timing.csv"))] for folder in (whole, resumed)]
assert rows[0] == rows[1], "timing.csv's simulated columns differ"
wall = {"wall_time_s", "real_time_factor", "particle_steps_per_second", "render_seconds", "rays_per_second", "seconds", "encode_seconds",
        "megabytes",
        "bytes", "scene"}
def compare(a, b, where=""):
    if isinstance(a, dict):
        assert a.keys() == b.keys(), f"{where}: keys differ"
        for key in a:
            if key not in wall:
                compare(a[key], b[key], f"{where}/{key}")
    elif isinstance(a, list):
        assert len(a) == len(b), f"{where}: lengths differ"
        for i, (x, y) in enumerate(zip(a, b)):
            compare(x, y, f"{where}/{i}")
    else:
        assert a == b, f"summary.json{where}: {a} vs {b}"
summary = [json.load(open(f"{folder}/summary.json")) for folder in (whole, resumed)]
compare(*summary)
assert summary[1]["status"] == "completed" and summary[1]["meshes_inserted"] >= 1, summary[1]
print(f"resumed run = whole run: {len(rows[0])} steps, {summary[0]['frames_written']} frames, {len(summary[0]['meshes'])} meshes")
PY

# Refused: no checkpoint in the folder; a scene changed since its checkpoint.
status=0
"$m3dp" run --resume "$out" --quiet > /dev/null 2> "$out/none.err" || status=$?
[ $status = 2 ] && grep -q "checkpoint.bin: error: no checkpoint to resume from" "$out/none.err" \
  || { cat "$out/none.err"; echo "FAIL: a folder without a checkpoint was not refused"; exit 1; }
cp "$here/../../scenes/hydrostatic.sdf" "$out/changed.sdf"
"$m3dp" run "$out/changed.sdf" --checkpoint-period 0.02 --pace 1 --quiet -o "$out/changed" > /dev/null 2>&1 &
pid=$!
for _ in $(seq 1 1000); do [ -f "$out/changed/checkpoint.bin" ] && break; sleep 0.01; done
kill -KILL $pid
wait $pid 2>/dev/null || true
echo "<!-- edited -->" >> "$out/changed.sdf"
status=0
"$m3dp" run --resume "$out/changed" --quiet > /dev/null 2> "$out/changed.err" || status=$?
[ $status = 2 ] && grep -q "changed.sdf: error: the scene changed since the checkpoint" "$out/changed.err" \
  || { cat "$out/changed.err"; echo "FAIL: a changed scene was resumed"; exit 1; }
echo "PASS"
