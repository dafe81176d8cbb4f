"""Work-precision of periodic.steady_state against scipy's solve_ivp (DOP853, Radau), side by side.

Every method computes the same monodromy Phi and periodic initial state z0 = [x0; v0] from
(I - Phi) z0 = b, where Phi and b come from integrating the 2n unit states and the particular
solution over one period.  Errors are measured against a reference from DOP853 at rtol 1e-13
(cross-checked against Newmark-Richardson at a large N, printed).  Times are medians over repeats
and include sampling the coefficient functions (Newmark) or evaluating them (scipy).

    state error : max(|x0 - x0_ref| / max|x0_ref|, |v0 - v0_ref| / max|v0_ref|)
    mu error    : max |mu - mu_ref| over the reference multipliers with |mu_ref| > 1e-6, matched one
                  to one (an unresolved stiff mode has no such partner, see the README)

Cases: (a) smooth: the 2-DOF Mathieu-type demo system ``periodic.demo_system``; (b) stiff: 2 DOF whose
second mode is 3000 times faster than the forcing (an axial mode of a steel link), 1 % damped.

``--overhead`` instead times ``steady_state`` with and without the error estimate (N/2 and N/4 runs)
and ``floquet`` on a random 12-DOF system at N = 256 and the 2-DOF one at N = 64 (medians of many calls).

Run: .venv/bin/python benchmarks/bench_periodic.py [--quick | --overhead]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import scipy.integrate
from scipy.optimize import linear_sum_assignment

import periodic
from periodic import _demo as demo

TARGET = 1e-5


class Case:
    def __init__(self, name, period, mass, damping, stiffness, force):
        self.name, self.period = name, period
        self.mass, self.damping, self.stiffness, self.force = mass, damping, stiffness, force
        self.n = mass(0.0).shape[0]

    def system(self, n_steps):
        return periodic.PeriodicSystem.from_functions(
            self.period, self.mass, self.damping, self.stiffness, self.force, n_steps=n_steps
        )


def smooth_case():
    return Case(
        "smooth (demo 2-DOF Mathieu-type)",
        2.0 * np.pi / demo.OMEGA,
        lambda t: demo.MASS,
        lambda t: demo.DAMPING,
        demo.stiffness,
        demo.force,
    )


def stiff_case():
    omega = 2.0 * np.pi  # forcing, T = 1 s
    slow, fast = 1.7 * omega, 3000.0 * omega  # rad/s
    rotation = np.array([[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]])
    mass = np.eye(2)
    stiffness = rotation @ np.diag([slow**2, fast**2]) @ rotation.T
    damping = rotation @ np.diag([2 * 0.02 * slow, 2 * 0.01 * fast]) @ rotation.T
    force = np.array([1.0, 0.5])
    return Case(
        "stiff (mode 3000x the forcing frequency)",
        1.0,
        lambda t: mass,
        lambda t: damping,
        lambda t: stiffness * (1.0 + 0.1 * np.cos(omega * t)),
        lambda t: force * np.cos(omega * t) + 0.3 * force[::-1] * np.sin(2 * omega * t),
    )


def newmark(case, n_steps, extrapolate):
    """z0, multipliers, status and the run time of steady_state alone (without sampling the functions)."""
    system = case.system(n_steps)
    if extrapolate:
        result = periodic.steady_state(system, extrapolate=True)
    else:
        result = periodic.steady_state(system, estimate_error=False)
    return np.concatenate((result.x[0], result.v[0])), result.multipliers, result.status, result.run_time


def scipy_shooting(case, method, rtol):
    """Phi and b from one solve_ivp run on the 2n x (2n+1) matrix state, then z0 from (I - Phi) z0 = b."""
    n = case.n
    m = 2 * n + 1

    def state_matrix(t):
        solve = np.linalg.solve(case.mass(t), np.column_stack((case.stiffness(t), case.damping(t), case.force(t))))
        A = np.zeros((2 * n, 2 * n))
        A[:n, n:] = np.eye(n)
        A[n:, :n] = -solve[:, :n]
        A[n:, n:] = -solve[:, n : 2 * n]
        return A, solve[:, -1]

    def rhs(t, y):
        A, g = state_matrix(t)
        Y = y.reshape(2 * n, m)
        dY = A @ Y
        dY[n:, -1] += g
        return dY.ravel()

    def jac(t, y):
        return np.kron(state_matrix(t)[0], np.eye(m))

    y0 = np.zeros((2 * n, m))
    y0[:, : 2 * n] = np.eye(2 * n)
    options = {"jac": jac} if method == "Radau" else {}
    sol = scipy.integrate.solve_ivp(
        rhs, (0.0, case.period), y0.ravel(), method=method, rtol=rtol, atol=rtol * 1e-3, **options
    )
    if sol.status != 0:
        raise RuntimeError(f"{method} failed: {sol.message}")
    Y = sol.y[:, -1].reshape(2 * n, m)
    phi = Y[:, : 2 * n]
    return np.linalg.solve(np.eye(2 * n) - phi, Y[:, -1]), np.linalg.eigvals(phi)


def state_error(z0, ref, n):
    return max(
        np.abs(z0[:n] - ref[:n]).max() / np.abs(ref[:n]).max(),
        np.abs(z0[n:] - ref[n:]).max() / np.abs(ref[n:]).max(),
    )


def multiplier_error(mu, ref_mu):
    ref_mu = ref_mu[np.abs(ref_mu) > 1e-6]
    cost = np.abs(ref_mu[:, None] - mu[None, :])
    rows, cols = linear_sum_assignment(cost)
    return cost[rows, cols].max()


def timed(func, repeats):
    """Median wall time of ``func()``, its last output, and the median of its last element if timed."""
    times, inner = [], []
    for _ in range(repeats):
        start = time.perf_counter()
        out = func()
        times.append(time.perf_counter() - start)
        inner.append(out[-1] if isinstance(out[-1], float) else times[-1])
    return statistics.median(times), out, statistics.median(inner)


def run_case(case, quick):
    print(f"\n## {case.name}")
    ref_z0, ref_mu = scipy_shooting(case, "DOP853", 1e-13)
    check_z0, *_ = newmark(case, 2**15 if quick else 2**16, extrapolate=True)
    print(f"reference: DOP853 rtol 1e-13; its state differs from Newmark-Richardson N=2^16 by "
          f"{state_error(check_z0, ref_z0, case.n):.1e} (relative)")
    rows = []
    repeats = 3 if quick else 7
    # Steps and tolerances in factors of about sqrt(2) and sqrt(10), so that "the cheapest run
    # reaching the target" overshoots the work needed by similar factors for all methods.
    steps = [2 * round(16 * 2 ** (k / 2)) for k in range(17)]  # 32 .. 8192, even
    for label, extrapolate in (("Newmark", False), ("Newmark+Richardson", True)):
        for n_steps in steps:
            t, (z0, mu, status, _), t_solve = timed(lambda: newmark(case, n_steps, extrapolate), repeats)
            rows.append(
                (
                    label,
                    f"N={n_steps}",
                    state_error(z0, ref_z0, case.n),
                    multiplier_error(mu, ref_mu),
                    t,
                    t_solve,
                    status,
                )
            )
            if rows[-1][2] < TARGET / 100:
                break
    for method in ("DOP853", "Radau"):
        for rtol in 10.0 ** -np.arange(3.0, 10.5, 0.5):
            t, (z0, mu), _ = timed(lambda: scipy_shooting(case, method, rtol), 1 if quick else 3)
            rows.append(
                (method, f"rtol={rtol:.0e}", state_error(z0, ref_z0, case.n), multiplier_error(mu, ref_mu), t, t, "")
            )
            if rows[-1][2] < TARGET / 100:
                break
    print("| method | setting | state error | mu error | time [ms] | solve only [ms] | status |")
    print("| --- | --- | ---: | ---: | ---: | ---: | --- |")
    for label, setting, err, mu_err, t, t_solve, status in rows:
        print(f"| {label} | {setting} | {err:.1e} | {mu_err:.1e} | {t * 1e3:.2f} | {t_solve * 1e3:.2f} | {status} |")
    for column, what in ((4, "including sampling"), (5, "solve only")):
        best = {}
        for row in rows:
            if row[2] <= TARGET:
                best[row[0]] = min(best.get(row[0], np.inf), row[column])
        newmark_best = min(best.get("Newmark", np.inf), best.get("Newmark+Richardson", np.inf))
        ratios = ", ".join(f"{m} {best[m] / newmark_best:.1f}x" for m in ("DOP853", "Radau") if m in best)
        print(f"cheapest run with state error <= {TARGET:g}, Newmark times {what}: "
              f"Newmark {newmark_best * 1e3:.2f} ms; scipy / Newmark: {ratios}")


def overhead():
    """Median call times of steady_state (with / without the estimate) and floquet, in microseconds."""
    rng = np.random.default_rng(1)
    for n, n_steps, repeats in ((12, 256, 400), (2, 64, 3000)):
        A, B = rng.normal(size=(n, n)), rng.normal(size=(n, n))
        mass, stiffness = A @ A.T + n * np.eye(n), 50.0 * (B @ B.T + n * np.eye(n))
        damping, force = 1e-3 * stiffness + 0.1 * mass, rng.normal(size=n)
        system = periodic.PeriodicSystem.from_functions(
            1.0, lambda t: mass, lambda t: damping, lambda t: stiffness * (1.0 + 0.1 * np.cos(2 * np.pi * t)),
            lambda t: force * np.cos(2 * np.pi * t), n_steps=n_steps)
        for label, call in (
            ("steady_state", lambda: (periodic.steady_state(system),)),
            ("steady_state(estimate_error=False)", lambda: (periodic.steady_state(system, estimate_error=False),)),
            ("floquet", lambda: (periodic.floquet(system),)),
        ):  # timed() wants a tuple
            call()
            print(f"n={n} N={n_steps} {label}: {timed(call, repeats)[0] * 1e6:.1f} us")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--overhead", action="store_true", help="only the call times of steady_state and floquet")
    args = parser.parse_args()
    if args.overhead:
        overhead()
        return
    case = stiff_case()
    periodic.steady_state(case.system(8))  # JIT warm-up outside the timings
    for case in (smooth_case(), stiff_case()):
        run_case(case, args.quick)


if __name__ == "__main__":
    main()
