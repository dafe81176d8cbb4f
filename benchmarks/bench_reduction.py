"""Cost of a modally reduced link against the 4-element model, at their accuracies.

Thesis four-bar (``four_bar_fem4``: stiffened coupler, 2 % Rayleigh damping) at 100 rad/s, N = 256
steps, one steady state each with its N/2 and N/4 error estimate, the linearisation included, a
new mechanism object per run (as every point of a sweep):

  1. coupler of 4 Hermite elements (12 elastic coordinates): the baseline;
  2. coupler of 64 elements reduced to 6 modes (9 coordinates: 6 modes + 3 static corrections),
     its reduction cached (a speed sweep: the link does not change);
  3. the same with the reduction recomputed every run: a steady state from scratch (or a sweep of
     the coupler's geometry); the issue's target, <= 2x the baseline. Computing the reduction is
     a sparse assembly and one sparse factorisation per block (shift-invert Lanczos, static
     corrections), about 10 ms;
  4. the full 64-element coupler (192 coordinates), once: the reference of the accuracies.

Each repeat times 1-3 side by side (the machine's load, 2 noisy cores, hits them alike); ratios
are medians of the per-repeat ratios. Accuracy: the midspan deflection's peak-to-peak against the
full 64-element model's.

Run: .venv/bin/python benchmarks/bench_reduction.py [--quick]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import linearize
import mechanisms
import periodic
from mechanisms._parts import fem as _fem

SPEC = "coupler.deflection@0.5"
N_STEPS = 256


def coupler(n_elements, modes=None, rate=100.0):
    changes = {"links.coupler.discretisation.n_elements": n_elements, "drive.rate": rate}
    if modes is not None:
        changes["links.coupler.discretisation.modes"] = modes
    return mechanisms.load("four_bar_fem4").with_parameters(changes)


def steady_peak_to_peak(mechanism):
    linear = linearize.about(mechanism, n_steps=N_STEPS)
    state = periodic.steady_state(linear.system)
    return float(np.ptp(linear.observe(state.x)[SPEC]))


def timed(func):
    start = time.perf_counter()
    value = func()
    return time.perf_counter() - start, value


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    args = parser.parse_args(argv)
    repeats = 3 if args.quick else 9
    steady_peak_to_peak(coupler(4))            # warm the JIT caches and the reduction cache
    steady_peak_to_peak(coupler(64, 6))

    rows = []
    for _ in range(repeats):
        t_fem4, ptp_fem4 = timed(lambda: steady_peak_to_peak(coupler(4)))
        t_cached, ptp_reduced = timed(lambda: steady_peak_to_peak(coupler(64, 6)))
        _fem._reduced.cache_clear()          # recompute the reduction: a geometry sweep
        t_fresh, _ = timed(lambda: steady_peak_to_peak(coupler(64, 6)))
        rows.append((t_fem4, t_cached, t_fresh))
    t_full, ptp_full = timed(lambda: steady_peak_to_peak(coupler(64)))

    t_fem4, t_cached, t_fresh = (statistics.median(column) for column in zip(*rows))
    cached_ratio = statistics.median(c / f for f, c, _ in rows)
    fresh_ratio = statistics.median(r / f for f, _, r in rows)
    print(f"thesis four-bar at 100 rad/s, N = {N_STEPS}, steady state with error estimate, "
          f"linearisation included; medians of {repeats}")
    print(f"  4 elements (12 coordinates)               {t_fem4 * 1e3:8.1f} ms   peak-to-peak "
          f"error {abs(ptp_fem4 / ptp_full - 1):.2e}")
    print(f"  64 elements -> 6 modes (9), reduction cached {t_cached * 1e3:8.1f} ms   "
          f"{cached_ratio:.2f}x   error {abs(ptp_reduced / ptp_full - 1):.2e}")
    print(f"  64 elements -> 6 modes, reduction each run  {t_fresh * 1e3:8.1f} ms   "
          f"{fresh_ratio:.2f}x")
    print(f"  64 elements, full (192 coordinates), once   {t_full * 1e3:8.1f} ms   "
          f"{t_full / t_fem4:.0f}x   (the reference)")
    print(f"target: reduced from scratch <= 2x the 4-element model: "
          f"{'met' if fresh_ratio <= 2.0 else 'MISSED'} ({fresh_ratio:.2f}x; cached {cached_ratio:.2f}x)")


if __name__ == "__main__":
    main()
