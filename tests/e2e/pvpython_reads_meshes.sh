#!/usr/bin/env bash
# End to end: `m3dp run` prints a ring, `m3dp mesh` turns its last frame into OBJ, binary PLY,
# binary STL and a Gazebo model folder, and ParaView's own readers (pvpython) open each mesh file
# and count the same triangles and a closed surface (no boundary edges).
set -euo pipefail
m3dp=$1 scene=$2 out=$3
rm -rf "$out"
"$m3dp" run "$scene" -o "$out/run" --until 1.5 --quiet > /dev/null
frame=$(ls "$out"/run/particles/*.vtu | tail -n 1)
for format in obj ply stl; do
  line=$("$m3dp" mesh "$frame" -o "$out/surface.$format" --method anisotropic)
  echo "$line"
  triangles=$(echo "$line" | sed -E 's/.* ([0-9]+) triangles.*/\1/')
  read_back=$(pvpython --force-offscreen-rendering - "$out/surface.$format" <<'PY' 2>/dev/null | tail -n 1
import sys
from paraview.simple import OpenDataFile, FeatureEdges, UpdatePipeline, servermanager
reader = OpenDataFile(sys.argv[1])
UpdatePipeline(proxy=reader)
data = servermanager.Fetch(reader)
edges = FeatureEdges(Input=reader, BoundaryEdges=1, FeatureEdges=0, NonManifoldEdges=1, ManifoldEdges=0)
UpdatePipeline(proxy=edges)
print(data.GetNumberOfCells(), servermanager.Fetch(edges).GetNumberOfCells())
PY
)
  echo "pvpython read $out/surface.$format: $read_back (triangles, open or non-manifold edges)"
  [ "$read_back" = "$triangles 0" ] || { echo "FAIL: expected '$triangles 0'"; exit 1; }
done
"$m3dp" mesh "$frame" -o "$out/printed_ring" --format sdf > /dev/null
test -f "$out/printed_ring/model.sdf" && test -f "$out/printed_ring/model.config" && test -f "$out/printed_ring/meshes/printed_ring.stl"
grep -q '<uri>model://printed_ring/meshes/printed_ring.stl</uri>' "$out/printed_ring/model.sdf"
if grep -q "$out" "$out/printed_ring/model.sdf" "$out/surface.obj"; then echo "FAIL: absolute path inside a mesh file"; exit 1; fi
echo "PASS"
