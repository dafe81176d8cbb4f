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
#: The line search halves the Newton step at most this many times (down to 1/1024 of it): near a
#: multiplier at +1 the step is long and the residual curved, and only a short one decreases it.
_MAX_HALVINGS = 10
#: ``J = monodromy - I`` with a condition number above this is singular: Newton's step would be
#: rounding noise (a multiplier at +1 to about 1e-12: a fold, or a free mode of an unforced system).
#: The condition number is that of ``J`` with its rows and columns equilibrated (``scaled_condition``):
#: a state of positions and rates has entries of very different units, and the raw condition number
#: measures those units (1.96e12 on ``two_link_arm``'s 64-step map, whose multipliers are all below
#: 0.92: 211 equilibrated), not the distance of a multiplier from +1; Newton's step is the same in
#: any scaling of the unknowns and the equations.
_SINGULAR_CONDITION = 1e12
#: A chord iteration (the Jacobian of a nearby orbit kept) that reduces the residual by less than this
#: factor per step is abandoned for Newton: the kept Jacobian is too far from this map's. A chord step
#: costs a period, a Newton step a period and its monodromy (about 1.3 periods on six_bar) and
#: converges quadratically: beyond 0.1 per step Newton reaches 1e-8 in fewer periods.
_CHORD_CONTRACTION = 0.1
#: ``find_orbit``'s ``settle_within_error``: an orbit settled at a correction whose share of its actual
#: distance from the N/2 orbit exceeds this times ``accuracy`` (the distance measured at the first iterate
#: misled) is solved on to ``tol``.
SETTLE_SLACK = 2.0
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
    settled_fraction : float
        0 where ``state`` is converged to ``tol``; with ``settle_within_error``, the largest share
        (over the state's blocks) of the Newton correction left at ``state`` in its distance from the
        coarse orbit of ``estimate``, by which the error bars were widened (:func:`find_orbit`).
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
    settled_fraction: float = 0.0


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


def scaled_condition(jacobian: np.ndarray) -> float:
    """The 2-norm condition number of ``jacobian`` (n, n) with its rows, then its columns, scaled to a
    largest entry of 1 (inf with a zero row or column): the condition of the linear solve
    independent of the units of the unknowns and of the equations."""
    rows = np.abs(jacobian).max(axis=1)
    if not np.all(rows > 0.0):
        return math.inf
    scaled = jacobian / rows[:, None]
    columns = np.abs(scaled).max(axis=0)
    if not np.all(columns > 0.0):
        return math.inf
    return float(np.linalg.cond(scaled / columns[None, :]))


def newton(evaluate, y0, *, tol: float, max_iterations: int, relative, floor: float = 0.0,
           settled=None, first=None, abandon=None) -> NewtonResult:
    """Damped Newton on ``F(y) = 0``.  ``evaluate(y) -> (F (m,), J (m, m), extra)`` may raise
    ``RuntimeError`` (a numerical failure of the map: treated like a non-finite value, the step is
    shortened); ``relative(y, F) -> float`` is the convergence measure, compared with ``tol``;
    ``floor``: an absolute ``|F|`` (2-norm) at or below which ``F`` may be round-off of the evaluation
    (the period map's ``resolution``): a full Newton step that does not decrease such a residual
    shows it stalled at round-off, and ``y`` is converged whatever ``tol`` asks.
    ``settled(y, correction) -> bool`` (optional, :class:`Settled`): ``y`` is also converged when its
    Newton correction is small enough for the caller (an error level's orbit); it is asked at every
    iterate, the last included (so ``max_iterations = 0`` checks ``y0``).
    ``first``: ``evaluate(y0)`` where the caller has it already (not evaluated again).
    ``abandon(y) -> str`` (optional): asked of each full Newton step's point before it is evaluated,
    and of each iterate after a (damped) step; a non-empty answer stops Newton, not converged, with
    that reason (a continuation step that turns too far: no period run for it).
    A backtracking line search on ``|F|`` makes each accepted step decrease it."""
    y = np.array(y0, dtype=float)
    try:
        value, jacobian, extra = evaluate(y) if first is None else first
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
        if iteration == max_iterations and settled is None:
            break
        if not np.all(np.isfinite(jacobian)):
            return NewtonResult(y, value, jacobian, extra, residual, iteration, False,
                                "the monodromy is not finite")
        condition = scaled_condition(jacobian)
        if not condition < _SINGULAR_CONDITION:
            return NewtonResult(y, value, jacobian, extra, residual, iteration, False, (
                f"singular Jacobian: monodromy - I has condition number {condition:.3g} (a multiplier at +1: "
                "a fold of the branch, use arclength continuation, or a free mode of an unforced system)"))
        direction = -np.linalg.solve(jacobian, value)
        if settled is not None and settled(y, direction):
            return NewtonResult(y, value, jacobian, extra, residual, iteration, True, "")
        if iteration == max_iterations:
            break
        norm = np.linalg.norm(value)
        length, accepted, failure = 1.0, False, ""
        for _ in range(_MAX_HALVINGS + 1):
            trial = y + length * direction
            reason = abandon(trial) if abandon is not None and length == 1.0 else ""
            if reason:    # the full step's point, before its period is run
                return NewtonResult(y, value, jacobian, extra, residual, iteration, False, reason)
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
                elif length == 1.0 and norm <= floor:
                    # a full step that does not decrease a residual already at the map's round-off:
                    # stalled at round-off, converged (the better of the two points)
                    if np.linalg.norm(trial_value) < norm:
                        y, value, jacobian, extra = trial, trial_value, trial_jacobian, trial_extra
                    return NewtonResult(y, value, jacobian, extra, relative(y, value), iteration + 1, True, "")
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
        reason = abandon(y) if abandon is not None else ""
        if reason:
            return NewtonResult(y, value, jacobian, extra, residual, iteration + 1, False, reason)
    return NewtonResult(y, value, jacobian, extra, residual, max_iterations, False, (
        f"max iterations: {max_iterations} Newton steps left the relative residual at {residual:.3g} > tol "
        f"{tol:g}; raise max_iterations or start nearer the orbit"))


def chord(evaluate_end, y0, jacobian, *, tol: float, max_iterations: int, relative, floor: float = 0.0,
          settled=None, value0=None, settle_on_iterate=False) -> NewtonResult:
    """Chord iterations on ``F(y) = 0`` with a fixed ``jacobian`` (m, m) (a nearby orbit's ``monodromy
    - I``): ``y <- y - J^-1 F(y)``, ``evaluate_end(y) -> F (m,)`` (no Jacobian: a period without its
    monodromy).  Converged as :func:`newton`; not converged (``reason`` says why, ``y`` the best
    iterate) when an evaluation fails or a step reduces ``|F|`` by less than ``_CHORD_CONTRACTION``:
    the caller then continues with Newton.  ``settled(y, correction)`` (optional, :class:`Settled`):
    once a correction is small enough for the caller, ``y + correction`` is returned converged, not
    evaluated (``residual_vector`` and ``residual`` are those of ``y``: the caller's exact evaluation
    there checks it).  ``value0`` (m,): ``F(y0)`` where the caller has it already (the period that gave
    ``jacobian``), so that it is not evaluated again.  ``settle_on_iterate``: a settled ``y`` is
    returned itself (evaluated: the caller's exact evaluation there reuses the period a map keeps),
    not ``y + correction`` (its error then about the correction, within ``settled``'s fraction, not
    the next one's).  ``jacobian`` and ``extra`` of the result are None."""
    import scipy.linalg

    y = np.array(y0, dtype=float)
    if not (np.all(np.isfinite(jacobian)) and scaled_condition(jacobian) < _SINGULAR_CONDITION):
        return NewtonResult(y, np.full(y.shape, np.nan), None, None, math.inf, 0, False,
                            "the kept Jacobian is singular or not finite")
    factors = scipy.linalg.lu_factor(jacobian, check_finite=False)
    best, best_value, norm = y, None, math.inf
    for iteration in range(max_iterations + 1):
        try:
            value = np.asarray(value0 if iteration == 0 and value0 is not None else evaluate_end(y), dtype=float)
        except RuntimeError as error:
            return NewtonResult(best, best_value, None, None, math.inf, iteration, False,
                                f"the period map failed at a chord iterate ({error})")
        value_norm = float(np.linalg.norm(value))
        if not np.isfinite(value_norm) or value_norm > _CHORD_CONTRACTION * norm:
            residual = relative(best, best_value) if best_value is not None else math.inf
            # a residual at the map's round-off that a step no longer reduces has stalled there
            stalled = np.isfinite(value_norm) and norm <= floor
            return NewtonResult(best, best_value, None, None, residual, iteration, stalled,
                                "" if stalled else "the chord iteration does not contract")
        best, best_value, norm = y, value, value_norm
        residual = relative(y, value)
        if residual <= tol:
            return NewtonResult(y, value, None, None, residual, iteration, True, "")
        if iteration == max_iterations:
            break
        correction = -scipy.linalg.lu_solve(factors, value, check_finite=False)
        if settled is not None and settled(y, correction):
            if settle_on_iterate:
                return NewtonResult(y, value, None, None, residual, iteration, True, "")
            return NewtonResult(y + correction, value, None, None, residual, iteration + 1, True, "")
        y = y + correction
    return NewtonResult(best, best_value, None, None, relative(best, best_value), max_iterations, False,
                        f"{max_iterations} chord steps left the relative residual above tol {tol:g}")


class CountingMap:
    """``period_map`` with input checks on what it returns and a count of its calls (``calls``; those
    with the monodromy: ``monodromies``)."""

    def __init__(self, period_map, n: int):
        if not callable(period_map):
            raise TypeError(f"period_map: expected a callable (state, parameter) -> (end_state, monodromy), "
                            f"got {type(period_map).__name__}")
        self.period_map, self.n, self.calls, self.monodromies = period_map, n, 0, 0

    def __call__(self, state, parameter):
        self.calls += 1
        self.monodromies += 1
        end, monodromy = self.period_map(state, parameter)
        end = np.asarray(end, dtype=float)
        monodromy = np.asarray(monodromy, dtype=float)
        if end.shape != (self.n,) or monodromy.shape != (self.n, self.n):
            raise PeriodicError(f"period_map: expected to return an end state ({self.n},) and a monodromy "
                                f"({self.n}, {self.n}), got {end.shape} and {monodromy.shape}")
        return end, monodromy

    def end_state(self, state, parameter) -> np.ndarray:
        """The end state alone: the map's own ``end_state(state, parameter)`` where it offers one (a
        period without its monodromy), else the map's call."""
        own = getattr(self.period_map, "end_state", None)
        if own is None:
            return self(state, parameter)[0]
        self.calls += 1
        end = np.asarray(own(state, parameter), dtype=float)
        if end.shape != (self.n,):
            raise PeriodicError(f"period_map.end_state: expected to return an end state ({self.n},), got "
                                f"{end.shape}")
        return end

    @property
    def blocks(self) -> tuple:
        """The map's ``blocks`` ((start, stop) index ranges of the state's parts in one unit, e.g. its
        positions and its rates; :class:`Settled` judges each apart) where it declares them, else the
        whole state as one."""
        blocks = getattr(self.period_map, "blocks", None)
        if blocks is None:
            return ((0, self.n),)
        blocks = tuple((int(a), int(b)) for a, b in blocks)
        if not all(0 <= a < b <= self.n for a, b in blocks):
            raise PeriodicError(f"period_map.blocks: expected (start, stop) index ranges within 0..{self.n}, "
                                f"got {blocks}")
        return blocks

    @property
    def floor(self) -> float:
        """The 2-norm of the map's ``resolution`` (the absolute round-off of its end state, a float or
        (n,), where it declares one; else 0): a residual at or below it is converged."""
        resolution = getattr(self.period_map, "resolution", None)
        if resolution is None:
            return 0.0
        return float(np.linalg.norm(np.broadcast_to(np.asarray(resolution, dtype=float), (self.n,))))


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


def solve_fixed_point(period_map: CountingMap, guess, parameter, *, tol, max_iterations, state_scale,
                      monodromy=None, settled=None, reuse_first=False, settle_on_iterate=False, abandon=None,
                      first_value=None, exact_monodromy=True):
    """Newton on ``P(x) - x`` at a fixed parameter; ``extra`` of the result is the monodromy.

    With ``monodromy`` (n, n), a nearby orbit's (the finer level's, of which this map is a coarser
    grid, or a neighbouring parameter's): chord iterations with it first, periods without their
    monodromy, and the exact monodromy once at the converged state (Newton from the chord's last
    iterate where the chord does not contract); ``first_value`` (n,): ``P(guess) - guess`` where the
    caller has it (a period run at ``guess`` already: not run again); ``exact_monodromy=False``: the
    chord's converged state is returned with the kept ``monodromy`` as its own (an error level whose
    multipliers nobody reads: one tangent propagation fewer).

    ``reuse_first`` (without ``monodromy``): the monodromy at ``guess`` is that kept monodromy, the
    chord's first step Newton's own (its period not run again): from a start whose error is mostly
    the linearisation's, the monodromy barely changes on the way to the orbit (six_bar at 100 rad/s:
    2.4 % from the linear start to the first iterate; the chord reached 7e-9 in two periods where
    Newton took two more periods with their monodromy).  ``settle_on_iterate``: ``chord``'s (an
    error level's orbit is the settled iterate, whose period a ``mechanisms.PeriodMap`` keeps: its
    monodromy without a period more).  ``abandon``: Newton's (its iterates only, not the chord's).
    A ``settled`` with a ``use_jacobian(J)`` method (:class:`WithinError`) is given the chord's kept
    Jacobian before the chord starts."""

    def evaluate(state):
        end, monodromy = period_map(state, parameter)
        return end - state, monodromy - np.eye(state.size), monodromy

    def relative(state, value):
        return relative_residual(state, value, state_scale)

    floor = period_map.floor
    start = np.array(guess, dtype=float)
    value0 = None if first_value is None else np.asarray(first_value, dtype=float)
    at_start = False     # whether ``monodromy`` is the exact one at ``guess`` (evaluated here)
    if monodromy is None and reuse_first:
        try:
            value0, _, monodromy = evaluate(start)
        except RuntimeError:    # Newton's own evaluation reports the failure
            value0 = monodromy = None
        if value0 is not None and not (np.all(np.isfinite(value0)) and np.all(np.isfinite(monodromy))):
            value0 = monodromy = None
        at_start = monodromy is not None
    if monodromy is not None:
        kept_jacobian = np.asarray(monodromy, dtype=float) - np.eye(guess.size)
        if callable(getattr(settled, "use_jacobian", None)):
            settled.use_jacobian(kept_jacobian)
        kept = chord(lambda state: period_map.end_state(state, parameter) - state, guess, kept_jacobian,
                     tol=tol, max_iterations=max_iterations, relative=relative, floor=floor, settled=settled,
                     value0=value0, settle_on_iterate=settle_on_iterate)
        guess = kept.y
        if kept.converged and not exact_monodromy:
            return replace(kept, jacobian=kept_jacobian, extra=np.asarray(monodromy, dtype=float))
        if kept.converged and at_start and kept.iterations == 0 and np.array_equal(guess, start):
            # the guess was the orbit already, and its monodromy the one just computed
            return NewtonResult(kept.y, value0, monodromy - np.eye(guess.size), monodromy, kept.residual, 0,
                                True, "")
        if kept.converged:    # the exact monodromy at the orbit (its period is not run again)
            found = newton(evaluate, guess, tol=tol, max_iterations=0, relative=relative, floor=floor,
                           settled=settled)
            if found.converged:
                return replace(found, iterations=kept.iterations)
            if kept.residual > tol and np.linalg.norm(found.residual_vector) <= floor:
                # the chord stalled at the map's round-off (``chord``): converged there, as Newton's
                # full step that no longer decreases such a residual is; its monodromy is exact
                return replace(found, converged=True, reason="", iterations=kept.iterations)
    # from the start again where the chord's first step did not contract: its monodromy is known
    first = ((value0, monodromy - np.eye(guess.size), monodromy)
             if at_start and np.array_equal(guess, start) else None)
    return newton(evaluate, guess, tol=tol, max_iterations=max_iterations, relative=relative, floor=floor,
                  settled=settled, first=first, abandon=abandon)


class Settled:
    """``settled(y, correction) -> bool``: whether an error level's iterate ``y`` (n,) is accurate
    enough, its Newton (or chord) ``correction`` (n,) at most ``fraction`` of its distance from the
    ``finer`` level's orbit (n,), in each block of the state (``blocks``: (start, stop) index ranges of
    parts in one unit, positions and rates, max norms).  A level run only to estimate the finer orbit's
    error needs that distance, ``|x_{N/2} - x_N|``, to a few digits, not its state to ``tol``: with
    ``fraction`` 0.01 the estimate is within about 1 % of itself (the correction is the iterate's error
    to first order), several chord periods fewer than a ``tol`` of 1e-8 takes."""

    def __init__(self, finer, fraction: float, blocks):
        self.finer, self.fraction, self.blocks = np.asarray(finer, dtype=float), float(fraction), tuple(blocks)

    def __call__(self, y, correction) -> bool:
        distance = np.asarray(y) + correction - self.finer
        return all(np.abs(correction[a:b]).max(initial=0.0) <= self.fraction * np.abs(distance[a:b]).max(initial=0.0)
                   for a, b in self.blocks)


class WithinError:
    """``settled(y, correction) -> bool`` of the orbit whose error the ``coarse`` map (a
    :class:`CountingMap` of the same system on N/2 steps) estimates (:func:`find_orbit`'s
    ``settle_within_error``): ``y`` is converged once its correction is at most ``fraction`` of its
    distance from the coarse orbit, in each block (``blocks``), as an error level's orbit is
    (:class:`Settled`): iterating further would refine the state far below its own time-step error.

    That distance is measured once, at the first iterate asked about after the start (the start's
    correction measures the start, e.g. the linearisation's error, not the orbit): one period of the
    coarse map there, without its monodromy, and its chord correction with the kept Jacobian
    (``use_jacobian``), about ``|x_{N/2} - y|`` per block. That period is the coarse level's first
    (``probe``: (y, P_{N/2}(y) - y)), so it costs nothing more where the coarse level starts there.
    ``correction`` is the last correction asked about, the settled state's error to first order:
    :class:`ErrorEstimate` compares it with the coarse orbit's actual distance."""

    def __init__(self, coarse: "CountingMap", parameter: float, fraction: float, blocks):
        self.coarse, self.parameter, self.fraction = coarse, float(parameter), float(fraction)
        self.blocks = tuple(blocks)
        self.factors = self.distance = self.probe = self.correction = None
        self.asked = 0

    def use_jacobian(self, jacobian) -> None:
        """The chord's kept Jacobian (n, n), ``monodromy - I``, factorised for the probe's correction."""
        import scipy.linalg

        self.factors = scipy.linalg.lu_factor(np.asarray(jacobian, dtype=float), check_finite=False)

    def _measure(self, y: np.ndarray) -> None:
        import scipy.linalg

        try:
            value = np.asarray(self.coarse.end_state(y, self.parameter), dtype=float) - y
        except RuntimeError:      # the coarse level reports its own failure later: settle to tol
            value = np.full(y.shape, np.nan)
        step = scipy.linalg.lu_solve(self.factors, value, check_finite=False)
        if np.all(np.isfinite(step)):
            self.probe = (y.copy(), value)
            self.distance = np.array([np.abs(step[a:b]).max(initial=0.0) for a, b in self.blocks])
        else:                     # no distance to settle within: converged to tol only
            self.distance = np.zeros(len(self.blocks))

    def __call__(self, y, correction) -> bool:
        self.asked += 1
        if self.asked == 1 or self.factors is None:
            return False
        y = np.asarray(y, dtype=float)
        if self.distance is None:
            self._measure(y)
        self.correction = np.array(correction, dtype=float)
        return all(np.abs(self.correction[a:b]).max(initial=0.0) <= self.fraction * distance
                   for (a, b), distance in zip(self.blocks, self.distance))

    @staticmethod
    def share_of(correction, state, coarse_state, blocks) -> float:
        """The largest ratio over ``blocks`` of ``correction`` (n,) to the distance of ``state +
        correction`` from the coarse orbit ``coarse_state`` (max norms; inf where that distance is 0
        and the correction not)."""
        ratios = []
        for a, b in blocks:
            size = float(np.abs(correction[a:b]).max(initial=0.0))
            distance = float(np.abs(state[a:b] + correction[a:b] - coarse_state[a:b]).max(initial=0.0))
            ratios.append(size / distance if distance > 0.0 else (0.0 if size == 0.0 else math.inf))
        return max(ratios, default=0.0)


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
               stability_tol: float = STABILITY_TOL, monodromy=None, finer=None,
               accuracy: float | None = None, reuse_first: bool = False,
               settle_on_iterate: bool = False, settle_within_error: bool = False,
               exact_monodromy: bool = True) -> PeriodicOrbit:
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
    The N/2 orbit is found by chord iterations with the N-step orbit's monodromy (periods without
    their monodromy) and one exact monodromy at its converged state.

    ``monodromy`` (n, n): a nearby orbit's (a finer grid's, a neighbouring parameter's) for chord
    iterations from ``guess`` (``solve_fixed_point``), else Newton throughout; ``reuse_first``
    (without ``monodromy``): the monodromy at ``guess`` kept for chord iterations after Newton's first
    step, the exact monodromy once more at the converged state (for the multipliers).
    ``settle_on_iterate`` (with ``accuracy``): an error level's orbit (this one with ``finer``, and
    the N/2 orbit of ``estimate``) is the chord's iterate whose correction is within ``accuracy``,
    not that iterate plus its correction: its monodromy from the period just run (a map that keeps
    its last period), one period fewer per level, the level's error about ``accuracy`` of its
    distance instead of a fraction of that.

    ``accuracy`` (a fraction, e.g. 0.01; default None: ``tol`` throughout): an error level's orbits
    are converged once their correction is at most ``accuracy`` of their distance from the finer
    level's orbit (:class:`Settled`, per block of the map's ``blocks``): the N/2 orbit of
    ``estimate`` against this orbit, and, given ``finer`` (n,), this orbit itself against ``finer``
    (this map a coarser grid of ``finer``'s, found only for an error estimate). Their residual is then
    above ``tol``, and the message says so.

    ``settle_within_error`` (with ``estimate`` a period map and ``accuracy``): this orbit, too, is
    converged once its correction is at most ``accuracy`` of its distance from the coarse orbit, in each
    block (:class:`WithinError`; that distance measured by one coarse period at the first iterate after
    the start, the coarse level's first period), before its residual reaches ``tol``: a state more
    accurate than its own time-step error is not needed. The settled iterate is the orbit (its
    monodromy exact there); its correction's largest share of the coarse orbit's actual distance is
    ``settled_fraction``, by which the error bars are made larger (the state's by the correction, the
    multipliers' by that share of their N, N/2 difference); a share above ``SETTLE_SLACK`` times
    ``accuracy`` (the measured distance misled) sends Newton on to ``tol``.
    ``exact_monodromy=False`` (with ``monodromy``): the orbit's monodromy is the kept one, not the exact
    one at the converged state (an error level whose multipliers are not read: one monodromy fewer).

    A period map may offer ``end_state(state, parameter) -> end_state`` (one period without its
    monodromy, for the chord iterations) and ``resolution`` (float or (n,), the absolute round-off of
    its end state): a residual whose 2-norm is at or below that of ``resolution`` and which a full
    Newton step no longer decreases has stalled at round-off and is converged whatever ``tol`` asks
    (not a failure); the message says so.
    """
    start_time = time.perf_counter()
    guess = check_state("guess", guess)
    parameter = check_real("parameter", parameter)
    tol = check_tol("tol", tol, 1.0)
    max_iterations = check_iterations("max_iterations", max_iterations)
    state_scale = check_tol("state_scale", state_scale)
    counted = CountingMap(period_map, guess.size)
    if accuracy is not None:
        accuracy = check_tol("accuracy", accuracy, 1.0)
    estimator = ErrorEstimate(estimate, error_factor, guess.size, tol=tol, max_iterations=max_iterations,
                              state_scale=state_scale, accuracy=accuracy, settle_on_iterate=settle_on_iterate)
    settled = within = None
    if finer is not None and accuracy is not None:
        settled = Settled(check_state("finer", finer), accuracy, counted.blocks)
        if settled.finer.shape != guess.shape:
            raise PeriodicError(f"finer: expected a state of shape {guess.shape}, got {settled.finer.shape}")
    if settle_within_error:
        if estimator.coarse is None or accuracy is None or settled is not None:
            raise PeriodicError("settle_within_error: expected `estimate` (the period map on N/2 steps) and "
                                "`accuracy`, and no `finer` (this orbit is the finest level)")
        settled = within = WithinError(estimator.coarse, parameter, accuracy, counted.blocks)
    found = solve_fixed_point(counted, guess, parameter, tol=tol, max_iterations=max_iterations,
                              state_scale=state_scale, monodromy=monodromy, settled=settled,
                              reuse_first=reuse_first, settle_on_iterate=settle_on_iterate,
                              exact_monodromy=exact_monodromy)
    early = within is not None and found.converged and found.residual > tol and within.correction is not None
    monodromy = found.extra if found.extra is not None else found.jacobian + np.eye(guess.size)
    orbit = classify(parameter, found.y, monodromy, residual=found.residual, iterations=found.iterations,
                     map_calls=counted.calls, converged=found.converged, reason=found.reason,
                     stability_tol=stability_tol, start_time=start_time)
    correction = within.correction if early else None
    orbit = estimator.apply(orbit, stability_tol=stability_tol, start_time=start_time,
                            probe=within.probe if within is not None else None, correction=correction)
    if early and not orbit.settled_fraction <= SETTLE_SLACK * accuracy and estimator.coarse_orbit is not None:
        # the probe's distance misled (or no coarse orbit to compare with): Newton on to tol from the
        # corrected iterate, the coarse orbit kept
        iterations = found.iterations
        found = solve_fixed_point(counted, found.y + within.correction, parameter, tol=tol,
                                  max_iterations=max_iterations, state_scale=state_scale,
                                  monodromy=orbit.monodromy)
        early = False
        monodromy = found.extra if found.extra is not None else found.jacobian + np.eye(guess.size)
        orbit = classify(parameter, found.y, monodromy, residual=found.residual,
                         iterations=iterations + 1 + found.iterations, map_calls=counted.calls,
                         converged=found.converged, reason=found.reason, stability_tol=stability_tol,
                         start_time=start_time)
        orbit = estimator.apply(orbit, stability_tol=stability_tol, start_time=start_time, coarse_again=True)
    if orbit.converged and early:
        orbit = replace(orbit, message=(
            f"{orbit.message} (> tol {tol:g}: converged to {orbit.settled_fraction:.2g} of its distance from "
            f"the N/2 orbit, within {accuracy:g}; the error bars include that share)"))
    elif orbit.converged and orbit.residual > tol and settled is not None and within is None:
        orbit = replace(orbit, message=(
            f"{orbit.message} (> tol {tol:g}: an error level, converged to {accuracy:g} of its distance from "
            "the finer orbit)"))
    elif orbit.converged and orbit.residual > tol:
        orbit = replace(orbit, message=(
            f"{orbit.message} (> tol {tol:g}: the residual stalled at the period map's round-off, its "
            f"resolution {counted.floor:.2g}, and the orbit is converged to it)"))
    return orbit


class ErrorEstimate:
    """The error bars of an orbit's verdict from ``estimate`` (see :func:`find_orbit`): None, the
    multipliers' modulus errors (a float or (n,)), or the period map on N/2 steps with its
    ``error_factor``.  ``calls`` counts the coarse map's calls (each orbit's ``map_calls`` has its own).
    ``accuracy`` (a fraction or None): the coarse orbit converged once its correction is at most that
    of its distance from the finer orbit (:class:`Settled`), else to ``tol``."""

    def __init__(self, estimate, error_factor, n: int, *, tol, max_iterations, state_scale, accuracy=None,
                 settle_on_iterate=False):
        self.errors, self.coarse, self.calls, self.coarse_monodromy = None, None, 0, None
        self.coarse_result = self.coarse_orbit = None
        self.counted = self.made = 0     # the coarse map's calls already in ``calls``; the last orbit's
        self.tol, self.max_iterations, self.state_scale = tol, max_iterations, state_scale
        self.accuracy, self.settle_on_iterate = accuracy, settle_on_iterate
        if estimate is None:
            return
        if callable(estimate):
            self.coarse = CountingMap(estimate, n)
            self.error_factor = check_tol("error_factor", error_factor, 1.0)
            return
        try:
            errors = np.broadcast_to(np.asarray(estimate, dtype=float), (n,)).copy()
        except (TypeError, ValueError):
            errors = None
        if errors is None or not np.all(errors >= 0.0):  # also refuses NaN
            raise PeriodicError(f"estimate: expected the multipliers' errors >= 0 (a float or ({n},)) or the "
                                f"period map on N/2 steps, got {estimate!r}")
        self.errors = errors

    def apply(self, orbit: PeriodicOrbit, *, stability_tol: float, start_time: float,
              chord: bool = True, probe=None, correction=None, coarse_again: bool = False) -> PeriodicOrbit:
        """``orbit`` judged again with the error bars (unchanged without an estimate or if not converged).
        The coarse orbit is solved from ``orbit.state`` by chord iterations with ``orbit.monodromy``
        (``chord``, the default), else by Newton (a continuation whose two levels' monodromies differ
        too much for the chord to contract); ``coarse_monodromy`` is then the coarse orbit's (None
        where there is none), ``coarse_orbit`` its state. ``probe`` ((y, P_{N/2}(y) - y), a coarse period
        run already: :class:`WithinError`): the chord starts at ``y`` with that period. ``correction``
        (n,): the Newton correction left at ``orbit.state`` (an orbit settled within its error, see
        :func:`find_orbit`), whose share of the distance from the coarse orbit widens the error bars and
        is ``settled_fraction``. ``coarse_again``: the coarse orbit of the last call, not solved again
        (the same orbit refined)."""
        self.coarse_monodromy = None if not coarse_again else self.coarse_monodromy
        if not orbit.converged or (self.errors is None and self.coarse is None):
            return orbit
        errors, state_error, map_calls, share = self.errors, math.nan, orbit.map_calls, 0.0
        if self.coarse is not None:
            if not coarse_again:
                settled = (None if self.accuracy is None
                           else Settled(orbit.state, self.accuracy, self.coarse.blocks))
                start, first_value = ((probe[0], probe[1]) if probe is not None and chord
                                      else (orbit.state, None))
                self.coarse_result = solve_fixed_point(
                    self.coarse, start, orbit.parameter, tol=self.tol, max_iterations=self.max_iterations,
                    state_scale=self.state_scale, monodromy=orbit.monodromy if chord else None,
                    settled=settled, settle_on_iterate=self.settle_on_iterate, first_value=first_value)
            coarse = self.coarse_result
            if not coarse_again:
                self.made = self.coarse.calls - self.counted
                self.calls += self.made
                self.counted = self.coarse.calls
            map_calls = orbit.map_calls + self.made
            self.coarse_orbit = coarse.y if coarse.converged else None
            if coarse.converged:
                self.coarse_monodromy = coarse.extra
            if not coarse.converged:
                return replace(orbit, status=worst_status(orbit.status, "inaccurate"),
                               map_calls=map_calls, message=(
                                   f"{orbit.message}; inaccurate: no error estimate, the orbit of the coarse map "
                                   f"(estimate) was not found ({coarse.reason}); near a fold the N/2 map's "
                                   "branch may turn before this parameter (its fold moves with the step): "
                                   "refine n_steps to estimate the error there"))
            # the modulus errors, not the complex ones: a lightly damped mode's phase error is far larger
            # and does not move its multiplier across the unit circle (periodic._floquet.modulus_errors)
            errors = modulus_errors(orbit.multipliers, sorted_eigenvalues(coarse.extra), self.error_factor)
            state_error = self.error_factor * float(np.max(np.abs(orbit.state - coarse.y)))
            if correction is not None:
                # the settled state's error, about its correction: that share of the N, N/2 distances
                # adds to the estimates taken from them (error_factor of each distance)
                share = WithinError.share_of(correction, orbit.state, coarse.y, self.coarse.blocks)
                errors = errors * (1.0 + share / self.error_factor)
                state_error += float(np.max(np.abs(correction)))
        judged = classify(orbit.parameter, orbit.state, orbit.monodromy, residual=orbit.residual,
                          iterations=orbit.iterations, map_calls=map_calls, converged=True,
                          errors=errors, state_error=state_error, stability_tol=stability_tol,
                          start_time=start_time)
        return replace(judged, settled_fraction=share)
