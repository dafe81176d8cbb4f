"""What the crash-safe result file costs a grid: a Mathieu speed sweep written point by point into a
plain h5py file (flushed at each point: the write strategy before ``ResultFile``), through
``studies.ResultFile`` (a copy and an atomic rename every ``COMMIT_INTERVAL`` seconds, and at
the end), through a ``ResultFile`` that commits after every point (the worst case), and into no file.
Medians of repeated runs in this process, side by side; ratios against the plain file.

Run: .venv/bin/python benchmarks/bench_result_file.py [--quick]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import studies  # noqa: E402
from studies import ResultFile  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer points and repeats")
    args = parser.parse_args()
    count, repeats = (40, 3) if args.quick else (200, 5)
    problem = studies.mathieu_problem(epsilon=0.3, damping_ratio=0.05)
    speeds = np.linspace(0.3, 2.4, count)
    folder = Path(tempfile.mkdtemp())

    def sweep(out=None):
        studies.sweep(problem, "speed", speeds, n_steps=64, out=out)

    def plain(run):
        path = folder / f"plain{run}.h5"
        with studies.open_file(path) as handle:
            sweep(handle)

    def result_file(run, interval=None):
        path = folder / f"safe{interval}{run}.h5"
        options = {} if interval is None else {"commit_interval": interval}
        with ResultFile(path, scene={"bench": 1}, **options) as file:
            sweep(file.handle)

    ways = {"no file": lambda run: sweep(), "plain h5py, flush per point": plain,
            "ResultFile (commit every few s)": result_file,
            "ResultFile (commit every point)": lambda run: result_file(run, 0.0)}
    sweep()  # warm the kernels
    times = {name: [] for name in ways}
    for run in range(repeats):
        for name, way in ways.items():  # interleaved: the machine's load falls on all alike
            start = time.perf_counter()
            way(run)
            times[name].append(time.perf_counter() - start)
    baseline = statistics.median(times["plain h5py, flush per point"])
    print(f"Mathieu sweep, {count} points, n_steps 64; median of {repeats} runs")
    for name, values in times.items():
        median = statistics.median(values)
        print(f"  {name:34s} {median:8.3f} s   {median / baseline:5.2f} x plain file")


if __name__ == "__main__":
    main()
