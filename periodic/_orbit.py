"""Periodic orbits of a nonlinear system by Newton shooting on its period map.

A period map is any callable ``period_map(state, parameter) -> (end_state, monodromy)``: the state
(n,) at t = 0 -> the state after one period of the nonlinear system at that parameter value, and the
Jacobian ``d end_state / d state`` (n, n), the monodromy of the discrete step map.  A periodic orbit is
a fixed point ``P(x) = x``; Newton solves ``r(x) = P(x) - x = 0`` with ``J = monodromy - I``, damped by
a backtracking line search on ``|r|`` (Armijo).  At the solution the monodromy is the orbit's, and its
eigenvalues are the Floquet multipliers of the orbit; the verdict (stable, unstable, marginal with
the kind of the critical multiplier) is :func:`periodic.stability_verdict`'s, with the multipliers'
error bars when an estimate is given.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from ._floquet import modulus_errors, sorted_eigenvalues
from ._system import PeriodicError, check_real, check_tol
from ._verdict import STABILITY_TOL, stability_verdict, worst_status

#: ``period_map(state (n,), parameter: float) -> (end_state (n,), monodromy (n, n))``.
PeriodMap = Callable[[np.ndarray, float], "tuple[np.ndarray, np.ndarray]"]

#: Armijo constant of the line search: a step of length ``lam`` is accepted when the residual norm
#: falls by at least this fraction of ``lam`` times itself.
_SUFFICIENT_DECREASE = 1e-4
#: The line search halves the Newton step at most this many times (down to 1/64 of it).
_MAX_HALVINGS = 6
#: ``J = monodromy - I`` with a condition number above this is singular: Newton's step would be
#: rounding noise (a multiplier at +1 to about 1e-12: a fold, or a free mode of an unforced system).
_SINGULAR_CONDITION = 1e12
#: Default error factor of an N/2 estimate: ``1 / (2^p - 1)`` for the order-2 integrators of the project.
DEFAULT_ERROR_FACTOR = 1.0 / 3.0
#: Values of ``PeriodicOrbit.bifurcation``.
BIFURCATIONS = ("none", "fold", "period_doubling", "secondary_hopf")


@dataclass(frozen=True)
class PeriodicOrbit:
    """A periodic orbit ``P(state) = state`` of a period map, and its stability.

    Attributes
    ----------
    parameter : float
        The parameter value of the map.
    state : ndarray (n,)
        The state at t = 0 on the orbit (the last iterate when not ``converged``).
    monodromy : ndarray (n, n)
        ``d P / d state`` at ``state``.
    multipliers : ndarray (n,) complex
        Floquet multipliers (eigenvalues of ``monodromy``), decreasing modulus.
    multiplier_errors : ndarray (n,)
        Error estimate of each multiplier's modulus (from ``estimate``; NaN without one: the stability
        verdict's bar is then ``stability_tol`` alone).
    state_error : float
        Estimated max abs error of ``state`` from the coarse map of ``estimate`` (NaN without one).
    spectral_radius : float
        ``max |multipliers|``.
    iterations : int
        Newton steps taken.
    map_calls : int
        Calls of the period map (line-search trials and the estimate's included).
    residual : float
        ``|P(state) - state| / (|state| + state_scale)`` (2-norms) at ``state``.
    converged : bool
        ``residual <= tol``.
    is_stable : bool
        False where unstable (a multiplier outside the unit circle beyond its error bar) or not
        converged.
    bifurcation : str
        The kind of the critical multiplier where it is outside the unit circle or on it within its
        error bar (``status`` ``"unstable"`` or ``"marginal"``): ``"fold"`` (real, near +1: fold, or a
        branch point), ``"period_doubling"`` (real, near -1), ``"secondary_hopf"`` (a complex pair);
        ``"none"`` where stable or not converged.
    status : str
        ``"failed"`` (Newton did not converge: ``message`` says why), else the stability verdict
        (``"ok"``, ``"unstable"``, ``"marginal"``), or ``"inaccurate"`` when the estimate's coarse
        orbit was not found.
    message : str
        The verdict in words.
    run_time : float
        Wall time, s.
    """

    parameter: float
    state: np.ndarray
    monodromy: np.ndarray
    multipliers: np.ndarray
    multiplier_errors: np.ndarray
    state_error: float
    spectral_radius: float
    iterations: int
    map_calls: int
    residual: float
    converged: bool
    is_stable: bool
    bifurcation: str
    status: str
    message: str
    run_time: float


@dataclass(frozen=True)
class NewtonResult:
    """What :func:`newton` found: the last iterate ``y``, the evaluation there (``residual_vector``,
    ``jacobian``, ``extra``), its relative ``residual``, ``iterations``, ``converged`` and the
    ``reason`` of a failure ("" when converged)."""

    y: np.ndarray
    residual_vector: np.ndarray
    jacobian: np.ndarray
    extra: object
    residual: float
    iterations: int
    converged: bool
    reason: str


def newton(evaluate, y0, *, tol: float, max_iterations: int, relative) -> NewtonResult:
    """Damped Newton on ``F(y) = 0``.  ``evaluate(y) -> (F (m,), J (m, m), extra)`` may raise
    ``RuntimeError`` (a numerical failure of the map: treated like a non-finite value, the step is
    shortened); ``relative(y, F) -> float`` is the convergence measure, compared with ``tol``.
    A backtracking line search on ``|F|`` makes each accepted step decrease it."""
    y = np.array(y0, dtype=float)
    try:
        value, jacobian, extra = evaluate(y)
    except RuntimeError as error:
        return NewtonResult(y, np.full(y.shape, np.nan), np.full((y.size, y.size), np.nan), None, math.inf,
                            0, False, f"the period map failed at the initial guess: {error}")
    if not np.all(np.isfinite(value)):
        return NewtonResult(y, value, jacobian, extra, math.inf, 0, False,
                            "the period map is not finite at the initial guess")
    residual = relative(y, value)
    for iteration in range(max_iterations + 1):
        if residual <= tol:
            return NewtonResult(y, value, jacobian, extra, residual, iteration, True, "")
        if iteration == max_iterations:
            break
        if not np.all(np.isfinite(jacobian)):
            return NewtonResult(y, value, jacobian, extra, residual, iteration, False,
                                "the monodromy is not finite")
        condition = np.linalg.cond(jacobian)
        if not condition < _SINGULAR_CONDITION:
            return NewtonResult(y, value, jacobian, extra, residual, iteration, False, (
                f"singular Jacobian: monodromy - I has condition number {condition:.3g} (a multiplier at +1: "
                "a fold of the branch, use arclength continuation, or a free mode of an unforced system)"))
        direction = -np.linalg.solve(jacobian, value)
        norm = np.linalg.norm(value)
        length, accepted, failure = 1.0, False, ""
        for _ in range(_MAX_HALVINGS + 1):
            trial = y + length * direction
            try:
                trial_value, trial_jacobian, trial_extra = evaluate(trial)
            except RuntimeError as error:
                failure = f"the period map failed at a Newton trial ({error})"
            else:
                if not np.all(np.isfinite(trial_value)):
                    failure = "the period map is not finite at a Newton trial"
                elif np.linalg.norm(trial_value) <= (1.0 - _SUFFICIENT_DECREASE * length) * norm:
                    accepted = True
                    break
                else:
                    failure = ""
            length *= 0.5
        if not accepted:
            words = failure or "the residual does not decrease"
            return NewtonResult(y, value, jacobian, extra, residual, iteration, False, (
                f"diverging residual: {words} along the Newton direction even at 1/{2**_MAX_HALVINGS} of the "
                f"step (relative residual {residual:.3g}); start nearer the orbit or take smaller steps"))
        y, value, jacobian, extra = trial, trial_value, trial_jacobian, trial_extra
        residual = relative(y, value)
    return NewtonResult(y, value, jacobian, extra, residual, max_iterations, False, (
        f"max iterations: {max_iterations} Newton steps left the relative residual at {residual:.3g} > tol "
        f"{tol:g}; raise max_iterations or start nearer the orbit"))


class CountingMap:
    """``period_map`` with input checks on what it returns and a count of its calls."""

    def __init__(self, period_map, n: int):
        if not callable(period_map):
            raise TypeError(f"period_map: expected a callable (state, parameter) -> (end_state, monodromy), "
                            f"got {type(period_map).__name__}")
        self.period_map, self.n, self.calls = period_map, n, 0

    def __call__(self, state, parameter):
        self.calls += 1
        end, monodromy = self.period_map(state, parameter)
        end = np.asarray(end, dtype=float)
        monodromy = np.asarray(monodromy, dtype=float)
        if end.shape != (self.n,) or monodromy.shape != (self.n, self.n):
            raise PeriodicError(f"period_map: expected to return an end state ({self.n},) and a monodromy "
                                f"({self.n}, {self.n}), got {end.shape} and {monodromy.shape}")
        return end, monodromy


def relative_residual(state, residual_vector, state_scale: float) -> float:
    """``|r| / (|state| + state_scale)`` (2-norms); ``|r|`` itself when both are 0."""
    denominator = np.linalg.norm(state) + state_scale
    norm = float(np.linalg.norm(residual_vector))
    return norm / denominator if denominator > 0.0 else norm


def check_state(name: str, state) -> np.ndarray:
    """A 1-D finite float array (n >= 1)."""
    state = np.array(state, dtype=float)
    if state.ndim != 1 or state.size == 0:
        raise PeriodicError(f"{name}: expected a 1-dimensional state (n,), got shape {state.shape}")
    if not np.all(np.isfinite(state)):
        raise PeriodicError(f"{name}: expected finite values, got {state}")
    return state


def check_iterations(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}: expected an integer >= 1, got {type(value).__name__}")
    if value < 1:
        raise PeriodicError(f"{name}: expected an integer >= 1, got {value}")
    return int(value)


def solve_fixed_point(period_map: CountingMap, guess, parameter, *, tol, max_iterations, state_scale):
    """Newton on ``P(x) - x`` at a fixed parameter; ``extra`` of the result is the monodromy."""

    def evaluate(state):
        end, monodromy = period_map(state, parameter)
        return end - state, monodromy - np.eye(state.size), monodromy

    return newton(evaluate, guess, tol=tol, max_iterations=max_iterations,
                  relative=lambda state, value: relative_residual(state, value, state_scale))


def classify(parameter, state, monodromy, *, residual, iterations, map_calls, converged, reason="",
             errors=None, state_error=math.nan, stability_tol=STABILITY_TOL, start_time) -> PeriodicOrbit:
    """A :class:`PeriodicOrbit` from a Newton result: multipliers, verdict, message."""
    n = state.size
    if np.all(np.isfinite(monodromy)):
        multipliers = sorted_eigenvalues(monodromy)
    else:
        multipliers = np.full(n, complex("nan"))
    radius = float(np.max(np.abs(multipliers)))
    error_array = np.full(n, math.nan) if errors is None else np.asarray(errors, dtype=float)
    run_time = time.perf_counter() - start_time
    if not converged:
        message = f"failed: Newton shooting did not converge at parameter {parameter:.6g}: {reason}"
        return PeriodicOrbit(parameter, state, monodromy, multipliers, error_array, state_error, radius,
                             iterations, map_calls, residual, False, False, "none", "failed", message, run_time)
    verdict = stability_verdict(multipliers, errors, np.zeros(n), stability_tol=stability_tol)
    bifurcation = verdict.kind if verdict.status in ("unstable", "marginal") else "none"
    message = (f"{verdict.message}; orbit found in {iterations} Newton steps, relative residual "
               f"{residual:.2g}")
    return PeriodicOrbit(parameter, state, monodromy, multipliers, error_array, state_error, radius,
                         iterations, map_calls, residual, True, verdict.is_stable, bifurcation or "none",
                         verdict.status, message, run_time)


def find_orbit(period_map: PeriodMap, guess, parameter: float, *, tol: float = 1e-10, max_iterations: int = 20,
               estimate=None, error_factor: float = DEFAULT_ERROR_FACTOR, state_scale: float = 0.0,
               stability_tol: float = STABILITY_TOL) -> PeriodicOrbit:
    """The periodic orbit of ``period_map`` at ``parameter`` near ``guess`` (n,) by Newton shooting.

    ``period_map(state (n,), parameter) -> (end_state (n,), monodromy (n, n))``.  Newton on
    ``P(x) - x`` with ``J = monodromy - I`` and a backtracking line search, until the relative residual
    ``|P(x) - x| / (|x| + state_scale)`` is at most ``tol`` (``state_scale``, units of the state: an
    absolute floor for orbits near 0).  A failure (``max_iterations`` reached, a singular Jacobian, a
    residual that no step shortening decreases, a map that raises ``RuntimeError`` or returns
    non-finite values) gives ``status = "failed"`` with the reason; nothing is raised.

    ``estimate`` sets the error bars of the stability verdict: None (the bar is ``stability_tol``),
    the multipliers' modulus errors (a float or (n,)), or the same period map on N/2 steps: the orbit
    is then found again on it from ``state``, and ``error_factor * |x_N - x_{N/2}|`` (max norm) and
    ``error_factor * ||mu_N| - |mu_{N/2}||`` (nearest multipliers) are the error estimates of the state
    and of each multiplier (``error_factor = 1 / (2^p - 1)`` for an integrator of order p: 1/3).
    """
    start_time = time.perf_counter()
    guess = check_state("guess", guess)
    parameter = check_real("parameter", parameter)
    tol = check_tol("tol", tol, 1.0)
    max_iterations = check_iterations("max_iterations", max_iterations)
    state_scale = check_tol("state_scale", state_scale)
    counted = CountingMap(period_map, guess.size)
    found = solve_fixed_point(counted, guess, parameter, tol=tol, max_iterations=max_iterations,
                              state_scale=state_scale)
    monodromy = found.extra if found.extra is not None else found.jacobian + np.eye(guess.size)
    errors, state_error, coarse_failure, coarse_calls = _estimate(estimate, found, parameter, monodromy, tol=tol,
                                                    max_iterations=max_iterations, state_scale=state_scale,
                                                    error_factor=error_factor)
    orbit = classify(parameter, found.y, monodromy, residual=found.residual, iterations=found.iterations,
                     map_calls=counted.calls + coarse_calls, converged=found.converged, reason=found.reason, errors=errors,
                     state_error=state_error, stability_tol=stability_tol, start_time=start_time)
    if coarse_failure:
        status = worst_status(orbit.status, "inaccurate")
        message = f"{orbit.message}; inaccurate: no error estimate, {coarse_failure}"
        orbit = replace(orbit, status=status, message=message)
    return orbit


def _estimate(estimate, found: NewtonResult, parameter, monodromy, *, tol, max_iterations, state_scale,
              error_factor):
    """``(multiplier errors or None, state error, failure words, coarse map calls)`` from ``estimate`` (see find_orbit)."""
    if estimate is None or not found.converged:
        return None, math.nan, "", 0
    n = found.y.size
    if not callable(estimate):
        errors = np.broadcast_to(np.asarray(estimate, dtype=float), (n,)).copy()
        if not np.all(errors >= 0.0):
            raise PeriodicError(f"estimate: expected multiplier errors >= 0 (a float or ({n},)), got {estimate}")
        return errors, math.nan, "", 0
    error_factor = check_tol("error_factor", error_factor, 1.0)
    counted = CountingMap(estimate, n)
    coarse = solve_fixed_point(counted, found.y, parameter, tol=tol,
                               max_iterations=max_iterations, state_scale=state_scale)
    if not coarse.converged:
        return None, math.nan, f"the orbit of the coarse map (estimate) was not found: {coarse.reason}", counted.calls
    multipliers = sorted_eigenvalues(monodromy)
    coarse_multipliers = sorted_eigenvalues(coarse.extra)
    errors = modulus_errors(multipliers, coarse_multipliers, error_factor)
    # the modulus errors, not the complex ones: a lightly damped mode's phase error is far larger and
    # does not move its multiplier across the unit circle (see periodic._floquet.modulus_errors)
    return errors, error_factor * float(np.max(np.abs(found.y - coarse.y))), "", counted.calls
