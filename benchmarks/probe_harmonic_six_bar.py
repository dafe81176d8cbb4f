"""A probe of issue 24's second route, not a method of the tool: harmonic balance of the six-bar's
nonlinear periodic state (8 elements per elastic link, reduced to 4 + 4 modes, 100 rad/s) in the
linearisation's independent coordinates, against the shooting (``periodic.find_orbit`` to 1e-10 with
its N/2 estimate).

The residual: the independent coordinates' Fourier series give ``z, z', z''`` at S samples; the
dependent coordinates follow from the position, velocity and acceleration constraints; the equations
``M s'' - Q`` are projected on the constraints' null space ``V = [I; -Phi_d^-1 Phi_i]`` at each
sample (the multipliers drop out). At ``z = 0`` it equals the linear system's ``-f`` (printed). Then:
(1) ``periodic.harmonic_balance`` with the linearisation's ``M, C, K`` kept (chord) from the linear
steady state; (2) the residual's Jacobian by differences against that tangent, at ``z = 0`` and at
the linear state, column by column; (2b) the same against the linearisation about the iterate's own
motion (``tangent_along``), (2c) Newton with it, (2d) chord with it kept from the linear state, and
the cost of one tangent and of one residual; (3) Newton with the difference Jacobian (slow: a check
of the route, not a method), and its orbit against the shooting's. Findings: docs/benchmarks.md
(session 12).

Run: .venv/bin/python benchmarks/probe_harmonic_six_bar.py [H [S]]   (defaults 16 harmonics, 64 samples)
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import mechanisms
import periodic
import studies
from periodic import _harmonic  # the balance's basis and Newton pieces: no public face
from studies._kinds._nonlinear_model import choose_model  # the study's model choice
from studies._kinds.nonlinear_steady_state import shooting_setup  # its linear start and period maps

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_nonlinear_exudyn as bench  # noqa: E402 - the benchmark's six-bar

N_STEPS = 256


class SixBar:
    """The projected residual of the reduced six-bar at S samples of one period."""

    def __init__(self, samples: int):
        problem, values = bench.problem_and_values()
        with mechanisms.fused_step(True):
            studies.nonlinear_steady_state(problem, values, n_steps=32, max_iterations=1)
        self.choice = choose_model(problem, values, "auto")
        self.setup = shooting_setup(self.choice.problem, self.choice.values, N_STEPS)
        linear = self.setup.linear
        context, self.model = linear.context, self.setup.fine.model
        self.independent = np.asarray(context.coefficients.independent)
        self.dependent = np.setdiff1d(np.arange(self.model.n_coords), self.independent)
        system = linear.system
        self.period, self.samples, self.m = system.period, samples, self.independent.size
        stride = N_STEPS // samples
        self.t = np.arange(samples) * (self.period / samples)
        nominal = context.nominal
        self.s0, self.s0_rate, self.s0_acc = (a[:-1:stride][:samples] for a in (nominal.s, nominal.sdot, nominal.sddot))
        self.drift = nominal.s[-1] - nominal.s[0]
        self.tangents = tuple(a[:-1:stride][:samples] for a in (system.M, system.C, system.K))
        self.force = system.f[:-1:stride][:samples]
        self.linear_state = self.setup.steady.state.x[:-1:stride][:samples, :self.m]
        self.calls = 0

    def motion(self, z, z_rate, z_acc):
        """Full coordinates, rates, accelerations (S, n) and the constraint blocks Phi_d, Phi_i."""
        ind, dep, model, t = self.independent, self.dependent, self.model, self.t
        s = self.s0.copy()
        s[:, ind] += z
        for _ in range(20):
            terms = model.constraint_terms_along(t, s, values=True)
            if np.abs(terms.values).max() < 1e-14:
                break
            s[:, dep] -= np.linalg.solve(terms.jacobian[:, :, dep], terms.values[..., None])[..., 0]
        rate = self.s0_rate.copy()
        rate[:, ind] += z_rate
        terms = model.constraint_terms_along(t, s)
        phi_d, phi_i = terms.jacobian[:, :, dep], terms.jacobian[:, :, ind]
        known = -terms.rate - np.einsum("sij,sj->si", phi_i, rate[:, ind])
        rate[:, dep] = np.linalg.solve(phi_d, known[..., None])[..., 0]
        gamma = model.constraint_terms_along(t, s, rate).gamma
        acc = self.s0_acc.copy()
        acc[:, ind] += z_acc
        known = gamma - np.einsum("sij,sj->si", phi_i, acc[:, ind])
        acc[:, dep] = np.linalg.solve(phi_d, known[..., None])[..., 0]
        return s, rate, acc, phi_d, phi_i

    def residual(self, t, z, z_rate, z_acc):
        self.calls += 1
        s, rate, acc, phi_d, phi_i = self.motion(z, z_rate, z_acc)
        out = np.empty((self.samples, self.m))
        for j in range(self.samples):
            full = self.model.mass_matrix(s[j]) @ acc[j] - self.model.forces(s[j], rate[j], self.t[j])
            # V^T R with V = [I; -Phi_d^-1 Phi_i]
            out[j] = full[self.independent] - phi_i[j].T @ np.linalg.solve(phi_d[j].T, full[self.dependent])
        return out

    def tangent(self, t, z, z_rate, z_acc):
        return self.tangents

    def tangent_along(self, t, z, z_rate, z_acc):
        """The linearisation about the iterate's own motion (``linearize``'s ``linear_coefficients``,
        its multipliers from the dependent rows, ``Phi_d^T lam = -(M s'' - Q)_d``): Newton's tangent."""
        from linearize._core import linear_coefficients  # the linearisation's core: no public face

        s, rate, acc, phi_d, _ = self.motion(z, z_rate, z_acc)
        lam = np.empty((self.samples, phi_d.shape[1]))
        for j in range(self.samples):
            full = self.model.mass_matrix(s[j]) @ acc[j] - self.model.forces(s[j], rate[j], self.t[j])
            lam[j] = np.linalg.solve(phi_d[j].T, -full[self.dependent])
        def close(a, drift=0.0):    # the grid's t_N = T repeats t_0 (the angles of turning links plus a turn)
            return np.concatenate([a, a[:1] + drift])

        grid = np.append(self.t, self.period)
        coefficients = linear_coefficients(self.model, grid, close(s, self.drift), close(rate), close(acc),
                                           close(lam), period=self.period, independent=self.independent)
        return coefficients.M[:-1], coefficients.C[:-1], coefficients.K[:-1]


