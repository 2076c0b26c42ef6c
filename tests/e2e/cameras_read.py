"""The demo's cameras, read back by PIL and numpy (Debian's python3-pil and python3-numpy):

    /usr/bin/python3 tests/e2e/cameras_read.py RUN_DIR

- every image has the size camera.json gives, the bit depth and value range its kind should have
  (RGB 8-bit; depth .npy float32 metres within the clip or inf, depth PNG 16-bit millimetres;
  segmentation 16-bit ids that legend.json names; the point cloud in the optical frame);
- the overview camera sees every link of the arm;
- while the wrist camera's nozzle prints, its images hold the fresh bead (the particles of the layer
  being printed, legend.json's layer_start_s) beside the nozzle, and the bead's top, from the depth image and the camera's pose, is
  at the printed layer's height (the nozzle's exit) within one particle radius.
Prints one line of figures and exits non-zero on a failed check.
"""
import json
import sys
from pathlib import Path

import numpy
from PIL import Image

run = Path(sys.argv[1])
summary = json.loads((run / "summary.json").read_text())
particle_radius = summary["particle_radius_m"]


def rotation(w, x, y, z):
    return numpy.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def load(camera):
    folder = run / "cameras" / camera
    settings = json.loads((folder / "camera.json").read_text())
    legend = {entry["id"]: entry for entry in json.loads((folder / "legend.json").read_text())}
    frames = numpy.loadtxt(folder / "frames.csv", delimiter=",", skiprows=1, ndmin=2)
    return folder, settings, legend, frames


