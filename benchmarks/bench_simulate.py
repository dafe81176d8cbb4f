"""Speed of mechanisms.simulate against scipy's solve_ivp on the same model at the same accuracy.

The thesis four-bar (rigid crank and rocker, elastic coupler with 4 Hermite elements, axial and
bending, 2 % stiffness-proportional damping, geometric stiffening) driven at 100 rad/s from the rigid
motion at t = 0, run for 50 crank revolutions.

Baseline: the equivalent ODE for ``y = (s, s')`` handed to ``solve_ivp(method=...)`` (Radau by
default): at every right-hand side the accelerations and multipliers are solved from the index-1 form
with Baumgarte stabilisation,

    [[M, Phi_s^T], [Phi_s, 0]] [s''; lam] = [Q; gamma - 2 a (Phi_s s' + Phi_t) - a^2 Phi],

(Baumgarte 1972) with a critically damped constraint drift at rate ``a``. The Jacobian is solve_ivp's
finite-difference one.

Accuracy is matched first on a shorter horizon: both methods are run for ``--calibration-revs``
revolutions (the start-up transient included) and compared with a fine Radau reference (rtol 1e-10)
in the coupler's midspan deflection (max abs error over the run, relative to the max abs
deflection). For each ``--target``, the coarsest generalized-alpha step (``steps_per_period``) and
the loosest solve_ivp ``rtol`` (with ``atol = rtol * 1e-3``) that reach it are then timed over 50
revolutions. Prints medians of ``--repeats`` runs and the ratio.

Usage: ``python benchmarks/bench_simulate.py [--target 1e-2 1e-3] [--repeats 3] [--method Radau]``
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from scipy.integrate import solve_ivp

import mechanisms

SPEC = "coupler.deflection@0.5"
# Newton tolerance of generalized-alpha (relative to max |s0| ~ 2): the loosest that leaves the
# calibration errors unchanged (1e-10 ... 1e-6 give the same errors to 3 digits at 125 and 400 steps
# per period; 1e-5 does not); the constraint residual stays below ~1e-8 m.
NEWTON_TOL = 1e-7


def thesis_four_bar():
    return mechanisms.assemble(mechanisms.four_bar(discretisation="fem", n_elements=4))


def rigid_start(model):
    """Positions on the constraints at t = 0 with elastic coordinates zero (Newton on the frame
    coordinates from the mechanism's ``initial_angles``) and the consistent rigid velocities."""
    n, ri = model.n_coords, model.rigid_index
    s = np.zeros(n)
    for name, lay in model.layouts.items():
        s[lay.offset + 2] = model.mechanism.initial_angles.get(name, 0.0)
    for _ in range(50):
        ds = np.linalg.solve(model.constraint_jacobian(s, 0.0)[:, ri], -model.constraints(s, 0.0))
        s[ri] += ds
        if np.max(np.abs(ds)) < 1e-15:
            break
    v = np.zeros(n)
    v[ri] = np.linalg.solve(model.constraint_jacobian(s, 0.0)[:, ri], -model.constraint_rate(s, 0.0))
    return s, v


def baumgarte_rhs(model, rate):
    n, r = model.n_coords, model.n_constraints
    A = np.zeros((n + r, n + r))

    def rhs(t, y):
        s, v = y[:n], y[n:]
        Phi_s = model.constraint_jacobian(s, t)
        A[:n, :n] = model.mass_matrix(s)
        A[:n, n:] = Phi_s.T
        A[n:, :n] = Phi_s
        drift = Phi_s @ v + model.constraint_rate(s, t)
        b = np.concatenate([model.forces(s, v, t),
                            model.constraint_gamma(s, v, t) - 2.0 * rate * drift
                            - rate**2 * model.constraints(s, t)])
        return np.concatenate([v, np.linalg.solve(A, b)[:n]])
    return rhs


def run_ga(model, s0, v0, n_revs, steps_per_period):
    res = mechanisms.simulate(model, n_periods=n_revs, steps_per_period=steps_per_period, s0=s0,
                              sdot0=v0, observables=[SPEC], tol=NEWTON_TOL,
                              estimate_error=False)
    return res.t, res.observables[SPEC], res


def run_ivp(model, s0, v0, n_revs, rtol, method, t_eval=None, baumgarte=1000.0):
    t_end = n_revs * model.period
    obs = model.observable(SPEC)
    sol = solve_ivp(baumgarte_rhs(model, baumgarte), (0.0, t_end), np.concatenate([s0, v0]),
                    method=method, rtol=rtol, atol=rtol * 1e-3, t_eval=t_eval)
    if not sol.success:
        raise RuntimeError(f"solve_ivp({method}, rtol={rtol}) failed: {sol.message}")
    n = model.n_coords
    return sol.t, np.array([obs.value(y[:n]) for y in sol.y.T]), sol


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", type=float, nargs="+", default=[1e-2, 1e-3],
                        help="relative accuracies in the midspan deflection (default 1e-2 1e-3)")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--revs", type=float, default=50.0)
    parser.add_argument("--calibration-revs", type=int, default=2)
    parser.add_argument("--method", default="Radau", choices=["Radau", "BDF"])
    args = parser.parse_args()
    finest = min(args.target)

    model = thesis_four_bar()
    s0, v0 = rigid_start(model)
    print(f"model: {model}, period {model.period:.6g} s, {args.revs:g} revolutions, "
          f"targets {args.target} (max error in {SPEC} relative to its max)")

    # --- calibration on a shorter horizon ------------------------------------------------------
    run_ga(model, s0, v0, 0.1, 100)   # JIT warm-up
    # reference on a grid of period / 32000, which holds every generalized-alpha grid below
    t_cal = args.calibration_revs * model.period
    grid = np.linspace(0.0, t_cal, 32000 * args.calibration_revs + 1)
    _, d_ref, _ = run_ivp(model, s0, v0, args.calibration_revs, 1e-10, "Radau", t_eval=grid)
    scale = np.max(np.abs(d_ref))

    def rel_error(t, d):
        idx = np.rint(t / (grid[1] - grid[0])).astype(np.int64)
        assert np.allclose(grid[idx], t, rtol=0, atol=1e-9 * t_cal)
        return np.max(np.abs(d - d_ref[idx])) / scale

    ga_errors = {}
    for spp in (100, 125, 160, 200, 250, 320, 400, 500, 640, 800, 1000, 1280, 1600):
        try:
            t, d, res = run_ga(model, s0, v0, args.calibration_revs, spp)
        except mechanisms.SimulationError as err:
            print(f"  generalized-alpha {spp:5d} steps/period: failed ({err})")
            continue
        ga_errors[spp] = rel_error(t, d)
        print(f"  generalized-alpha {spp:5d} steps/period: rel. error {ga_errors[spp]:.3g} "
              f"({res.n_newton / res.n_steps:.2f} Newton it./step, {res.n_jacobian} Jacobians)")
        if ga_errors[spp] <= finest:
            break
    ivp_errors = {}
    for rtol in (1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01, 5e-3, 2e-3, 1e-3, 5e-4, 2e-4, 1e-4, 5e-5,
                 2e-5, 1e-5):
        t, d, sol = run_ivp(model, s0, v0, args.calibration_revs, rtol, args.method,
                            t_eval=grid[::80])
        ivp_errors[rtol] = rel_error(t, d)
        print(f"  solve_ivp {args.method} rtol {rtol:.0e}: rel. error {ivp_errors[rtol]:.3g} "
              f"(nfev {sol.nfev}, njev {sol.njev}, nlu {sol.nlu})")
        if ivp_errors[rtol] <= finest:
            break

    # --- timing over the full horizon ----------------------------------------------------------
    for target in sorted(args.target, reverse=True):
        spp = next((k for k, e in ga_errors.items() if e <= target), None)
        rtol = next((k for k, e in ivp_errors.items() if e <= target), None)
        if spp is None or rtol is None:
            print(f"target {target:g}: not reached with the settings tried")
            continue
        ga_times, ivp_times = [], []
        for _ in range(args.repeats):
            start = time.perf_counter()
            _, _, res = run_ga(model, s0, v0, args.revs, spp)
            ga_times.append(time.perf_counter() - start)
            start = time.perf_counter()
            _, _, sol = run_ivp(model, s0, v0, args.revs, rtol, args.method)
            ivp_times.append(time.perf_counter() - start)
        ga_med, ivp_med = statistics.median(ga_times), statistics.median(ivp_times)
        print(f"target {target:g}:")
        print(f"  generalized-alpha, {spp} steps/period (rel. error {ga_errors[spp]:.2g}): median "
              f"{ga_med:.3f} s over {args.repeats} runs ({res.n_steps} steps, {res.n_newton} Newton "
              f"it., {res.n_jacobian} Jacobians, max |Phi| {np.max(res.constraint_residual):.2g})")
        print(f"  solve_ivp {args.method}, rtol {rtol:.0e} (rel. error {ivp_errors[rtol]:.2g}): "
              f"median {ivp_med:.3f} s over {args.repeats} runs (nfev {sol.nfev}, njev {sol.njev}, "
              f"nlu {sol.nlu})")
        print(f"  ratio solve_ivp / generalized-alpha: {ivp_med / ga_med:.1f}x")


if __name__ == "__main__":
    main()
