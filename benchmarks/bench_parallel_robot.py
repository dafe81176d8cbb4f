"""Speed of a stability chart of the 3-RRR parallel robot (parallel_robot), issue 14's target: a
100 x 100 chart (speed x payload mass) in at most 120 s on 2 processes.

1. The chart on a 2-process pool: speed 20..400 rad/s x payload 0.1..2 kg, 32 steps per period (the
   charts' minimum; the loss of stability lies above 160 rad/s, where 32 steps resolve the first
   elastic mode at h omega_1 < 0.21). Each process builds one ``linearize.speed_family`` per
   payload (the robot's three drives are prescribed: its coefficients are polynomials in the speed
   2 pi / period) and a cell costs a few array operations and its Floquet multipliers. So the
   timed grid keeps the full speed axis (100 speeds) with fewer payloads, and is scaled to 100 x 100
   by the cell count (each payload costs a family plus 100 cells); ``--full`` runs the 100 x 100
   itself. Side by side, the same grid of the thesis four-bar (four_bar_fem4, speed x
   coupler thickness), a constant-rate crank.
2. One robot chart cell, in-process, by the two routes side by side: linearised afresh (the nominal
   motion ``mechanisms.nominal_motion``, the rest of ``linearize.about``) against the speed family
   (built once for 100 speeds, then ``system_at``), each plus the Floquet multipliers with their
   N/2 error estimate (``periodic.floquet``).

All times are medians of repeated runs with a warm JIT cache. Run:
    .venv/bin/python benchmarks/bench_parallel_robot.py [--quick] [--full]
"""

from __future__ import annotations

import argparse
import logging
import math

import numpy as np
from bench_linearize import median_time  # this folder is the script's path: the same timer

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
    # with the full speed axis the cells keep their share of the families: scale by cell count
    scale = TARGET_CELLS / cells
    print(f"1. stability charts, {n_speeds} speeds x {n_values} values = {cells} cells, "
          f"{N_STEPS} steps, 2 processes (medians of {repeats}); scaled to {TARGET_CELLS} cells "
          f"(x {scale:g})")
    with studies.process_pool(2) as pool:
        for scene in CHARTS:  # warm every worker's JIT cache and imports
            chart_time(scene, 4, 2, pool, 1)
        measured = {scene: chart_time(scene, n_speeds, n_values, pool, repeats) for scene in CHARTS}
    for scene, seconds in measured.items():
        scaled = seconds * scale
        print(f"   {scene:15s} {seconds:7.2f} s, {1e3 * seconds / cells:6.1f} ms per cell -> "
              f"100 x 100: {scaled:7.1f} s  ({scaled / TARGET_SECONDS:.2f} of the 120 s target)")
    ratio = measured["parallel_robot"] / measured["four_bar_fem4"]
    print(f"   robot / four-bar (same cell count): {ratio:.1f}x")
    return measured


def bench_cell(n_cells, repeats):
    """Per-cell cost of a robot chart cell at speeds spread over the chart's range, linearised
    afresh against taken from a speed family (its cost shared by 100 speeds, as in a chart row)."""
    robot = mechanisms.load("parallel_robot")
    speeds = np.linspace(20.0, 400.0, n_cells)
    variants = [robot.with_parameter("period", 2.0 * math.pi / w) for w in speeds]
    linearize.about(variants[0], n_steps=N_STEPS)  # warm-up
    nominal = median_time(lambda: [mechanisms.nominal_motion(m, n_steps=N_STEPS)
                                   for m in variants], repeats)
    linear = median_time(lambda: [linearize.about(m, n_steps=N_STEPS) for m in variants], repeats)
    family = linearize.speed_family(robot, n_steps=N_STEPS)
    family_once = median_time(lambda: linearize.speed_family(robot, n_steps=N_STEPS), repeats)
    systems_at = median_time(lambda: [family.system_at(w) for w in speeds], repeats)
    systems = [family.system_at(w) for w in speeds]
    floquet = median_time(lambda: [periodic.floquet(s, estimate_error=True) for s in systems],
                          repeats)
    direct = (linear + floquet) / n_cells
    shared = (family_once / 100 + (systems_at + floquet) / n_cells)
    print(f"2. one robot chart cell, in-process ({n_cells} speeds, medians of {repeats}), ms:")
    for name, seconds in (("nominal motion", nominal / n_cells),
                          ("rest of the linearisation", (linear - nominal) / n_cells),
                          ("speed family / 100 speeds", family_once / 100),
                          ("system_at", systems_at / n_cells),
                          ("Floquet multipliers + N/2 error", floquet / n_cells)):
        print(f"   {name:32s} {1e3 * seconds:6.2f}")
    print(f"   cell linearised afresh {1e3 * direct:6.2f} ms, from the speed family "
          f"{1e3 * shared:6.2f} ms: {direct / shared:.1f}x faster; 100 x 100 on 2 processes "
          f"(perfect split): {shared * TARGET_CELLS / 2:.0f} s against {direct * TARGET_CELLS / 2:.0f} s")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller grids, one repeat")
    parser.add_argument("--full", action="store_true", help="the 100 x 100 charts themselves")
    args = parser.parse_args()
    logging.disable(logging.WARNING)
    if args.full:
        bench_charts(100, 100, 1)
    elif args.quick:
        bench_charts(100, 4, 1)
    else:
        bench_charts(100, 10, 3)
    bench_cell(10 if args.quick else 40, 1 if args.quick else 3)


if __name__ == "__main__":
    main()
