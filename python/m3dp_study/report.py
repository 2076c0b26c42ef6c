"""A study's table and plots: results.csv (one row a run), results.h5 (the same columns, HDF5 through
h5py), and plots/ (each figure against each parameter; for two parameters, a map over both)."""
from __future__ import annotations

import csv
import math
import os
from pathlib import Path

from .spec import Study

FIXED_FIRST = ("run", "status", "reason")
FIXED_LAST = ("wall_time_s", "worker", "attempts", "folder")


def _columns(study: Study, rows: list[dict]) -> list[str]:
    parameters = [parameter.name for parameter in study.parameters]
    figures = sorted({key for row in rows for key in row} - set(FIXED_FIRST) - set(FIXED_LAST) - set(parameters) - {"repeat", "seed"})
    return list(FIXED_FIRST) + parameters + ["repeat", "seed"] + figures + list(FIXED_LAST)


def _replace(path: Path, write):
    partial = path.with_name(path.name + f".{os.getpid()}.part")
    write(partial)
    os.replace(partial, path)


def write_results(out: Path, study: Study, rows: list[dict], plots: bool):
    columns = _columns(study, rows)

    def write_csv(path):
        with open(path, "w", newline="") as stream:
            writer = csv.DictWriter(stream, fieldnames=columns, restval="")
            writer.writeheader()
            for row in rows:
                writer.writerow({key: row.get(key, "") for key in columns})

    _replace(out / "results.csv", write_csv)
    _replace(out / "results.h5", lambda path: _write_hdf5(path, study, columns, rows))
    if plots:
        write_plots(out, study, rows)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _write_hdf5(path: Path, study: Study, columns: list[str], rows: list[dict]):
    import h5py
    import numpy as np

    with h5py.File(path, "w") as file:
        group = file.create_group("runs")
        group.attrs["study"] = str(study.file)
        group.attrs["parameters"] = [parameter.name for parameter in study.parameters]
        group.attrs["columns"] = columns
        for column in columns:
            values = [row.get(column) for row in rows]
            if all(value is None or _is_number(value) for value in values):
                data = np.array([math.nan if value is None else float(value) for value in values], dtype=np.float64)
                group.create_dataset(column, data=data)
            else:
                group.create_dataset(column, data=["" if value is None else str(value) for value in values], dtype=h5py.string_dtype())


def read_results(out: Path) -> list[dict]:
    """results.csv's rows, numbers as numbers."""
    rows = []
    with open(out / "results.csv", newline="") as stream:
        for raw in csv.DictReader(stream):
            row = {}
            for key, text in raw.items():
                try:
                    row[key] = int(text) if text.lstrip("-").isdigit() else float(text)
                except ValueError:
                    row[key] = text
            rows.append(row)
    return rows


def _plotted_figures(study: Study, rows: list[dict]) -> list[str]:
    if study.plots:
        return study.plots
    numeric = sorted({key for row in rows if row.get("status") == "ok" for key, value in row.items()
                      if _is_number(value) and "." in key and math.isfinite(value)})
    quality = [name for name in numeric if name.startswith("quality.") and not name.endswith(".layers")]
    return quality or [name for name in ("summary.mass_final_kg", "summary.volume_m3.emitted") if name in numeric]


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)


def write_plots(out: Path, study: Study, rows: list[dict]):
    """plots/FIGURE_vs_PARAMETER.png for each figure and parameter of numbers; with two parameters
    also plots/map_FIGURE.png (the figure's colour over both) and plots/map_status.png (which runs
    failed: a printability map)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder = out / "plots"
    folder.mkdir(exist_ok=True)
    numeric_parameters = [parameter.name for parameter in study.parameters if all(_is_number(row.get(parameter.name)) for row in rows)]
    ok = [row for row in rows if row.get("status") == "ok"]
    failed = [row for row in rows if row.get("status") != "ok"]
    figures = _plotted_figures(study, rows)
    for figure in figures:
        for parameter in numeric_parameters:
            axes = plt.figure(figsize=(5, 3.6)).gca()
            points = [(row[parameter], row[figure]) for row in ok if _is_number(row.get(figure))]
            axes.plot([p for p, _ in points], [v for _, v in points], "o", color="tab:blue", label="run")
            if failed:
                low = min((v for _, v in points), default=0)
                axes.plot([row[parameter] for row in failed], [low] * len(failed), "x", color="tab:red", label="failed")
                axes.legend()
            axes.set_xlabel(parameter)
            axes.set_ylabel(figure)
            axes.set_title(f"{study.name}: {figure}", fontsize=9)
            axes.grid(alpha=0.3)
            plt.tight_layout()
            plt.savefig(folder / f"{_safe(figure)}_vs_{_safe(parameter)}.png", dpi=110)
            plt.close()
    if len(numeric_parameters) == 2:
        x_name, y_name = numeric_parameters
        for figure in figures:
            points = [(row[x_name], row[y_name], row[figure]) for row in ok if _is_number(row.get(figure))]
            if not points:
                continue
            axes = plt.figure(figsize=(5.4, 4)).gca()
            shown = axes.scatter([p[0] for p in points], [p[1] for p in points], c=[p[2] for p in points], s=120, cmap="viridis")
            plt.colorbar(shown, label=figure)
            if failed:
                axes.plot([row[x_name] for row in failed], [row[y_name] for row in failed], "x", color="tab:red", ms=10, label="failed")
                axes.legend()
            axes.set_xlabel(x_name)
            axes.set_ylabel(y_name)
            axes.set_title(f"{study.name}: {figure}", fontsize=9)
            plt.tight_layout()
            plt.savefig(folder / f"map_{_safe(figure)}.png", dpi=110)
            plt.close()
        axes = plt.figure(figsize=(5.4, 4)).gca()
        for group, marker, colour, label in ((ok, "o", "tab:green", "completed"), (failed, "x", "tab:red", "failed")):
            if group:
                axes.plot([row[x_name] for row in group], [row[y_name] for row in group], marker, color=colour, ms=10, label=label)
        axes.set_xlabel(x_name)
        axes.set_ylabel(y_name)
        axes.legend()
        axes.set_title(f"{study.name}: which runs completed", fontsize=9)
        plt.tight_layout()
        plt.savefig(folder / "map_status.png", dpi=110)
        plt.close()
