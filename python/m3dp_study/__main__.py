"""m3dp study FILE -o DIR [--scheduler ADDRESS] [--workers N] [--report] [--rerun-failed] [-q]
(also python3 -m m3dp_study ...)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .spec import StudyError, load_study


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="m3dp study", description="Run a study of many M3DP runs (a TOML file; docs/studies.md) on Dask.")
    parser.add_argument("file", help="the study file (TOML)")
    parser.add_argument("-o", "--output", required=True, help="the study's folder: results.csv, results.h5, plots/, runs/")
    parser.add_argument("--scheduler", default=None,
                        help="a Dask scheduler's address (tcp://host:8786) to run on an existing cluster; 'inprocess' runs one "
                             "after another here, without Dask; default a local cluster sized to this machine")
    parser.add_argument("--workers", type=int, default=None, help="workers of the local cluster (default: cores / threads a run)")
    parser.add_argument("--report", action="store_true", help="remake the plots from results.csv alone; runs nothing")
    parser.add_argument("--rerun-failed", action="store_true", help="run again the runs that failed before (finished ones are skipped)")
    parser.add_argument("--dataset", action="store_true",
                        help="write each run's camera frames with per-pixel labels into DIR/dataset (COCO-style annotations.json); "
                             "the study file's [dataset] table says when and which cameras (default: every camera at the end)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    arguments = parser.parse_args(argv)
    try:
        study = load_study(arguments.file)
        if arguments.dataset and study.dataset is None:
            study.dataset = {"every": None, "cameras": None}
        if arguments.report:
            from .study import remake_report

            if not (Path(arguments.output) / "results.csv").exists():
                raise StudyError(arguments.output, 0, "no results.csv here: run the study first")
            rows = remake_report(study, arguments.output)
            print(f"m3dp study: plots of {len(rows)} runs in {Path(arguments.output) / 'plots'}")
            return 0
        if arguments.workers is not None and arguments.workers < 1:
            raise StudyError("--workers", 0, f"--workers {arguments.workers}: at least 1")
        from .study import STATUS_OK, run_study

        rows = run_study(study, arguments.output, scheduler=arguments.scheduler, workers=arguments.workers, progress=not arguments.quiet,
                         rerun_failed=arguments.rerun_failed)
    except StudyError as problem:
        print(problem, file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("m3dp study: interrupted; finished runs are kept, and the same command goes on from them", file=sys.stderr)
        return 130
    failed = [row for row in rows if row["status"] != STATUS_OK]
    print(f"m3dp study: {len(rows)} runs, {len(rows) - len(failed)} completed, {len(failed)} failed; "
          f"{Path(arguments.output) / 'results.csv'}")
    for row in failed[:10]:
        print(f"  failed {row['run']}: {row['reason']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
