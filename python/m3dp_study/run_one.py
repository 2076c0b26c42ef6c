"""One run of a study, in its own process: `python3 -m m3dp_study.run_one RUN_FOLDER`. It reads
run.json there, simulates, and writes result.json (status, reason, figures) last, atomically: a
folder without result.json is a run that did not finish (its process died or was killed), which the
study then reports or retries. A crash of the simulation kills only this process."""
from __future__ import annotations

import importlib
import importlib.util
import json
import math
import os
import sys
import time
import traceback
from pathlib import Path


def _scalars(value, prefix, out, depth=0):
    """The numbers (and booleans, and status text) of a JSON value, flattened as prefix.key.key."""
    if isinstance(value, bool):
        out[prefix] = int(value)
    elif isinstance(value, (int, float)):
        out[prefix] = value
    elif isinstance(value, dict) and depth < 3:
        for key, inner in value.items():
            if key in ("definition", "history", "layers", "sections", "section_arrays"):
                continue
            _scalars(inner, f"{prefix}.{key}", out, depth + 1)
    elif isinstance(value, list) and depth < 3 and value and all(isinstance(entry, dict) and "name" in entry for entry in value):
        for entry in value:
            _scalars({key: inner for key, inner in entry.items() if key != "name"}, f"{prefix}.{entry['name']}", out, depth + 1)


def summary_figures(summary: dict) -> dict:
    figures = {}
    for key, value in summary.items():
        if key in ("scene", "status", "error", "quality", "cameras", "meshes", "recording", "live", "coordinator", "materials"):
            continue
        _scalars(value, f"summary.{key}", figures)
    return figures


def quality_figures(report: dict) -> dict:
    """The quality report's headline figures: the fill volumes, and per head the layers' mean
    designed and measured width, height and area and offsets (weighted by their measured stations);
    with one head, without its name."""
    figures = {}
    for key, value in report.get("fill_m3", {}).items():
        figures[f"quality.fill_{key}_m3"] = value
    heads = report.get("heads", [])
    for head in heads:
        prefix = "quality." if len(heads) == 1 else f"quality.{head['name']}."
        sums, weights = {}, {}
        for layer in head.get("layers", []):
            weight = layer.get("stations", 0) - layer.get("stations_empty", 0)
            for key in ("design_width_m", "width_m", "design_height_m", "height_m", "extent_m", "design_area_m2", "area_m2", "offset_across_m",
                        "offset_up_m"):
                value = layer.get(key)
                if isinstance(value, (int, float)) and math.isfinite(value) and weight > 0:
                    sums[key] = sums.get(key, 0.0) + value * weight
                    weights[key] = weights.get(key, 0) + weight
        for key in sums:
            figures[prefix + key] = sums[key] / weights[key]
        figures[prefix + "layers"] = len(head.get("layers", []))
    return figures


def _controller(spec):
    if spec is None:
        return None
    module_name = spec["module"]
    if module_name.endswith(".py"):
        loader = importlib.util.spec_from_file_location(Path(module_name).stem, module_name)
        module = importlib.util.module_from_spec(loader)
        loader.loader.exec_module(module)
    else:
        module = importlib.import_module(module_name)
    return getattr(module, spec["function"])


# Depth images are 16-bit PNGs of depth × 5000 (0.2 mm a unit, 13 m at most; 0: nothing seen), as
# the TUM RGB-D benchmark writes them.
DEPTH_UNITS_PER_METRE = 5000


def capture(simulation, folder: Path, cameras, index: int) -> list[dict]:
    """Each camera's picture now with its labels: rgb, segment ids (uint16, legend in the entry),
    print layer + 1 per pixel (0: not printed material), depth. Returns the frames' entries."""
    import numpy as np
    from PIL import Image

    frames = []
    legend = {int(key): value for key, value in simulation.camera_legend().items()}
    layer_of = np.zeros(max(legend) + 1 if legend else 1, dtype=np.uint16)
    for segment, entry in legend.items():
        if "layer" in entry:
            layer_of[segment] = entry["layer"] + 1
    for camera in cameras:
        images = simulation.camera(camera)
        stem = f"{camera}_{index:04d}"
        entry = {"camera": camera, "time_s": simulation.time, "index": index, "rgb": f"{stem}.png"}
        Image.fromarray(np.ascontiguousarray(images["rgb"])).save(folder / entry["rgb"])
        if "segmentation" in images:
            segments = np.asarray(images["segmentation"], dtype=np.uint16)
            entry["segment"], entry["layer"] = f"{stem}_segment.png", f"{stem}_layer.png"
            Image.fromarray(segments).save(folder / entry["segment"])
            Image.fromarray(layer_of[np.minimum(segments, len(layer_of) - 1)]).save(folder / entry["layer"])
            entry["legend"] = {str(segment): legend[int(segment)] for segment in np.unique(segments) if int(segment) in legend}
        if "depth" in images:
            depth = np.asarray(images["depth"], dtype=np.float64)
            units = np.where(np.isfinite(depth), np.round(depth * DEPTH_UNITS_PER_METRE), 0)
            entry["depth"] = f"{stem}_depth.png"
            Image.fromarray(np.clip(units, 0, 65535).astype(np.uint16)).save(folder / entry["depth"])
        entry["height"], entry["width"] = images["rgb"].shape[:2]
        frames.append(entry)
    return frames


