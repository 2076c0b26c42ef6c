#!/usr/bin/env python3
"""What a study costs beyond its simulations (issue 40): RUNS short runs of tests/data/strand_study.sdf
(each a different travel speed, END_TIME s simulated, one thread a run) simulated one after another
in one process (the simulations alone), then as a study on a local Dask cluster of 1 and of 2
workers (cluster start, each run's own process, its files and the table included). Prints each wall
time, a study's cost a run beyond the simulation (the slope from RUNS/2 to RUNS runs) and its fixed
cost, and the speed-up from 1 to 2 workers. Usage: PYTHONPATH=build/python /usr/bin/python3 bench/study_overhead.py [RUNS] [END_TIME]"""
import pathlib
import subprocess
import sys
import tempfile
import time

import m3dp

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENE = ROOT / "tests" / "data" / "strand_study.sdf"


def speeds(runs):
    return [round(0.05 + 0.15 * k / max(1, runs - 1), 6) for k in range(runs)]


def bare_loop(runs, end_time):
    start = time.perf_counter()
    for speed in speeds(runs):
        simulation = m3dp.Simulation(SCENE, threads=1, overrides={"print_head[head].path.speed": speed})
        simulation.step_to(end_time)
        simulation.quality(0.005)
        simulation.close()
    return time.perf_counter() - start


def study(folder, runs, end_time, workers):
    folder.mkdir()
    study_file = folder / "study.toml"
    study_file.write_text(f'[study]\nscene = "{SCENE}"\nend_time = {end_time}\nfigures = ["summary", "quality"]\n\n'
                          f'[parameters]\n"print_head[head].path.speed" = {speeds(runs)}\n')
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "m3dp_study", str(study_file), "-o", str(folder / "out"), "--workers", str(workers), "-q"],
                   check=True, capture_output=True)
    return time.perf_counter() - start


def main():
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 32
    end_time = float(sys.argv[2]) if len(sys.argv) > 2 else 0.3
    half = runs // 2
    with tempfile.TemporaryDirectory() as scratch:
        folder = pathlib.Path(scratch)
        bare = bare_loop(runs, end_time)
        one_half = study(folder / "one_half", half, end_time, 1)
        one = study(folder / "one", runs, end_time, 1)
        two = study(folder / "two", runs, end_time, 2)
    # A study's cost is a fixed part (the cluster's start, planning, the plots) and a part a run: the
    # latter is the slope between the half and the whole study, less the simulation's own time.
    per_run = (one - one_half) / (runs - half)
    overhead = per_run - bare / runs
    fixed = one - runs * per_run
    print(f"{runs} runs of {end_time} s simulated (strand_study.sdf, 1 thread a run):")
    print(f"  one after another in one process: {bare:7.2f} s ({bare / runs:.3f} s a run)")
    print(f"  study, 1 worker, {half:3d} runs:        {one_half:7.2f} s")
    print(f"  study, 1 worker, {runs:3d} runs:        {one:7.2f} s: {overhead:.3f} s a run beyond its simulation, "
          f"{fixed:.2f} s fixed (cluster start, planning, table, plots)")
    print(f"  study, 2 workers, {runs:3d} runs:       {two:7.2f} s: {one / two:.2f}x the speed of 1 worker, "
          f"{(one - fixed) / max(1e-9, two - fixed):.2f}x on the runs alone")


if __name__ == "__main__":
    main()
