#!/usr/bin/env bash
# docs/scene_reference.md is what `m3dp schema` prints from the scene reader's own table: a change to
# the table (a new element, a range, a default) without the page regenerated fails here.
set -euo pipefail
m3dp=$1 page=$2
if ! "$m3dp" schema | diff -u "$page" - > /tmp/m3dp_schema_diff.$$; then
  cat /tmp/m3dp_schema_diff.$$
  rm -f /tmp/m3dp_schema_diff.$$
  echo "FAIL: $page is stale: regenerate it with 'build/apps/m3dp/m3dp schema > docs/scene_reference.md'"
  exit 1
fi
rm -f /tmp/m3dp_schema_diff.$$
grep -q '| `<particles_period>` | time | s (ms) | >= 0 |' "$page" || { echo "FAIL: the page lacks <particles_period>'s row"; exit 1; }
echo "PASS: $page is current ($(grep -c '^| `<' "$page") elements)"
