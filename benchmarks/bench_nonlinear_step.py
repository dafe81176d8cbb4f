"""The fused generalized-alpha step (``mechanisms/_alpha_kernel.py``, the Newton iteration of a step in one
numba call) against the Python iteration it replaced (``_Stepper._newton``, a chain of calls into the
model's methods), side by side in one process, interleaved, on the workloads it serves (issues 20 and 24):

- ``simulate``: ``four_bar_fem4`` at 100 rad/s over ``--revolutions`` revolutions at the run-up's step
  (``bench_run_up.py``'s: 64 steps a revolution at 150 rad/s, dt = 0.654 ms), no error estimate;
- ``simulate``: the six-bar with 8 elements per elastic link at 100 rad/s, 256 steps a revolution, the
  full element model (48 coordinates) and both links reduced to 4 modes (18 coordinates);
- ``nonlinear_steady_state`` of that six-bar with its defaults (the issue 24 case).

Each workload is run once before the clocks (JIT compilation). The machine is shared: medians of
``--repeats`` rounds, ratios python / fused; the load average is printed.

Usage: ``.venv/bin/python benchmarks/bench_nonlinear_step.py [--repeats 3] [--revolutions 50]``
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time

import mechanisms
import studies
from mechanisms import _alpha_step  # the switch between the two iterations: no public face

SIX_BAR_PATHS = ("links.link2.discretisation.n_elements", "links.link4.discretisation.n_elements")


def workloads(revolutions: int):
    """{name: callable returning a dict of counts} of the timed workloads."""
    four_bar = mechanisms.load("four_bar_fem4")
    dt = 2.0 * math.pi / 150.0 / 64.0   # the run-up's step: 64 steps a revolution at its top speed
    problem = studies.MechanismProblem.from_scene("six_bar", parameter_paths=SIX_BAR_PATHS)
    values = {"speed": 100.0, **{path: 8 for path in SIX_BAR_PATHS}}
    six_full = problem.mechanism({path: 8 for path in SIX_BAR_PATHS})
    six_reduced = six_full
    for path in SIX_BAR_PATHS:
        six_reduced = six_reduced.with_parameter(path.replace("n_elements", "modes"), 4)

    def run(system, **options):
        def go():
            result = mechanisms.simulate(system, estimate_error=False, **options)
            return {"steps": result.n_steps, "newton": result.n_newton}
        return go

    def steady():
        result = studies.nonlinear_steady_state(problem, values)
        return {"status": result.status, "map_calls": result.map_calls}

    return {
        f"simulate four_bar_fem4, {revolutions} rev, dt {dt * 1e3:.3f} ms": run(
            four_bar, t_end=revolutions * 2.0 * math.pi / 100.0, dt=dt),
        "simulate six_bar 8 el. full (48 coords), 5 rev x 256": run(six_full, n_periods=5, steps_per_period=256),
        "simulate six_bar 8 el. 4 modes (18 coords), 5 rev x 256": run(six_reduced, n_periods=5,
                                                                        steps_per_period=256),
        "nonlinear_steady_state six_bar 8 el., defaults": steady,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--revolutions", type=int, default=50)
    args = parser.parse_args()
    jobs = workloads(args.revolutions)
    for fused in (True, False):             # JIT compilation outside the clocks
        _alpha_step.FUSED_STEP = fused
        for job in jobs.values():
            job()
    times = {name: {True: [], False: []} for name in jobs}
    counts = {}
    for _ in range(args.repeats):
        for name, job in jobs.items():
            for fused in (True, False):
                _alpha_step.FUSED_STEP = fused
                started = time.perf_counter()
                counts[name, fused] = job()
                times[name][fused].append(time.perf_counter() - started)
    _alpha_step.FUSED_STEP = True
    print(f"load average {os.getloadavg()[0]:.1f} (2 cores, shared); medians of {args.repeats} rounds")
    for name in jobs:
        fused, python = (statistics.median(times[name][flag]) for flag in (True, False))
        print(f"{name}: fused {fused:.3f} s, python {python:.3f} s, ratio {python / fused:.2f}; "
              f"{counts[name, True]} (python: {counts[name, False]})")


if __name__ == "__main__":
    main()
