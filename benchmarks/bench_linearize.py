"""Cost of a linearisation against the shooting it feeds, and of a crank-speed sweep.

Thesis four-bar, 4 Hermite elements on the coupler (axial and bending, 12 independent elastic
coordinates), N = 512 steps per period. Every figure is the median of several runs in this process.

  1. linearize.about (nominal motion + linearisation + geometric stiffness) against one
     periodic.steady_state of the system it produces (with its N/2 error estimate). Target <= 5x.
  2. A sweep of S speeds: speed_family once plus at_speed + steady_state per speed, against
     about + steady_state per speed (the direct route), side by side.

Run: .venv/bin/python benchmarks/bench_linearize.py [--quick]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import linearize
import mechanisms
import periodic


def median_time(func, repeats):
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats and speeds")
    args = parser.parse_args(argv)
    repeats = 3 if args.quick else 7
    n_speeds = 10 if args.quick else 40
    n_steps = 512
    mechanism = mechanisms.load("four_bar_fem4")
    lin = linearize.about(mechanism, n_steps=n_steps)        # warm the JIT caches
    periodic.steady_state(lin.system)

    # Paired runs: each repeat times the three side by side, so that the machine's load (2 noisy
    # cores) hits them alike; the ratio is the median of the per-repeat ratios.
    pairs = []
    for _ in range(repeats):
        t_about = median_time(lambda: linearize.about(mechanism, n_steps=n_steps), 1)
        t_nominal = median_time(lambda: mechanisms.nominal_motion(mechanism, n_steps=n_steps), 1)
        t_shoot = median_time(lambda: periodic.steady_state(lin.system), 3)
        pairs.append((t_about, t_nominal, t_shoot))
    t_about, t_nominal, t_shoot = (statistics.median(column) for column in zip(*pairs))
    ratio = statistics.median(a / s for a, _, s in pairs)
    print(f"thesis four-bar, 4 elements, {len(lin.labels)} elastic coordinates, N = {n_steps}")
    print(f"  linearize.about          {t_about * 1e3:8.1f} ms  (nominal motion alone "
          f"{t_nominal * 1e3:.1f} ms)")
    print(f"  periodic.steady_state    {t_shoot * 1e3:8.1f} ms  (with its N/2 error estimate)")
    print(f"  ratio about / shooting   {ratio:8.1f}   (median of paired runs; target <= 5)")

    speeds = np.linspace(40.0, 160.0, n_speeds)

    def family_sweep():
        family = linearize.speed_family(mechanism, n_steps=n_steps)
        return [np.abs(periodic.steady_state(family.at_speed(w).system).multipliers).max()
                for w in speeds]

    def direct_sweep():
        return [np.abs(periodic.steady_state(linearize.about(
            mechanism.with_parameter("drive.rate", w), n_steps=n_steps).system).multipliers).max()
            for w in speeds]

    rho_family, rho_direct = family_sweep(), direct_sweep()
    agreement = np.max(np.abs(np.array(rho_family) - np.array(rho_direct)))
    sweep_repeats = max(1, repeats // 3)
    t_family = median_time(family_sweep, sweep_repeats)
    t_direct = median_time(direct_sweep, sweep_repeats)
    family = linearize.speed_family(mechanism, n_steps=n_steps)
    t_at = median_time(lambda: family.at_speed(123.0), repeats)
    t_family_once = median_time(lambda: linearize.speed_family(mechanism, n_steps=n_steps),
                                sweep_repeats)
    print(f"sweep over {n_speeds} crank speeds (steady state + multipliers at each):")
    print(f"  speed_family route       {t_family:8.2f} s   (family once {t_family_once:.2f} s, "
          f"at_speed {t_at * 1e3:.1f} ms per speed)")
    print(f"  direct route             {t_direct:8.2f} s")
    print(f"  ratio direct / family    {t_direct / t_family:8.1f}")
    print(f"  max |spectral radius difference| between routes: {agreement:.2e}")


if __name__ == "__main__":
    main()
