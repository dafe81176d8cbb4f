"""Nonlinear periodic state by shooting against the transient from the rigid start, at the same accuracy.

``four_bar_fem4`` (the stiffened thesis four-bar, elastic coupler with 4 Hermite elements) at its
nominal 100 rad/s with 1 % stiffness-proportional damping (``links.coupler.damping.ratio = 0.01``),
N = ``--n-steps`` generalized-alpha steps per period for both routes.

- Shooting: ``periodic.find_orbit`` on ``mechanisms.PeriodMap`` from the linear periodic state
  (its cost included: linearisation and linear shooting), to a relative residual ``--tol`` (1e-4:
  the orbit's error is then ~1e-7 of the peak-to-peak, printed, far inside the 0.1 %); JIT
  compilation excluded (warm-up first), no N/2 error estimate (the transient has none either).
- Transient: ``mechanisms.simulate`` from the rigid nominal motion (elastic coordinates at rest) for
  the fewest whole periods after which the coupler's midspan deflection over the last period is
  within ``--accuracy`` (0.1 %) of its peak-to-peak from the shooting orbit (the count is found
  from one long run first, then a run of exactly that many periods is timed).

Both are timed ``--repeats`` times, interleaved; medians and the ratio are printed.

``--dampings 0.01 0.003 0.001`` repeats the comparison at lighter damping: the transient's periods
grow as 1 / damping, the shooting's cost does not.

Usage: ``python benchmarks/bench_nonlinear_steady.py [--n-steps 256] [--repeats 3] [--dampings ...]``
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import mechanisms
import periodic
import studies
from studies._kinds.nonlinear_steady_state import shooting_setup

SPEC = "coupler.deflection@0.5"
DAMPING = "links.coupler.damping.ratio"


def shoot(problem, values, n_steps, tol):
    """(seconds, orbit, setup): linear start + Newton shooting."""
    started = time.perf_counter()
    setup = shooting_setup(problem, values, n_steps)
    orbit = periodic.find_orbit(setup.fine, setup.guess, values["speed"], tol=tol)
    return time.perf_counter() - started, orbit, setup


def observable_deviation(setup, s):
    """Midspan deflection over samples ``s`` (k, n) minus the nominal one (period repeated)."""
    observable = setup.fine.model.observable(SPEC)
    nominal = np.array([observable.value(q) for q in setup.linear.context.nominal.s[:-1]])
    values = np.array([observable.value(q) for q in s])
    return values - np.resize(nominal, values.size)


def compare(problem, damping, args):
    """(periods the transient needs, shooting s, transient s, shooting error / peak to peak, Newton
    steps, period maps, peak to peak m) at one damping ratio, medians of ``args.repeats``."""
    n = args.n_steps
    values = {"speed": 100.0, DAMPING: damping}
    mechanism = problem.mechanism({DAMPING: damping})
    _, orbit, setup = shoot(problem, values, n, tol=1e-10)       # warm-up and reference
    reference = observable_deviation(setup, setup.fine.run(orbit.state, tangent=False).s)
    peak_to_peak = np.ptp(reference)
    long_run = mechanisms.simulate(mechanism, n_periods=args.max_periods, steps_per_period=n,
                                   estimate_error=False, observables=[SPEC])
    deviation = observable_deviation(setup, long_run.s)
    periods = None
    for p in range(1, args.max_periods + 1):
        last = deviation[(p - 1) * n:p * n + 1]
        if np.abs(last - reference).max() <= args.accuracy * peak_to_peak:
            periods = p
            break
    if periods is None:
        raise SystemExit(f"damping {damping:g}: the transient did not reach {args.accuracy:g} of the "
                         f"peak-to-peak in {args.max_periods} periods")
    shooting_times, transient_times, errors = [], [], []
    for _ in range(args.repeats):
        seconds, found, check = shoot(problem, values, n, tol=args.tol)
        shooting_times.append(seconds)
        errors.append(np.abs(observable_deviation(check, check.fine.run(found.state, tangent=False).s)
                             - reference).max() / peak_to_peak)
        started = time.perf_counter()
        mechanisms.simulate(mechanism, n_periods=periods, steps_per_period=n, estimate_error=False,
                            observables=[SPEC])
        transient_times.append(time.perf_counter() - started)
    return (periods, statistics.median(shooting_times), statistics.median(transient_times), max(errors),
            found.iterations, found.map_calls, peak_to_peak)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-steps", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--accuracy", type=float, default=1e-3)
    parser.add_argument("--tol", type=float, default=1e-4)
    parser.add_argument("--max-periods", type=int, default=400)
    parser.add_argument("--dampings", type=float, nargs="+", default=[0.01],
                        help="damping ratios of the coupler, one comparison each (the issue's: 0.01)")
    args = parser.parse_args()
    problem = studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=[DAMPING])
    print(f"four_bar_fem4, 100 rad/s, N = {args.n_steps} steps per period, midspan deflection; "
          f"accuracy {args.accuracy:g} of its peak to peak")
    print("damping | transient periods | transient s | shooting s (Newton steps, period maps) | "
          "shooting error / p2p | ratio")
    for damping in args.dampings:
        periods, shooting, transient, error, steps, maps, _ = compare(problem, damping, args)
        print(f"{damping:7.3%} | {periods:17d} | {transient:11.3f} | {shooting:8.3f} ({steps}, {maps})"
              f"{'':>17} | {error:20.2g} | {transient / shooting:5.1f}")


if __name__ == "__main__":
    main()
