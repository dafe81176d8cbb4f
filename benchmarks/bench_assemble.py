"""Cost of one evaluation of the assembled equations of motion, against sympy-generated code.

Thesis four-bar OABC with an elastic coupler (2 Ritz bending modes + 1 axial mode, geometric
stiffening, Rayleigh damping, a point mass, gravity; 12 coordinates, 9 constraints). The baseline is
the same model derived by sympy (Lagrange with the energies integrated exactly, as in
tests/test_assemble.py) and lambdified with common-subexpression elimination: closed-form code for
this one mechanism, the fastest thing a hand derivation can give. The generic assembler is also
timed on the four-bar with 4 and 16 Hermite elements on the coupler (no baseline: the sympy route is
not practical there). Times are medians of repeated runs in this process, per call, in microseconds,
including the wrappers' argument checks.

Run: .venv/bin/python benchmarks/bench_assemble.py [--quick]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from mechanisms import Fem, Ritz, assemble

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the sympy model lives in the tests
from tests.test_assemble import _derive_fourbar, fourbar, random_state  # noqa: E402


def per_call(func, calls, repeats):
    times = []
    func()
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            func()
        times.append((time.perf_counter() - start) / calls)
    return statistics.median(times) * 1e6


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    args = parser.parse_args()
    calls, repeats = (200, 3) if args.quick else (2000, 7)

    model = assemble(fourbar(Ritz(2, 1)))
    mass_f, forces_f, jac_f, _ = _derive_fourbar(True, False, cse=True)
    s, sdot = random_state(model, np.random.default_rng(0))
    t = 0.01
    print(f"thesis four-bar, Ritz(2, 1): n = {model.n_coords}, r = {model.n_constraints}")
    print(f"{'method':<22}{'assembler us':>14}{'sympy us':>12}{'ratio':>8}")
    for name, ours, theirs in (
            ("mass_matrix", lambda: model.mass_matrix(s), lambda: mass_f(s, sdot, t)),
            ("forces", lambda: model.forces(s, sdot, t), lambda: forces_f(s, sdot, t)),
            ("constraint_jacobian", lambda: model.constraint_jacobian(s, t),
             lambda: jac_f(s, sdot, t))):
        a, b = per_call(ours, calls, repeats), per_call(theirs, calls, repeats)
        print(f"{name:<22}{a:>14.1f}{b:>12.1f}{b / a:>8.2f}")

    for n_elements in (4, 16):
        model = assemble(fourbar(Fem(n_elements)))
        s, sdot = random_state(model, np.random.default_rng(0))
        lam = np.ones(model.n_constraints)
        print(f"\nthesis four-bar, Fem({n_elements}): n = {model.n_coords}")
        for name, func in (
                ("mass_matrix", lambda: model.mass_matrix(s)),
                ("forces", lambda: model.forces(s, sdot, t)),
                ("force_jacobians", lambda: model.force_jacobians(s, sdot, t)),
                ("mass_matrix_jacobian", lambda: model.mass_matrix_jacobian(s, sdot)),
                ("constraints", lambda: model.constraints(s, t)),
                ("constraint_jacobian", lambda: model.constraint_jacobian(s, t)),
                ("constraint_gamma", lambda: model.constraint_gamma(s, sdot, t)),
                ("constraint_force_jac", lambda: model.constraint_force_jacobian(s, lam, t))):
            print(f"{name:<22}{per_call(func, calls, repeats):>14.1f}")


if __name__ == "__main__":
    main()
