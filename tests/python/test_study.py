"""m3dp study (issue 40): sweeps of a scene's values on Dask, their table, plots, resumption, failures
and the study file's errors. Runs the real command (m3dp study = python3 -m m3dp_study), on real
local Dask clusters and, once, on a `dask scheduler` and a `dask worker` started as processes."""
import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import h5py
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "tests" / "data" / "strand_study.sdf"
SPEED = "print_head[head].path.speed"
YIELD = "material[paste].rheology.yield_stress"


def study_file(folder: Path, body: str, name="study.toml") -> Path:
    path = folder / name
    path.write_text(f'[study]\nscene = "{SCENE}"\n' + body)
    return path


def run_study(*arguments, check=True, timeout=900):
    process = subprocess.run([sys.executable, "-m", "m3dp_study", *map(str, arguments), "-q"], capture_output=True, text=True,
                             timeout=timeout)
    if check:
        assert process.returncode == 0, process.stderr
    return process


def read_csv(folder: Path):
    with open(folder / "results.csv", newline="") as stream:
        return list(csv.DictReader(stream))


SWEEP = f"""end_time = 0.8
figures = ["quality", "summary"]

[parameters]
"{SPEED}" = [0.05, 0.1, 0.2]
"{YIELD}" = {{ from = 100, to = 400, steps = 4 }}
"""


def test_a_sweep_on_two_workers_is_the_table_of_the_same_runs_in_process(tmp_path):
    study = study_file(tmp_path, SWEEP)
    run_study(study, "-o", tmp_path / "dask", "--workers", "2")
    run_study(study, "-o", tmp_path / "inprocess", "--scheduler", "inprocess")
    on_dask, in_process = read_csv(tmp_path / "dask"), read_csv(tmp_path / "inprocess")
    assert len(on_dask) == 12
    assert {row["status"] for row in on_dask} == {"ok"}, [row["reason"] for row in on_dask]
    assert len({row["worker"] for row in on_dask}) == 2  # both workers ran some
    # Deterministic runs: every figure the same, whichever worker or process ran them.
    figures = [key for key in on_dask[0] if key.startswith(("quality.", "summary.")) and "wall_time" not in key
               and "per_second" not in key and "real_time" not in key]
    assert "quality.width_m" in figures and "summary.particles" in figures
    for a, b in zip(on_dask, in_process):
        assert a["run"] == b["run"]
        for key in figures:
            assert a[key] == b[key], (key, a[key], b[key])
    # The bead widens as the nozzle slows (V/U falls), at every yield stress; its section follows U/V.
    for stress in {row[YIELD] for row in on_dask}:
        line = sorted((float(row[SPEED]), float(row["quality.width_m"]), float(row["quality.area_m2"])) for row in on_dask if row[YIELD] == stress)
        widths = [width for _, width, _ in line]
        assert widths[0] > widths[1] > widths[2], (stress, line)
        areas = [area for _, _, area in line]
        assert areas[0] > 1.6 * areas[1] > 2.56 * areas[2], (stress, line)
    # The same table in HDF5, read by h5py; plots PIL opens, a map over both parameters among them.
    with h5py.File(tmp_path / "dask" / "results.h5") as file:
        runs = file["runs"]
        assert list(runs.attrs["parameters"]) == [SPEED, YIELD]
        assert [value.decode() for value in runs["run"][:]] == [row["run"] for row in on_dask]
        assert runs["quality.width_m"][:].tolist() == [float(row["quality.width_m"]) for row in on_dask]
    plots = sorted(path.name for path in (tmp_path / "dask" / "plots").glob("*.png"))
    assert "map_status.png" in plots and "map_quality.width_m.png" in plots
    assert f"quality.width_m_vs_{SPEED}.png".replace("[", "_").replace("]", "_") in plots
    with Image.open(tmp_path / "dask" / "plots" / "map_quality.width_m.png") as image:
        assert image.size[0] > 300
    # --report remakes the plots from results.csv alone.
    for plot in (tmp_path / "dask" / "plots").glob("*.png"):
        plot.unlink()
    run_study(study, "-o", tmp_path / "dask", "--report")
    assert sorted(path.name for path in (tmp_path / "dask" / "plots").glob("*.png")) == plots


FAILING_CONTROLLER = """
import os

def control(simulation, run):
    mode = run["parameters"]["flow_scale"]
    if mode == 0.5 and simulation.time > 0.05:
        raise ValueError("the controller gave up")
    if mode == 0.75 and simulation.time > 0.05:
        os.abort()  # a crash of the run's process
    return {"emitted_cm3": simulation.volume_m3["emitted"] * 1e6, "seed": run["seed"]}
"""


