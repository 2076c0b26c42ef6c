"""The inspect_scan scene's scan, read with numpy (Debian's python3-numpy):

    /usr/bin/python3 tests/e2e/inspect_scan.py RUN_DIR

The depth camera on the driving TurtleBot wrote its point clouds in the world frame
(cameras/scanner/points_*.ply); together they are the wall: its material's points cover the
wall's 0.6 m length, stand on the floor no higher than the block was made, and lie on the side
facing the robot's path. Prints one line of figures; exits non-zero on a failed check.
"""
import json
import sys
from pathlib import Path

import numpy

folder = Path(sys.argv[1]) / "cameras" / "scanner"
settings = json.loads((folder / "camera.json").read_text())
assert settings["type"] == "depth_camera" and settings["point_cloud"] == "world", settings
legend = json.loads((folder / "legend.json").read_text())
material = [entry["id"] for entry in legend if entry["kind"] == "material"]
point = numpy.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgba", "u1", 4), ("segment", "<u2"), ("padding", "<u2")])
clouds = []
for file in sorted(folder.glob("points_*.ply")):
    data = file.read_bytes()
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    assert b"comment m3dp camera point cloud, world frame" in data[:header_end], file
    clouds.append(numpy.frombuffer(data[header_end:], dtype=point))
assert len(clouds) >= 40, f"{len(clouds)} point clouds"
scan = numpy.concatenate(clouds)
wall = scan[numpy.isin(scan["segment"], material)]
assert len(wall) > 10000, f"{len(wall)} points of the wall"
# Built as x 0.6..0.64, y -0.3..0.3, z 0..0.06; it settles and spreads a little at its foot.
assert (wall["x"] > 0.55).all() and (wall["x"] < 0.66).all(), f"x from {wall['x'].min()} to {wall['x'].max()}"
assert (wall["z"] > -0.005).all() and (wall["z"] < 0.065).all(), f"z from {wall['z'].min()} to {wall['z'].max()}"
# The robot drives at x = 0.2: it sees the wall's near face (x below the middle), not the far one.
assert numpy.median(wall["x"]) < 0.62, f"median x {numpy.median(wall['x'])}"
# Every centimetre of the wall's length was seen.
bins = numpy.histogram(wall["y"], bins=60, range=(-0.3, 0.3))[0]
assert (bins > 0).all(), f"unseen centimetres along the wall: {numpy.nonzero(bins == 0)[0]}"
print(f"{len(clouds)} clouds, {len(scan)} points, {len(wall)} on the wall: y {wall['y'].min():.3f} to {wall['y'].max():.3f} m, "
      f"x {numpy.percentile(wall['x'], 1):.3f} to {numpy.percentile(wall['x'], 99):.3f} m, top {numpy.percentile(wall['z'], 99):.3f} m")
