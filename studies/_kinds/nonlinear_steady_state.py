"""``[studies.nonlinear_steady_state]``: the periodic solution of the full nonlinear constrained
equations by Newton shooting (``periodic.find_orbit`` on ``mechanisms.PeriodMap``), started from the
linear periodic state, with the Floquet multipliers of the nonlinear orbit and an N against N/2 error
estimate."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

import mechanisms
import periodic

from .._budget import NOT_APPLICABLE, mesh_terms
from .._kind import StudyKind, register_kind
from .._mechanism import coordinate_parts, observables_along
from .._numerics import DEFAULT_SCHEME, solve_steady
from .._plots import (
    Plot,
    axes_for,
    cost_line,
    drawn,
    headline,
    label,
    legend_outside,
    plain,
    plot_multipliers,
    quantity,
    scene_and_point,
)
from .._result import DerivedPeaks, StudyResult, peaks_of
from .._toolkit import (
    WARM_UP_STEPS,
    Headline,
    StudiesError,
    Summary,
    check_integer,
    check_n_steps,
    cost,
    integer,
    number,
    response_rows,
    speed_values,
    steps,
)
from ._nonlinear_model import AUTO, check_modes, choose_model

#: The fewest steps per period (docs/studies.md): N/2 = 16 steps must still carry the integrator.
MIN_STEPS = 32
#: Default relative residual of the shooting Newton, ``|P(x) - x| / (|x| + scale)``.
TOL = 1e-8
#: Default Newton steps of the shooting.
MAX_ITERATIONS = 12
#: Upper limit of ``max_iterations``: Newton from the linear start converges in a few steps or not at all.
MAX_NEWTON = 100
NEWTON_WHY = "Newton steps of one shooting, each a period with its monodromy; it converges in a few or not at all"
#: Order of the generalized-alpha integrator of ``mechanisms.PeriodMap``.
ORDER = 2
#: Richardson factor of the order-2 integrator: the N-step error is about ``|o_N - o_{N/2}| / (2^2 - 1)``.
ERROR_FACTOR = 1.0 / (2**ORDER - 1)
#: The error levels' orbits (N/2, N/4) are converged once their correction is at most this fraction
#: of their distance from the finer level's orbit (``periodic.find_orbit``'s ``accuracy``, per block
#: of the state: coordinates, rates, lag states): the error estimate to about 1 % of itself, in fewer
#: periods than ``tol`` takes (the N/4 level: ``QUARTER_ACCURACY``).
LEVEL_ACCURACY = 0.01
#: The N-step orbit by chord iterations with the monodromy at the linear start (Newton's first step,
#: then periods without their monodromy; ``periodic.find_orbit``'s ``reuse_first``), the exact
#: monodromy once more at the converged orbit for the multipliers: on six_bar (8 elements per link,
#: 100 rad/s) the monodromy moves by 2.4 % from the linear start to the first iterate, and the chord
#: reached 7e-9 in two periods where Newton took two more with their monodromy. False: Newton
#: throughout (the benchmark's baseline, benchmarks/bench_nonlinear_exudyn.py).
REUSE_FIRST_MONODROMY = True
#: The error levels' orbits (N/2, N/4) are the chord iterates whose correction is within
#: ``LEVEL_ACCURACY``, not those plus their correction (``periodic.find_orbit``'s
#: ``settle_on_iterate``): their monodromy from the period just run, one period fewer per level; the
#: error estimate to about ``LEVEL_ACCURACY`` of itself, as that constant says. False: the iterate
#: plus its correction, evaluated once more (the benchmark's baseline).
SETTLE_ON_ITERATE = True
#: The error budget's mesh term takes the linear start's steady state as its base level
#: (``studies._budget.mesh_terms``' ``response``: the same problem, N and scheme, the same numbers)
#: instead of solving it again. False: solved again (the benchmark's baseline).
REUSE_LINEAR_STATE = True
#: The N-step orbit, too, is converged once its chord correction is within ``LEVEL_ACCURACY`` of its
#: distance from the N/2 orbit (``periodic.find_orbit``'s ``settle_within_error``: that distance
#: measured by the N/2 level's first period, run at the first chord iterate), its residual then above
#: ``tol``, and the error bars widened by the correction's share of that distance: on six_bar (8
#: elements per link, 100 rad/s) the first chord iterate's correction was 0.2 % (positions) and 0.4 %
#: (rates) of the distance, and two periods of N steps were left out of four. False: to ``tol``.
SETTLE_WITHIN_ERROR = True
#: The N/4 level's orbit is converged once its correction is at most this fraction of its distance
#: from the N/2 orbit (with ``LEVEL_ACCURACY``; None: both to ``tol``): it only checks that the ratio
#: of successive differences is in the asymptotic range, so that ratio to about this fraction of
#: itself: on six_bar (8 elements per link, 100 rad/s) one N/4 period of three fewer, 200 -> 192 ms.
QUARTER_ACCURACY = 0.05
#: The trust window's lower end is raised by the ratio's uncertainty, ``RATIO_MARGIN`` times the sum
#: of the levels' settled shares (N/4 ``QUARTER_ACCURACY``, N/2 ``LEVEL_ACCURACY`` twice, the N
#: orbit's ``settled_fraction``): 1.5 for what their first-order reading leaves out (a chord that
#: contracts by 0.1 leaves 1/0.9 of its last correction; a share of the state's distance is not
#: exactly that share of the observables' difference). On six_bar: 0.11, observed order at least
#: 1.67 (ratio 3.2) instead of 1.5 (2.83); the ratio there is 4.49.
RATIO_MARGIN = 1.5
#: An observable whose estimated error exceeds this fraction of its peak-to-peak is ``inaccurate``:
#: the rule and value of the linear steady state's (docs/methods.md), applied to each observable
#: since the nonlinear study reports them.
MAX_RELATIVE_ERROR = periodic.MAX_RELATIVE_ERROR


@dataclass(frozen=True, eq=False)
class NonlinearSteadyState(DerivedPeaks, StudyResult):
    """The periodic orbit of the full nonlinear model over one period, with its stability (the
    fields every result has: ``studies._result``).

    Attributes
    ----------
    problem, scene : str
        The problem's name and scene text.
    parameters : dict
        {name: value} where the orbit is sought.
    units : dict
        {spec: unit} of each observable.
    response : dict of ndarray, {spec: (N+1,)}, units[spec]
        The observables as the linear steady state reports them (deviations from their nominal
        values; joint forces, drive torques and stresses as totals, a drive's torque as the run
        applied it: feedforward plus feedback clipped to its limits, plus lag states).
    response_error : dict, {spec: float}, units[spec]
        The estimated max abs error of each (N against N/2 steps).
    linear_response : dict of ndarray, {spec: (N+1,)}, units[spec]
        The linear periodic state on the same grid.
    labels : tuple of str, (m + L,)
        The independent coordinates, then ``lag.<name>`` of the L lagged controllers.
    t : ndarray, (N+1,), s
        The samples over one period.
    crank_angle : ndarray, (N+1,), rad
        The crank angle at each sample.
    x : ndarray, (N+1, m + L), SI (see labels)
        The independent coordinates' deviation from the nominal rigid motion, then the lag states
        (N m; L = 0 without).
    state : ndarray, (2m + L,), SI
        The orbit's shooting state (coordinates and rates at t = 0, then the lag states).
    multipliers : ndarray of complex, (2m + L,), 1
        The Floquet multipliers of the nonlinear orbit (from the monodromy of the discrete step map).
    multiplier_errors : ndarray, (2m + L,), 1
        The error estimate of their moduli.
    spectral_radius : float, 1
        Their largest modulus.
    error_estimate : float, SI
        The max abs error of ``state``.
    iterations, map_calls : int
        Newton steps, and period map evaluations (N/2 included).
    residual : float, 1
        The final relative residual.
    status, message : str
        ``periodic.find_orbit``'s verdict (``failed`` with the reason when Newton did not converge),
        made at least ``inaccurate`` where its numbers are not trusted.
    is_stable : bool
        The orbit's stability (a best estimate where the status says it is not trusted).
    instability_kind : str
        "fold", "period_doubling", "secondary_hopf" or "".
    n_steps : int
        Steps per period N.
    run_time : float, s
        The whole study: the linear start and the shooting.
    linear_run_time : float, s
        The linear start.
    shooting_run_time : float, s
        The shooting (N and N/2, JIT compilation excluded).
    settings : dict
        The study's arguments.
    reduced_modes : dict, {link: int}
        The modes of each elastic link the study reduced (``modes`` option; {} on the full element
        models, and in files written before the option).
    reduction_error : dict, {spec: float}, units[spec]
        The reduction check's error of each observable (the linear steady state against the next
        larger mode set, ``studies._kinds._nonlinear_model``); {} without a reduction. Not part of
        ``response_error`` (the time step's).
    peak, peak_error, peak_to_peak, peak_to_peak_error : dict, {spec: float}, units[spec]
        Properties: of ``response`` with ``response_error`` (``studies._numerics.peak_summary``).
    linear_peak_to_peak : dict, {spec: float}, units[spec]
        Property: the peak-to-peak of ``linear_response``.
    """

    problem: str
    scene: str
    parameters: Mapping[str, float]
    units: Mapping[str, str]
    response: Mapping[str, np.ndarray]
    response_error: Mapping[str, float]
    linear_response: Mapping[str, np.ndarray]
    labels: tuple[str, ...]
    t: np.ndarray
    crank_angle: np.ndarray
    x: np.ndarray
    state: np.ndarray
    multipliers: np.ndarray
    multiplier_errors: np.ndarray
    spectral_radius: float
    error_estimate: float
    iterations: int
    map_calls: int
    residual: float
    status: str
    message: str
    is_stable: bool
    instability_kind: str
    n_steps: int
    run_time: float
    linear_run_time: float
    settings: Mapping[str, Any] = field(default_factory=dict)
    shooting_run_time: float = float("nan")
    reduced_modes: Mapping[str, int] = field(default_factory=dict)
    reduction_error: Mapping[str, float] = field(default_factory=dict)
    mesh_error: Mapping[str, float] = field(default_factory=dict)
    error_methods: Mapping[str, str] = field(default_factory=dict)

    _units = {"t": "s", "crank_angle": "rad", "x": "SI (see labels)", "response": "@observables",
              "linear_response": "@observables", "state": "SI (see labels: coordinates, rates, lags)",
              "multipliers": "1", "multiplier_errors": "1"}

    @property
    def headline(self) -> str:
        return headline(self.status, self.instability_kind)

    def _peaks(self) -> dict[str, dict[str, float]]:
        # the errors are the budget's totals: the time step's and the mesh's (studies._budget)
        return peaks_of(self.response, {spec: e + abs(self.mesh_error.get(spec, 0.0))
                                        for spec, e in self.response_error.items()})

    @property
    def error_budget(self) -> dict[str, dict[str, Any]]:
        """{spec: {term: float or "not applicable"}}: the peak-to-peak's error budget
        (``studies._budget``): the time step (N against N/2), the mesh (the linear state's, where
        it applies), the reduction where links were reduced (``reduction_error``); the linearisation
        does not apply to the nonlinear state."""
        time_step = peaks_of(self.response, self.response_error)["peak_to_peak_error"]
        # a file written before the budget (no error_methods) did not estimate the mesh: unknown
        unmeshed = NOT_APPLICABLE if self.error_methods else math.nan
        budget = {spec: {"time_step": time_step[spec],
                         "mesh": 2.0 * abs(self.mesh_error[spec]) if spec in self.mesh_error else unmeshed,
                         "linearisation": NOT_APPLICABLE} for spec in self.response}
        # links reduced by default (``modes``): the reduction check's difference (max abs over the
        # period) bounds the peak-to-peak's change by twice itself
        for spec in budget:
            if spec in self.reduction_error:
                budget[spec]["reduction"] = 2.0 * abs(self.reduction_error[spec])
        return budget

    @property
    def linear_peak_to_peak(self) -> dict[str, float]:
        """{spec: float} the peak-to-peak of the linear periodic state (units of each spec)."""
        return peaks_of(self.linear_response, {})["peak_to_peak"]

    def _filled(self, group: Any) -> dict[str, Any]:
        if "shooting_run_time" in group.attrs:
            return {}
        # written when run_time was the shooting's alone
        return {"shooting_run_time": self.run_time, "run_time": self.run_time + self.linear_run_time}

    def plot(self, *, axes: Any = None) -> Plot:
        """Each observable over one crank revolution, nonlinear and linear (one axes each), and the
        multipliers of the nonlinear orbit (last axes)."""
        specs = list(self.response)
        axes = axes_for(len(specs) + 1, axes)
        angle = np.degrees(self.crank_angle - self.crank_angle[0])
        artists: dict[str, list] = {}
        for ax, spec in zip(axes, specs):
            nonlinear, linear = self.peak_to_peak[spec], self.linear_peak_to_peak[spec]
            error = float(self.response_error.get(spec, float("nan")))
            response = np.asarray(self.response[spec], dtype=float)
            # the error bar of the nonlinear curve (N against N/2), a band about it
            band = [ax.fill_between(angle, response - error, response + error, color="C0", alpha=0.25, lw=0,
                                    label="± error estimate")] if np.isfinite(error) else []
            artists[spec] = (ax.plot(angle, response, color="C0", label="nonlinear periodic") + band
                             + ax.plot(angle, self.linear_response[spec], "--", color="C1",
                                       label="linear periodic"))
            ax.set_xlabel("drive angle (deg)")
            ax.set_ylabel(label(spec, self.units[spec]))
            ax.set_title(f"{spec}: peak to peak nonlinear / linear = {nonlinear / linear:.4g}; error "
                         f"estimate {quantity(error, self.units[spec])}", fontsize="small")
            legend_outside(ax)
        axes[0].figure.suptitle(f"{scene_and_point(self)}: nonlinear periodic state, {self.headline}",
                                fontsize="medium", color="C3" if self.status != "ok" else "k")
        # the radius's error bar: the error estimate of the largest multiplier's modulus
        errors = np.asarray(self.multiplier_errors, dtype=float)
        radius_error = float(errors[int(np.argmax(np.abs(self.multipliers)))]) if errors.size else float("nan")
        artists["multipliers"] = plot_multipliers(
            self.multipliers, ax=axes[-1],
            title=f"spectral radius {self.spectral_radius:.6f} ± {plain(radius_error)}\n" + cost_line(
                f"{self.iterations} Newton steps, relative residual {plain(self.residual)}", self.shooting_run_time))
        return drawn(axes, artists)


class _Recording:
    """A period map that remembers the last state it was called with (the coarse orbit's, once
    ``periodic.find_orbit``'s estimate has converged on it) and the monodromy there (None when that
    call ran the period without it)."""

    def __init__(self, period_map: Any):
        self.period_map, self.last, self.last_monodromy = period_map, None, None

    def __call__(self, state: np.ndarray, parameter: float):
        self.last = np.array(state, dtype=float)
        end, self.last_monodromy = self.period_map(state, parameter)
        return end, self.last_monodromy

    def end_state(self, state: np.ndarray, parameter: float) -> np.ndarray:
        """A period without its monodromy (``periodic.find_orbit``'s chord iterations)."""
        self.last, self.last_monodromy = np.array(state, dtype=float), None
        return self.period_map.end_state(state, parameter)

    @property
    def resolution(self) -> np.ndarray:
        return self.period_map.resolution

    @property
    def blocks(self) -> tuple:
        return self.period_map.blocks


@dataclass(frozen=True)
class ShootingSetup:
    """The linear start of a shooting at one parameter point (package-internal, shared by the
    nonlinear studies): ``linear`` the ``studies.Linear``, ``steady`` its steady state, ``fine`` and
    ``coarse`` the ``mechanisms.PeriodMap`` on N and N/2 steps, ``guess`` (2m + L,) the linear periodic
    state as a shooting state (coordinates, then rates, SI, then the L lag states, N m), ``run_time`` s
    of the linear start."""

    linear: Any
    steady: Any
    fine: Any
    coarse: Any
    guess: np.ndarray
    run_time: float

    def period_map(self, n_steps: int) -> Any:
        """The period map of the same mechanism on ``n_steps`` steps (a divisor of N), about the same
        nominal motion and on the same independent coordinates."""
        import mechanisms

        lin = self.linear.context
        return mechanisms.PeriodMap(lin.mechanism, n_steps=n_steps, independent=self.fine.independent,
                                    nominal=lin.nominal)


def shooting_setup(problem: Any, values: Mapping[str, float] | None, n_steps: int) -> ShootingSetup:
    """The linear start of a nonlinear shooting of ``problem`` at ``values`` on ``n_steps`` steps (a
    multiple of 4): the linear periodic state and the period maps on N and N/2 steps. Raises
    ``StudiesError`` for a problem without a full nonlinear model."""
    if not getattr(problem, "supports_nonlinear", False) or not hasattr(problem, "outlines"):
        raise StudiesError(f"problem {problem.name!r}: a nonlinear steady state needs a mechanism problem "
                           "(studies.MechanismProblem), expected one with a full nonlinear model")
    import mechanisms

    started = time.perf_counter()
    linear = problem.linearize(values, n_steps=n_steps)
    steady = solve_steady(linear)
    lin = linear.context
    fine = mechanisms.PeriodMap(lin.mechanism, n_steps=n_steps, independent=lin.coefficients.independent,
                                nominal=lin.nominal)
    coarse = mechanisms.PeriodMap(lin.mechanism, n_steps=n_steps // 2, independent=fine.independent,
                                  nominal=lin.nominal)
    # the linear periodic state on the constraints (with the axial shortening of stiffened links); the
    # lagged controllers' states are the linear coordinates' last L entries (linearize: lag.<name>)
    start = steady.state.x[0]
    guess = fine.state_of(*lin.start_state(start, steady.state.v[0]),
                          lag_states=start[start.size - fine.n_lags:])
    return ShootingSetup(linear, steady, fine, coarse, guess, time.perf_counter() - started)


def orbit_observables(linear: Any, period_map: Any, state: np.ndarray, *, observables: bool = True
                      ) -> tuple[dict, np.ndarray, int]:
    """Over one period of ``period_map`` (a ``mechanisms.PeriodMap`` whose steps divide the N steps of
    ``linear``, a ``studies.Linear``) from the shooting state ``state`` (2m + L,): ({spec: (n+1,)} the
    observables as the linear steady state reports them (``studies._mechanism.observables_along``:
    deviations from their nominal values, totals of forces, torques and stresses; units of each
    spec; {} without ``observables``), z (n+1, m + L) the independent coordinates' deviations (SI)
    and the L lag states (N m), the number of steps the integrator split into substeps), n the map's
    steps. Package-internal, shared by the nonlinear studies.

    Observables of the multipliers or rates (joint forces, drive torques) are read over a second
    period: each period of the map restarts from the shooting state with consistent accelerations
    and multipliers, which the index-3 scheme's own differ from; the multipliers carry that restart
    for the first ~16 steps (1.3 % of a joint force's peak to peak at N = 256, 4 % at N = 128, about
    the size of their N/2 error estimate), whereas the second period is the scheme's steady motion,
    as a long transient ends in it. The coordinates carry the restart far less (0.04 of their error
    estimate): they, and the observables that are functions of them, are read over the first."""
    lin = linear.context
    model, n = period_map.model, period_map.n_steps
    settled = {spec for spec in (linear.observables if observables else ())
               if not _of_coordinates_only(model.observable(spec))}
    run = period_map.run(state, tangent=False, n_periods=2 if settled else 1)
    stride = (lin.nominal.s.shape[0] - 1) // n
    response = {}
    for period, specs in ((0, [spec for spec in linear.observables if observables and spec not in settled]),
                          (1, sorted(settled))):
        if specs:
            part = slice(period * n, (period + 1) * n + 1)
            response.update(observables_along(linear, model, run.t[part], run.s[part], run.sdot[part],
                                              run.lam[part], run.lag_states[part], stride=stride, specs=specs))
    response = {spec: response[spec] for spec in linear.observables if spec in response}
    z = np.concatenate([(run.s[:n + 1] - lin.nominal.s[::stride])[:, period_map.independent],
                        run.lag_states[:n + 1]], axis=1)
    return response, z, run.n_substeps


def _of_coordinates_only(observable: Any) -> bool:
    """Whether ``observable`` is a function of the coordinates, or composed of such (a point's
    displacement; a joint force's magnitude is not): ``studies._mechanism.coordinate_parts``."""
    return coordinate_parts(observable) is not None


def substep_verdict(status: str, message: str, n_substeps: int, n_steps: int) -> tuple[str, str]:
    """(status, message) of an orbit whose period the integrator ran with ``n_substeps`` split steps.

    The monodromy (``mechanisms.PeriodMap``) is exact only for a period taken in the N uniform steps:
    a split step enters it as the tangent of the full step it replaced, an approximation of unknown
    error. The multipliers, and a verdict of stability read from them, are then not trusted: the status
    becomes at least ``inaccurate`` (a wrong ``ok`` is worse than none)."""
    reason = substep_reason(n_substeps, n_steps)
    if not reason:
        return status, message
    return periodic.worst_status(status, "inaccurate"), f"{message}; inaccurate: {reason}"


def substep_reason(n_substeps: int, n_steps: int, run: str = "") -> str:
    """Why an orbit whose period (``run``: which one, e.g. "the N/2 run's") the integrator ran with
    ``n_substeps`` split steps is not trusted ("" when no step was split)."""
    if n_substeps <= 0:
        return ""
    return (f"the integrator split steps into {n_substeps} substeps on {run or 'this'} orbit, so its "
            f"monodromy (and the multipliers and stability verdict from it) is only approximate; raise "
            f"n_steps above {n_steps} until no step is split")


def untrusted_verdict(status: str, message: str, reasons: list[str]) -> tuple[str, str]:
    """(status, message) of an orbit with the verdict ``status``, ``message`` (``periodic.find_orbit``'s)
    and the ``reasons`` its numbers are not trusted: the status becomes at least ``inaccurate``, and the
    message leads with the status and the reasons, then gives the stability verdict as a best estimate
    only (``is_stable`` stays that best estimate)."""
    if not reasons or status == "failed":
        return status, message
    status = periodic.worst_status(status, "inaccurate")
    return status, (f"{status}: {'; '.join(reasons)}; the stability verdict is therefore a best estimate "
                    f"only, not trusted: {message}")


def _error_estimates(setup: ShootingSetup, response: Mapping[str, np.ndarray], z: np.ndarray,
                     coarse_state: np.ndarray, speed: float, *, tol: float, max_iterations: int,
                     monodromy: np.ndarray | None = None, state: np.ndarray | None = None,
                     coarse_monodromy: np.ndarray | None = None, settled_fraction: float = 0.0
                     ) -> tuple[dict[str, float], list[str]]:
    """({spec: estimated max abs error of the N-step response} from the N/2 orbit ``coarse_state``,
    the reasons the estimate is not trusted): the N/2 run must not split steps, the orbit found again
    on N/4 steps must give a ratio of successive differences of z in the asymptotic range
    (``periodic.error_verdict``, as the linear steady state's check), and each observable's error must
    stay within ``MAX_RELATIVE_ERROR`` of its peak-to-peak."""
    linear, n_steps, m = setup.linear, setup.fine.n_steps, setup.fine.independent.size
    coarse_response, z_coarse, coarse_substeps = orbit_observables(linear, setup.coarse, coarse_state)
    # the convergence check on the coordinates (the lag states, N m, would set its scale instead)
    z, z_coarse = z[:, :m], z_coarse[:, :m]
    # an N orbit settled within its error (``settled_fraction`` of its distance from the N/2 orbit):
    # that share of each difference adds to the estimate (``periodic.find_orbit``)
    widened = ERROR_FACTOR + settled_fraction
    errors = {spec: widened * float(np.abs(response[spec][::2] - coarse_response[spec]).max())
              for spec in response}
    reasons = [substep_reason(coarse_substeps, n_steps, "the N/2 run's")]
    quarter_map = setup.period_map(n_steps // 4)
    # started from the N and N/2 orbits extrapolated with the order (where the step's error is in its
    # asymptotic range, which this level checks, x_{N/4} - x_{N/2} = 2^p (x_{N/2} - x_N)), by chord
    # iterations with the N/2 orbit's monodromy where it is known (nearer the N/4 map's than the N
    # orbit's ``monodromy``: on six_bar the chord with the N orbit's stopped contracting after 4
    # periods and Newton took 3 more), converged to LEVEL_ACCURACY of its distance from the N/2 orbit
    guess = coarse_state if state is None else coarse_state + 2**ORDER * (coarse_state - state)
    kept = monodromy if coarse_monodromy is None else coarse_monodromy
    # (its multipliers are not read: no exact monodromy at its orbit)
    accuracy = None if LEVEL_ACCURACY is None else QUARTER_ACCURACY
    options = {"tol": tol, "max_iterations": max_iterations, "monodromy": kept, "finer": coarse_state,
               "accuracy": accuracy, "settle_on_iterate": SETTLE_ON_ITERATE, "exact_monodromy": False}
    quarter = periodic.find_orbit(quarter_map, guess, speed, **options)
    if not quarter.converged:    # the extrapolation failed (e.g. a state outside the linkage): from N/2
        quarter = periodic.find_orbit(quarter_map, coarse_state, speed, **options)
    if quarter.converged:
        _, z_quarter, quarter_substeps = orbit_observables(linear, quarter_map, quarter.state,
                                                           observables=False)
        z_quarter = z_quarter[:, :m]
        # the ratio's uncertainty from the levels' settled errors: the N/4 and N/2 orbits' (the N/2
        # one in both differences) and the N orbit's own share, to first order, with RATIO_MARGIN for
        # what first order leaves out; the lowest trusted ratio raised by it
        uncertainty = 0.0 if accuracy is None else RATIO_MARGIN * (accuracy + 2 * LEVEL_ACCURACY + settled_fraction)
        window = periodic.ORDER_TOLERANCE + math.log2(1.0 - min(uncertainty, 0.5))
        check = periodic.error_verdict(float(np.abs(z[::2] - z_coarse).max()),
                                       float(np.abs(z_coarse[::2] - z_quarter).max()), ORDER,
                                       scale=float(np.abs(z).max()), n_steps=n_steps, quantity="z",
                                       order_tolerance=window)
        if check.status != "ok":
            reasons.append(check.message)
        reasons.append(substep_reason(quarter_substeps, n_steps, "the N/4 run's"))
    else:
        reasons.append(f"refine n_steps: the orbit on N/4 = {n_steps // 4} steps was not found "
                       f"({quarter.message}), so the N/2 error estimate could not be checked")
    for spec, error in errors.items():
        size = float(np.ptp(response[spec]))
        if error > MAX_RELATIVE_ERROR * size:
            reasons.append(f"refine n_steps: the estimated error of {spec}, {error:.3g}, is "
                           f"{error / size if size else math.inf:.3g} of its peak-to-peak "
                           f"(> {MAX_RELATIVE_ERROR:g})")
    return errors, [reason for reason in reasons if reason]


def settling_tol(tol: float | None) -> tuple[float, bool]:
    """(the residual Newton stops at, whether the finest orbit settles within its error) for a
    nonlinear study's ``tol``: None the default ``TOL`` and settling (``SETTLE_WITHIN_ERROR``, with
    ``LEVEL_ACCURACY``); a number that residual alone."""
    return (TOL if tol is None else tol), (SETTLE_WITHIN_ERROR and LEVEL_ACCURACY is not None and tol is None)


def nonlinear_steady_state(problem: Any, values: Mapping[str, float] | None = None, *, n_steps: int = 256,
                           tol: float | None = None, max_iterations: int = MAX_ITERATIONS,
                           modes: Any = AUTO) -> NonlinearSteadyState:
    """The periodic solution of the full nonlinear constrained equations at ``values`` by shooting:
    Newton on the independent coordinates and rates at t = 0 (``mechanisms.PeriodMap``: one period of
    ``mechanisms.simulate``'s integrator on ``n_steps`` steps, the monodromy from its iteration
    matrices), started from the linear periodic state (``studies.steady_state``'s). The orbit is found
    again on ``n_steps / 2`` steps for the error estimates. A Newton that does not converge gives
    status ``failed`` with the reason, not an exception.

    ``modes``: ``"auto"`` (default) the elastic element-model links reduced to the fewest modes whose
    reduction check (against two more modes) stays within 0.1 % of each peak-to-peak, its error in
    ``reduction_error``; ``"full"`` (or None) the element models as the scene has them; a count: every
    such link reduced to it (``studies._kinds._nonlinear_model``).

    ``tol``: None (default) the orbit converged once its correction is within ``LEVEL_ACCURACY`` of
    its distance from the N/2 orbit (``SETTLE_WITHIN_ERROR``, the error bars widened by that share) or
    its relative residual is at most ``TOL``; a number: Newton to that residual."""
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a nonlinear steady state")
    check_integer("max_iterations", max_iterations, 1)
    tol, settle = settling_tol(tol)
    if not (isinstance(tol, (int, float)) and 0.0 < tol < 1.0):
        raise StudiesError(f"tol: expected a relative residual in (0, 1), got {tol!r}")
    given, given_values, modes = problem, values, check_modes(modes)
    choice = choose_model(problem, values, modes) if getattr(problem, "supports_nonlinear", False) else None
    if choice is not None:
        problem, values = choice.problem, choice.values
    setup = shooting_setup(problem, values, n_steps)
    linear, fine = setup.linear, setup.fine
    fine.warm_up()
    started = time.perf_counter()
    coarse = _Recording(setup.coarse)
    parameters = given.resolve(given_values)
    speed = float(parameters.get("speed", 0.0))
    orbit = periodic.find_orbit(fine, setup.guess, speed, tol=tol, max_iterations=max_iterations,
                                estimate=coarse, error_factor=ERROR_FACTOR, accuracy=LEVEL_ACCURACY,
                                reuse_first=REUSE_FIRST_MONODROMY, settle_on_iterate=SETTLE_ON_ITERATE,
                                settle_within_error=settle)
    specs = linear.observables
    linear_response = {spec: setup.steady.response[:, k] for k, spec in enumerate(specs)}
    # the mesh term's base level is this linear state (the same problem, N and scheme): not solved again
    mesh, mesh_method, _ = mesh_terms(problem, values, specs, n_steps, DEFAULT_SCHEME,
                                      response=linear_response if REUSE_LINEAR_STATE else None)
    errors = {spec: math.nan for spec in specs}
    reasons: list[str] = []
    if orbit.converged:
        response, z, n_substeps = orbit_observables(linear, fine, orbit.state)
        reasons.append(substep_reason(n_substeps, n_steps))
        if coarse.last is not None and np.isfinite(orbit.state_error):
            errors, trust = _error_estimates(setup, response, z, coarse.last, speed, tol=tol,
                                             max_iterations=max_iterations, monodromy=orbit.monodromy,
                                             state=orbit.state, coarse_monodromy=coarse.last_monodromy,
                                             settled_fraction=orbit.settled_fraction)
            reasons += trust
    else:
        response = {spec: np.full(n_steps + 1, np.nan) for spec in specs}
        z = np.full((n_steps + 1, fine.independent.size + fine.n_lags), np.nan)
    if choice is not None and choice.modes and choice.relative > MAX_RELATIVE_ERROR:
        reasons.append(f"raise modes (or modes = 'full'): {choice.message}")
    status, message = untrusted_verdict(orbit.status, orbit.message, [r for r in reasons if r])
    if choice is not None and choice.message:
        message += f"; {', '.join(f'{k} {v} modes' for k, v in choice.modes.items()) or 'model'}: {choice.message}"
    run_time = time.perf_counter() - started
    if orbit.converged:
        nonlinear_ptp, linear_ptp = (peaks_of(r, {})["peak_to_peak"] for r in (response, linear_response))
        ratios = ", ".join(f"{spec} {nonlinear_ptp[spec] / linear_ptp[spec]:.4g}"
                           for spec in specs if linear_ptp[spec] > 0)
        message += f"; peak to peak nonlinear / linear: {ratios}"
    linear_time = setup.run_time + (choice.run_time if choice is not None else 0.0)
    return NonlinearSteadyState(
        problem=given.name, parameters=parameters, scene=given.text, labels=tuple(linear.labels),
        units=dict(zip(specs, linear.units)), t=np.asarray(linear.system.t, dtype=float),
        crank_angle=np.asarray(linear.crank_angle, dtype=float), x=z, response=response,
        response_error=errors, linear_response=linear_response, state=orbit.state,
        multipliers=orbit.multipliers, multiplier_errors=orbit.multiplier_errors,
        spectral_radius=orbit.spectral_radius, error_estimate=orbit.state_error,
        iterations=orbit.iterations, map_calls=orbit.map_calls, residual=orbit.residual,
        status=status, message=message, is_stable=orbit.is_stable,
        instability_kind="" if orbit.bifurcation == "none" else orbit.bifurcation, n_steps=n_steps,
        run_time=run_time + linear_time, linear_run_time=linear_time, shooting_run_time=run_time,
        settings={"n_steps": n_steps, "tol": tol, "max_iterations": max_iterations, "modes": modes},
        reduced_modes=dict(choice.modes) if choice is not None else {},
        reduction_error=dict(choice.error) if choice is not None and choice.modes else {},
        mesh_error={} if mesh == NOT_APPLICABLE else dict(mesh["response"]),
        error_methods={"time_step": f"N = {n_steps} against N/2 steps" + (
                           f"; the N orbit settled within {orbit.settled_fraction:.2g} of its distance from the "
                           "N/2 orbit, that share added" if orbit.settled_fraction > 0.0 else ""),
                       "mesh": mesh_method,
                       "linearisation": "not applicable: the full nonlinear equations",
                       **({"reduction": f"reduced links checked against the next larger mode set or the full "
                                        f"model: {choice.message}"} if choice is not None and choice.modes else {})})


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    return {"values": speed_values(where, table),
            "n_steps": steps(where, table, n_steps, minimum=MIN_STEPS),
            # absent: None, the orbit settled within its error (``nonlinear_steady_state``'s tol)
            "tol": number(where, "tol", table["tol"], positive=True) if "tol" in table else None,
            "max_iterations": integer(where, "max_iterations", table.get("max_iterations", MAX_ITERATIONS), 1,
                                      maximum=MAX_NEWTON, why=NEWTON_WHY),
            "modes": modes_option(where, table)}


def modes_option(where: str, table: Mapping[str, Any]) -> Any:
    """The table's ``modes`` ("auto", "full" or a mode count; default "auto"), checked
    (``StudiesError`` naming the table)."""
    try:
        return check_modes(table.get("modes", AUTO))
    except StudiesError as error:
        raise StudiesError(f"{where}: {error}") from None


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> NonlinearSteadyState:
    return nonlinear_steady_state(problem, options["values"], n_steps=options["n_steps"], tol=options["tol"],
                                  max_iterations=options["max_iterations"], modes=options.get("modes", AUTO))


def _summary(result: NonlinearSteadyState) -> str:
    errors = ", ".join(f"{k} +- {v:.2g}" for k, v in result.response_error.items())
    return (f"{result.headline}: {result.message}; spectral radius {result.spectral_radius:.6f}; errors "
            f"{errors}; {result.shooting_run_time:.3g} s shooting + {result.linear_run_time:.3g} s linear start")


def _headlines(result: NonlinearSteadyState) -> Summary:
    rows = response_rows(result.response, result.response_error, result.units)
    for spec in result.response:
        # sampled, as the table's other peak-to-peak rows (``response_rows``)
        nonlinear, linear = np.ptp(result.response[spec]), np.ptp(result.linear_response[spec])
        rows.append(Headline(f"{spec} peak to peak, nonlinear / linear", nonlinear / linear if linear else math.nan))
    errors = np.asarray(result.multiplier_errors, dtype=float)
    rows.append(Headline("spectral radius of the nonlinear orbit", float(result.spectral_radius), "1",
                         float(np.nanmax(errors)) if errors.size and np.isfinite(errors).any() else math.nan))
    return Summary(status=result.headline, run_time=float(result.run_time),
                   rows=rows)


def _cost(name, problem, options, workers):
    """A linearisation and periodic solve (the start), and ``cost.SHOOTING_PERIODS`` periods of the period
    map with the monodromy's iteration matrices."""
    sizes = cost.sizes_at(problem, options["values"])
    n_steps = options["n_steps"]
    build_bytes, build_seconds = cost.linearisation(n_steps, sizes)
    seconds = (cost.STUDY_SECONDS + build_seconds + cost.solve_seconds(n_steps, sizes)
               + cost.SHOOTING_PERIODS * cost.nonlinear_period_seconds(n_steps, sizes))
    memory = max(build_bytes, cost.tangent_bytes(n_steps, sizes))
    found = cost.Estimate(name, memory, seconds, f"{cost.SHOOTING_PERIODS:g} periods x {n_steps} steps x {sizes.n} "
                                                 "coordinates")
    return cost.with_mesh_term(found, problem, options["values"], n_steps)  # the error budget's



def warm_up_shooting(problem: Any) -> None:
    """One Newton step of the nonlinear shooting on the JIT warm-up's tiny grid (a period, its
    monodromy, a trial period): the integrator's and the monodromy's kernels, the fused step's
    included (``mechanisms.fused_step``: the shootings' many periods repay its compile)."""
    if getattr(problem, "supports_nonlinear", False):
        with mechanisms.fused_step(True):
            nonlinear_steady_state(problem, n_steps=WARM_UP_STEPS, max_iterations=1)


KIND = register_kind(StudyKind(
    name="nonlinear_steady_state", result=NonlinearSteadyState,
    keys=("speed", "n_steps", "tol", "max_iterations", "modes"),
    check=_check, run=_run, summary=_summary, headlines=_headlines, cost=_cost, warm_up=warm_up_shooting,
    aliases=("NonlinearSteadyState",)))