def difference_jacobian(newton, coefficients, scale=1e-7):
    value = newton.projected(coefficients).ravel()
    jacobian = np.empty((value.size, value.size))
    for column in range(value.size):
        step = np.zeros(value.size)
        step[column] = scale * max(1e-3, abs(coefficients.ravel()[column]))
        jacobian[:, column] = (newton.projected(coefficients + step.reshape(coefficients.shape)).ravel()
                               - value) / step[column]
    return value, jacobian


def _mean_ms(call, repeats: int = 5) -> float:
    started = time.perf_counter()
    for _ in range(repeats):
        call()
    return (time.perf_counter() - started) / repeats * 1e3


def main() -> None:
    harmonics = int(sys.argv[1]) if len(sys.argv) > 1 else 16
    samples = int(sys.argv[2]) if len(sys.argv) > 2 else 64
    case = SixBar(samples)
    m, t, period = case.m, case.t, case.period
    zero = np.zeros((samples, m))
    print(f"six_bar reduced: {case.model.n_coords} coordinates, {m} independent, H = {harmonics}, S = {samples}")
    at_zero = np.abs(case.residual(t, zero, zero, zero) + case.force).max()
    print(f"residual at z = 0 against the linear system's -f: {at_zero:.3g} (|f| {np.abs(case.force).max():.3g})")
    basis, rate, acceleration = _harmonic.fourier_basis(t, period, harmonics)
    guess = np.linalg.lstsq(basis, case.linear_state, rcond=None)[0]
    started = time.perf_counter()
    chord = periodic.harmonic_balance(case.residual, case.tangent, guess, period, harmonics=harmonics,
                                      samples=samples, update_jacobian=False, tol=1e-9, max_iterations=40)
    print(f"(1) chord with the linearisation's tangent: {chord.message} ({time.perf_counter() - started:.3f} s)")
    projection = basis.T * (2.0 / samples)
    projection[0] *= 0.5
    newton = _harmonic._Newton(case.residual, case.tangent, t, basis, rate, acceleration, projection, False)
    for name, at in (("z = 0", np.zeros_like(guess)), ("the linear state", guess)):
        _, jacobian = difference_jacobian(newton, at)
        linear = newton.jacobian(at)
        worst = np.abs(jacobian - linear).max(axis=0) / np.abs(linear).max(axis=0)
        print(f"(2) at {name}: the residual's Jacobian against the linear tangent, largest column difference "
              f"{worst.max():.3g} of the column (median {np.median(worst):.3g})")
    tangent_newton = _harmonic._Newton(case.residual, case.tangent_along, t, basis, rate, acceleration, projection,
                                       True)
    for name, at in (("z = 0", np.zeros_like(guess)), ("the linear state", guess)):
        _, jacobian = difference_jacobian(newton, at)
        along = tangent_newton.jacobian(at)
        worst = np.abs(jacobian - along).max(axis=0) / np.abs(along).max(axis=0)
        print(f"(2b) at {name}: against the linearisation about the iterate's motion, largest column difference "
              f"{worst.max():.3g} (median {np.median(worst):.3g})")
    started = time.perf_counter()
    exact = periodic.harmonic_balance(case.residual, case.tangent_along, guess, period, harmonics=harmonics,
                                      samples=samples, update_jacobian=True, tol=1e-9, max_iterations=40)
    print(f"(2c) Newton with that tangent: {exact.message} ({time.perf_counter() - started:.3f} s)")
    started = time.perf_counter()
    kept = periodic.harmonic_balance(case.residual, case.tangent_along, guess, period, harmonics=harmonics,
                                     samples=samples, update_jacobian=False, tol=1e-9, max_iterations=40,
                                     estimate_error=True)
    print(f"(2d) chord with that tangent at the linear state: {kept.message} ({time.perf_counter() - started:.3f} s,"
          f" the truncation estimate's H/2 and H/4 solutions included)")
    print(f"     one tangent and Jacobian: {_mean_ms(lambda: tangent_newton.jacobian(guess)):.1f} ms; "
          f"one residual: {_mean_ms(lambda: case.residual(t, zero, zero, zero)):.1f} ms")
    speed = float(case.choice.values["speed"])
    orbit = periodic.find_orbit(case.setup.fine, case.setup.guess, speed, tol=1e-10, estimate=case.setup.coarse)
    coefficients, started, iterations = guess.copy(), time.perf_counter(), 0
    while iterations < 12:
        value, jacobian = difference_jacobian(newton, coefficients)
        step = np.linalg.solve(jacobian, value).reshape(coefficients.shape)
        coefficients, iterations = coefficients - step, iterations + 1
        correction = np.abs(step).max() / np.abs(coefficients).max()
        if correction <= 1e-9:
            break
    state = np.concatenate([basis[:1] @ coefficients, rate[:1] @ coefficients], axis=1)[0]
    print(f"(3) Newton with the difference Jacobian: {iterations} iterations, correction {correction:.2g} "
          f"({time.perf_counter() - started:.1f} s); against the shooting ({orbit.status}, state error "
          f"{orbit.state_error:.3g}): positions {np.abs(state[:m] - orbit.state[:m]).max():.3g}, rates "
          f"{np.abs(state[m:2 * m] - orbit.state[m:2 * m]).max():.3g}; residual evaluations "
          f"{case.calls}")


if __name__ == "__main__":
    main()
