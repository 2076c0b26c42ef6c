"""A study's runs on Dask: planned and checked in full before any starts, each keyed by a hash of
what it reads (the resolved scene, its input files, the controller, the time and seed), run in its own
process on a worker, and collected into one table as they finish. A run whose folder already holds a
result is not run again; a run whose worker dies is run again on another (Dask's own retry)."""
from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from .spec import FLOW_SCALE, Study, StudyError, file_digest

STATUS_OK = "ok"


def _overrides_and_scales(point: dict):
    overrides, scales = {}, {}
    for name, value in point.items():
        match = FLOW_SCALE.match(name)
        if match:
            scales[match.group("head") or ""] = value
        else:
            overrides[name] = value
    return overrides, scales


def _reader_message(problem) -> str:
    """The scene reader's problems without its file:line prefixes (the study's line is the one that matters)."""
    lines = []
    for line in str(problem).splitlines():
        _, _, message = line.partition(" error: ")
        lines.append(message or line)
    return "; ".join(lines)


def plan_runs(study: Study, out_dir: Path) -> list[dict]:
    """Every run of the study, each checked by the scene reader with its values (so that a bad path or
    a value out of the scene's range fails here, at the study's line) and keyed by what it reads."""
    import m3dp

    try:
        base = m3dp.resolve_scene(str(study.scene))
    except m3dp.InputError as problem:
        raise StudyError(study.file, _scene_line(study), f"the scene does not load:\n{problem}") from None
    controller = None
    if study.controller is not None:
        controller = {"module": study.controller.module, "function": study.controller.function, "period": study.controller.period}
    controller_identity = dict(controller or {})
    if controller and controller["module"].endswith(".py"):
        controller_identity["module"] = file_digest(controller["module"])

    runs = []
    resolved_by_point = {}
    for point in study.points:
        overrides, scales = _overrides_and_scales(point)
        for head, scale in scales.items():
            name = f"flow_scale[{head}]" if head else "flow_scale"
            if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not scale > 0:
                raise StudyError(study.file, study.line_of(name), f"{name} = {scale!r}: a flow scale is a number > 0")
            if head and head not in base["heads"]:
                raise StudyError(study.file, study.line_of(name), f"{name}: the scene has no print head '{head}' (its heads: {', '.join(base['heads'])})")
        identity_key = json.dumps(overrides, sort_keys=True, default=str)
        if identity_key not in resolved_by_point:
            try:
                resolved_by_point[identity_key] = m3dp.resolve_scene(str(study.scene), overrides)
            except m3dp.InputError as problem:
                culprit = _culprit(m3dp, study, overrides)
                raise StudyError(study.file, study.line_of(culprit), f"parameter '{culprit}' = {overrides[culprit]!r}: {_reader_message(problem)}") from None
        point_resolved = resolved_by_point[identity_key]
        inputs = {path: file_digest(path) for path in point_resolved["input_files"]}
        end_time = study.end_time if study.end_time is not None else point_resolved["end_time"]
        # Repeats differ by their seed: the controller gets it, and the scene's noisy cameras draw their
        # noise from it (a seed the study varies itself is left to it).
        seeded = [path for path in point_resolved["noise_seeds"] if path not in overrides] if study.repeats > 1 or study.seed else []
        for repeat in range(study.repeats):
            seed = study.seed + repeat
            run_overrides, resolved = overrides, point_resolved
            if seeded:
                run_overrides = {**overrides, **{path: seed for path in seeded}}
                resolved = m3dp.resolve_scene(str(study.scene), run_overrides)
            identity = {"scene": resolved["text"], "scene_file": str(study.scene), "inputs": inputs, "flow_scales": scales,
                        "end_time": end_time, "seed": seed, "threads": study.threads, "figures": list(study.figures),
                        "quality_spacing": study.quality_spacing, "record": study.record, "controller": controller_identity,
                        "dataset": study.dataset}
            key = hashlib.sha256(json.dumps(identity, sort_keys=True, default=str).encode()).hexdigest()[:16]
            runs.append({
                "key": key,
                "folder": str(out_dir / "runs" / key),
                "parameters": point,
                "repeat": repeat,
                "seed": seed,
                "timeout": study.timeout,
                "spec": {"scene": str(study.scene), "overrides": run_overrides, "flow_scales": scales, "end_time": end_time, "seed": seed,
                         "threads": study.threads, "figures": list(study.figures), "quality_spacing": study.quality_spacing,
                         "record": study.record, "controller": controller, "parameters": point, "dataset": study.dataset},
            })
    return runs


def _scene_line(study: Study) -> int:
    from .spec import _line
    return _line(study.text, "study", "scene")


