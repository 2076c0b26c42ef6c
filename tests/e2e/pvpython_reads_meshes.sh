#!/usr/bin/env bash
# End to end: `m3dp run` prints a ring, `m3dp mesh` turns its last frame into OBJ, binary PLY,
# binary STL and a Gazebo model folder, and ParaView's own readers (pvpython) open each mesh file
# and count the same triangles and a closed surface (no boundary edges). The whole .pvd sequence is
# meshed too, with the resting material's field kept from frame to frame.
set -euo pipefail
source "$(dirname "$0")/pvpython_errors.sh"
m3dp=$1 scene=$2 out=$3
rm -rf "$out"
"$m3dp" run "$scene" -o "$out/run" --until 1.5 --quiet > /dev/null
frame=$(ls "$out"/run/particles/*.vtu | tail -n 1)
for format in obj ply stl; do
  line=$("$m3dp" mesh "$frame" -o "$out/surface.$format" --method anisotropic)
  echo "$line"
  triangles=$(echo "$line" | sed -E 's/.* ([0-9]+) triangles.*/\1/')
  read_back=$(pvpython --force-offscreen-rendering - "$out/surface.$format" <<'PY' 2>"$out/pvpython.err" | tail -n 1
import sys
from paraview.simple import OpenDataFile, FeatureEdges, UpdatePipeline, servermanager
reader = OpenDataFile(sys.argv[1])
UpdatePipeline(proxy=reader)
data = servermanager.Fetch(reader)
edges = FeatureEdges(Input=reader, BoundaryEdges=1, FeatureEdges=0, NonManifoldEdges=1, ManifoldEdges=0)
UpdatePipeline(proxy=edges)
print(data.GetNumberOfCells(), servermanager.Fetch(edges).GetNumberOfCells())
PY
) || pvpython_failed "$out/pvpython.err"
check_pvpython_errors "$out/pvpython.err"
  echo "pvpython read $out/surface.$format: $read_back (triangles, open or non-manifold edges)"
  [ "$read_back" = "$triangles 0" ] || { echo "FAIL: expected '$triangles 0'"; exit 1; }
done
"$m3dp" mesh "$frame" -o "$out/printed_ring" --format sdf > /dev/null
test -f "$out/printed_ring/model.sdf" && test -f "$out/printed_ring/model.config" && test -f "$out/printed_ring/meshes/printed_ring.stl"
grep -q '<uri>model://printed_ring/meshes/printed_ring.stl</uri>' "$out/printed_ring/model.sdf"
if grep -q "$out" "$out/printed_ring/model.sdf" "$out/surface.obj"; then echo "FAIL: absolute path inside a mesh file"; exit 1; fi
# A .pvd sequence: material that has come to rest is meshed from a kept field, and the last mesh
# is the one its frame gives alone.
"$m3dp" mesh "$out/run/particles.pvd" -o "$out/sequence" --method sph_blobby -q > "$out/sequence.log"
frames=$(grep -c '<DataSet' "$out/run/particles.pvd")
meshes=$(ls "$out"/sequence/mesh_*.obj | wc -l)
[ "$meshes" = "$frames" ] || { echo "FAIL: $meshes meshes for $frames frames"; exit 1; }
last=$(grep ' kept field' "$out/sequence.log" | tail -n 1)
echo "$last"
kept=$(echo "$last" | sed -E 's/.*\(([0-9]+) meshed from a kept field.*/\1/')
[ "$kept" -gt 0 ] || { echo "FAIL: nothing at rest was kept"; exit 1; }
alone=$("$m3dp" mesh "$frame" -o "$out/alone.obj" --method sph_blobby)
[ "$(echo "$last" | sed -E 's/.* ([0-9]+) triangles.*/\1/')" = "$(echo "$alone" | sed -E 's/.* ([0-9]+) triangles.*/\1/')" ] ||
  { echo "FAIL: the sequence's last mesh differs from its frame's own: $alone"; exit 1; }
echo "PASS"
