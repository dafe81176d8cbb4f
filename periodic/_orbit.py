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

from ._fixed_point import CountingMap, check_iterations, check_state, solve_fixed_point
from ._floquet import modulus_errors, sorted_eigenvalues
from ._system import PeriodicError, check_real, check_tol
from ._verdict import STABILITY_TOL, stability_verdict, worst_status

#: ``period_map(state (n,), parameter: float) -> (end_state (n,), monodromy (n, n))``.
PeriodMap = Callable[[np.ndarray, float], "tuple[np.ndarray, np.ndarray]"]

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


def block_max(vector, blocks) -> np.ndarray:
    """The max norm of ``vector`` (n,) over each block ((start, stop) index ranges), (blocks,)."""
    vector = np.abs(np.asarray(vector, dtype=float))
    return np.array([vector[a:b].max(initial=0.0) for a, b in blocks])


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
        distance = block_max(np.asarray(y) + correction - self.finer, self.blocks)
        return bool(np.all(block_max(correction, self.blocks) <= self.fraction * distance))


class WithinError:
    """``settled(y, correction) -> bool`` of the orbit whose error the ``coarse`` map (a
    :class:`CountingMap` of the same system on N/2 steps) estimates (:func:`find_orbit`'s
    ``settle_within_error``): ``y`` is converged once its correction is at most ``fraction`` of its
    distance from the coarse orbit, in each block (``blocks``), as an error level's orbit is
    (:class:`Settled`): iterating further would refine the state far below its own time-step error.

    That distance (unless given, ``distance``) is measured once, at the first iterate other than
    ``start`` (the start's correction measures the start, e.g. the linearisation's error, not the
    orbit): one period of the coarse map there, without its monodromy, and its correction with the
    Jacobian last given (``use_jacobian``: the chord's kept one, or Newton's at ``y``), about
    ``|x_{N/2} - y|`` per block. That period is the coarse level's first (``probe``: (y, P_{N/2}(y) -
    y)), so it costs nothing more where the coarse level starts there.
    ``correction`` is the last correction asked about (at ``at``), the settled state's error to first
    order: :class:`ErrorEstimate` compares it with the coarse orbit's actual distance."""

    def __init__(self, coarse: "CountingMap", parameter: float, fraction: float, blocks, start, distance=None):
        self.coarse, self.parameter, self.fraction = coarse, float(parameter), float(fraction)
        self.blocks, self.start = tuple(blocks), np.array(start, dtype=float)
        self.jacobian = self.probe = self.correction = None
        #: per block; given (a neighbouring orbit's, on a branch whose coarse level is solved by Newton,
        #: which would not reuse the probe's period): not measured
        self.distance = None if distance is None else np.asarray(distance, dtype=float)
        #: the state ``correction`` was asked at
        self.at = None

    def use_jacobian(self, jacobian) -> None:
        """The Jacobian (n, n), ``monodromy - I``, of the probe's correction: the chord's kept one, or
        Newton's at each iterate (``periodic._fixed_point.newton`` hands it over); factorised only
        when the distance is measured."""
        self.jacobian = jacobian

    def _measure(self, y: np.ndarray) -> None:
        import scipy.linalg

        factors = scipy.linalg.lu_factor(np.asarray(self.jacobian, dtype=float), check_finite=False)
        try:
            value = np.asarray(self.coarse.end_state(y, self.parameter), dtype=float) - y
        except RuntimeError:      # the coarse level reports its own failure later: settle to tol
            value = np.full(y.shape, np.nan)
        step = scipy.linalg.lu_solve(factors, value, check_finite=False)
        if np.all(np.isfinite(step)):
            self.probe = (y.copy(), value)
            self.distance = block_max(step, self.blocks)
        else:                     # no distance to settle within: converged to tol only
            self.distance = np.zeros(len(self.blocks))

    def __call__(self, y, correction) -> bool:
        y = np.asarray(y, dtype=float)
        # the start itself (asked again where a chord that did not contract hands over to Newton)
        if self.jacobian is None or np.array_equal(y, self.start):
            return False
        if self.distance is None:
            self._measure(y)
        self.correction, self.at = np.array(correction, dtype=float), y.copy()
        return bool(np.all(block_max(self.correction, self.blocks) <= self.fraction * self.distance))

    @staticmethod
    def share_of(correction, state, coarse_state, blocks) -> float:
        """The largest ratio over ``blocks`` of ``correction`` (n,) to the distance of ``state +
        correction`` from the coarse orbit ``coarse_state`` (max norms; inf where that distance is 0
        and the correction not)."""
        sizes = block_max(correction, blocks)
        distances = block_max(np.asarray(state) + correction - coarse_state, blocks)
        ratios = [size / distance if distance > 0.0 else (0.0 if size == 0.0 else math.inf)
                  for size, distance in zip(sizes, distances)]
        return max(ratios, default=0.0)


