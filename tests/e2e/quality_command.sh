#!/usr/bin/env bash
# `m3dp quality RUN_DIR`: the demo printed for a few seconds measured against its path (quality.json
# read back by Python's json, quality.csv by its csv), and each missing input a clear error, exit 2.
set -euo pipefail
m3dp=$1 scenes=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
"$m3dp" run "$scenes/ur10_wall.sdf" -o "$work/run" --until 4 --quiet > /dev/null
# The run wrote its own report (the in-run observer); the command remakes it from the frames alone.
cp "$work/run/quality.json" "$work/in_run_quality.json"
"$m3dp" quality "$work/run"
/usr/bin/python3 - "$work/in_run_quality.json" "$work/run/quality.json" "$work/run/summary.json" <<'PY'
import json, sys
in_run, offline, summary = (json.load(open(path)) for path in sys.argv[1:])
assert abs(in_run["time_s"] - offline["time_s"]) < 1e-6  # particles.pvd keeps 9 digits
for key in ("particles", "fill_m3", "surface_deviation_m"):
    assert in_run[key] == offline[key], (key, in_run[key], offline[key])
def same_history(history, frames):
    assert len(history) == len(frames), (len(history), len(frames))
    for (time, *rest), (frame_time, *frame_rest) in zip(history, frames):  # looked at every 0.1 s, as the frames
        assert abs(time - frame_time) < 1e-6 and rest == frame_rest, (time, rest, frame_time, frame_rest)
same_history(in_run["height"]["history"], offline["height"]["history"])
for head, frame_head in zip(in_run["heads"], offline["heads"], strict=True):  # each head's own height too
    same_history(head.pop("height")["history"], frame_head.pop("height")["history"])
assert in_run["heads"] == offline["heads"]
quality = summary["quality"]
assert quality["file"] == "quality.json" and quality["stood"] is True and quality["layers"] == 1, quality
assert abs(quality["fill_under_m3"] - in_run["fill_m3"]["under"]) < 1e-12
print("the in-run report and m3dp quality's agree")
PY
/usr/bin/python3 - "$work/run" <<'PY'
import csv, json, pathlib, sys
folder = pathlib.Path(sys.argv[1])
report = json.loads((folder / "quality.json").read_text())
head = report["heads"][0]
assert head["name"] == "nozzle", head["name"]
layer = head["layers"][0]
# Stopped at 4 s, it is judged against what the path had laid by then (part of the first side), not
# the whole square: every station of that part has material.
assert layer["layer"] == 0 and 10 <= layer["stations"] <= 30 and layer["stations_empty"] == 0, layer
assert abs(layer["design_width_m"] - 0.01373) < 1e-4 and abs(layer["design_height_m"] - 0.008) < 1e-6, layer
assert 0.8 * 0.01373 < layer["width_m"] < 1.4 * 0.01373, layer
assert 0.006 < layer["height_m"] < 0.012 and layer["height_m"] == layer["extent_m"], layer  # on the bed: its rise is its extent
assert report["height"]["stood"] is True and report["height"]["shortfall"] is None, report["height"]["shortfall"]
fill = report["fill_m3"]
assert fill["under"] < 0.25 * fill["designed"], fill  # what was laid by then is there (the whole wall would be 95 % under)
summary = json.loads((folder / "summary.json").read_text())
assert abs(fill["designed"] - summary["volume_m3"]["commanded"]) < 0.1 * fill["designed"], (fill, summary["volume_m3"])
rows = list(csv.DictReader((folder / "quality.csv").open()))
assert sum(row["layer"] == "0" for row in rows) == layer["stations"], len(rows)
assert {"width_m", "height_m", "extent_m", "offset_across_m", "offset_up_m"} <= set(rows[0]), rows[0]
from PIL import Image
with Image.open(folder / "quality.png") as image:
    assert image.size[0] > 1000 and image.size[1] > 300, image.size
