"""Speed of a stability chart of the 3-RRR parallel robot (parallel_robot), issue 14's target: a
100 x 100 chart (speed x payload mass) in at most 120 s on 2 processes.

1. The chart on a 2-process pool: speed 20..400 rad/s x payload 0.1..2 kg, 32 steps per period (the
   charts' minimum; the loss of stability lies above 160 rad/s, where 32 steps resolve the first
   elastic mode at h omega_1 < 0.21). A smaller grid of the same ranges is timed and scaled to
   100 x 100 cells by the cell count (the cells cost alike); ``--full`` runs the 100 x 100 itself.
   Side by side, the same grid of the thesis four-bar (four_bar_fem4, speed x coupler thickness),
   whose constant-rate crank lets each process linearise once per thickness (``speed_family``).
2. Where a robot cell's time goes, in-process: the nominal motion (``mechanisms.nominal_motion``),
   the rest of the linearisation (``linearize.about`` minus the nominal motion) and the Floquet
   multipliers with their N/2 error estimate (``periodic.floquet``), the work of one chart cell.

All times are medians of repeated runs with a warm JIT cache. Run:
    .venv/bin/python benchmarks/bench_parallel_robot.py [--quick] [--full]
"""

from __future__ import annotations

import argparse
import logging
import math
import statistics
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

import linearize
import mechanisms
import periodic
import studies

N_STEPS = 32
TARGET_CELLS, TARGET_SECONDS = 100 * 100, 120.0
CHARTS = {  # scene: (second parameter, its range)
    "parallel_robot": ("point_masses.payload.mass", (0.1, 2.0)),
    "four_bar_fem4": ("links.coupler.thickness", (1.2e-3, 2.4e-3)),
}


def median_time(func, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def chart_time(scene, n_speeds, n_values, pool, repeats):
    """Median wall time (s) of an ``n_speeds x n_values`` chart of ``scene`` on ``pool``."""
    parameter, (low, high) = CHARTS[scene]
    problem = studies.MechanismProblem.from_scene(scene, parameter_paths=(parameter,))
    speeds = ("speed", np.linspace(20.0, 400.0, n_speeds))
    values = (parameter, np.linspace(low, high, n_values))
    return median_time(lambda: studies.stability_chart(problem, speeds, values, n_steps=N_STEPS,
                                                       executor=pool), repeats)


def bench_charts(n_speeds, n_values, repeats):
    cells = n_speeds * n_values
    print(f"1. stability charts, {n_speeds} speeds x {n_values} values = {cells} cells, "
          f"{N_STEPS} steps, 2 processes (medians of {repeats}); scaled to {TARGET_CELLS} cells")
    with ProcessPoolExecutor(2) as pool:
        for scene in CHARTS:  # warm every worker's JIT cache and imports
            chart_time(scene, 4, 2, pool, 1)
        measured = {scene: chart_time(scene, n_speeds, n_values, pool, repeats) for scene in CHARTS}
    for scene, seconds in measured.items():
        scaled = seconds * TARGET_CELLS / cells
        print(f"   {scene:15s} {seconds:7.2f} s, {1e3 * seconds / cells:6.1f} ms per cell -> "
              f"100 x 100: {scaled:7.1f} s  ({scaled / TARGET_SECONDS:.2f} of the 120 s target)")
    ratio = measured["parallel_robot"] / measured["four_bar_fem4"]
    print(f"   robot / four-bar (same cell count): {ratio:.1f}x")
    return measured


def bench_cell(n_cells, repeats):
    """Per-cell shares of a robot chart cell, at speeds spread over the chart's range."""
    robot = mechanisms.load("parallel_robot")
    variants = [robot.with_parameter("period", 2.0 * math.pi / w)
                for w in np.linspace(20.0, 400.0, n_cells)]
    linearize.about(variants[0], n_steps=N_STEPS)  # warm-up
    nominal = median_time(lambda: [mechanisms.nominal_motion(m, n_steps=N_STEPS)
                                   for m in variants], repeats)
    linear = median_time(lambda: [linearize.about(m, n_steps=N_STEPS) for m in variants], repeats)
    systems = [linearize.about(m, n_steps=N_STEPS).system for m in variants]
    floquet = median_time(lambda: [periodic.floquet(s, estimate_error=True) for s in systems],
                          repeats)
    total = linear + floquet
    print(f"2. one robot chart cell, in-process ({n_cells} speeds, medians of {repeats}), "
          f"{1e3 * total / n_cells:.1f} ms:")
    for name, seconds in (("nominal motion", nominal), ("rest of the linearisation", linear - nominal),
                          ("Floquet multipliers + N/2 error", floquet)):
        print(f"   {name:32s} {1e3 * seconds / n_cells:6.2f} ms  ({seconds / total:5.1%})")
    print(f"   without the linearisation per cell (a speed family: polynomials in the speed), "
          f"100 x 100 on 2 processes would be about {floquet / n_cells * TARGET_CELLS / 2:.0f} s "
          f"plus 100 linearisations")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller grids, one repeat")
    parser.add_argument("--full", action="store_true", help="the 100 x 100 charts themselves")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    if args.full:
        bench_charts(100, 100, 1)
    elif args.quick:
        bench_charts(20, 2, 1)
    else:
        bench_charts(25, 8, 3)
    bench_cell(10 if args.quick else 40, 1 if args.quick else 3)


if __name__ == "__main__":
    main()