def test_failed_runs_are_rows_with_their_reason_and_a_second_invocation_skips_finished_runs(tmp_path):
    (tmp_path / "controller.py").write_text(FAILING_CONTROLLER)
    study = study_file(tmp_path, f"""end_time = 0.3
figures = ["summary"]

[parameters]
flow_scale = [0.5, 0.75, 1.0]
"solver.bounds.min" = ["-0.05 -0.04 -0.02", "-0.05 -0.04 0.005"]

[controller]
module = "controller.py"
function = "control"
period = 0.05
""")
    out = tmp_path / "out"
    run_study(study, "-o", out, "--workers", "2")
    rows = read_csv(out)
    assert len(rows) == 6
    by = {(row["flow_scale"], row["solver.bounds.min"]): row for row in rows}
    assert by[("1.0", "-0.05 -0.04 -0.02")]["status"] == "ok"
    # The controller's own figures: the last dict it returned.
    ok = by[("1.0", "-0.05 -0.04 -0.02")]
    assert float(ok["controller.emitted_cm3"]) > 0 and ok["controller.seed"] == "0"
    assert "ValueError: the controller gave up" in by[("0.5", "-0.05 -0.04 -0.02")]["reason"]
    assert "the run's process died (signal SIGABRT)" in by[("0.75", "-0.05 -0.04 -0.02")]["reason"]
    # Bounds above the bed: the material falls out of them, the simulation's own error, a failed row.
    blown = by[("1.0", "-0.05 -0.04 0.005")]
    assert blown["status"] == "failed" and "SimulationError: simulation blew up" in blown["reason"], blown
    attempts = {row["run"]: (out / "runs" / row["run"] / "attempts.jsonl").read_text() for row in rows}
    # Again: nothing runs (no new attempt anywhere), the table is the same.
    run_study(study, "-o", out, "--workers", "2")
    assert read_csv(out) == rows
    assert {run: (out / "runs" / run / "attempts.jsonl").read_text() for run in attempts} == attempts


