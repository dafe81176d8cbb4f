"""Calibration of the resource guard's cost models (studies/_cost.py) against real runs.

For the thesis four-bar with 1 to 32 Hermite elements on the coupler (12 to 105 coordinates) and 64
to 512 steps, each study kind is run small (a few grid points, 2 nonlinear periods) in this process
with tracemalloc on, and its peak traced memory (numpy's arrays included) and wall time are printed
next to the guard's estimate for the same options, as ratios measured / estimated. Times are medians
of ``--repeats`` runs with a warm JIT cache and fresh speed-family caches. The guard is meant to be
good to a factor of a few and on the safe side: ratios between about 0.3 and 1.5 are fine; if a
machine gives ratios far outside, scale the constants in studies/_cost.py.

Run: .venv/bin/python benchmarks/bench_guard.py [--quick] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time
import tracemalloc

import numpy as np

import mechanisms
from studies import _mechanism, estimate, kinds
from studies._mechanism import MechanismProblem

SCENE = "four_bar_fem4"
ELEMENTS = "links.coupler.discretisation.n_elements"


def options(kind: str, n_steps: int) -> dict:
    tables = {
        "steady_state": {"n_steps": n_steps},
        "sweep": {"values": [80.0, 90.0, 100.0, 110.0], "n_steps": n_steps},
        "campbell": {"values": [80.0, 90.0, 100.0, 110.0], "n_steps": n_steps, "frozen_samples": 32},
        "nonlinear_check": {"n_periods": 2, "n_steps": n_steps},
    }
    checked = kinds()[kind].check(f"studies.{kind}", tables[kind], n_steps)
    return next(iter(kinds()[kind].runs(checked).values()))  # the one run the table declares


def measure(problem, kind: str, checked: dict) -> tuple[float, float]:
    """(peak traced bytes, seconds) of one run, with the speed-family cache emptied first."""
    _mechanism._families.clear()
    tracemalloc.start()
    start = time.perf_counter()
    kinds()[kind].run(problem, checked, out=None, executor=None, progress=False)
    seconds = time.perf_counter() - start
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return float(peak), seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer sizes")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    sizes = [(1, 64), (4, 256), (16, 256)] if args.quick else [(1, 64), (4, 256), (16, 256), (16, 512),
                                                              (32, 256)]
    print(f"{'kind':16s} {'elements':>8s} {'coords':>6s} {'steps':>5s}  {'memory meas/est':>22s}  "
          f"{'time meas/est':>22s}")
    for n_elements, n_steps in sizes:
        mechanism = mechanisms.load(SCENE).with_parameter(ELEMENTS, n_elements)
        problem = MechanismProblem.from_mechanism(mechanism)
        n = mechanisms.assemble(mechanism).n_coords
        for kind in ("steady_state", "sweep", "campbell", "nonlinear_check"):
            checked = options(kind, n_steps)
            guess = estimate(problem, kind, checked)
            measure(problem, kind, checked)  # warm the JIT
            runs = [measure(problem, kind, checked) for _ in range(args.repeats)]
            memory = statistics.median(r[0] for r in runs)
            seconds = statistics.median(r[1] for r in runs)
            print(f"{kind:16s} {n_elements:8d} {n:6d} {n_steps:5d}  "
                  f"{memory / 1e6:7.1f}/{guess.memory / 1e6:7.1f} MB {memory / guess.memory:5.2f}  "
                  f"{seconds:7.3f}/{guess.time:7.3f} s {seconds / guess.time:5.2f}", flush=True)


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
