"""Cost of the Newmark shooting as the number of coordinates n grows: the kernel's three linear
solvers side by side, and the shooting's flop rate against a plain LU of the same size.

Per step the shooting factorises the effective matrix S = M + gamma h C + beta h^2 K (n, n) once and
solves it for m right-hand sides (m = 2n + 1 for the monodromy and the particular solution, m = 1
for the final forced run), whose residual forces f - C v~ - K x~ cost two (n, n) x (n, m) products:

    flops per step = 2/3 n^3 (LU) + 2 n^2 m (solves) + 4 n^2 m (products)    [~12.7 n^3 at m = 2n + 1]

The reference is what this machine does for the same LU and solves as plain library calls,
``scipy.linalg.lu_factor(S)`` + ``lu_solve(.., B)`` with B (n, m): 2/3 n^3 + 2 n^2 m flops.
Printed per n: the median time per step of ``periodic._newmark.newmark_march`` with each solver
(the hand-written LU and column loops; LAPACK dgetrf + dgetrs; dgetrf + dgetri and one dgemm), the
one ``choose_solver`` picks and its speed-up over the loops (the loops were the only path before
issue 14; the crossover ``LAPACK_FROM_N_DOF`` comes from these columns), the shooting's GFLOP/s
(the flops above, not dgetri's extra 4/3 n^3), the LU reference's, and their ratio.  ``--steady``
also times ``periodic.steady_state`` (N/2 and N/4 runs included) at a few n on the loops and on the
chosen path, and ``--mechanism`` on the thesis four-bar with 4..64 coupler elements (n = 12..192).

Timings are CPU times of this process, medians of interleaved repeats, with one BLAS thread (see
below): the machine is shared and noisy, so ratios, not absolute times, are the result.  Scipy's
OpenBLAS does all the library work (numba's np.dot calls it too).

Run: .venv/bin/python benchmarks/bench_shooting_scale.py [--quick] [--steady] [--mechanism]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

# One BLAS thread (before numpy loads OpenBLAS): the rates are those of one core, as in a parallel
# grid of processes, and the timings below count this process's CPU time, which a shared machine
# disturbs far less than wall time (another process taking the core does not count).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
import scipy.linalg

import periodic
from periodic import _newmark

SIZES = (2, 4, 8, 12, 16, 20, 24, 32, 40, 48, 64, 96, 128, 160, 200)


def random_system(n, n_steps, seed=0):
    """A random, well-conditioned, stable n-DOF system with periodic stiffness (coefficients only)."""
    rng = np.random.default_rng(seed)
    A, B = rng.normal(size=(n, n)), rng.normal(size=(n, n))
    mass, stiffness = A @ A.T + n * np.eye(n), 50.0 * (B @ B.T + n * np.eye(n))
    damping, force = 1e-3 * stiffness + 0.1 * mass, rng.normal(size=n)
    return periodic.PeriodicSystem.from_functions(
        1.0, lambda t: mass, lambda t: damping, lambda t: stiffness * (1.0 + 0.1 * np.cos(2 * np.pi * t)),
        lambda t: force * np.cos(2 * np.pi * t), n_steps=n_steps)


def shooting_flops(n, m):
    return 2.0 / 3.0 * n**3 + 6.0 * n * n * m


def lu_flops(n, m):
    return 2.0 / 3.0 * n**3 + 2.0 * n * n * m


def march_call(solver, system, m):
    """A kernel call with ``solver`` on the unit states (plus the forced column when m is odd), from scratch."""
    n = system.n_dof
    scheme = periodic.SCHEMES["trapezoidal"]
    forced = np.zeros(m)
    forced[-1] = 1.0
    empty = np.empty((0, n, m))

    def call():
        x, v = np.zeros((n, m)), np.zeros((n, m))
        x[:, : min(n, m)] = np.eye(n, min(n, m))
        status = _newmark.march(system.M, system.C, system.K, system.f, system.step, scheme.beta, scheme.gamma,
                                forced, x, v, np.empty((n, m)), empty, empty, empty, solver)
        assert status == -1
    return call


def lu_call(system, m):
    """scipy's LU of one effective matrix and its solve with m right-hand sides."""
    h = system.step
    S = system.M[1] + 0.5 * h * system.C[1] + 0.25 * h * h * system.K[1]
    B = np.random.default_rng(1).normal(size=(system.n_dof, m))
    return lambda: scipy.linalg.lu_solve(scipy.linalg.lu_factor(S), B)


def interleaved_medians(calls, repeats, inner):
    """Median seconds per call of each of ``calls``, run in turn ``repeats`` times (``inner`` calls each)."""
    times = [[] for _ in calls]
    for _ in range(repeats):
        for call, store in zip(calls, times):
            start = time.process_time()
            for _ in range(inner):
                call()
            store.append((time.process_time() - start) / inner)
    return [statistics.median(store) for store in times]


SOLVERS = {"loops": _newmark.SOLVE_LOOPS, "dgetrs": _newmark.SOLVE_LAPACK, "dgetri+dgemm": _newmark.SOLVE_INVERSE}


