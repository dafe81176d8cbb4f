"""Periodic solutions by harmonic balance: the first piece of issue 24's second route.

The unknowns are the Fourier coefficients of ``x(t)`` (n,) over one period ``T``,

    x(t) = X_0 + sum_k X_k cos(k w t) + Y_k sin(k w t),   k = 1..H,   w = 2 pi / T,

stored as the rows ``[X_0, X_1..X_H, Y_1..Y_H]`` ((2H + 1, n)). The equations ``r(t, x, x', x'') = 0``
(n,) are met in the Galerkin sense: their projection on the same 2H + 1 functions vanishes. They are
evaluated in the time domain (alternating frequency-time, AFT) at ``S`` equally spaced samples, and
projected by the discrete Fourier sums, which are exact for the harmonics up to ``S/2 - 1``: a cubic
term of a signal of H harmonics has 3H, so ``S >= 4H + 2`` keeps the projection free of aliasing
(the default). Newton on the coefficients takes its Jacobian from the equations' tangent matrices
``M = dr/dx''``, ``C = dr/dx'``, ``K = dr/dx`` at the samples, ``J = P (M E'' + C E' + K E)`` with ``E``
the basis at the samples and ``P`` the projection: with ``update_jacobian=False`` the tangent at the
start is kept for every iteration (chord iterations: a mechanism's linearisation about its nominal
motion is such a tangent), else it is evaluated again at every iterate (Newton).

No time step: for a smooth periodic solution the truncation error falls faster than any power of H
(``estimate_error``: the solution again on H/2 harmonics, the largest difference of the two signals
at the samples; it bounds the error only where the spectrum already decays, which the H/4 solution
checks: ``error_trusted``). Stability (the multipliers) is not computed here: a monodromy of the
converged orbit is the shooting's (``periodic.find_orbit``).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ._system import PeriodicError, check_real, check_tol

#: A correction whose end gives a non-finite residual is halved at most this many times.
_MAX_HALVINGS = 10
#: The truncation estimate (H against H/2) is trusted where the H/2, H/4 difference is at least this
#: many times the H, H/2 one (the spectrum decays: the estimate is then the H/2 solution's error,
#: larger than the H one's) and H >= 4; on the pumped Duffing oscillator the ratio is 0.5 at H = 4
#: (not yet decaying), 70 at 8 and 3500 at 16.
TRUSTED_DECAY = 2.0

#: ``residual(t (S,), x (S, n), v (S, n), a (S, n)) -> (S, n)``: the equations at the samples.
Residual = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]
#: ``tangent(t, x, v, a) -> (M, C, K)``, each (S, n, n): the residual's derivatives by a, v and x.
Tangent = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], "tuple[np.ndarray, np.ndarray, np.ndarray]"]


@dataclass(frozen=True)
class HarmonicBalance:
    """A periodic solution by :func:`harmonic_balance` (n unknowns, H harmonics).

    Attributes
    ----------
    coefficients : ndarray (2H + 1, n)
        ``[X_0, X_1..X_H, Y_1..Y_H]`` (units of x): ``x(t) = X_0 + sum X_k cos(k w t) + Y_k sin(k w t)``.
    period : float
        ``T``, s.
    harmonics : int
        H.
    samples : int
        S, the time samples of the residual's evaluation.
    residual : float
        The projected residual's 2-norm at the solution (units of the equations).
    correction : float
        The last Newton correction's max norm relative to the coefficients' (the convergence test).
    iterations : int
        Newton (or chord) iterations.
    converged : bool
    truncation_error : float
        ``estimate_error``: max over the samples and unknowns of ``|x_H - x_{H/2}|`` (units of x); NaN
        where not estimated or the H/2 solution was not found.
    error_trusted : bool
        Whether ``truncation_error`` bounds the error: H >= 4 and the H/2, H/4 difference at least
        ``TRUSTED_DECAY`` times the H, H/2 one (the spectrum decays; the estimate is then the H/2
        solution's error, larger than this one's). False where not estimated.
    message : str
        What happened, in words.
    run_time : float
        Wall time, s.
    """

    coefficients: np.ndarray
    period: float
    harmonics: int
    samples: int
    residual: float
    correction: float
    iterations: int
    converged: bool
    truncation_error: float
    error_trusted: bool
    message: str
    run_time: float

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(x, v, a)`` at the times ``t`` (m,), each (m, n)."""
        basis, rate, acceleration = fourier_basis(np.atleast_1d(np.asarray(t, dtype=float)), self.period,
                                                  self.harmonics)
        return basis @ self.coefficients, rate @ self.coefficients, acceleration @ self.coefficients


