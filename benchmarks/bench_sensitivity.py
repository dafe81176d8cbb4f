"""All sensitivities of one point (``studies.sensitivity``: every headline's derivative with respect to
n parameters, with their N/2 error estimates) against what a user would otherwise run: 2n + 1 steady
states (the point and a central difference for each parameter), each a linearisation and a shooting
with its N/2 and N/4 runs (``studies._numerics.solve_steady``, the lean core of ``studies.steady_state``
without its drawings).  Issue 20 asks for at most 0.8 of the baseline's time for n = 2 and 0.6 for n = 6.

Side by side in one process on ``four_bar_fem4`` (the thesis four-bar, 4-element coupler, 12 coordinates),
N = 256 steps; each repeat at a slightly different point (a fresh thickness), so that neither side reuses
the other's cached speed family or mechanisms.  Wall and CPU time (``time.process_time``, this process's
threads) of each: on the shared, loaded machine the CPU ratio is the steadier figure.

With ``--controlled``: the same comparison on ``four_bar_controlled`` (the torque-driven four-bar, its
gains and the coupler's Young's modulus: the closed forms of the controllers' ``law_derivative`` and
``K_ee / E``), n = 5, each repeat at a fresh coupler thickness.

With ``--optimize``: ``benchmarks/bench_optimize.py``'s optimisation (two strain-feedback gains of
``four_bar_controlled`` over 10 speeds, stability margin 0.05) with the sensitivities' gradients against
the same with forward differences of whole sweeps (``gradient="differences"``, the method before issue 20),
side by side, medians of ``--repeats``.

    PYTHONPATH=. python benchmarks/bench_sensitivity.py [--repeats 5] [--controlled | --optimize]
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import studies
from studies._numerics import solve_steady  # the baseline: the lean steady state (no drawings)

PARAMETERS = {2: ["speed", "links.coupler.thickness"],
              6: ["speed", "links.coupler.thickness", "links.coupler.youngs_modulus", "links.coupler.density",
                  "links.coupler.damping.ratio", "links.crank.length"]}
OBSERVABLES = ["coupler.deflection@0.5", "joint.B.force", "drive.O.torque"]
N_STEPS = 256
LIMITS = {2: 0.8, 6: 0.6}
#: ``--controlled``: the gains of both controllers and the coupler's Young's modulus
CONTROLLED = ["controllers.crank_pd.kp", "controllers.crank_pd.kd", "controllers.strain.gain",
              "controllers.strain.rate_gain", "links.coupler.youngs_modulus"]


def problem(scene="four_bar_fem4", paths=tuple(PARAMETERS[6][1:])):
    return studies.MechanismProblem.from_scene(scene, parameter_paths=list(paths), observables=OBSERVABLES)


def sensitivities(scene, names, point) -> tuple[float, float]:
    """(wall, CPU) seconds of one ``studies.sensitivity``."""
    start, cpu = time.perf_counter(), time.process_time()
    studies.sensitivity(scene, point, parameters=names, n_steps=N_STEPS)
    return time.perf_counter() - start, time.process_time() - cpu


def central_differences(scene, names, point) -> tuple[float, float]:
    """(wall, CPU) seconds of the 2n + 1 steady states."""
    start, cpu = time.perf_counter(), time.process_time()
    nominal = scene.resolve(point)
    solve_steady(scene.linearize(point, n_steps=N_STEPS))
    for name in names:
        step = 1e-4 * nominal[name]
        for value in (nominal[name] + step, nominal[name] - step):
            solve_steady(scene.linearize(dict(point, **{name: value}), n_steps=N_STEPS))
    return time.perf_counter() - start, time.process_time() - cpu


def optimise_both(repeats: int) -> None:
    """The two optimisations alternately (on a loaded machine a pair sees about the same load)."""
    import bench_optimize as bench

    scene = bench.problem()

    def run(gradient):
        start = time.perf_counter()
        found = studies.optimize(scene, bench.BOUNDS, objective=bench.OBJECTIVE, speeds=bench.SPEEDS,
                                 n_steps=bench.N_STEPS, constraints=[studies.StabilityMargin(0.05)],
                                 gradient=gradient)
        return time.perf_counter() - start, found

    run("sensitivities")   # warm
    times = {"sensitivities": [], "differences": []}
    found = {}
    for _ in range(repeats):
        for gradient in times:
            seconds, found[gradient] = run(gradient)
            times[gradient].append(seconds)
    for gradient, seconds in times.items():
        result = found[gradient]
        print(f"optimize, gradient = {gradient!r}: median {statistics.median(seconds):.1f} s of {repeats} "
              f"({', '.join(f'{t:.1f}' for t in seconds)}); {result.n_evaluations} evaluations; x = "
              f"{result.x[0]:.6g}, {result.x[1]:.6g}; objective {result.objective_value:.6g} m; {result.gradients}")
    ratios = [a / b for a, b in zip(times["sensitivities"], times["differences"])]
    print(f"ratio sensitivities / differences, pair by pair: {', '.join(f'{r:.2f}' for r in ratios)}; median "
          f"{statistics.median(ratios):.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--optimize", action="store_true")
    parser.add_argument("--controlled", action="store_true")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    if args.optimize:
        optimise_both(args.repeats)
        return
    sets = PARAMETERS
    scene = problem()
    if args.controlled:
        sets = {len(CONTROLLED): CONTROLLED}
        scene = problem("four_bar_controlled", CONTROLLED + ["links.coupler.thickness"])
    first = next(iter(sets.values()))
    sensitivities(scene, first, {})   # warm: JIT compilation
    central_differences(scene, first, {})
    for n, names in sets.items():
        ours, theirs = [], []
        for repeat in range(args.repeats):
            point = {"links.coupler.thickness": 0.0016 * (1.0 + 1e-3 * (repeat + 1) + 1e-2 * n)}
            ours.append(sensitivities(scene, names, point))
            theirs.append(central_differences(scene, names, dict(point, **{
                "links.coupler.thickness": point["links.coupler.thickness"] * (1.0 + 1e-5)})))
        for clock, k in (("wall", 0), ("CPU", 1)):
            mine, baseline = [t[k] for t in ours], [t[k] for t in theirs]
            ratios = [a / b for a, b in zip(mine, baseline)]
            print(f"n = {n}, {clock}: sensitivity median {statistics.median(mine):.3f} s, 2n+1 = {2 * n + 1} "
                  f"steady states median {statistics.median(baseline):.3f} s; ratio median "
                  f"{statistics.median(ratios):.2f} (each repeat: {', '.join(f'{r:.2f}' for r in ratios)}); "
                  f"limit {LIMITS.get(n, 'none')}")


if __name__ == "__main__":
    main()