def test_a_killed_worker_loses_no_run(tmp_path):
    study = study_file(tmp_path, f"""end_time = 0.8
figures = ["summary"]

[parameters]
"{SPEED}" = [0.05, 0.1, 0.15, 0.2]
""")
    out = tmp_path / "out"
    process = subprocess.Popen([sys.executable, "-m", "m3dp_study", str(study), "-o", str(out), "--workers", "2", "-q"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # The first run that starts: kill its worker (the process that runs Dask's task, not the run's own).
    deadline = time.time() + 120
    victim = None
    while victim is None and time.time() < deadline:
        for attempts in out.glob("runs/*/attempts.jsonl"):
            text = attempts.read_text().strip()
            if text:
                victim = (attempts.parent.name, json.loads(text.splitlines()[0])["pid"])
                break
        time.sleep(0.05)
    assert victim is not None, "no run started"
    os.kill(victim[1], signal.SIGKILL)
    stdout, stderr = process.communicate(timeout=600)
    assert process.returncode == 0, stderr
    rows = read_csv(out)
    assert len(rows) == 4 and {row["status"] for row in rows} == {"ok"}, rows
    retried = next(row for row in rows if row["run"] == victim[0])
    assert int(retried["attempts"]) == 2


def free_port():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_a_study_runs_on_a_dask_scheduler_and_worker_started_as_processes(tmp_path):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    environment = dict(os.environ)
    scheduler = subprocess.Popen(["dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=environment)
    worker = subprocess.Popen(["dask", "worker", address, "--nworkers", "1", "--nthreads", "1", "--no-dashboard", "--memory-limit", "0"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=environment)
    try:
        study = study_file(tmp_path, f"""end_time = 0.4
figures = ["summary"]

[parameters]
"{SPEED}" = [0.1, 0.2]
""")
        deadline = time.time() + 60
        while time.time() < deadline:  # the worker has joined
            probe = subprocess.run([sys.executable, "-c", f"from distributed import Client; c = Client('{address}', timeout='5s'); "
                                    "print(len(c.scheduler_info()['workers']))"], capture_output=True, text=True)
            if probe.stdout.strip() == "1":
                break
            time.sleep(0.5)
        run_study(study, "-o", tmp_path / "out", "--scheduler", address)
        rows = read_csv(tmp_path / "out")
        assert [row["status"] for row in rows] == ["ok", "ok"]
        assert {row["worker"] for row in rows} != {""} and all(row["worker"].startswith("tcp://127.0.0.1:") for row in rows)
    finally:
        for process in (worker, scheduler):
            process.terminate()
            process.wait(timeout=30)


@pytest.mark.parametrize("body, line, message", [
    (f'[parameters]\n"print_head[head].path.sped" = [0.1]\n', 4,
     "parameter 'print_head[head].path.sped' = 0.1: unknown element <sped> in <path>"),
    (f'[parameters]\n"{SPEED}" = [0.1]\n"{YIELD}" = [150, -5]\n', 5,
     f"parameter '{YIELD}' = -5: <yield_stress> must be"),
    (f'[parameters]\n"material[mortar].density" = [1000]\n', 4,
     "has no <material name=\"mortar\"> (its <material>: paste)"),
    (f'[sampling]\nmethod = "sobol"\nsamples = 0\n[parameters]\n"{YIELD}" = {{ from = 100, to = 200 }}\n', 5,
     "samples must be at least 1, got 0"),
    (f'end_tme = 1\n[parameters]\n"{YIELD}" = [100]\n', 3, "unknown key 'end_tme' in [study]; did you mean 'end_time'?"),
])
def test_a_bad_study_file_fails_before_any_run_at_its_line(tmp_path, body, line, message):
    study = study_file(tmp_path, body)
    process = run_study(study, "-o", tmp_path / "out", check=False)
    assert process.returncode == 2, process.stderr
    assert f"{study}:{line}: error: " in process.stderr, process.stderr
    assert message in process.stderr, process.stderr
    assert not (tmp_path / "out" / "runs").exists()


def test_an_unreachable_scheduler_fails_before_any_run(tmp_path):
    study = study_file(tmp_path, f'[parameters]\n"{SPEED}" = [0.1]\n')
    process = run_study(study, "-o", tmp_path / "out", "--scheduler", f"tcp://127.0.0.1:{free_port()}", check=False)
    assert process.returncode == 2
    assert "cannot reach the Dask scheduler at tcp://127.0.0.1:" in process.stderr
    assert not (tmp_path / "out" / "runs").exists()


def decode_rle(segmentation):
    """COCO's uncompressed RLE back to a mask (written here from the format's definition)."""
    import numpy as np
    height, width = segmentation["size"]
    flat = np.zeros(height * width, dtype=bool)
    position, value = 0, False
    for count in segmentation["counts"]:
        flat[position:position + count] = value
        position += count
        value = not value
    return flat.reshape((width, height)).T


def test_a_dataset_of_labelled_camera_frames(tmp_path):
    import numpy as np
    study = study_file(tmp_path, f"""end_time = 0.6
figures = ["summary"]

[parameters]
"{SPEED}" = [0.05, 0.2]

[dataset]
every = 0.3
""")
    out = tmp_path / "out"
    run_study(study, "-o", out, "--workers", "2", "--dataset")
    index = json.loads((out / "dataset" / "annotations.json").read_text())
    manifest = json.loads((out / "dataset" / "manifest.json").read_text())
    assert manifest["parameters"] == [SPEED] and len(manifest["runs"]) == 2
    assert len(index["images"]) == 4  # two runs, at 0.3 s and at the end
    categories = {entry["id"]: entry["name"] for entry in index["categories"]}
    for image in index["images"]:
        with Image.open(out / "dataset" / image["file_name"]) as picture:
            assert picture.mode == "RGB" and picture.size == (160, 120)
        with Image.open(out / "dataset" / image["segment_file"]) as picture:
            segments = np.array(picture)
        with Image.open(out / "dataset" / image["layer_file"]) as picture:
            layers = np.array(picture)
        with Image.open(out / "dataset" / image["depth_file"]) as picture:
            depth = np.array(picture) / 5000.0
        assert segments.shape == (120, 160)
        # Every id in the mask is in the legend; the layer mask is layer + 1 exactly where layered material is.
        legend = {int(key): value for key, value in image["legend"].items()}
        assert set(np.unique(segments).tolist()) <= set(legend)
        layered = [segment for segment, entry in legend.items() if "layer" in entry]
        assert layered, legend  # the strand is seen
        for segment in layered:
            assert (layers[segments == segment] == legend[segment]["layer"] + 1).all()
        assert (layers[~np.isin(segments, layered)] == 0).all()
        # The camera is 0.12 m above the bed, the strand about 1 cm high under it.
        strand = np.isin(segments, layered)
        assert 0.10 < np.median(depth[strand]) < 0.118
        # Each annotation's RLE is its segment's pixels.
        mine = [entry for entry in index["annotations"] if entry["image_id"] == image["id"]]
        assert {entry["segment_id"] for entry in mine} == {segment for segment in legend if legend[segment]["kind"] != "background"} & set(np.unique(segments).tolist())
        for entry in mine:
            mask = decode_rle(entry["segmentation"])
            assert (mask == (segments == entry["segment_id"])).all()
            assert entry["area"] == int(mask.sum())
            assert categories[entry["category_id"]] == legend[entry["segment_id"]]["kind"]
    # The slower nozzle lays a wider bead: more strand pixels in its last picture.
    last = {image["parameters"][SPEED]: image for image in index["images"] if image["time_s"] > 0.55}
    def strand_pixels(image):
        return sum(entry["area"] for entry in index["annotations"] if entry["image_id"] == image["id"] and "layer" in entry)
    assert strand_pixels(last[0.05]) > strand_pixels(last[0.2])


def test_the_m3dp_program_runs_a_study(tmp_path):
    import m3dp
    program = Path(m3dp.__file__).resolve().parent.parent / "apps" / "m3dp" / "m3dp"  # beside the module in the build tree
    study = study_file(tmp_path, f'end_time = 0.3\nfigures = ["summary"]\n[parameters]\n"{SPEED}" = [0.1, 0.2]\n')
    process = subprocess.run([str(program), "study", str(study), "-o", str(tmp_path / "out"), "--scheduler", "inprocess", "-q"],
                             capture_output=True, text=True, timeout=300)
    assert process.returncode == 0, process.stderr
    assert "m3dp study: 2 runs, 2 completed, 0 failed" in process.stdout
    assert [row["status"] for row in read_csv(tmp_path / "out")] == ["ok", "ok"]


def test_repeats_draw_the_cameras_noise_from_their_seeds(tmp_path):
    import numpy as np
    study = study_file(tmp_path, f"""end_time = 0.3
figures = ["summary"]
repeats = 2

[parameters]
"camera[top].noise.type" = ["gaussian"]
"camera[top].noise.stddev" = [0.05]

[dataset]
""")
    out = tmp_path / "out"
    run_study(study, "-o", out, "--scheduler", "inprocess")
    rows = read_csv(out)
    assert [row["seed"] for row in rows] == ["0", "1"] and rows[0]["run"] != rows[1]["run"]
    # The same material in both (the noise is only the camera's), other noise on its picture.
    assert rows[0]["summary.particles"] == rows[1]["summary.particles"]
    index = json.loads((out / "dataset" / "annotations.json").read_text())
    pictures = [np.array(Image.open(out / "dataset" / image["file_name"])) for image in index["images"]]
    masks = [np.array(Image.open(out / "dataset" / image["segment_file"])) for image in index["images"]]
    assert len(pictures) == 2 and (masks[0] == masks[1]).all() and (pictures[0] != pictures[1]).any()
    run = json.loads((out / "runs" / rows[1]["run"] / "run.json").read_text())
    assert run["overrides"]["camera[top].noise.seed"] == 1


EXAMPLE_STUDIES = ["strand_printability", "material_hypercube", "bead_width_study"]


@pytest.mark.parametrize("name", EXAMPLE_STUDIES)
def test_the_example_study_files_read_and_plan_every_run(name, tmp_path):
    """examples/*.toml (issue 58): each reads, and every run's scene, with its values, is one the
    scene reader accepts (what `m3dp study` checks before anything runs)."""
    from m3dp_study.spec import load_study
    from m3dp_study.study import plan_runs

    study = load_study(ROOT / "examples" / f"{name}.toml")
    runs = plan_runs(study, tmp_path)
    assert len(runs) == {"strand_printability": 16, "material_hypercube": 16, "bead_width_study": 9}[name]
    assert study.scene.is_file() and study.scene.parent == ROOT / "examples"


def test_the_strand_printability_example_runs_and_maps(tmp_path):
    """examples/strand_printability.toml as written, cut to its first 0.15 s: all 16 runs complete,
    and its printability maps are pictures PIL reads."""
    text = (ROOT / "examples" / "strand_printability.toml").read_text()
    text = text.replace('scene = "strand_sweep.sdf"', f'scene = "{ROOT / "examples" / "strand_sweep.sdf"}"\nend_time = 0.15')
    study = tmp_path / "strand_printability.toml"
    study.write_text(text)
    out = tmp_path / "out"
    run_study(study, "-o", out, "--workers", "2")
    rows = read_csv(out)
    assert len(rows) == 16 and all(row["status"] == "ok" for row in rows), [row["reason"] for row in rows]
    assert all(float(row["summary.volume_m3.laid"]) > 0 for row in rows)
    # Judged on what was laid by 0.15 s: the slowest strand's 7.5 mm is no bead yet (21 mm wide), and
    # its row says so instead of giving quality figures; the fastest's 30 mm is measured.
    slowest = [row for row in rows if row[SPEED] == "0.05"]
    assert all("quality not measured: head 'head' extrudes along" in row["reason"] for row in slowest), slowest[0]["reason"]
    assert all(float(row["quality.width_m"]) > 0 for row in rows if row[SPEED] == "0.2")
    for plot in ("map_status.png", "map_quality.width_m.png"):
        with Image.open(out / "plots" / plot) as image:
            assert image.size[0] > 100 and image.size[1] > 100