def run(folder: Path) -> dict:
    import m3dp  # here, so that a broken install is this run's reported failure

    spec = json.loads((folder / "run.json").read_text())
    started = time.time()
    result = {"status": "failed", "reason": "", "figures": {}}
    simulation = None
    try:
        simulation = m3dp.Simulation(spec["scene"], threads=spec["threads"], overrides=spec["overrides"])
        if spec["record"]:
            simulation.record(str(folder / "output"))
        for head, scale in spec["flow_scales"].items():
            for name in ([head] if head else simulation.head_names):
                simulation.set_extrusion(name, flow_scale=scale)
        end_time = spec["end_time"] if spec["end_time"] is not None else simulation.end_time
        control = _controller(spec["controller"])
        period = spec["controller"]["period"] if control is not None else math.inf
        dataset = spec.get("dataset")
        frames, captures = [], []
        if dataset is not None:
            cameras = dataset["cameras"] or simulation.cameras
            missing = [name for name in cameras if name not in simulation.cameras]
            if not cameras or missing:
                raise ValueError(f"the dataset's cameras {missing or '(none)'}: the scene's cameras are {simulation.cameras or 'none'}")
            (folder / "dataset").mkdir(exist_ok=True)
            every = dataset["every"]
            count = int(math.floor(end_time / every + 1e-9)) if every else 0
            captures = [every * (k + 1) for k in range(count) if every * (k + 1) < end_time - 1e-9] + [end_time]
        next_control = 0.0 if control is not None else math.inf
        controller_figures = {}
        while True:
            if control is not None and simulation.time >= next_control - 1e-12 and simulation.time < end_time - 1e-12:
                said = control(simulation, {"seed": spec["seed"], "parameters": spec["parameters"]})
                if isinstance(said, dict):  # the controller's own figures (a score): the last it gave
                    controller_figures = {f"controller.{key}": value for key, value in said.items()
                                          if isinstance(value, (int, float)) and not isinstance(value, bool)}
                next_control += period
            while captures and simulation.time >= captures[0] - 1e-12:
                frames += capture(simulation, folder / "dataset", cameras, len(frames) // len(cameras))
                captures.pop(0)
            if simulation.time >= end_time - 1e-12:
                break
            simulation.step_to(min(end_time, next_control, captures[0] if captures else math.inf))
        if dataset is not None:
            (folder / "dataset" / "frames.json").write_text(json.dumps(frames, indent=1))
        figures = dict(controller_figures)
        if "quality" in spec["figures"]:
            try:
                figures.update(quality_figures(simulation.quality(spec["quality_spacing"])))
            except m3dp.UnmeasurableDesign as problem:  # nothing laid that is a bead yet (a pour, a run cut short): no quality figures
                result["quality_note"] = str(problem)
        summary = simulation.close()
        if "summary" in spec["figures"]:
            figures.update(summary_figures(summary))
        result["figures"] = figures
        result["status"] = "ok" if summary.get("status") == "completed" else summary.get("status", "failed")
        result["reason"] = summary.get("error") or ""
    except Exception as problem:  # every failure is the run's row, with its reason
        result["reason"] = f"{type(problem).__name__}: {problem}".strip()
        result["traceback"] = traceback.format_exc()
        if simulation is not None:
            try:
                simulation.close()
            except Exception:
                pass
    result["run_seconds"] = time.time() - started
    return result


def _die_with(parent: int):
    """Killed when the worker that started it dies, so that a run retried elsewhere has no twin
    writing into its folder (Linux's PR_SET_PDEATHSIG, then a check that the parent is still there)."""
    import ctypes
    import signal

    ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)
    if os.getppid() != parent:
        os._exit(1)


def main(argv):
    if len(argv) not in (2, 3):
        print("usage: python3 -m m3dp_study.run_one RUN_FOLDER [WORKER_PID]", file=sys.stderr)
        return 2
    if len(argv) == 3:
        _die_with(int(argv[2]))
    folder = Path(argv[1])
    result = run(folder)
    partial = folder / f"result.json.{os.getpid()}"
    partial.write_text(json.dumps(result, indent=1, default=float))
    os.replace(partial, folder / "result.json")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