print("quality.json, quality.csv and quality.png read back")
PY
# The surface's deviation field: ParaView reads quality_mesh.vtp's deviation_m; quality_mesh.ply (for
# MeshLab, whose vertex quality it is) has the same values, its geometry read by ParaView too.
pvpython --force-offscreen-rendering - "$work/run" > "$work/pvpython.out" 2>"$work/pvpython.err" <<'PY' || { cat "$work/pvpython.err"; exit 1; }
import json, pathlib, struct, sys
from paraview.simple import OpenDataFile, UpdatePipeline, servermanager
folder = pathlib.Path(sys.argv[1])
def fetch(name):
    reader = OpenDataFile(str(folder / name))
    UpdatePipeline(proxy=reader)
    return servermanager.Fetch(reader)
surface, ply = fetch("quality_mesh.vtp"), fetch("quality_mesh.ply")
deviation = surface.GetPointData().GetArray("deviation_m")
report = json.loads((folder / "quality.json").read_text())["surface_deviation_m"]
assert surface.GetNumberOfPoints() == ply.GetNumberOfPoints() == report["vertices"] > 1000, report
low, high = deviation.GetRange()
assert abs(max(-low, high) - report["max"]) < 1e-6, (low, high, report)
data = (folder / "quality_mesh.ply").read_bytes()
header_end = data.index(b"end_header\n") + len(b"end_header\n")
assert b"property float quality" in data[:header_end]
first = struct.unpack_from("<4f", data, header_end)  # x, y, z, quality of the first vertex
assert abs(first[3] - deviation.GetValue(0)) < 1e-6, (first, deviation.GetValue(0))
print("OK", report["vertices"], low, high)
PY
tail -n 1 "$work/pvpython.out"
grep -q "^OK" "$work/pvpython.out" || { echo "FAIL: pvpython did not read the deviation field"; exit 1; }
# gcode_part (PrusaSlicer's G-code, five times larger) reports its quality too, and says that its
# 1.5 mm layers are under two particle diameters (2 mm particles): at the resolution's limit.
"$m3dp" run "$scenes/gcode_part.sdf" -o "$work/gcode_part" --until 3 --quiet 2> /dev/null | grep -E "quality" || true
/usr/bin/python3 - "$work/gcode_part" <<'PY'
import json, pathlib, sys
folder = pathlib.Path(sys.argv[1])
quality = json.loads((folder / "summary.json").read_text())["quality"]
report = json.loads((folder / "quality.json").read_text())
assert quality["file"] == "quality.json" and quality["layers"] >= 1, quality
warning = quality["resolution_warning"]  # a quarter of 1.5 mm, as the layer's float height rounds
assert "thinnest layer, 1.50 mm" in warning and ("0.37 mm or less" in warning or "0.38 mm or less" in warning), quality
assert report["resolution_warning"] == quality["resolution_warning"]
first = report["heads"][0]["layers"][0]
assert first["stations"] > first["stations_empty"] and abs(first["design_height_m"] - 0.0015) < 1e-6, first
print("gcode_part: its quality reported, with the resolution warning")
PY
expect_error() {  # expected message, then the command's arguments
  local expected=$1; shift
  set +e
  output=$("$m3dp" quality "$@" 2>&1)
  status=$?
  set -e
  echo "$output"
  [ $status -eq 2 ] || { echo "FAIL: exit status $status, expected 2"; exit 1; }
  grep -qF -- "$expected" <<<"$output" || { echo "FAIL: missing '$expected'"; exit 1; }
}
expect_error "no such run folder" "$work/nowhere"
mkdir -p "$work/empty"
expect_error "not a run folder: no summary.json naming its scene and no scene.sdf" "$work/empty"
"$m3dp" run "$scenes/hydrostatic.sdf" -o "$work/no_heads" --until 0.01 --quiet > /dev/null
expect_error "the scene has no print heads" "$work/no_heads"
cp "$work/run/summary.json" "$work/empty/"
expect_error "no particle frames (particles.pvd)" "$work/empty"
# A run that ended before the nozzle reached the wall (it extrudes from 1.76 s).
"$m3dp" run "$scenes/ur10_wall.sdf" -o "$work/early" --until 0.5 --quiet > /dev/null
expect_error "no particle in the last frame was printed by a head's path" "$work/early"
echo "PASS"