def judge_within_error(orbit: PeriodicOrbit, within: WithinError | None, estimator: "ErrorEstimate", refine, *,
                       tol: float, accuracy: float | None, stability_tol: float, start_time: float,
                       chord: bool = True) -> tuple[PeriodicOrbit, bool]:
    """(``orbit`` judged by ``estimator``, ``ErrorEstimate.apply``; whether it settled within its
    error) where it may have (``within``, :class:`WithinError`; None: judged as it is): a converged orbit whose
    residual is above ``tol`` settled at ``within.correction``, whose share of the coarse orbit's
    actual distance widens the bars; a share above ``SETTLE_SLACK`` times ``accuracy`` (the probe's
    distance misled) sends it on, ``refine(start (n,), monodromy (n, n)) -> PeriodicOrbit`` (Newton
    to ``tol`` from the corrected iterate), judged with the same coarse orbit. The message says how
    a settled orbit settled (the caller adds its other notes)."""
    # settled where the correction was asked (to a scaled round trip's round-off), not at a later
    # iterate (one Newton kept at its round-off floor: its correction is that floor's, not this one)
    early = (within is not None and orbit.converged and orbit.residual > tol and within.correction is not None
             and np.allclose(within.at, orbit.state, rtol=1e-10, atol=0.0))
    judged = estimator.apply(orbit, stability_tol=stability_tol, start_time=start_time, chord=chord,
                             probe=None if within is None else within.probe,
                             correction=within.correction if early else None)
    if not early:
        return judged, False
    if estimator.coarse_orbit is None or not judged.settled_fraction <= SETTLE_SLACK * accuracy:
        # the probe's distance misled, or no coarse orbit to measure the share by: on to tol
        refined = refine(orbit.state + within.correction, judged.monodromy)
        return estimator.apply(refined, stability_tol=stability_tol, start_time=start_time, coarse_again=True), False
    return replace(judged, message=(
        f"{judged.message} (> tol {tol:g}: converged to {judged.settled_fraction:.2g} of its distance from "
        f"the N/2 orbit, within {accuracy:g}; the error bars include that share)")), True


def refined_orbit(period_map: CountingMap, start, parameter: float, monodromy, *, tol: float, max_iterations: int,
                  state_scale: float, iterations: int, map_calls: int, stability_tol: float,
                  start_time: float) -> PeriodicOrbit:
    """The orbit solved on to ``tol`` from ``start`` (n,) by ``solve_fixed_point`` with ``monodromy``
    (n, n) kept (``judge_within_error``'s ``refine``), classified; ``iterations`` and ``map_calls``:
    those before it (the correction that led to ``start`` counts as one more iteration)."""
    calls_before = period_map.calls
    found = solve_fixed_point(period_map, start, parameter, tol=tol, max_iterations=max_iterations,
                              state_scale=state_scale, monodromy=monodromy)
    kept = found.extra if found.extra is not None else found.jacobian + np.eye(np.size(start))
    return classify(parameter, found.y, kept, residual=found.residual, iterations=iterations + 1 + found.iterations,
                    map_calls=map_calls + period_map.calls - calls_before, converged=found.converged,
                    reason=found.reason, stability_tol=stability_tol, start_time=start_time)


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
        settled = within = WithinError(estimator.coarse, parameter, accuracy, counted.blocks, start=guess)
    found = solve_fixed_point(counted, guess, parameter, tol=tol, max_iterations=max_iterations,
                              state_scale=state_scale, monodromy=monodromy, settled=settled,
                              reuse_first=reuse_first, settle_on_iterate=settle_on_iterate,
                              exact_monodromy=exact_monodromy)
    monodromy = found.extra if found.extra is not None else found.jacobian + np.eye(guess.size)
    orbit = classify(parameter, found.y, monodromy, residual=found.residual, iterations=found.iterations,
                     map_calls=counted.calls, converged=found.converged, reason=found.reason,
                     stability_tol=stability_tol, start_time=start_time)

    def refine(start, kept):
        return refined_orbit(counted, start, parameter, kept, tol=tol, max_iterations=max_iterations,
                             state_scale=state_scale, iterations=found.iterations, map_calls=counted.calls,
                             stability_tol=stability_tol, start_time=start_time)

    orbit, early = judge_within_error(orbit, within, estimator, refine, tol=tol, accuracy=accuracy,
                                      stability_tol=stability_tol, start_time=start_time)
    if early:
        pass    # settled within its error: its message says so (judge_within_error)
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