def fourier_basis(t: np.ndarray, period: float, harmonics: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The basis ``[1, cos(k w t), sin(k w t)]`` (k = 1..H) at the times ``t`` (m,) and its first and
    second time derivatives, each (m, 2H + 1)."""
    w = 2.0 * math.pi / period
    k = np.arange(1, harmonics + 1)
    phase = np.outer(t, k * w)
    cos, sin = np.cos(phase), np.sin(phase)
    kw = k * w
    basis = np.hstack([np.ones((t.size, 1)), cos, sin])
    rate = np.hstack([np.zeros((t.size, 1)), -sin * kw, cos * kw])
    acceleration = np.hstack([np.zeros((t.size, 1)), -cos * kw**2, -sin * kw**2])
    return basis, rate, acceleration


def harmonic_balance(residual: Residual, tangent: Tangent, guess, period: float, *, harmonics: int,
                     samples: int | None = None, tol: float = 1e-10, max_iterations: int = 30,
                     update_jacobian: bool = True, estimate_error: bool = False) -> HarmonicBalance:
    """The periodic solution of ``residual(t, x, x', x'') = 0`` over ``period`` (s) on ``harmonics``
    harmonics (module notes), from ``guess``: coefficients ((2H + 1, n), e.g. a linear solution's) or
    an (n,) constant. ``samples``: S (default ``4 H + 4``; at least ``2 H + 2``). Converged once the
    Newton correction is at most ``tol`` of the coefficients (max norms; plus 1e-300); a correction is
    shortened only where the residual is not finite at its end. A numerical failure (``residual`` or
    ``tangent`` raising ``RuntimeError``, a non-finite value, a singular Jacobian, no convergence in
    ``max_iterations``) is returned, not raised (``converged`` False, ``message``); bad input raises ``PeriodicError``
    naming the argument."""
    started = time.perf_counter()
    period = check_real("period", period)
    if not period > 0.0:
        raise PeriodicError(f"period: expected a duration > 0 s, got {period:g}")
    harmonics = _count("harmonics", harmonics, 1)
    samples = 4 * harmonics + 4 if samples is None else _count("samples", samples, 2 * harmonics + 2)
    tol = check_tol("tol", tol, 1.0)
    max_iterations = _count("max_iterations", max_iterations, 1)
    if not callable(residual) or not callable(tangent):
        raise TypeError("residual, tangent: expected callables (t, x, v, a) -> residual (S, n) and -> (M, C, K)")
    coefficients = _start(guess, harmonics)
    t = np.arange(samples) * (period / samples)
    basis, rate, acceleration = fourier_basis(t, period, harmonics)
    # the discrete projection: exact for the harmonics up to S/2 - 1
    projection = basis.T * (2.0 / samples)
    projection[0] *= 0.5
    solver = _Newton(residual, tangent, t, basis, rate, acceleration, projection, update_jacobian)
    found = solver.solve(coefficients, tol, max_iterations)
    error, trusted, words = math.nan, False, ""
    if estimate_error and found.converged:
        error, trusted, words = _truncation(residual, tangent, found, t, period, samples, tol, max_iterations,
                                            update_jacobian)
    return HarmonicBalance(found.coefficients, period, harmonics, samples, found.residual, found.correction,
                           found.iterations, found.converged, error, trusted, found.message + words,
                           time.perf_counter() - started)


def _truncation(residual, tangent, found, t, period, samples, tol, max_iterations, update_jacobian):
    """(estimate, trusted, words) of the truncation error of ``found`` (H harmonics): the largest
    difference of its signal from the H/2 solution's at the samples, trusted where the H/2, H/4
    difference is at least ``TRUSTED_DECAY`` times as large (H >= 4)."""
    harmonics = (found.coefficients.shape[0] - 1) // 2
    signals = [fourier_basis(t, period, harmonics)[0] @ found.coefficients]
    for level in (harmonics // 2, harmonics // 4):
        if level < 1:
            break
        coarse = harmonic_balance(residual, tangent, found.coefficients[_kept_rows(harmonics, level)], period,
                                  harmonics=level, samples=samples, tol=tol, max_iterations=max_iterations,
                                  update_jacobian=update_jacobian)
        if not coarse.converged:
            break
        signals.append(fourier_basis(t, period, level)[0] @ coarse.coefficients)
    if len(signals) < 2:
        return math.nan, False, f"; no truncation error estimate: the solution on H/2 = {harmonics // 2} harmonics " \
                                "was not found"
    error = float(np.abs(signals[0] - signals[1]).max())
    coarse_error = float(np.abs(signals[1] - signals[2]).max()) if len(signals) > 2 else math.nan
    trusted = harmonics >= 4 and (coarse_error >= TRUSTED_DECAY * error or coarse_error == error == 0.0)
    words = f"; truncation error estimate {error:.3g} (H against H/2 = {harmonics // 2}"
    if trusted:
        return error, True, words + ", trusted: the differences decay)"
    return error, False, words + (f", not trusted: the H/2, H/4 difference {coarse_error:.3g} is not "
                                  f"{TRUSTED_DECAY:g} times it; raise harmonics)")


def _count(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}: expected an integer >= {minimum}, got {type(value).__name__}")
    if value < minimum:
        raise PeriodicError(f"{name}: expected an integer >= {minimum}, got {value}")
    return int(value)


def _kept_rows(harmonics: int, kept: int) -> np.ndarray:
    """Rows of the coefficients of H harmonics that the first ``kept`` harmonics take."""
    return np.concatenate([[0], np.arange(1, kept + 1), harmonics + np.arange(1, kept + 1)])


def _start(guess, harmonics: int) -> np.ndarray:
    guess = np.array(guess, dtype=float)
    if guess.size and not np.all(np.isfinite(guess)):
        raise PeriodicError("guess: expected finite values")
    if guess.ndim == 1 and guess.size:
        start = np.zeros((2 * harmonics + 1, guess.size))
        start[0] = guess
        return start
    if guess.ndim != 2 or guess.shape[0] % 2 != 1 or guess.shape[1] == 0:
        raise PeriodicError(f"guess: expected coefficients (2H + 1, n) or a constant (n,), got shape {guess.shape}")
    given = (guess.shape[0] - 1) // 2
    start = np.zeros((2 * harmonics + 1, guess.shape[1]))
    kept = min(given, harmonics)
    start[_kept_rows(harmonics, kept)] = guess[_kept_rows(given, kept)]
    return start


@dataclass(frozen=True)
class _Found:
    coefficients: np.ndarray
    residual: float
    correction: float
    iterations: int
    converged: bool
    message: str


class _Newton:
    """Newton (or chord) iterations on the projected residual of :func:`harmonic_balance`."""

    def __init__(self, residual, tangent, t, basis, rate, acceleration, projection, update_jacobian):
        self.residual, self.tangent, self.t = residual, tangent, t
        self.basis, self.rate, self.acceleration, self.projection = basis, rate, acceleration, projection
        self.update_jacobian = update_jacobian

    def signals(self, coefficients):
        return self.basis @ coefficients, self.rate @ coefficients, self.acceleration @ coefficients

    def projected(self, coefficients) -> np.ndarray:
        """The projected residual (2H + 1, n)."""
        x, v, a = self.signals(coefficients)
        values = np.asarray(self.residual(self.t, x, v, a), dtype=float)
        if values.shape != x.shape:
            raise PeriodicError(f"residual: expected to return shape {x.shape} (samples, unknowns), got {values.shape}")
        return self.projection @ values

    def jacobian(self, coefficients) -> np.ndarray:
        """d(projected residual) / d(coefficients), ((2H + 1) n, (2H + 1) n), rows and columns in the
        coefficients' row-major order."""
        x, v, a = self.signals(coefficients)
        mass, damping, stiffness = (np.asarray(m, dtype=float) for m in self.tangent(self.t, x, v, a))
        blocks = (np.einsum("hs,sij,sk->hikj", self.projection, mass, self.acceleration)
                  + np.einsum("hs,sij,sk->hikj", self.projection, damping, self.rate)
                  + np.einsum("hs,sij,sk->hikj", self.projection, stiffness, self.basis))
        size = blocks.shape[0] * blocks.shape[1]
        return blocks.reshape(size, size)

    def solve(self, coefficients, tol, max_iterations) -> _Found:
        """Newton (or chord) iterations, full steps unless the residual is not finite at one."""
        import scipy.linalg

        shape = coefficients.shape
        kind = "Newton" if self.update_jacobian else "chord"
        factors, correction, iteration = None, math.inf, 0
        try:
            value = self.projected(coefficients)
            if not np.all(np.isfinite(value)):
                return _Found(coefficients, math.inf, math.inf, 0, False, "the residual is not finite at the start")
            for iteration in range(1, max_iterations + 1):
                if factors is None or self.update_jacobian:
                    jacobian = self.jacobian(coefficients)
                    if not np.all(np.isfinite(jacobian)):
                        return _Found(coefficients, math.inf, correction, iteration, False,
                                      "the tangent matrices are not finite")
                    factors = scipy.linalg.lu_factor(jacobian, check_finite=False)
                step = scipy.linalg.lu_solve(factors, value.ravel(), check_finite=False).reshape(shape)
                if not np.all(np.isfinite(step)):
                    return _Found(coefficients, math.inf, math.inf, iteration, False,
                                  f"the {kind} correction is not finite (a singular Jacobian: a resonance of the "
                                  "tangent, or a free mode)")
                length = 1.0
                size = float(np.abs(coefficients - step).max()) + 1e-300
                if float(np.abs(step).max()) <= tol * size:
                    # converged: a correction this small is taken whole (the residual may be at its
                    # round-off already, where no step decreases it)
                    coefficients = coefficients - step
                    correction = float(np.abs(step).max()) / size
                    value = self.projected(coefficients)
                    return _Found(coefficients, float(np.linalg.norm(value)), correction, iteration, True,
                                  f"converged in {iteration} {kind} iterations (correction {correction:.2g} of the "
                                  "coefficients)")
                # full steps (a line search on the residual's norm stalled at a local minimum of it on
                # the pumped Duffing oscillator from rest, where full steps converge in 11), shortened
                # only where the residual is not finite there
                for _ in range(_MAX_HALVINGS + 1):
                    trial = coefficients - length * step
                    trial_value = self.projected(trial)
                    if np.all(np.isfinite(trial_value)):
                        break
                    length *= 0.5
                else:
                    return _Found(coefficients, float(np.linalg.norm(value)), correction, iteration, False, (
                        f"the residual is not finite along the {kind} correction even at 1/{2**_MAX_HALVINGS} "
                        "of it; start nearer the solution"))
                coefficients, value = trial, trial_value
                correction = length * float(np.abs(step).max()) / (float(np.abs(coefficients).max()) + 1e-300)
        except PeriodicError:
            raise
        except (np.linalg.LinAlgError, RuntimeError, FloatingPointError) as error:
            # the equations' own failure (e.g. a state outside the model), or a singular factorisation
            return _Found(coefficients, math.inf, correction, iteration, False,
                          f"the equations failed at a {kind} iterate ({type(error).__name__}: {error})")
        return _Found(coefficients, float(np.linalg.norm(value)), correction, max_iterations, False,
                      f"max iterations: {max_iterations} left the correction at {correction:.3g} of the coefficients "
                      f"> tol {tol:g}; raise max_iterations or start nearer the solution")
