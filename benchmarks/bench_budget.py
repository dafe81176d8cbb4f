"""The cost of the error budget (studies._budget), side by side in one process, on four_bar_fem4.

1. A 200-speed sweep (20..400 rad/s, 256 steps) with the full budget (time step, each point's own
   linearisation term, the mesh term of the scene's point) against the same sweep with
   ``budget=False``: the time step's error alone, the sweep as it was before the budget.
2. The steady state at 100 rad/s with its budget against ``budget=False``.
3. "Steady state against brute force" at matched accuracy against the same reference: the converged
   nonlinear periodic state (``nonlinear_steady_state``, 1024 steps) of the scene with 1 % coupler
   damping. The linear route reports its total bar and how far it truly is; the nonlinear periodic
   state (coarsest N within 1 %) and brute-force integration of the full model
   (``mechanisms.simulate`` from the nominal rigid motion until every later period's peak is within 1 %
   of the reference) reach 1 %.

Medians of repeated runs with a warm JIT cache; the machine may be loaded (say so with the figures).
Run:
    .venv/bin/python benchmarks/bench_budget.py [--quick]
"""

from __future__ import annotations

import argparse
import logging
import statistics
import time
import warnings

import numpy as np
from _timing import clear_study_caches, median_time

import mechanisms
import studies

SCENE = "four_bar_fem4"
SPEC = "coupler.deflection@0.5"


def bench_sweep(count, repeats):
    speeds = np.linspace(20.0, 400.0, count)
    problem = studies.MechanismProblem.from_scene(SCENE)
    studies.sweep(problem, "speed", speeds[:4], n_steps=256)  # JIT warm-up

    def run(budget):
        clear_study_caches()
        return studies.sweep(problem, "speed", speeds, n_steps=256, budget=budget)

    times = {True: [], False: []}
    for _ in range(repeats):  # alternated, so that the machine's load falls on both alike
        for budget in (False, True):
            started = time.perf_counter()
            result = run(budget)
            times[budget].append(time.perf_counter() - started)
    with_budget, without = statistics.median(times[True]), statistics.median(times[False])
    known = np.isfinite(result.budget_linearisation[SPEC]).sum()
    print(f"sweep, {count} speeds, 256 steps: with the budget {with_budget:.2f} s, without "
          f"{without:.2f} s: ratio {with_budget / without:.2f} (runs {', '.join(f'{t:.2f}' for t in times[True])}"
          f" / {', '.join(f'{t:.2f}' for t in times[False])}); linearisation term known at {known} of "
          f"{count} points")


def bench_steady(repeats):
    problem = studies.MechanismProblem.from_scene(SCENE)
    studies.steady_state(problem, {"speed": 100.0})
    times = {True: [], False: []}
    for _ in range(repeats):
        for budget in (False, True):
            clear_study_caches()
            started = time.perf_counter()
            result = studies.steady_state(problem, {"speed": 100.0}, budget=budget)
            times[budget].append(time.perf_counter() - started)
    with_budget, without = statistics.median(times[True]), statistics.median(times[False])
    print(f"steady state at 100 rad/s: with the budget {1e3 * with_budget:.1f} ms, without "
          f"{1e3 * without:.1f} ms: ratio {with_budget / without:.2f}")
    print(f"  {SPEC} peak to peak {1e3 * result.peak_to_peak[SPEC]:.3f} mm +- "
          f"{1e3 * result.peak_to_peak_error[SPEC]:.3f} mm; budget {result.error_budget[SPEC]}")


def peak(values):
    return float(np.max(np.abs(values)))


def bench_matched(repeats):
    mechanism = mechanisms.load(SCENE).with_parameter("links.coupler.damping.ratio", 0.01)
    problem = studies.MechanismProblem.from_mechanism(mechanism)
    reference = studies.nonlinear_steady_state(problem, n_steps=1024)
    target = reference.peak[SPEC]
    print(f"matched accuracy, {SCENE} at its speed with 1 % damping; reference: the nonlinear periodic "
          f"state at 1024 steps, peak {1e3 * target:.4f} mm ({reference.status})")

    def linear():
        clear_study_caches()
        return studies.steady_state(problem, n_steps=256)

    t_linear, result = median_time(linear, repeats)
    off = abs(result.peak[SPEC] - target) / target
    print(f"  linear steady state with its budget, 256 steps: {1e3 * t_linear:.1f} ms, peak "
          f"{1e3 * result.peak[SPEC]:.4f} mm +- {1e3 * result.peak_error[SPEC]:.4f} mm "
          f"({result.status}); truly {100 * off:.2f} % off the reference, bar "
          f"{100 * result.peak_error[SPEC] / target:.2f} %")
    found = None
    for n in (32, 64, 128, 256, 512):
        run = studies.nonlinear_steady_state(problem, n_steps=n)
        if run.status != "failed" and abs(run.peak[SPEC] - target) <= 0.01 * target:
            found = n
            break
    if found is None:
        print("  the nonlinear periodic state did not reach 1 % up to 512 steps")
        t_nonlinear = float("nan")
    else:
        t_nonlinear, run = median_time(lambda: studies.nonlinear_steady_state(problem, n_steps=found),
                                       repeats)
        print(f"  nonlinear periodic state, {found} steps: {t_nonlinear:.2f} s, peak "
              f"{1e3 * run.peak[SPEC]:.4f} mm ({100 * abs(run.peak[SPEC] - target) / target:.2f} %)")
    for n_brute in (64, 128, 256, 512):
        try:
            history = mechanisms.simulate(mechanism, n_periods=80, steps_per_period=n_brute,
                                          observables=[SPEC]).observables[SPEC]
        except mechanisms.SimulationError:
            continue
        peaks = np.array([peak(history[p * n_brute:(p + 1) * n_brute + 1])
                          for p in range(history.size // n_brute)])
        within = np.abs(peaks - target) <= 0.01 * target
        if within[-1]:
            periods = within.size - int(np.argmin(within[::-1])) + 1 if not within.all() else 1
            t_brute, _ = median_time(lambda: mechanisms.simulate(
                mechanism, n_periods=periods, steps_per_period=n_brute, observables=[SPEC]),
                max(1, repeats // 2))
            print(f"  brute force {n_brute} steps x {periods} periods: {t_brute:.2f} s: "
                  f"{t_brute / t_nonlinear:.1f}x the nonlinear periodic state, "
                  f"{t_brute / t_linear:.0f}x the linear steady state (which is not within 1 %)")
            return
    print("  brute force did not reach 1 % of the reference within 80 periods and 512 steps")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a 40-speed sweep, fewer repeats")
    parser.add_argument("--only", choices=("sweep", "steady", "matched"), help="run one part")
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    warnings.simplefilter("ignore")
    repeats = 1 if args.quick else 3
    if args.only in (None, "sweep"):
        bench_sweep(40 if args.quick else 200, repeats)
    if args.only in (None, "steady"):
        bench_steady(3 if args.quick else 7)
    if args.only in (None, "matched"):
        bench_matched(repeats)


if __name__ == "__main__":
    main()
