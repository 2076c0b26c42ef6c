"""The study file (TOML): the base scene, the values to vary and how, what to collect. Everything in it
is checked before any run starts, and each problem names the file and line (TOML readers give no
positions, so lines are found in the text by the table and key they belong to)."""
from __future__ import annotations

import difflib
import hashlib
import itertools
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

FIGURE_KINDS = ("summary", "quality")
SAMPLING_METHODS = ("grid", "latin_hypercube", "sobol")
# The keys each table takes, with what they mean (docs/studies.md says more).
STUDY_KEYS = {
    "scene": "the SDF world every run starts from (relative to the study file)",
    "name": "the study's name (default: the file's)",
    "end_time": "simulated seconds a run lasts (default: the scene's <end_time>)",
    "threads": "threads a run uses (default 1); workers x threads stays within the cores",
    "repeats": "runs of each point, each with its own seed (default 1)",
    "seed": "the first repeat's seed (default 0)",
    "figures": "what each run reports: summary, quality (default both)",
    "quality_spacing": "m between the quality module's sections (default 0.005)",
    "record": "write each run's full outputs (frames, meshes) into its folder (default false)",
    "timeout": "s of wall time after which a run is stopped and failed (default 3600)",
    "plots": "the figures to plot against each parameter (default: every quality figure, or mass and wall time)",
}
SAMPLING_KEYS = ("method", "samples", "seed")
PARAMETER_TABLE_KEYS = ("from", "to", "steps", "scale")
CONTROLLER_KEYS = ("module", "function", "period")
DATASET_KEYS = ("every", "cameras")
# Parameters that are not scene values: the heads' flow scale (all heads, or one by name).
FLOW_SCALE = re.compile(r"^flow_scale(\[(?P<head>[^\]]+)\])?$")


class StudyError(Exception):
    """A problem in a study file, at its line: "file:line: error: what"."""

    def __init__(self, file, line: int, message: str):
        self.file, self.line, self.message = str(file), line, message
        super().__init__(f"{file}:{line}: error: {message}" if line else f"{file}: error: {message}")


@dataclass
class Parameter:
    name: str            # a scene path (material[mortar].rheology.yield_stress) or flow_scale[head]
    line: int
    values: list | None = None   # a list, or a range's grid
    low: float | None = None     # a range sampled by Latin hypercube or Sobol
    high: float | None = None
    log: bool = False

    @property
    def flow_scale_head(self) -> str | None:
        """For flow_scale parameters: the head's name ('' for every head); None for scene paths."""
        match = FLOW_SCALE.match(self.name)
        return None if match is None else (match.group("head") or "")


@dataclass
class Controller:
    module: str      # a Python file (relative to the study) or an importable module
    function: str
    period: float    # s of simulated time between calls
    line: int


@dataclass
class Study:
    file: Path
    text: str
    name: str
    scene: Path
    parameters: list[Parameter]
    end_time: float | None = None
    threads: int = 1
    repeats: int = 1
    seed: int = 0
    figures: tuple = FIGURE_KINDS
    quality_spacing: float = 0.005
    record: bool = False
    timeout: float = 3600
    plots: list[str] | None = None
    method: str = "grid"
    samples: int = 0
    sampling_seed: int = 0
    controller: Controller | None = None
    dataset: dict | None = None  # {"every": s or None, "cameras": [names] or None}: labelled camera frames
    points: list[dict] = field(default_factory=list)  # each point's {parameter: value}

    def line_of(self, parameter_name: str) -> int:
        for parameter in self.parameters:
            if parameter.name == parameter_name:
                return parameter.line
        return 0


