#!/usr/bin/env python3
"""What stepping from Python costs: the demo (scenes/ur10_wall.sdf, its outputs and recording) run by
`m3dp run` and by a Python loop of sim.step() with the same outputs, in alternating pairs; prints
each pair's wall times and their ratio. Usage: PYTHONPATH=build/python python3 bench/python_step.py [PAIRS] [UNTIL]"""
import pathlib
import subprocess
import sys
import tempfile
import time

import m3dp

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENE = ROOT / "scenes" / "ur10_wall.sdf"
M3DP = ROOT / "build" / "apps" / "m3dp" / "m3dp"


def cli(folder, until):
    start = time.perf_counter()
    subprocess.run([str(M3DP), "run", str(SCENE), "-o", str(folder), "--until", str(until), "--threads", "2", "--quiet"],
                   check=True, capture_output=True)
    return time.perf_counter() - start


def python(folder, until):
    start = time.perf_counter()
    sim = m3dp.Simulation(SCENE, threads=2)
    sim.record(folder)
    while sim.time < until - 1e-12:
        sim.step()
    sim.close()
    return time.perf_counter() - start


def main():
    pairs = int(sys.argv[1]) if len(sys.argv) > 1 else 3
    until = float(sys.argv[2]) if len(sys.argv) > 2 else 31.0
    with tempfile.TemporaryDirectory() as folder:
        for pair in range(pairs):
            c = cli(pathlib.Path(folder) / f"cli{pair}", until)
            p = python(pathlib.Path(folder) / f"python{pair}", until)
            print(f"pair {pair + 1}: m3dp run {c:.2f} s, Python step() loop {p:.2f} s, ratio {p / c:.3f}", flush=True)


if __name__ == "__main__":
    main()