def scale(quick, m_of_n, label):
    print(f"\n## {label}")
    print("| n | m | " + " | ".join(f"{name} [us/step]" for name in SOLVERS) + " | chosen | loops / chosen "
          "| shooting GFLOP/s | LU+solve GFLOP/s | shooting / LU |")
    print("| ---: | ---: | " + "---: | " * len(SOLVERS) + "--- | ---: | ---: | ---: | ---: |")
    for n in SIZES:
        m = m_of_n(n)
        n_steps = 64 if n <= 48 else 16
        system = random_system(n, n_steps)
        calls = [march_call(solver, system, m) for solver in SOLVERS.values()]
        reference = lu_call(system, m)
        for call in calls + [reference]:
            call()  # JIT and BLAS warm-up
        budget = 0.2 if quick else 0.6  # s per kernel and repeat count below
        one = max(interleaved_medians(calls, 1, 1))
        inner = max(1, int(0.02 / one))
        repeats = max(3, min(15, int(budget / (one * inner))))
        per_step = [t / n_steps for t in interleaved_medians(calls, repeats, inner)]
        lu_time = interleaved_medians([reference], repeats, max(1, int(inner * n_steps)))[0]
        chosen = list(SOLVERS.values()).index(_newmark.choose_solver(n, m))
        # the rate counts the algorithm's flops (LU, solves, products), not dgetri's extra 4/3 n^3
        rate, lu_rate = shooting_flops(n, m) / per_step[chosen], lu_flops(n, m) / lu_time
        print(f"| {n} | {m} | " + " | ".join(f"{t * 1e6:.1f}" for t in per_step) + f" | {list(SOLVERS)[chosen]} | "
              f"{per_step[0] / per_step[chosen]:.2f} | {rate * 1e-9:.2f} | {lu_rate * 1e-9:.2f} | "
              f"{rate / lu_rate:.2f} |", flush=True)


PATHS = {"loops": (10**9, 2.0), "LAPACK": (0, 0.0)}  # (LAPACK_FROM_N_DOF, LAPACK_FROM_DENSITY) forcing a path


def with_path(thresholds, call):
    """``call`` with ``periodic._newmark``'s crossover constants set to ``thresholds`` (one of
    :data:`PATHS`, or None: the defaults, i.e. the path ``periodic`` chooses)."""
    def run():
        saved = _newmark.LAPACK_FROM_N_DOF, _newmark.LAPACK_FROM_DENSITY
        if thresholds is not None:
            _newmark.LAPACK_FROM_N_DOF, _newmark.LAPACK_FROM_DENSITY = thresholds
        try:
            return call()
        finally:
            _newmark.LAPACK_FROM_N_DOF, _newmark.LAPACK_FROM_DENSITY = saved
    return run


def side_by_side(system, repeats):
    """Median CPU seconds of steady_state(system) on the loops, on LAPACK and on the chosen path."""
    calls = [with_path(thresholds, lambda: periodic.steady_state(system)) for thresholds in (*PATHS.values(), None)]
    for call in calls:
        call()
    return interleaved_medians(calls, repeats, 1)


def steady(quick):
    """steady_state (the N/2 and N/4 runs included) on random dense systems, each path."""
    print("\n## periodic.steady_state, random dense systems, N = 64 (N/2 and N/4 runs included), CPU time")
    print("| n | loops [s] | LAPACK [s] | chosen [s] | loops / chosen | chosen: s / n^3 [ns] |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: |")
    for n in (12, 24, 48, 96, 192):
        loops, lapack, chosen = side_by_side(random_system(n, 64), 3 if quick or n > 100 else 7)
        print(f"| {n} | {loops:.4f} | {lapack:.4f} | {chosen:.4f} | {loops / chosen:.2f} | "
              f"{chosen / n**3 * 1e9:.1f} |", flush=True)


def mechanism(quick):
    """The thesis four-bar (four_bar_fem4) with a finer coupler mesh (sparse matrices): linearize.about
    once, then steady_state on each path; the linearisation's time is printed for scale."""
    import linearize
    import mechanisms

    print("\n## four_bar_fem4 at its scene speed, coupler of n_elements Hermite elements, N = 256, CPU time")
    print(
        "| elements | n | nonzero fraction | linearize.about [s] | loops [s] | LAPACK [s] | chosen [s] "
        "| loops / LAPACK |"
    )
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for n_elements in (4, 8, 16, 32) if quick else (4, 8, 16, 32, 64):
        model = mechanisms.load("four_bar_fem4").with_parameter("links.coupler.discretisation.n_elements", n_elements)
        start = time.process_time()
        system = linearize.about(model, n_steps=256).system
        about = time.process_time() - start
        loops, lapack, chosen = side_by_side(system, 3)
        density = _newmark.nonzero_fraction(system.M, system.C, system.K)
        print(f"| {n_elements} | {system.n_dof} | {density:.2f} | {about:.2f} | {loops:.3f} | {lapack:.3f} | "
              f"{chosen:.3f} | {loops / lapack:.2f} |", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--steady", action="store_true", help="also time steady_state on random systems, both paths")
    parser.add_argument("--mechanism", action="store_true", help="also the four-bar with a finer coupler mesh")
    args = parser.parse_args()
    print(f"crossover in use: periodic._newmark.LAPACK_FROM_N_DOF = {_newmark.LAPACK_FROM_N_DOF}, "
          f"LAPACK_FROM_DENSITY = {_newmark.LAPACK_FROM_DENSITY}")
    scale(args.quick, lambda n: 2 * n + 1, "monodromy march: m = 2n + 1 columns")
    scale(args.quick, lambda n: 1, "forced run: m = 1 column (the reference solves 1 right-hand side)")
    if args.steady:
        steady(args.quick)
    if args.mechanism:
        mechanism(args.quick)


if __name__ == "__main__":
    main()
