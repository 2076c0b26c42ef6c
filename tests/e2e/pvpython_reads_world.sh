#!/usr/bin/env bash
# End to end: `m3dp run` of the UR10 wall writes world.pvd beside particles.pvd, and ParaView's own
# readers (pvpython) open it: at the last frame's time the multiblock holds one block per UR10 link
# with collision shapes (from the URDF) plus the nozzle's barrel, the base link where the scene's
# <include> puts it, and the nozzle where the commanded path (its own block, vertices timed) says
# the head is then, within the arm's tracking.
set -euo pipefail
source "$(dirname "$0")/pvpython_errors.sh"
m3dp=$1 scene=$2 urdf=$3 out=$4
rm -rf "$out"
"$m3dp" run "$scene" -o "$out" --until 2.5 --quiet > /dev/null
test -f "$out/world.pvd" && test -f "$out/particles.pvd"
read_back=$(pvpython --force-offscreen-rendering - "$out/world.pvd" "$urdf" <<'PY' 2>"$out/pvpython.err" | tail -n 1
import sys
import xml.etree.ElementTree as ElementTree
from paraview.simple import OpenDataFile, UpdatePipeline, servermanager
from paraview.vtk import vtkCompositeDataSet
import numpy

reader = OpenDataFile(sys.argv[1])
times = list(reader.TimestepValues)
time = times[-1]
UpdatePipeline(time=time, proxy=reader)
data = servermanager.Fetch(reader)
blocks = {}
for b in range(data.GetNumberOfBlocks()):
    blocks[data.GetMetaData(b).Get(vtkCompositeDataSet.NAME())] = data.GetBlock(b)

def field(block, name):
    array = block.GetFieldData().GetArray(name)
    return numpy.array([array.GetComponent(0, c) for c in range(array.GetNumberOfComponents())])

nozzle_name = [name for name in blocks if name.startswith("nozzle/")][0]
head = nozzle_name[len("nozzle/"):]
links = sorted(name for name in blocks if name.startswith("ur10/"))
urdf_links = [link.get("name") for link in ElementTree.parse(sys.argv[2]).getroot().iter("link") if link.find("collision") is not None]
# The barrel is a link of its own, named after the print head.
expected = sorted(["ur10/" + name for name in urdf_links] + ["ur10/" + head])
assert links == expected, f"links {links}, expected {expected}"
base = blocks["ur10/base_link"]
assert base.GetNumberOfCells() > 0, "the base link has no triangles"
assert numpy.linalg.norm(field(base, "position")) < 1e-6, f"base link at {field(base, 'position')}"

path = blocks["path/" + head]
path_times = numpy.array([path.GetPointData().GetArray("time").GetValue(i) for i in range(path.GetNumberOfPoints())])
path_points = numpy.array([path.GetPoint(i) for i in range(path.GetNumberOfPoints())])
commanded = numpy.array([numpy.interp(time, path_times, path_points[:, axis]) for axis in range(3)])
nozzle = field(blocks[nozzle_name], "position")
# The block's triangles are where its pose says: the tube's vertices lie within 4 inner diameters of the exit.
tube = numpy.array([blocks[nozzle_name].GetPoint(i) for i in range(blocks[nozzle_name].GetNumberOfPoints())])
assert numpy.max(numpy.linalg.norm(tube - nozzle, axis=1)) < 0.1, "the nozzle's triangles are not at its pose"
print(len(times), len(links), f"{time:.3f}", f"{numpy.linalg.norm(nozzle - commanded) * 1000:.2f}")
PY
) || pvpython_failed "$out/pvpython.err"
check_pvpython_errors "$out/pvpython.err"
echo "pvpython read $out/world.pvd: $read_back (frames, UR10 links, time s, nozzle from its commanded point mm)"
read -r frames links time offset_mm <<< "$read_back"
frames_written=$(grep -c '<DataSet' "$out/particles.pvd")
[ "$frames" = "$frames_written" ] || { echo "FAIL: world.pvd has $frames frames, particles.pvd $frames_written"; exit 1; }
awk -v mm="$offset_mm" 'BEGIN { exit !(mm < 5) }' || { echo "FAIL: the nozzle is $offset_mm mm from its commanded point"; exit 1; }
echo "PASS"