def _line(text: str, table: str | None, key: str | None = None) -> int:
    """The line of `key` in `[table]` (1-based), or of the table's header; 0 when not found."""
    lines = text.splitlines()
    start, header_line = 0, 0
    if table is not None:
        header = re.compile(r"^\s*\[\s*" + re.escape(table) + r"\s*\]\s*(#.*)?$")
        for number, line in enumerate(lines):
            if header.match(line):
                start, header_line = number + 1, number + 1
                break
        else:
            return 0
    if key is None:
        return header_line
    pattern = re.compile(r"^\s*(\"" + re.escape(key) + r"\"|'" + re.escape(key) + r"'|" + re.escape(key) + r")\s*=")
    for number in range(start, len(lines)):
        if table is not None and re.match(r"^\s*\[", lines[number]):
            break  # the next table
        if pattern.match(lines[number]):
            return number + 1
    return header_line


def _unknown_keys(study_file, text, table, given, known):
    for key in given:
        if key not in known:
            close = difflib.get_close_matches(key, list(known), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else f" (expected one of: {', '.join(known)})"
            raise StudyError(study_file, _line(text, table, key), f"unknown key '{key}' in [{table}]{hint}")


def _number(study_file, line, where, value, *, integer=False, positive=False, at_least=None):
    kind = "a whole number" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (integer and not isinstance(value, int)):
        raise StudyError(study_file, line, f"{where} must be {kind}, got {value!r}")
    if not math.isfinite(value):
        raise StudyError(study_file, line, f"{where} must be finite, got {value!r}")
    if positive and not value > 0:
        raise StudyError(study_file, line, f"{where} must be > 0, got {value!r}")
    if at_least is not None and value < at_least:
        raise StudyError(study_file, line, f"{where} must be at least {at_least}, got {value!r}")
    return value


def load_study(path) -> Study:
    """Reads and checks a study file; raises StudyError (file:line: what) on the first problem."""
    study_file = Path(path)
    try:
        text = study_file.read_text()
    except OSError as problem:
        raise StudyError(study_file, 0, f"cannot read the study file: {problem.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as problem:
        found = re.search(r"\(at line (\d+)", str(problem))
        message = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(problem))
        raise StudyError(study_file, int(found.group(1)) if found else 0, f"not valid TOML: {message}") from None

    _unknown_keys(study_file, text, None, data.keys(), ("study", "parameters", "sampling", "controller", "dataset"))
    for table in ("study", "parameters", "sampling", "controller", "dataset"):
        if table in data and not isinstance(data[table], dict):
            raise StudyError(study_file, _line(text, None, table), f"'{table}' must be a table: [{table}]")
    settings = data.get("study")
    if settings is None:
        raise StudyError(study_file, 1, "missing [study] (its scene = \"...\" at least)")
    _unknown_keys(study_file, text, "study", settings.keys(), STUDY_KEYS)
    line = lambda key: _line(text, "study", key)  # noqa: E731

    if "scene" not in settings:
        raise StudyError(study_file, _line(text, "study"), "missing scene = \"...\" in [study] (the SDF world each run starts from)")
    if not isinstance(settings["scene"], str):
        raise StudyError(study_file, line("scene"), "scene must be a file name (text)")
    scene = (study_file.parent / settings["scene"]).resolve()
    if not scene.is_file():
        raise StudyError(study_file, line("scene"), f"scene '{settings['scene']}' not found (looked for {scene})")

    study = Study(file=study_file.resolve(), text=text, name=str(settings.get("name", study_file.stem)), scene=scene, parameters=[])
    if "end_time" in settings:
        study.end_time = float(_number(study_file, line("end_time"), "end_time", settings["end_time"], positive=True))
    if "threads" in settings:
        study.threads = _number(study_file, line("threads"), "threads", settings["threads"], integer=True, at_least=1)
        if study.threads > (os.cpu_count() or 1):
            raise StudyError(study_file, line("threads"), f"threads = {study.threads}: this machine has {os.cpu_count()} cores")
    if "repeats" in settings:
        study.repeats = _number(study_file, line("repeats"), "repeats", settings["repeats"], integer=True, at_least=1)
    if "seed" in settings:
        study.seed = _number(study_file, line("seed"), "seed", settings["seed"], integer=True, at_least=0)
    if "figures" in settings:
        figures = settings["figures"]
        if not isinstance(figures, list) or not all(isinstance(figure, str) for figure in figures):
            raise StudyError(study_file, line("figures"), "figures must be a list of names: [\"summary\", \"quality\"]")
        for figure in figures:
            if figure not in FIGURE_KINDS:
                raise StudyError(study_file, line("figures"), f"unknown figure '{figure}' (expected: {', '.join(FIGURE_KINDS)})")
        study.figures = tuple(figures)
    if "quality_spacing" in settings:
        study.quality_spacing = float(_number(study_file, line("quality_spacing"), "quality_spacing", settings["quality_spacing"], positive=True))
    if "record" in settings:
        if not isinstance(settings["record"], bool):
            raise StudyError(study_file, line("record"), "record must be true or false")
        study.record = settings["record"]
    if "timeout" in settings:
        study.timeout = float(_number(study_file, line("timeout"), "timeout", settings["timeout"], positive=True))
    if "plots" in settings:
        plots = settings["plots"]
        if not isinstance(plots, list) or not all(isinstance(name, str) for name in plots):
            raise StudyError(study_file, line("plots"), "plots must be a list of figure names: [\"quality.width_m\"]")
        study.plots = plots

    sampling = data.get("sampling", {})
    _unknown_keys(study_file, text, "sampling", sampling.keys(), SAMPLING_KEYS)
    if "method" in sampling:
        if sampling["method"] not in SAMPLING_METHODS:
            raise StudyError(study_file, _line(text, "sampling", "method"),
                             f"method = {sampling['method']!r} (expected one of: {', '.join(SAMPLING_METHODS)})")
        study.method = sampling["method"]
    if study.method != "grid":
        if "samples" not in sampling:
            raise StudyError(study_file, _line(text, "sampling"), f"method = \"{study.method}\" needs samples = N")
        study.samples = _number(study_file, _line(text, "sampling", "samples"), "samples", sampling["samples"], integer=True, at_least=1)
    elif "samples" in sampling:
        raise StudyError(study_file, _line(text, "sampling", "samples"), "samples is for method = \"latin_hypercube\" or \"sobol\"; a grid runs every point")
    if "seed" in sampling:
        study.sampling_seed = _number(study_file, _line(text, "sampling", "seed"), "seed", sampling["seed"], integer=True, at_least=0)

    parameters = data.get("parameters", {})
    if not parameters:
        raise StudyError(study_file, _line(text, "parameters") or 1, "no [parameters]: name at least one scene value to vary")
    for name, spec in parameters.items():
        parameter = Parameter(name=name, line=_line(text, "parameters", name))
        where = f"parameter '{name}'"
        if isinstance(spec, list):
            if not spec:
                raise StudyError(study_file, parameter.line, f"{where}: an empty list of values")
            for value in spec:
                if isinstance(value, (dict, list)):
                    raise StudyError(study_file, parameter.line, f"{where}: values are numbers, booleans or text, got {value!r}")
            parameter.values = list(spec)
        elif isinstance(spec, dict):
            _unknown_keys(study_file, text, "parameters", spec.keys(), PARAMETER_TABLE_KEYS)
            for key in ("from", "to"):
                if key not in spec:
                    raise StudyError(study_file, parameter.line, f"{where}: a range needs from = and to =")
            low = float(_number(study_file, parameter.line, f"{where}: from", spec["from"]))
            high = float(_number(study_file, parameter.line, f"{where}: to", spec["to"]))
            scale = spec.get("scale", "linear")
            if scale not in ("linear", "log"):
                raise StudyError(study_file, parameter.line, f"{where}: scale = {scale!r} (expected \"linear\" or \"log\")")
            if scale == "log" and not (low > 0 and high > 0):
                raise StudyError(study_file, parameter.line, f"{where}: a log scale needs from and to > 0")
            parameter.low, parameter.high, parameter.log = low, high, scale == "log"
            if study.method == "grid":
                if "steps" not in spec:
                    raise StudyError(study_file, parameter.line, f"{where}: a range on a grid needs steps = N (or give a list)")
                steps = _number(study_file, parameter.line, f"{where}: steps", spec["steps"], integer=True, at_least=1)
                parameter.values = _spaced(low, high, steps, parameter.log)
            elif "steps" in spec:
                raise StudyError(study_file, parameter.line, f"{where}: steps is for a grid; {study.method} draws samples = {study.samples}")
        else:
            raise StudyError(study_file, parameter.line, f"{where}: give a list of values or a range {{ from = a, to = b, steps = n }}")
        study.parameters.append(parameter)

    controller = data.get("controller")
    if controller is not None:
        _unknown_keys(study_file, text, "controller", controller.keys(), CONTROLLER_KEYS)
        for key in ("module", "function"):
            if not isinstance(controller.get(key), str):
                raise StudyError(study_file, _line(text, "controller", key) or _line(text, "controller"),
                                 f"[controller] needs {key} = \"...\" (text)")
        period = float(_number(study_file, _line(text, "controller", "period"), "period", controller.get("period", 0.1), positive=True))
        module = controller["module"]
        if module.endswith(".py"):
            module_path = (study_file.parent / module).resolve()
            if not module_path.is_file():
                raise StudyError(study_file, _line(text, "controller", "module"), f"controller module '{module}' not found (looked for {module_path})")
            module = str(module_path)
        study.controller = Controller(module, controller["function"], period, _line(text, "controller"))

    dataset = data.get("dataset")
    if dataset is not None:
        _unknown_keys(study_file, text, "dataset", dataset.keys(), DATASET_KEYS)
        every = None
        if "every" in dataset:
            every = float(_number(study_file, _line(text, "dataset", "every"), "every", dataset["every"], positive=True))
        cameras = dataset.get("cameras")
        if cameras is not None and (not isinstance(cameras, list) or not all(isinstance(name, str) for name in cameras) or not cameras):
            raise StudyError(study_file, _line(text, "dataset", "cameras"), "cameras must be a list of the scene's camera names")
        study.dataset = {"every": every, "cameras": cameras}

    study.points = _points(study)
    return study


def _spaced(low, high, steps, log):
    if steps == 1:
        return [low]
    if log:
        return [math.exp(math.log(low) + (math.log(high) - math.log(low)) * k / (steps - 1)) for k in range(steps)]
    return [low + (high - low) * k / (steps - 1) for k in range(steps)]


def _points(study: Study) -> list[dict]:
    """Every point of the study: the grid's product, or the samples drawn (SciPy's qmc, seeded)."""
    if study.method == "grid":
        names = [parameter.name for parameter in study.parameters]
        return [dict(zip(names, values)) for values in itertools.product(*(parameter.values for parameter in study.parameters))]
    from scipy.stats import qmc

    dimensions = len(study.parameters)
    if study.method == "latin_hypercube":
        unit = qmc.LatinHypercube(d=dimensions, seed=study.sampling_seed).random(study.samples)
    else:
        sampler = qmc.Sobol(d=dimensions, scramble=True, seed=study.sampling_seed)
        unit = sampler.random(study.samples)
    points = []
    for row in unit:
        point = {}
        for parameter, u in zip(study.parameters, row):
            if parameter.values is not None:  # a list: a sampled choice among its values
                point[parameter.name] = parameter.values[min(int(u * len(parameter.values)), len(parameter.values) - 1)]
            elif parameter.log:
                point[parameter.name] = math.exp(math.log(parameter.low) + u * (math.log(parameter.high) - math.log(parameter.low)))
            else:
                point[parameter.name] = parameter.low + u * (parameter.high - parameter.low)
        points.append(point)
    return points


def file_digest(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
