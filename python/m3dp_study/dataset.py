"""A study's labelled pictures (m3dp study --dataset): every completed run's camera frames gathered in
one folder that common training code reads, with a COCO-style index.

    dataset/images/RUN_CAMERA_NNNN.png          colour (8-bit RGB)
    dataset/masks/RUN_CAMERA_NNNN_segment.png   segment id per pixel (16-bit; ids in the image's legend)
    dataset/masks/RUN_CAMERA_NNNN_layer.png     print layer + 1 per pixel (16-bit; 0: not printed material)
    dataset/depth/RUN_CAMERA_NNNN_depth.png     depth x 5000 (16-bit, 0.2 mm a unit; 0: nothing seen)
    dataset/annotations.json                    COCO: images, categories (segment kinds), annotations (one per
                                                segment in an image: uncompressed RLE, bbox, area, layer)
    dataset/manifest.json                       the study, its parameters, and each run's values and status
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from .spec import Study

CATEGORIES = ("static", "link", "body", "nozzle", "printed_material", "material")  # the background is no category


def rle(mask: np.ndarray) -> dict:
    """COCO's uncompressed run-length encoding of a boolean mask: counts of alternating 0s and 1s in
    column-major order, starting with 0s."""
    flat = np.asarray(mask, dtype=np.uint8).flatten(order="F")
    changes = np.flatnonzero(np.diff(flat)) + 1
    bounds = np.concatenate(([0], changes, [flat.size]))
    counts = np.diff(bounds).tolist()
    if flat.size and flat[0] == 1:
        counts = [0] + counts
    return {"size": [int(mask.shape[0]), int(mask.shape[1])], "counts": counts}


def _place(source: Path, target: Path):
    target.parent.mkdir(parents=True, exist_ok=True)
    target.unlink(missing_ok=True)
    try:
        os.link(source, target)  # the run's file, not a copy, where the file system allows
    except OSError:
        shutil.copyfile(source, target)


def write_dataset(out: Path, study: Study, runs: list[dict], rows: list[dict]):
    from PIL import Image

    root = out / "dataset"
    root.mkdir(exist_ok=True)
    categories = [{"id": k + 1, "name": name, "supercategory": "scene"} for k, name in enumerate(CATEGORIES)]
    category_of = {entry["name"]: entry["id"] for entry in categories}
    images, annotations = [], []
    status = {row["run"]: row["status"] for row in rows}
    for run in runs:
        frames_file = Path(run["folder"]) / "dataset" / "frames.json"
        if status.get(run["key"]) != "ok" or not frames_file.exists():
            continue
        for frame in json.loads(frames_file.read_text()):
            image_id = len(images) + 1
            name = f"{run['key']}_{frame['camera']}_{frame['index']:04d}"
            source = frames_file.parent
            entry = {"id": image_id, "file_name": f"images/{name}.png", "width": frame["width"], "height": frame["height"],
                     "run": run["key"], "camera": frame["camera"], "time_s": frame["time_s"], "parameters": run["parameters"],
                     "repeat": run["repeat"], "seed": run["seed"]}
            _place(source / frame["rgb"], root / entry["file_name"])
            if "depth" in frame:
                entry["depth_file"] = f"depth/{name}_depth.png"
                _place(source / frame["depth"], root / entry["depth_file"])
            if "segment" in frame:
                entry["segment_file"], entry["layer_file"] = f"masks/{name}_segment.png", f"masks/{name}_layer.png"
                _place(source / frame["segment"], root / entry["segment_file"])
                _place(source / frame["layer"], root / entry["layer_file"])
                entry["legend"] = frame["legend"]
                with Image.open(root / entry["segment_file"]) as picture:
                    segments = np.array(picture)
                for segment, label in frame["legend"].items():
                    if label["kind"] not in category_of:
                        continue
                    mask = segments == int(segment)
                    rows_hit, columns_hit = np.nonzero(mask)
                    if rows_hit.size == 0:
                        continue
                    annotation = {"id": len(annotations) + 1, "image_id": image_id, "category_id": category_of[label["kind"]],
                                  "segmentation": rle(mask), "area": int(mask.sum()), "iscrowd": 0,
                                  "bbox": [int(columns_hit.min()), int(rows_hit.min()), int(columns_hit.max() - columns_hit.min() + 1),
                                           int(rows_hit.max() - rows_hit.min() + 1)],
                                  "segment_id": int(segment), "name": label.get("name", "")}
                    if "layer" in label:
                        annotation["layer"] = label["layer"]
                    annotations.append(annotation)
            images.append(entry)
    index = {"info": {"description": f"M3DP study {study.name}: simulated camera frames with per-pixel labels",
                      "depth_units_per_metre": 5000,
                      "layer_mask": "print layer + 1 per pixel; 0 where no printed material is seen"},
             "images": images, "annotations": annotations, "categories": categories}
    (root / "annotations.json").write_text(json.dumps(index, indent=1))
    manifest = {"study": str(study.file), "name": study.name, "scene": str(study.scene),
                "parameters": [parameter.name for parameter in study.parameters],
                "runs": [{"run": run["key"], "parameters": run["parameters"], "repeat": run["repeat"], "seed": run["seed"],
                          "status": status.get(run["key"], "")} for run in runs],
                "images": len(images), "annotations": len(annotations)}
    (root / "manifest.json").write_text(json.dumps(manifest, indent=1))
