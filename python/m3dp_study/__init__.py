"""Studies of many M3DP runs (issue 40): parameter sweeps and samples of a scene's values, run on a
Dask cluster (a local one sized to the machine by default, or an existing one), with a table of
every run's figures (results.csv, results.h5), plots, and runs that resume where they stopped.

The study file is TOML (see docs/studies.md); `m3dp study FILE -o DIR` runs it, or from Python:

    from m3dp_study import load_study, run_study
    run_study(load_study("sweep.toml"), "out/sweep")
"""
from .spec import Study, StudyError, load_study
from .study import run_study, remake_report

__all__ = ["Study", "StudyError", "load_study", "run_study", "remake_report"]