def _culprit(m3dp, study: Study, overrides: dict) -> str:
    """The parameter whose value the scene refuses: each tried alone, in the study's order."""
    for name, value in overrides.items():
        try:
            m3dp.resolve_scene(str(study.scene), {name: value})
        except m3dp.InputError:
            return name
    return next(iter(overrides))


def _worker_name() -> str:
    try:
        from distributed import get_worker
        return get_worker().address
    except (ImportError, ValueError):
        return f"local:{os.getpid()}"


def _row(run: dict, result: dict, wall_time: float, worker: str, attempts: int) -> dict:
    # A completed run whose print the quality report could not measure says why in its reason.
    reason = result.get("reason", "") or (f"quality not measured: {result['quality_note']}" if result.get("quality_note") else "")
    row = {"run": run["key"], "status": result.get("status", "failed"), "reason": reason}
    row.update(run["parameters"])
    row.update({"repeat": run["repeat"], "seed": run["seed"]})
    row.update(result.get("figures", {}))
    row.update({"wall_time_s": wall_time, "worker": worker, "attempts": attempts, "folder": run["folder"]})
    return row


def finished_row(run: dict) -> dict | None:
    """The row of a run whose folder holds its result (an earlier invocation's), else None."""
    folder = Path(run["folder"])
    try:
        result = json.loads((folder / "result.json").read_text())
        meta = json.loads((folder / "row.json").read_text())
    except (OSError, ValueError):
        return None
    return _row(run, result, meta.get("wall_time_s", 0.0), meta.get("worker", ""), meta.get("attempts", 1))


def _run_process(folder: Path, timeout: float, fork: bool = True):
    """Runs m3dp_study.run_one on `folder` in a process of its own, its output in run.log: forked from
    this one, which has M3DP and numpy loaded already (0.01 s against 0.3 s for a new interpreter),
    or started afresh where there is no fork or this process may have run M3DP's threads (TBB's are
    not fork-safe: a study run in process has read every scene). Returns (exit status or None, why
    it was stopped)."""
    parent = os.getpid()
    if not fork or not hasattr(os, "fork"):
        with open(folder / "run.log", "w") as log:
            process = subprocess.Popen([sys.executable, "-m", "m3dp_study.run_one", str(folder), str(parent)], stdout=log,
                                       stderr=subprocess.STDOUT)
            try:
                return process.wait(timeout=timeout), ""
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
                return None, f"timed out after {timeout:g} s of wall time"
    import m3dp  # noqa: F401  (loaded once a worker, inherited by each run's process)
    from . import run_one

    log = os.open(folder / "run.log", os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    child = os.fork()
    if child == 0:  # the run's process: never returns into the worker's code
        code = 1
        try:
            os.dup2(log, 1)
            os.dup2(log, 2)
            code = run_one.main(["run_one", str(folder), str(parent)])
        except BaseException:
            import traceback

            traceback.print_exc()
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
    os.close(log)
    deadline = time.time() + timeout
    pause = 0.001
    while True:
        done, status = os.waitpid(child, os.WNOHANG)
        if done:
            return os.waitstatus_to_exitcode(status), ""
        if time.time() > deadline:
            os.kill(child, signal.SIGKILL)
            os.waitpid(child, 0)
            return None, f"timed out after {timeout:g} s of wall time"
        time.sleep(pause)
        pause = min(0.02, pause * 2)


def execute(run: dict) -> dict:
    """One run, on a worker: its own process (python3 -m m3dp_study.run_one), its row back."""
    folder = Path(run["folder"])
    done = finished_row(run)
    if done is not None:
        return done
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "run.json").write_text(json.dumps(run["spec"], indent=1, default=float))
    worker = _worker_name()
    with open(folder / "attempts.jsonl", "a") as attempts_log:
        attempts_log.write(json.dumps({"worker": worker, "pid": os.getpid(), "started": time.time()}) + "\n")
    attempts = sum(1 for _ in open(folder / "attempts.jsonl"))
    started = time.time()
    code, reason = _run_process(folder, run["timeout"], fork=run.get("fork", True))
    wall_time = time.time() - started
    result_file = folder / "result.json"
    if not result_file.exists():
        if not reason:
            died = f"signal {signal.Signals(-code).name}" if code is not None and code < 0 else f"exit code {code}"
            tail = (folder / "run.log").read_text(errors="replace").strip().splitlines()[-3:]
            reason = f"the run's process died ({died})" + (f": {' | '.join(tail)}" if tail else "")
        result_file.write_text(json.dumps({"status": "failed", "reason": reason, "figures": {}}))
    result = json.loads(result_file.read_text())
    (folder / "row.json").write_text(json.dumps({"wall_time_s": wall_time, "worker": worker, "attempts": attempts}))
    return _row(run, result, wall_time, worker, attempts)


