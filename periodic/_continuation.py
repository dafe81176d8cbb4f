"""Continuation of periodic orbits over a parameter, with bifurcation detection.

Unknowns ``y = (x / X, p / P)``, scaled so that both parts are O(1): ``X`` the state's scale (the
largest rms state met so far, or ``state_scale``), ``P = |stop - start|``.  Each new point solves

    P(x, p) - x = 0,    t . (y - y_pred) = 0

by damped Newton (:func:`periodic._fixed_point.newton`) from the predictor ``y_pred = y_k + ds t``:
``t`` is the unit tangent of the branch at the last point, the null vector of the bordered matrix
``[Phi - I, dP/dp]`` there (oriented along the parameter for ``natural``, along the step just taken
for ``arclength``).  ``natural`` fixes the parameter (``e_p`` in the constraint, the predictor along
``t`` scaled to move ``p`` by the step), and solves at it (:func:`periodic._fixed_point.solve_fixed_point`)
by chord iterations with the last orbit's monodromy (periods without their own) and one exact
monodromy at the converged orbit where they are predicted to contract fast enough (``CHORD_RATE``:
the rate they would have had over the step just taken), else by Newton; the error level's orbit
(``estimate``) likewise, by chord with the orbit's monodromy or by Newton;
``arclength`` (pseudo-arclength, Keller) takes the constraint's normal along ``t``, so the branch is
followed through folds, where ``Phi - I`` is singular but the bordered matrix is not.  ``dP/dp`` is a
forward difference of the map, ``(P(x, p + dp) - P(x, p)) / dp`` with ``dp = sqrt(eps) max(|p|, P)``
(relative error ~1e-8, which slows Newton's convergence negligibly), computed once per corrector
solve at its first iterate (arclength) and once at each accepted point for its tangent (one extra
period without its monodromy each).  Step control: a corrector that fails, or whose new secant turns
by more than ``MAX_TURN`` from the tangent at the last point (it may have jumped to another branch),
halves the step (checked at each Newton iterate, and at a full Newton step's point before its period
is run, ``EARLY_TURN_CHECK``: no more periods for a step that has turned); one that converges in at
most ``EASY_ITERATIONS`` Newton steps
(``EASY_CHORD_ITERATIONS`` chord steps) grows it by ``GROWTH``.  The reference is the local tangent,
not the last secant: where the branch bends sharply (near a resonance) a long last secant differs
from the local direction by more than ``MAX_TURN`` however short the new step.  For the same reason
a step across the bend may make more than 90 degrees with the tangent at its end, so a natural
continuation orients that tangent along the parameter, not along the step.

Bifurcations.  Between two accepted points, a change in the number of multipliers outside the unit
circle (``|mu| > 1 + stability_tol``) is a bifurcation; its kind is read from the test function that
changes sign -- ``det(I - Phi)`` (a real multiplier crossing +1: fold or branch point),
``det(I + Phi)`` (crossing -1: period doubling), else ``prod (|mu|^2 - 1)`` over the complex pairs
(secondary Hopf / Neimark-Sacker) -- and it is located by Brent's method on that test function along
the chord between the two points (each evaluation a corrector solve on the hyperplane normal to the
chord), the orbit there inserted in the branch.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, replace

import numpy as np

from ._fixed_point import (
    CountingMap,
    check_iterations,
    check_state,
    newton,
    relative_residual,
    solve_fixed_point,
)
from ._orbit import (
    DEFAULT_ERROR_FACTOR,
    ErrorEstimate,
    PeriodicOrbit,
    WithinError,
    block_max,
    classify,
    judge_within_error,
    refined_orbit,
)
from ._system import PeriodicError, check_real, check_tol
from ._verdict import STABILITY_TOL, worst_status

logger = logging.getLogger(__name__)

METHODS = ("natural", "arclength")
#: A corrector whose new secant turns by more than this from the tangent at the last point (radians,
#: in the scaled variables) is rejected and the step halved: it may have converged onto another branch.
MAX_TURN = math.radians(30.0)
#: A corrector that converges in at most this many Newton steps lets the next step grow ...
EASY_ITERATIONS = 3
#: ... or, at a fixed parameter (natural steps: chord iterations with the last orbit's monodromy,
#: contracting by some 0.01-0.1 a step where Newton squares), in at most this many chord steps.
EASY_CHORD_ITERATIONS = 5
#: A natural step is solved by chord iterations with the last orbit's monodromy only where they are
#: predicted to contract by at least this factor a step (``chord_rate``: the rate they would have had
#: over the step just taken), else by Newton. A chord step costs a period, a Newton step a period and
#: its monodromy (1.2-1.4 periods on six_bar's reduced model), and from the predictor's residual
#: (0.04-0.1 at 1 rad/s steps on six_bar) to tol = 1e-8 Newton takes 3-4 steps: a chord at this rate
#: takes about 4 periods and the converged orbit's monodromy, about even. On six_bar at 1 rad/s steps
#: the rate is 0.1-0.4 (the monodromy changes by 20-50 % a step): every chord tried there failed and
#: cost its periods (issue 24).
CHORD_RATE = 0.01
#: ... by this factor (up to max_step); a failed or turning one halves it.
GROWTH = 1.5
#: The N/2 level's orbit is its settled chord iterate, not that iterate plus its correction
#: (``settle_on_iterate``): its monodromy from the period just run.
SETTLE_ON_ITERATE = True
#: The turn check (``MAX_TURN``) at each Newton iterate of a step's corrector, not only at its converged
#: point: Newton's first step is within 1e-4 or so of the orbit, its secant within about 0.1 degree of
#: the converged one's, so a step that will turn too far is abandoned after the predictor's period
#: with its monodromy (a full step's point is checked before its period is run) instead of three or
#: four (on six_bar's 50-speed sweep 25 of 75 steps were rejected by it, a third of the N periods
#: with their monodromy; issue 24). Newton's iterates only: not the chords'.
EARLY_TURN_CHECK = True
#: Brent's method locates a bifurcation to this fraction of the chord between two points.
LOCATE_XTOL = 1e-10
#: Without ``state_scale`` the state's scale follows the largest rms state met, by factors of this.
RESCALE = 2.0
_FORWARD_DIFFERENCE = math.sqrt(np.finfo(float).eps)


@dataclass(frozen=True)
class OrbitBranch:
    """A branch of periodic orbits over a parameter (m points, state of size n).

    Attributes
    ----------
    parameters : ndarray (m,)
        Parameter values, in the order followed (not monotone past a fold).
    states : ndarray (m, n)
        Orbit states at t = 0.
    multipliers : ndarray (m, n) complex
        Floquet multipliers of each orbit, decreasing modulus.
    stable : ndarray (m,) bool
        ``is_stable`` of each orbit (True also where ``marginal``: see ``statuses``).
    statuses : tuple of str (m,)
        Each orbit's status (``"ok"``, ``"unstable"``, ``"marginal"``; ``"inaccurate"`` where the N/2
        orbit of ``estimate`` was not found).
    orbits : tuple of PeriodicOrbit (m,)
        The orbits themselves (monodromy, messages, residuals).
    bifurcations : tuple of (float, str)
        ``(parameter, kind)`` where a multiplier crosses the unit circle, kind ``"fold"``,
        ``"period_doubling"`` or ``"secondary_hopf"``; the located orbit is on the branch, at
        ``bifurcation_indices``.
    bifurcation_indices : tuple of int
        Index into the branch of each bifurcation's orbit (-1 where it was only interpolated).
    status : str
        ``"failed"`` (the first orbit was not found, the step fell below ``min_step``, or
        ``max_points`` ran out before ``stop``: ``message`` says why and where), ``"unstable"``
        (stopped where the orbit loses stability, ``stop_at_instability``), else the worst status of
        the points (``"ok"``, ``"marginal"``, ``"unstable"``).
    message : str
        What happened, in words.
    method : str
        ``"natural"`` or ``"arclength"``.
    map_calls : int
        Calls of the period map (and of the N/2 map of ``estimate``).
    run_time : float
        Wall time, s.
    """

    parameters: np.ndarray
    states: np.ndarray
    multipliers: np.ndarray
    stable: np.ndarray
    statuses: tuple
    orbits: tuple
    bifurcations: tuple
    bifurcation_indices: tuple
    status: str
    message: str
    method: str
    map_calls: int
    run_time: float


class _Corrector:
    """Newton on ``[P(x, p) - x; normal . (y - y_pred)] = 0`` in the scaled unknowns ``y``."""

    def __init__(self, period_map: CountingMap, state_scale: float, parameter_scale: float, floor: float,
                 tol: float, max_iterations: int, stability_tol: float, estimator: ErrorEstimate,
                 settle_accuracy: float | None = None):
        self.map, self.X, self.P, self.floor = period_map, state_scale, parameter_scale, floor
        self.tol, self.max_iterations, self.stability_tol = tol, max_iterations, stability_tol
        self.estimator = estimator
        #: ``settle_within_error``'s accuracy (None: every orbit to ``tol``), and the
        #: :class:`WithinError` of the last settling solve (None where it was solved to ``tol``)
        self.settle_accuracy = settle_accuracy
        self.last_within: WithinError | None = None
        #: the last accepted orbit's distance from its coarse orbit, per block (None: not known)
        self.last_distance: np.ndarray | None = None
        self.calls_of_last_solve = 0
        #: the monodromy of the last accepted orbit: the chord iterations' Jacobian at a fixed parameter
        self.kept: np.ndarray | None = None
        #: the chord's predicted contraction per step at the next natural step (``keep``)
        self.chord_rate = math.inf
        #: the coarse level's chord rate at the last point (``estimate``; 0: the chord is tried first)
        self.coarse_chord_rate = 0.0

    def keep(self, monodromy: np.ndarray) -> None:
        """``monodromy`` (n, n), an accepted orbit's, becomes the next chord's Jacobian; ``chord_rate``
        the rate a chord with the one before would have had on it (``chord_rate``)."""
        self.chord_rate = math.inf if self.kept is None else chord_rate(self.kept, monodromy)
        self.kept = monodromy

    def scaled(self, state, parameter) -> np.ndarray:
        return np.append(state / self.X, parameter / self.P)

    def unscaled(self, y):
        return y[:-1] * self.X, float(y[-1] * self.P)

    def parameter_derivative(self, state, parameter, end) -> np.ndarray:
        """``dP/dp`` (n,) by a forward difference (see the module notes)."""
        increment = _FORWARD_DIFFERENCE * max(abs(parameter), self.P)
        shifted = self.map.end_state(state, parameter + increment)    # a period without its monodromy
        return (shifted - end) / increment

    def tangent(self, state, parameter, monodromy, end, direction: float) -> np.ndarray:
        """Unit null vector of ``[Phi - I, dP/dp]`` (scaled), its parameter part along ``direction``."""
        n = state.size
        bordered = np.empty((n, n + 1))
        bordered[:, :n] = monodromy - np.eye(n)
        bordered[:, n] = self.parameter_derivative(state, parameter, end) * self.P / self.X
        tangent = np.linalg.svd(bordered)[2][-1]
        if tangent[-1] * direction < 0.0 or (tangent[-1] == 0.0 and direction < 0.0):
            tangent = -tangent
        return tangent

    def solve(self, y_pred, normal, *, fixed_parameter: float | None = None, abandon=None, settle: bool = False):
        """Newton from ``y_pred`` on the hyperplane ``normal . (y - y_pred) = 0``, or at the parameter
        value ``fixed_parameter`` exactly (``normal = e_p``); returns the :class:`NewtonResult`
        (``extra``: the monodromy). At a fixed parameter with a ``kept`` monodromy (the last orbit's):
        chord iterations with it, periods without their monodromy, and the exact one at the converged
        state (``solve_fixed_point``), about half the cost of Newton's every-period monodromy.
        ``settle`` (at a fixed parameter, with ``settle_accuracy``): converged once within its own
        error (``last_within``, for ``orbit``), as :func:`periodic.find_orbit`'s ``settle_within_error``."""
        self.last_within = None
        if fixed_parameter is not None and self.kept is not None:
            return self._chord_at(y_pred, fixed_parameter, abandon, settle)
        n = y_pred.size - 1
        column = {}

        def evaluate(y):
            state, parameter = self.unscaled(y)
            if fixed_parameter is not None:  # the exact value, not its scaled round trip
                parameter = fixed_parameter
            end, monodromy = self.map(state, parameter)
            jacobian = np.empty((n + 1, n + 1))
            jacobian[:n, :n] = monodromy - np.eye(n)
            if fixed_parameter is not None:  # the last row fixes dp = 0: the column does not matter
                jacobian[:n, n] = 0.0
            else:
                if "dP/dp" not in column:  # once per solve, at its first iterate (see the module notes)
                    column["dP/dp"] = self.parameter_derivative(state, parameter, end) * self.P / self.X
                jacobian[:n, n] = column["dP/dp"]
            jacobian[n] = normal
            value = np.append((end - state) / self.X, normal @ (y - y_pred))
            return value, jacobian, monodromy

        def relative(y, value):
            return relative_residual(y[:-1] * self.X, value[:-1] * self.X, self.floor)

        calls_before = self.map.calls
        found = newton(evaluate, y_pred, tol=self.tol, max_iterations=self.max_iterations, relative=relative,
                       abandon=abandon)
        self.calls_of_last_solve = self.map.calls - calls_before
        return found

    def _chord_at(self, y_pred, parameter: float, abandon=None, settle: bool = False):
        """``solve`` at the fixed ``parameter`` by ``solve_fixed_point`` with the ``kept`` monodromy,
        its result in the scaled unknowns (``y`` with the parameter, the residual with a zero
        constraint row, ``extra`` the monodromy at ``y``)."""
        n = y_pred.size - 1
        calls_before = self.map.calls
        by_chord = self.chord_rate <= CHORD_RATE
        turned = None if abandon is None else (lambda state: abandon(self.scaled(state, parameter)))
        start, within = self.unscaled(y_pred)[0], None
        if settle and self.settle_accuracy is not None and self.estimator.coarse is not None:
            # where the coarse level goes by Newton it does not start from the probe's period: the last
            # orbit's distance instead of a probe (its actual share is checked all the same)
            known = self.last_distance if self.coarse_chord_rate > CHORD_RATE else None
            within = WithinError(self.estimator.coarse, parameter, self.settle_accuracy, self.map.blocks, start,
                                 distance=known)
        found = solve_fixed_point(self.map, start, parameter, tol=self.tol,
                                  max_iterations=self.max_iterations, state_scale=self.floor,
                                  monodromy=self.kept if by_chord else None, abandon=turned, settled=within)
        self.last_within = within
        self.calls_of_last_solve = self.map.calls - calls_before
        monodromy = found.extra if found.extra is not None else found.jacobian + np.eye(n)
        return replace(found, y=self.scaled(found.y, parameter), residual_vector=np.append(
            found.residual_vector / self.X, 0.0), jacobian=None, extra=monodromy)

    def orbit(self, found, start_time, fixed_parameter: float | None = None,
              within: WithinError | None = None) -> PeriodicOrbit:
        """The orbit of ``found`` (``solve``'s), judged (``estimate``); ``within``: the solve's
        ``last_within`` where it settled within its error."""
        state, parameter = self.unscaled(found.y)
        if fixed_parameter is not None:
            parameter = fixed_parameter
        orbit = classify(parameter, state, found.extra, residual=found.residual, iterations=found.iterations,
                         map_calls=self.calls_of_last_solve, converged=found.converged, reason=found.reason,
                         stability_tol=self.stability_tol, start_time=start_time)
        return self.estimate(orbit, start_time, within)

    def estimate(self, orbit: PeriodicOrbit, start_time: float, within: WithinError | None = None) -> PeriodicOrbit:
        """``orbit`` with its error bars from the coarse level (``ErrorEstimate.apply``), the coarse
        orbit solved by chord iterations with this orbit's monodromy only where they are predicted to
        contract by ``CHORD_RATE`` (``chord_rate`` of the two levels' monodromies at the last point;
        tried at the first), else by Newton: on six_bar at N = 128 the N/2 orbit differs from the N
        one by 10-110 % of the state near 78 rad/s and the chord contracted by 0.1-0.2 only (issue 24)."""
        by_chord = self.coarse_chord_rate <= CHORD_RATE

        def refine(start, kept):
            return refined_orbit(self.map, start, orbit.parameter, kept, tol=self.tol,
                                 max_iterations=self.max_iterations, state_scale=self.floor,
                                 iterations=orbit.iterations, map_calls=orbit.map_calls,
                                 stability_tol=self.stability_tol, start_time=start_time)

        judged, _ = judge_within_error(orbit, within, self.estimator, refine, tol=self.tol,
                                       accuracy=self.settle_accuracy, stability_tol=self.stability_tol,
                                       start_time=start_time, chord=by_chord)
        coarse = self.estimator.coarse_monodromy
        if coarse is not None:
            self.coarse_chord_rate = chord_rate(orbit.monodromy, coarse)
        coarse_state = self.estimator.coarse_orbit
        self.last_distance = (None if coarse_state is None or not judged.converged
                              else block_max(judged.state - coarse_state, self.map.blocks))
        return judged


def chord_rate(kept: np.ndarray, monodromy: np.ndarray) -> float:
    """The asymptotic contraction per step of chord iterations with the Jacobian ``kept - I`` on a map
    whose monodromy is ``monodromy`` (both (n, n)): the error goes as ``e <- (kept - I)^-1 (kept -
    monodromy) e``, so its spectral radius (inf where ``kept - I`` is singular)."""
    try:
        iteration = np.linalg.solve(kept - np.eye(kept.shape[0]), kept - monodromy)
    except np.linalg.LinAlgError:
        return math.inf
    if not np.all(np.isfinite(iteration)):
        return math.inf
    return float(np.max(np.abs(np.linalg.eigvals(iteration)), initial=0.0))


def _test_functions(multipliers: np.ndarray) -> dict:
    """Test functions whose sign changes where a multiplier crosses the unit circle (see module notes)."""
    pairs = multipliers[multipliers.imag > 0.0]
    return {
        "fold": float(np.prod(1.0 - multipliers).real),
        "period_doubling": float(np.prod(1.0 + multipliers).real),
        "secondary_hopf": float(np.prod(np.abs(pairs) ** 2 - 1.0)),
    }


def _outside(orbit: PeriodicOrbit, stability_tol: float) -> int:
    return int(np.sum(np.abs(orbit.multipliers) > 1.0 + stability_tol))


def continue_orbits(period_map, guess, start: float, stop: float, *, step: float | None = None,
                    method: str = "natural", min_step: float | None = None, max_step: float | None = None,
                    tol: float = 1e-10, max_iterations: int = 10, max_points: int = 500,
                    stop_at_instability: bool = True, state_scale: float | None = None,
                    estimate=None, error_factor: float = DEFAULT_ERROR_FACTOR,
                    stability_tol: float = STABILITY_TOL, accuracy: float | None = None,
                    settle_within_error: bool = False) -> OrbitBranch:
    """Follow the periodic orbit of ``period_map`` from ``parameter = start`` (near ``guess`` (n,)) to
    ``stop``.

    ``period_map(state (n,), parameter) -> (end_state (n,), monodromy (n, n))`` as for
    :func:`periodic.find_orbit`.  ``method``: ``"natural"`` (parameter steps; stops at a fold, where
    the orbit turns back) or ``"arclength"`` (pseudo-arclength: through folds).  ``step``, ``min_step``
    and ``max_step`` are in units of the parameter (defaults ``|stop - start|`` / 50, * 1e-6, / 10;
    for ``arclength`` the length of a step in the scaled variables, which moves the parameter by
    ``step`` where the state barely changes).  ``tol`` and ``max_iterations``: each corrector's Newton
    (relative residual ``|P(x) - x| / (|x| + state_scale)``).  ``state_scale`` (units of the state):
    the scale of the state in the arclength norm and the residual's absolute floor (default: the
    largest rms state met so far for the former, 0 for the latter).  With ``stop_at_instability`` the
    branch ends at the first bifurcation where a multiplier leaves the unit circle (the located
    orbit is its last point), else it goes on and records every crossing.  ``estimate`` and
    ``error_factor``: the error bars of each orbit's verdict, as for :func:`periodic.find_orbit` (the
    map on N/2 steps costs a Newton solve on it per point, about a third more calls; the bifurcations
    are detected and located on the N-step multipliers either way); ``accuracy`` (a fraction, default
    None: ``tol``): each N/2 orbit converged once its correction is at most that of its distance from
    the N-step orbit, as :func:`periodic.find_orbit`'s.  ``settle_within_error`` (with ``estimate`` a
    period map and ``accuracy``; natural steps): each step's orbit converged once its correction is
    at most ``accuracy`` of its distance from its N/2 orbit, the error bars widened by that share, as
    :func:`periodic.find_orbit`'s (the first orbit, the located bifurcations: to ``tol``).  Nothing is
    raised on a numerical failure: see ``OrbitBranch.status``.
    """
    start_time = time.perf_counter()
    guess = check_state("guess", guess)
    start, stop = check_real("start", start), check_real("stop", stop)
    if start == stop:
        raise PeriodicError(f"stop: expected a value different from start = {start:g}, got {stop:g}")
    if method not in METHODS:
        raise PeriodicError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    span, direction = abs(stop - start), math.copysign(1.0, stop - start)
    step = _positive("step", span / 50.0 if step is None else step)
    max_step = _positive("max_step", max(span / 10.0, step) if max_step is None else max_step)
    min_step = _positive("min_step", min(span * 1e-6, step) if min_step is None else min_step)
    if not min_step <= step <= max_step:
        raise PeriodicError(f"step: expected min_step <= step <= max_step, got {min_step:g}, {step:g}, {max_step:g}")
    tol = check_tol("tol", tol, 1.0)
    max_iterations = check_iterations("max_iterations", max_iterations)
    max_points = check_iterations("max_points", max_points)
    floor = 0.0 if state_scale is None else check_tol("state_scale", state_scale)
    counted = CountingMap(period_map, guess.size)
    if accuracy is not None:
        accuracy = check_tol("accuracy", accuracy, 1.0)
    estimator = ErrorEstimate(estimate, error_factor, guess.size, tol=tol, max_iterations=max_iterations,
                              state_scale=floor, accuracy=accuracy,
                              settle_on_iterate=SETTLE_ON_ITERATE and accuracy is not None)

    if settle_within_error and (estimator.coarse is None or accuracy is None):
        raise PeriodicError("settle_within_error: expected `estimate` (the period map on N/2 steps) and `accuracy`")
    first = solve_fixed_point(counted, guess, start, tol=tol, max_iterations=max(max_iterations, 20),
                              state_scale=floor)
    first_orbit = classify(start, first.y, first.extra if first.extra is not None else first.jacobian,
                           residual=first.residual, iterations=first.iterations, map_calls=counted.calls,
                           converged=first.converged, reason=first.reason, stability_tol=stability_tol,
                           start_time=start_time)
    if not first.converged:
        return _branch([], [], [], "failed", f"failed: the first orbit was not found: {first_orbit.message}",
                       method, counted.calls + estimator.calls, start_time, guess.size)
    rms = float(np.sqrt(np.mean(first.y**2)))
    scale = state_scale if state_scale else (rms if rms > 0.0 else 1.0)
    corrector = _Corrector(counted, scale, span, floor, tol, max_iterations, stability_tol, estimator,
                           settle_accuracy=accuracy if settle_within_error else None)
    first_orbit = corrector.estimate(first_orbit, start_time)
    follower = _Follower(corrector, method, direction, stop, stop_at_instability, start_time,
                         adaptive_scale=not state_scale)
    return follower.run(first_orbit, step=step, min_step=min_step, max_step=max_step, max_points=max_points)


def _positive(name, value) -> float:
    value = check_real(name, value)
    if not value > 0.0:
        raise PeriodicError(f"{name}: expected a step > 0 in units of the parameter, got {value:g}")
    return value


class _Follower:
    """The continuation loop: predictor, corrector, step control, bifurcations, the end."""

    def __init__(self, corrector: _Corrector, method, direction, stop, stop_at_instability, start_time,
                 adaptive_scale: bool):
        self.corrector, self.method, self.direction, self.stop = corrector, method, direction, stop
        self.adaptive_scale = adaptive_scale
        self.stop_at_instability, self.start_time = stop_at_instability, start_time
        self.orbits: list[PeriodicOrbit] = []
        self.bifurcations: list[tuple[float, str]] = []
        self.indices: list[int] = []

    def run(self, first: PeriodicOrbit, *, step, min_step, max_step, max_points) -> OrbitBranch:
        corrector = self.corrector
        self.orbits.append(first)
        corrector.keep(first.monodromy)
        # the first tangent: null vector of [Phi - I, dP/dp] at the first orbit (P(x) = x there, to tol)
        tangent = corrector.tangent(first.state, first.parameter, first.monodromy, first.state, self.direction)
        y = corrector.scaled(first.state, first.parameter)
        last_reason = ""
        while True:
            current = self.orbits[-1]
            if current.parameter == self.stop:
                return self._finish("reached")
            if len(self.orbits) >= max_points:
                return self._finish("max_points", max_points=max_points)
            if step < min_step:
                return self._finish("min_step", min_step=min_step, reason=last_reason)
            y_pred, normal, fixed = self._predict(y, tangent, step)
            turned = self._turn_check(y, tangent) if EARLY_TURN_CHECK else None
            found = corrector.solve(y_pred, normal, fixed_parameter=fixed, abandon=turned, settle=True)
            if not found.converged:
                last_reason = found.reason
                step *= 0.5
                continue
            secant = found.y - y
            secant /= np.linalg.norm(secant)
            # against the tangent at the last point, not the last secant (see the module notes)
            if secant @ tangent < math.cos(MAX_TURN):
                last_reason = (f"the branch turned by more than {math.degrees(MAX_TURN):g} degrees in a step "
                               "(a fold, or a jump to another branch)")
                step *= 0.5
                continue
            parameter = fixed if fixed is not None else corrector.unscaled(found.y)[1]
            passed = (parameter - self.stop) * self.direction > 0.0
            if not passed:
                # the tangent where the step ends (the next step's direction and turn check); the step
                # itself may make a large angle with it where the branch bends sharply (issue 12)
                new_tangent = self._local_tangent(found, parameter, secant)
                new = corrector.orbit(found, self.start_time, fixed, within=corrector.last_within)
                if not new.converged:     # sent on to tol where its settling misled, and failed there
                    last_reason = new.message
                    step *= 0.5
                    continue
                if fixed is not None:     # the orbit's state (sent on to tol where its settling misled)
                    found = replace(found, y=corrector.scaled(new.state, fixed))
            else:  # passed: the end point exactly at stop
                new, found = self._at_stop(y, found.y)
                if new is None:
                    last_reason = "the orbit at stop was not found"
                    step *= 0.5
                    continue
                new_tangent = tangent    # not used: the branch ends at stop
            if self._crossing(current, new, y, found.y):
                return self._finish("instability")
            self.orbits.append(new)
            corrector.keep(new.monodromy)
            y, tangent = found.y, new_tangent
            if self.adaptive_scale:
                y, tangent = self._rescale(y, tangent, new.state)
            if found.iterations <= (EASY_ITERATIONS if fixed is None else EASY_CHORD_ITERATIONS):
                step = min(step * GROWTH, max_step)

    @staticmethod
    def _turn_check(y, tangent):
        """``abandon(y_new) -> str`` for the corrector's Newton: the turn check's reason where the secant
        from ``y`` to the iterate ``y_new`` (scaled) turns by more than ``MAX_TURN`` from ``tangent``
        (``EARLY_TURN_CHECK``), else ""."""
        def turned(y_new) -> str:
            secant = y_new - y
            norm = float(np.linalg.norm(secant))
            if norm > 0.0 and secant @ tangent >= math.cos(MAX_TURN) * norm:
                return ""
            return (f"the branch turned by more than {math.degrees(MAX_TURN):g} degrees in a step "
                    "(a fold, or a jump to another branch)")
        return turned

    def _local_tangent(self, found, parameter, secant) -> np.ndarray:
        """The unit tangent (scaled) of the branch at the converged point ``found`` (at ``parameter``):
        the next predictor's direction and the turn checks' reference. Oriented, for ``natural``,
        along the direction of the parameter (the branch it follows has no fold: where the tangent's
        parameter part vanishes the step fails), for ``arclength`` along ``secant``, the step just taken
        (through folds). A secant across a sharp bend may make more than 90 degrees with the tangent at
        its end: orienting a natural continuation's tangent by it turned the branch back (six_bar,
        75 -> 125 rad/s, at 106.283 rad/s: every later step rejected, issue 24)."""
        corrector = self.corrector
        state = corrector.unscaled(found.y)[0]
        end = state + found.residual_vector[:-1] * corrector.X
        if self.method == "natural":
            return corrector.tangent(state, parameter, found.extra, end, self.direction)
        tangent = corrector.tangent(state, parameter, found.extra, end, 1.0)
        return tangent if tangent @ secant >= 0.0 else -tangent

    def _rescale(self, y, tangent, state):
        """Grow the state's scale ``X`` to the rms of ``state`` once that exceeds ``RESCALE`` X: steps
        stay a fraction of the branch's size as the response grows (near a resonance by 10-100x)."""
        rms = float(np.sqrt(np.mean(state**2)))
        corrector = self.corrector
        if not rms > RESCALE * corrector.X:
            return y, tangent
        ratio = corrector.X / rms
        corrector.X = rms
        y, tangent = y.copy(), tangent.copy()
        y[:-1] *= ratio
        tangent[:-1] *= ratio
        return y, tangent / np.linalg.norm(tangent)

    def _predict(self, y, tangent, step):
        """``(y_pred, normal, fixed parameter value or None)`` of the next step."""
        ds = step / self.corrector.P
        if self.method == "natural":
            current = self.orbits[-1].parameter
            remaining = abs(self.stop - current) / self.corrector.P
            ds_parameter = min(ds, remaining) * self.direction
            if abs(tangent[-1]) < 1e-12:  # a vertical tangent: natural continuation cannot go on
                tangent = np.zeros_like(tangent)
                tangent[-1] = self.direction
            y_pred = y + tangent * (ds_parameter / tangent[-1])
            parameter = self.stop if ds >= remaining else current + ds_parameter * self.corrector.P
            normal = np.zeros_like(y)
            normal[-1] = 1.0
            return y_pred, normal, parameter
        return y + ds * tangent, tangent, None

    def _at_stop(self, y_before, y_after):
        """The orbit at ``parameter = stop`` between two scaled points (arclength passing ``stop``)."""
        corrector = self.corrector
        p_before, p_after = y_before[-1] * corrector.P, y_after[-1] * corrector.P
        fraction = (self.stop - p_before) / (p_after - p_before)
        y_pred = y_before + fraction * (y_after - y_before)
        y_pred[-1] = self.stop / corrector.P
        normal = np.zeros_like(y_pred)
        normal[-1] = 1.0
        found = corrector.solve(y_pred, normal, fixed_parameter=self.stop)
        if not found.converged:
            return None, found
        return corrector.orbit(found, self.start_time, self.stop), found

    def _crossing(self, before: PeriodicOrbit, after: PeriodicOrbit, y_before, y_after) -> bool:
        """Record a bifurcation between two accepted points (inserting its orbit); True to stop."""
        tol = self.corrector.stability_tol
        change = _outside(after, tol) - _outside(before, tol)
        if change == 0:
            return False
        signs_before, signs_after = _test_functions(before.multipliers), _test_functions(after.multipliers)
        kind = next((name for name in ("fold", "period_doubling")
                     if signs_before[name] * signs_after[name] < 0.0), "secondary_hopf")
        located = self._locate(kind, y_before, y_after, signs_before[kind], signs_after[kind])
        if located is None:  # interpolate the test function linearly
            fraction = signs_before[kind] / (signs_before[kind] - signs_after[kind])
            parameter = before.parameter + fraction * (after.parameter - before.parameter)
            self.bifurcations.append((parameter, kind))
            self.indices.append(-1)
            logger.warning("the %s near parameter %.6g was not located (interpolated)", kind, parameter)
        else:
            self.orbits.append(located)
            self.bifurcations.append((located.parameter, kind))
            self.indices.append(len(self.orbits) - 1)
        return change > 0 and self.stop_at_instability

    def _locate(self, kind, y_before, y_after, value_before, value_after):
        """The orbit where the test function ``kind`` vanishes on the chord (Brent), or None."""
        corrector = self.corrector
        chord = y_after - y_before
        normal = chord / np.linalg.norm(chord)
        natural = self.method == "natural"
        if natural:
            normal = np.zeros_like(chord)
            normal[-1] = 1.0
        p_before, p_after = corrector.unscaled(y_before)[1], corrector.unscaled(y_after)[1]
        solved = {}

        def test_function(fraction):
            if fraction <= 0.0:
                return value_before
            if fraction >= 1.0:
                return value_after
            fixed = p_before + fraction * (p_after - p_before) if natural else None
            found = corrector.solve(y_before + fraction * chord, normal, fixed_parameter=fixed)
            if not found.converged:
                raise _NotLocated(found.reason)
            solved[fraction] = found, fixed
            multipliers = np.linalg.eigvals(found.extra).astype(complex)
            return _test_functions(multipliers)[kind]

        if not (value_before * value_after < 0.0):
            return None
        from scipy.optimize import brentq  # here: scipy.optimize costs about 0.5 s to import

        try:
            fraction = brentq(test_function, 0.0, 1.0, xtol=LOCATE_XTOL)
        except (_NotLocated, RuntimeError, ValueError):
            return None
        if fraction not in solved:
            return None
        found, fixed = solved[fraction]
        return corrector.orbit(found, self.start_time, fixed)

    def _finish(self, why, *, max_points=0, min_step=0.0, reason="") -> OrbitBranch:
        orbits = self.orbits
        last = orbits[-1]
        named = "; ".join(f"{kind} at {parameter:.6g}" for parameter, kind in self.bifurcations)
        bifurcation_words = f"; bifurcations: {named}" if named else ""
        if why == "reached":
            status = worst_status(*(orbit.status for orbit in orbits))
            message = f"{status}: reached stop = {self.stop:.6g} in {len(orbits)} orbits{bifurcation_words}"
            if status == "unstable":
                message += "; unstable orbits on the branch (see stable)"
        elif why == "instability":
            parameter, kind = self.bifurcations[-1]
            status = "unstable"
            message = (f"unstable: the orbit loses stability by {kind.replace('_', ' ')} at parameter "
                       f"{parameter:.6g} (multiplier {_critical(last):.6g}); stopped there "
                       f"(stop_at_instability){bifurcation_words}")
        elif why == "max_points":
            status = "failed"
            message = (f"failed: max_points = {max_points} orbits used before reaching stop = {self.stop:.6g} "
                       f"(last at {last.parameter:.6g}); raise max_points or max_step{bifurcation_words}")
        else:
            status = "failed"
            message = (f"failed: the step fell below min_step = {min_step:.3g} at parameter {last.parameter:.6g} "
                       f"({reason or 'no reason recorded'}){bifurcation_words}")
            mu = _critical(last)
            if self.method == "natural" and abs(mu.imag) < 1e-9 and abs(mu.real - 1.0) < 0.1:
                message += (f"; the last orbit's critical multiplier {mu.real:.6g} is real and near +1: the branch "
                            "probably turns at a fold there, method='arclength' follows it through")
        return _branch(orbits, self.bifurcations, self.indices, status, message, self.method,
                       self.corrector.map.calls + self.corrector.estimator.calls, self.start_time,
                       last.state.size)


class _NotLocated(RuntimeError):
    """A corrector failed while locating a bifurcation."""


def _critical(orbit: PeriodicOrbit) -> complex:
    """The largest multiplier (the first: they are sorted by decreasing modulus)."""
    return complex(orbit.multipliers[0])


def _branch(orbits, bifurcations, indices, status, message, method, map_calls, start_time, n) -> OrbitBranch:
    return OrbitBranch(
        parameters=np.array([orbit.parameter for orbit in orbits], dtype=float),
        states=np.array([orbit.state for orbit in orbits], dtype=float).reshape(len(orbits), n),
        multipliers=np.array([orbit.multipliers for orbit in orbits], dtype=complex).reshape(len(orbits), n),
        stable=np.array([orbit.is_stable for orbit in orbits], dtype=bool),
        statuses=tuple(orbit.status for orbit in orbits),
        orbits=tuple(orbits),
        bifurcations=tuple(bifurcations),
        bifurcation_indices=tuple(indices),
        status=status,
        message=message,
        method=method,
        map_calls=map_calls,
        run_time=time.perf_counter() - start_time,
    )
