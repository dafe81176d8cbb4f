"""Newton and chord iterations on the fixed point of a period map, ``P(x) - x = 0``.

:func:`newton` (damped, with a backtracking line search) and :func:`chord` (a kept Jacobian) on any
``evaluate``; :func:`solve_fixed_point` joins them on a :class:`CountingMap` (a period map with its
calls counted): chord iterations with a nearby orbit's monodromy where one is given, Newton else.
The orbit, its verdict and its error levels are :mod:`periodic._orbit`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ._system import PeriodicError

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
        if callable(getattr(settled, "use_jacobian", None)):
            settled.use_jacobian(jacobian)    # this iterate's (``periodic._orbit.WithinError``)
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
    A ``settled`` with a ``use_jacobian(J)`` method (``periodic._orbit.WithinError``) is given the
    chord's kept Jacobian before the chord starts, and Newton's at each of its iterates."""

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