def _client(scheduler: str | None, workers: int | None, threads: int):
    """A Dask client: a local cluster of processes sized to the machine (workers x threads <= cores),
    or the scheduler at `scheduler` (tcp://host:8786)."""
    from distributed import Client, LocalCluster

    if scheduler in (None, "local"):
        cores = os.cpu_count() or 1
        count = workers or max(1, cores // threads)
        if count * threads > cores:
            raise StudyError("--workers", 0, f"{count} workers x {threads} threads a run is more than this machine's {cores} cores")
        cluster = LocalCluster(n_workers=count, threads_per_worker=1, processes=True, dashboard_address=None, memory_limit=0)
        return Client(cluster), cluster, count
    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as problem:
        raise StudyError("--scheduler", 0, f"cannot reach the Dask scheduler at {scheduler}: {problem}") from None
    slots = sum(info.get("nthreads", 1) for info in client.scheduler_info().get("workers", {}).values())
    return client, None, max(1, slots)


class _Progress:
    """Runs done, running, failed and the ETA, on one line (tqdm's bar)."""

    def __init__(self, total: int, already: int, slots: int, enabled: bool):
        from tqdm import tqdm

        self.slots, self.failed = slots, 0
        self.bar = tqdm(total=total, initial=already, unit="run", desc="study", disable=not enabled, dynamic_ncols=True,
                        file=sys.stderr, smoothing=0)
        self._update_running()

    def _update_running(self):
        remaining = self.bar.total - self.bar.n
        self.bar.set_postfix_str(f"running {min(self.slots, remaining)}, failed {self.failed}", refresh=True)

    def done(self, row: dict):
        if row["status"] != STATUS_OK:
            self.failed += 1
        self.bar.update(1)
        self._update_running()

    def close(self):
        self.bar.close()


def run_study(study: Study, out_dir, scheduler: str | None = None, workers: int | None = None, progress: bool = True,
              rerun_failed: bool = False) -> list[dict]:
    """Runs every run of `study` not already in `out_dir` and writes the table and plots. `scheduler`:
    None or "local" (a local Dask cluster), "inprocess" (one after another in this process, no
    Dask), or a Dask scheduler's address. Returns the rows in the study's order."""
    from .report import write_results

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    runs = plan_runs(study, out)
    rows: dict[str, dict] = {}
    for run in runs:
        row = finished_row(run)
        if row is not None and (row["status"] == STATUS_OK or not rerun_failed):
            rows[run["key"]] = row
        elif row is not None:
            for name in ("result.json", "row.json"):
                (Path(run["folder"]) / name).unlink(missing_ok=True)
    pending = [run for run in runs if run["key"] not in rows]
    written = time.time()  # when the table was last written while runs finish
    (out / "study.toml").write_text(study.text)

    if pending and scheduler == "inprocess":
        bar = _Progress(len(runs), len(rows), 1, progress)
        for run in pending:
            run["fork"] = False
            rows[run["key"]] = execute(run)
            bar.done(rows[run["key"]])
            if time.time() - written > 5:
                write_results(out, study, [rows[r["key"]] for r in runs if r["key"] in rows], plots=False)
                written = time.time()
        bar.close()
    elif pending:
        from distributed import as_completed

        client, cluster, slots = _client(scheduler, workers, study.threads)
        try:
            bar = _Progress(len(runs), len(rows), slots, progress)
            futures = {client.submit(execute, run, key=f"m3dp-run-{run['key']}", pure=False): run for run in pending}
            for future in as_completed(futures):
                run = futures[future]
                try:
                    row = future.result()
                except Exception as problem:  # the worker died each time it ran it (KilledWorker), or could not run it
                    row = _row(run, {"status": "failed", "reason": f"{type(problem).__name__}: {problem}"}, 0.0, "", 0)
                rows[run["key"]] = row
                bar.done(row)
                if time.time() - written > 5:  # the table so far, for a look while the study runs
                    write_results(out, study, [rows[r["key"]] for r in runs if r["key"] in rows], plots=False)
                    written = time.time()
            bar.close()
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    ordered = [rows[run["key"]] for run in runs]
    write_results(out, study, ordered, plots=True)
    if study.dataset is not None:
        from .dataset import write_dataset

        write_dataset(out, study, runs, ordered)
    return ordered


def remake_report(study: Study, out_dir) -> list[dict]:
    """The plots again from results.csv alone (m3dp study FILE -o DIR --report)."""
    from .report import read_results, write_plots

    rows = read_results(Path(out_dir))
    write_plots(Path(out_dir), study, rows)
    return rows
