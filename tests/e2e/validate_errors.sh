#!/usr/bin/env bash
# `m3dp validate` accepts every shipped scene, and names file:line and what was expected for a bad one.
set -euo pipefail
m3dp=$1 data=$2 scenes=$3
for scene in "$scenes"/*.sdf; do
  "$m3dp" validate "$scene"
done
set +e
output=$("$m3dp" validate "$data/bad_scene.sdf" 2>&1)
status=$?
set -e
echo "$output"
[ $status -eq 2 ] || { echo "FAIL: exit status $status, expected 2"; exit 1; }
for expected in "bad_scene.sdf:9: error: <particle_radius> must be > 0" "bad_scene.sdf:18: error:" "density" \
                "bad_scene.sdf:21: error: unknown element <colour>"; do
  grep -qF -- "$expected" <<<"$output" || { echo "FAIL: missing '$expected'"; exit 1; }
done
echo "PASS"