def check_files(camera):
    folder, settings, legend, frames = load(camera)
    width, height = settings["width"], settings["height"]
    assert len(frames) >= 5, f"{camera}: {len(frames)} frames"
    for index in range(len(frames)):
        rgb = Image.open(folder / f"rgb_{index:06d}.png")
        assert rgb.mode == "RGB" and rgb.size == (width, height), f"{camera} {index}: rgb {rgb.mode} {rgb.size}"
        pixels = numpy.asarray(rgb)
        assert pixels.dtype == numpy.uint8 and pixels.max() > pixels.min(), f"{camera} {index}: a flat colour image"
        segmentation = Image.open(folder / f"segmentation_{index:06d}.png")
        assert segmentation.mode in ("I", "I;16") and segmentation.size == (width, height), f"{camera} {index}: segmentation {segmentation.mode}"
        ids = numpy.unique(numpy.asarray(segmentation))
        assert all(int(i) in legend for i in ids), f"{camera} {index}: ids {ids} not all in legend.json"
        depth = numpy.load(folder / f"depth_{index:06d}.npy")
        assert depth.dtype == numpy.float32 and depth.shape == (height, width), f"{camera} {index}: depth {depth.dtype} {depth.shape}"
        seen = numpy.isfinite(depth)
        assert seen.any(), f"{camera} {index}: the depth image sees nothing"
        assert depth[seen].min() >= settings["near_m"] - 1e-6 and depth[seen].max() <= settings["far_m"] + 1e-6, f"{camera} {index}: depth outside the clip"
        # What is hit has a segment, and what has none was not hit.
        segment = numpy.asarray(segmentation)
        assert ((segment != 0) == seen).all(), f"{camera} {index}: segments and depth disagree"
        millimetres = numpy.asarray(Image.open(folder / f"depth_{index:06d}.png"))
        assert (numpy.abs(millimetres[seen] - numpy.round(1000 * depth[seen])) <= 1).all(), f"{camera} {index}: 16UC1 depth is not the float depth in mm"
        assert (millimetres[~seen] == 0).all()
    # The last point cloud, where the camera writes one: binary PLY, as many points as pixels that saw something.
    if settings["point_cloud"] == "none":
        assert not list(folder.glob("points_*.ply")), f"{camera}: point clouds it was not asked for"
        return len(frames)
    ply = (folder / f"points_{len(frames) - 1:06d}.ply").read_bytes()
    header_end = ply.index(b"end_header\n") + len(b"end_header\n")
    count = int(next(line for line in ply[:header_end].decode().splitlines() if line.startswith("element vertex")).split()[2])
    points = numpy.frombuffer(ply[header_end:], dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgba", "u1", 4), ("segment", "<u2"), ("pad", "<u2")])
    assert len(points) == count == int(seen.sum()), f"{camera}: {len(points)} points, {count} in the header, {seen.sum()} pixels"
    if settings["point_cloud"] == "optical":
        assert (points["z"] > 0).all()
    return len(frames)


def overview_sees_the_arm():
    folder, settings, legend, frames = load("overview")
    links = {entry["id"]: entry["name"] for entry in legend.values() if entry["kind"] == "link" and entry.get("robot") == "ur10"}
    assert len(links) >= 7, f"legend links: {links}"
    last = len(frames) - 1
    counts = dict(zip(*numpy.unique(numpy.asarray(Image.open(folder / f"segmentation_{last:06d}.png")), return_counts=True)))
    missing = [name for id, name in links.items() if counts.get(id, 0) < 50]
    assert not missing, f"the overview camera does not see {missing}"
    return len(links)


def wrist_sees_the_bead():
    folder, settings, legend, frames = load("wrist")
    fx, fy, cx, cy = settings["fx"], settings["fy"], settings["cx"], settings["cy"]
    mount = settings["pose_in_mount"]
    mount_rotation, mount_position = rotation(*mount["orientation_wxyz"]), numpy.array(mount["position_m"])
    optical_to_camera = numpy.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]])
    # Each print layer's segment and when the nozzle began it.
    starts = {id: entry["layer_start_s"] for id, entry in legend.items() if entry["kind"] == "material" and entry.get("layer") is not None}

    def nozzle_of(frame):
        """The nozzle's exit: 0.15 m along the flange (tool0) axis, the flange from the camera's mount."""
        optical_rotation = rotation(*frame[5:9])
        tool_rotation = optical_rotation @ optical_to_camera.T @ mount_rotation.T
        return frame[2:5] - tool_rotation @ mount_position + tool_rotation @ numpy.array([0, 0, 0.15])

    nozzles = [nozzle_of(frame) for frame in frames]
    printing, with_bead, offsets = 0, 0, []
    for index, frame in enumerate(frames):
        time, position, optical_rotation = frame[1], frame[2:5], rotation(*frame[5:9])
        nozzle = nozzles[index]
        # Printing: after the nozzle reaches the first corner (about 1.8 s), moving level (not rising
        # to the next layer) between the frames before and after.
        if time < 2.5 or index + 1 >= len(frames) or max(abs(nozzles[index - 1][2] - nozzle[2]), abs(nozzles[index + 1][2] - nozzle[2])) > 2e-4:
            continue
        printing += 1
        segment = numpy.asarray(Image.open(folder / f"segmentation_{index:06d}.png"))
        depth = numpy.load(folder / f"depth_{index:06d}.npy")
        # The layer being printed now: the last one begun; its bead, where the camera sees it.
        current = max((id for id in starts if starts[id] <= time), key=lambda id: starts[id])
        rows, columns = numpy.nonzero(segment == current)
        if len(rows) == 0:
            continue
        z = depth[rows, columns]
        optical = numpy.stack([(columns + 0.5 - cx) / fx * z, (rows + 0.5 - cy) / fy * z, z], axis=1)
        world = optical @ optical_rotation.T + position
        beside = numpy.hypot(world[:, 0] - nozzle[0], world[:, 1] - nozzle[1]) < 0.03
        if beside.sum() < 50:
            continue
        with_bead += 1
        # Its top: the 95th percentile of the bead's heights beside the nozzle, against the exit's height.
        offsets.append(numpy.percentile(world[beside, 2], 95) - nozzle[2])
    assert printing >= 20, f"{printing} wrist frames while printing"
    share = with_bead / printing
    # The barrel hides the bead on one side of the square (it trails away from the camera there).
    assert share >= 0.6, f"the fresh bead is beside the nozzle in {with_bead} of {printing} frames"
    offsets = numpy.array(offsets)
    worst = numpy.abs(offsets).max()
    assert worst <= particle_radius, f"the bead's top is {1000 * worst:.2f} mm from the layer height (allowed {1000 * particle_radius:.2f} mm)"
    return with_bead, printing, 1000 * numpy.median(offsets), 1000 * worst


frames = {camera: check_files(camera) for camera in ("wrist", "overview")}
links = overview_sees_the_arm()
with_bead, printing, median_mm, worst_mm = wrist_sees_the_bead()
print(f"frames {frames}; the overview sees all {links} links; the wrist sees the fresh bead beside the nozzle in {with_bead} of "
      f"{printing} printing frames, its top {median_mm:+.2f} mm (median, worst {worst_mm:.2f} mm) from the layer height")
