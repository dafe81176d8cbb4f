"""``[studies.nonlinear_sweep]``: the nonlinear periodic orbit followed over the speed or a scene
parameter (``periodic.continue_orbits`` on ``mechanisms.PeriodMap``), its stability along the way,
where it is lost and what a transient from the last stable state then does; the linear and nonlinear
response curves side by side."""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

import mechanisms
import periodic

from .._kind import StudyKind, register_kind
from .._mechanism import observables_along
from .._numerics import peak, peak_to_peak, solve_steady
from .._plots import Plot, axes_for, cost_line, drawn, headline, label, legend_outside, plain
from .._result import StudyResult, unknown_peaks
from .._toolkit import (
    MAX_PERIODS,
    MAX_STEPS,
    PERIODS_WHY,
    SPEED,
    STEPS_WHY,
    Headline,
    StudiesError,
    Summary,
    boolean,
    check_integer,
    check_n_steps,
    check_parameter,
    cost,
    integer,
    largest_over_grid,
    number,
)
from ._nonlinear_model import AUTO, check_modes, choose_model
from .nonlinear_steady_state import (
    ERROR_FACTOR,
    LEVEL_ACCURACY,
    MIN_STEPS,
    modes_option,
    orbit_observables,
    settling_tol,
    shooting_setup,
    substep_verdict,
    warm_up_shooting,
)

#: Periods of the transient run from the last stable orbit past the loss of stability.
TRANSIENT_PERIODS = 100
#: A transient has settled on an orbit of period k T when its shooting states k periods apart agree to
#: this fraction of their size over the last periods.
SETTLE_TOL = 1e-4
#: Points of the linear response curve drawn under the branch.
LINEAR_POINTS = 41
METHODS = ("natural", "arclength")
#: Orbits of one branch (``max_points``): each costs a few periods with their monodromy.
MAX_ORBITS = 10_000
ORBITS_WHY = "orbits of one branch, each a few nonlinear periods with their monodromy"
#: Periods of N steps an orbit of the branch costs, its N/2 level's included (six_bar, 8 elements per
#: link, 75 -> 87 rad/s at N = 128: 13 orbits, 92 periods of N steps and 31 of N/2, 8.3 a point) ...
PERIODS_PER_ORBIT = 8
#: ... and the points of a branch without ``step`` (``periodic.continue_orbits``' default: the range
#: over 50): with the two, a sweep's steps decide whether it takes the fused step (``mechanisms.fused_step_for``).
DEFAULT_POINTS = 50


@dataclass(frozen=True, eq=False)
class NonlinearSweep(StudyResult):
    """The nonlinear periodic orbit over one parameter, with the linear response for comparison (the
    fields every result has: ``studies._result``; the grid is the branch's k orbits).

    Peaks and peak-to-peaks are those of ``studies._numerics.peak_summary`` (extremes refined through
    their neighbours) for the nonlinear orbits and the linear curves alike; their errors
    ``|value_N - value_{N/2}| / 3`` from the orbit found again on N/2 steps (NaN where it was not).

    Attributes
    ----------
    problem, scene : str
        The problem's name and scene text.
    parameter : str
        "speed" or a dotted scene path.
    parameter_unit : str
        Its unit.
    units : dict
        {spec: unit} of each observable.
    values : ndarray, (k,), parameter_unit
        The branch's parameter values in the order followed (not monotone past a fold).
    peak_to_peak, peak_to_peak_error : dict of ndarray, {spec: (k,)}, units[spec]
        The nonlinear orbit's peak-to-peak and its estimated error.
    peak, peak_error : dict of ndarray, {spec: (k,)}, units[spec]
        The nonlinear orbit's largest magnitude and its estimated error.
    linear_at_branch : dict of ndarray, {spec: (k,)}, units[spec]
        The linear periodic state's peak-to-peak at the same values.
    linear_values : ndarray, (n_lin,), parameter_unit
        The linear curve's values over the whole range.
    linear_peak_to_peak : dict of ndarray, {spec: (n_lin,)}, units[spec]
        The linear curve.
    stable : ndarray of bool, (k,)
        Each orbit's stability.
    spectral_radius : ndarray, (k,), 1
        Of the nonlinear orbits.
    point_status : ndarray of str, (k,)
        Each orbit's status (its stability decided with the error bars of the N/2 orbit's
        multipliers).
    bifurcation_values : ndarray, (b,), parameter_unit
        Where a multiplier crosses the unit circle.
    bifurcation_kinds : tuple of str, (b,)
        "fold", "period_doubling", "secondary_hopf".
    after_instability : str
        What the transient from the last stable orbit, just past the loss of stability, does (""
        when stability is not lost).
    transient_value : float, parameter_unit
        The transient's parameter value.
    transient_t : ndarray, (n_t,), s
        The transient's samples.
    transient : dict of ndarray, {spec: (n_t,)}, units[spec]
        Its observables (deviation from nominal).
    status, message : str
        The branch's (``periodic.continue_orbits``).
    run_time : float, s
        The whole study.
    settings : dict
        The study's arguments.
    """

    problem: str
    scene: str
    parameter: str
    parameter_unit: str
    units: Mapping[str, str]
    values: np.ndarray
    peak_to_peak: Mapping[str, np.ndarray]
    peak_to_peak_error: Mapping[str, np.ndarray]
    linear_at_branch: Mapping[str, np.ndarray]
    linear_values: np.ndarray
    linear_peak_to_peak: Mapping[str, np.ndarray]
    stable: np.ndarray
    spectral_radius: np.ndarray
    point_status: np.ndarray
    bifurcation_values: np.ndarray
    bifurcation_kinds: tuple[str, ...]
    after_instability: str
    transient_value: float
    transient_t: np.ndarray
    transient: Mapping[str, np.ndarray]
    status: str
    message: str
    run_time: float
    settings: Mapping[str, Any] = field(default_factory=dict)
    peak: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_error: Mapping[str, np.ndarray] = field(default_factory=dict)
    reduced_modes: Mapping[str, int] = field(default_factory=dict)
    reduction_error: Mapping[str, float] = field(default_factory=dict)

    # written as "statuses" (a tuple) before the results shared their field names
    _stored_as = {"point_status": ("point_status", "statuses")}
    _axes = {"values": "@parameter"}
    _units = {"values": "@parameter_unit", "peak_to_peak": "@observables",
              "peak_to_peak_error": "@observables", "linear_at_branch": "@observables",
              "linear_values": "@parameter_unit", "linear_peak_to_peak": "@observables", "stable": "1",
              "spectral_radius": "1", "bifurcation_values": "@parameter_unit", "transient_t": "s",
              "transient": "@observables", "peak": "@observables", "peak_error": "@observables",
              "point_status": "1"}

    def _filled(self, group: Any) -> dict[str, Any]:
        if "peak" in group:
            return {}
        unknown = unknown_peaks(self.peak_to_peak, np.shape(self.values))
        return {"point_status": np.asarray(self.point_status, dtype=str), "peak": unknown["peak"],
                "peak_error": unknown["peak_error"]}

    def plot(self, *, axes: Any = None) -> Plot:
        """Peak-to-peak of each observable against the parameter: the linear curve (dashed), the
        nonlinear branch (filled where stable, hollow where not), bifurcations marked."""
        specs = list(self.peak_to_peak)
        axes = axes_for(len(specs), axes)
        artists: dict[str, list] = {}
        stable = np.asarray(self.stable, dtype=bool)
        for ax, spec in zip(axes, specs):
            lines = ax.plot(self.linear_values, self.linear_peak_to_peak[spec], "--", color="C1", label="linear")
            lines += ax.plot(self.values, self.peak_to_peak[spec], "-", color="C0", lw=0.8)
            lines += ax.plot(self.values[stable], self.peak_to_peak[spec][stable], "o", color="C0", ms=4,
                             label="nonlinear, stable")
            lines += ax.plot(self.values[~stable], self.peak_to_peak[spec][~stable], "o", mfc="none",
                             color="C3", ms=4, label="nonlinear, unstable")
            for value, kind in zip(self.bifurcation_values, self.bifurcation_kinds):
                lines.append(ax.axvline(value, color="C3", lw=0.8, ls=":"))
                ax.annotate(kind.replace("_", " "), (value, 0.95), xycoords=("data", "axes fraction"),
                            fontsize="x-small", color="C3", rotation=90, va="top")
            ax.set_xlabel(label(self.parameter, self.parameter_unit))
            ax.set_ylabel(label(f"{spec} peak to peak", self.units[spec]))
            ax.set_title(cost_line(f"{self.status}: {self.after_instability or 'stable throughout'}",
                                   self.run_time), fontsize="small")
            legend_outside(ax)
            artists[spec] = lines
        axes[0].figure.suptitle(f"{self.problem}: linear and nonlinear response", fontsize="medium")
        return drawn(axes, artists)


#: Steps of the nominal rigid motion a sweep's period maps are built about: a map reads only its
#: start and end states (and the period), which the kinematics solve to their tolerance on any grid,
#: so a coarser one (5.6 degrees of crank a step, small enough for the kinematics' continuation from
#: step to step) does; the default 360 steps were a quarter of a sweep's time on six_bar (a map at
#: each value, and at each value's dP/dp).
NOMINAL_STEPS = 64
#: Values whose last period run a sweep's map keeps for the orbits' observables (each a period's
#: coordinates, rates and multipliers, (N + 1) x (2 n + r) doubles, 0.08 MB on six_bar at N = 128;
#: a longer branch runs the older ones again).
KEPT_RUNS = 256
#: A state within this fraction of its size (max norm) of the kept run's is that run's: a relative
#: change of 1e-12 in the start moves the observables far below their error estimate (and the
#: orbit's residual tolerance, 1e-8).
SAME_STATE = 1e-12


class _Mechanisms:
    """The mechanism at each parameter value and its nominal rigid motion (``NOMINAL_STEPS``), the other
    parameters at ``values``; the last few are kept, shared by the N and N/2 maps."""

    def __init__(self, problem: Any, parameter: str, values: Mapping[str, float]):
        self.problem, self.parameter, self.values = problem, parameter, dict(values)
        self._kept: dict[float, tuple[Any, Any]] = {}
        self._first: Any = None     # a speed sweep's first nominal motion, the others its phases'

    def at(self, value: float) -> tuple[Any, Any]:
        if value not in self._kept:
            if len(self._kept) >= 6:
                self._kept.pop(next(iter(self._kept)))
            mechanism = self.problem.mechanism(dict(self.values, **{self.parameter: value}))
            self._kept[value] = mechanism, self._nominal(mechanism)
        return self._kept[value]

    def _nominal(self, mechanism: Any) -> Any:
        """The nominal motion of ``mechanism`` (``NOMINAL_STEPS``): along a speed, prescribed drives turn
        the linkage through the same configurations at every speed, so the first value's motion at
        the same phases (``mechanisms.nominal_at_period``, its positions and rates checked against
        the constraints) saves the continuation; else, or when that check fails, computed."""
        if self._first is not None:
            try:
                return mechanisms.nominal_at_period(mechanism, self._first)
            except mechanisms.ArgumentError:
                pass
        motion = mechanisms.nominal_motion(mechanism, n_steps=NOMINAL_STEPS)
        if self.parameter == SPEED and self._first is None and not mechanism.torque_drives:
            self._first = motion
        return motion


class _ParameterMap:
    """``(y, parameter value) -> (end y, monodromy)`` of the mechanism at that value (``_Mechanisms``),
    on the scaled shooting state ``y = x / scale``: the coordinates divided by
    their largest deviation in the linear start, the rates and the lagged controllers' states (N m) by
    theirs, so that positions (m) and rates (m/s, about speed times larger) weigh alike in the
    continuation's norms. The period maps of the last
    few values are kept (the corrector calls the map several times at one value)."""

    def __init__(self, mechanisms_at: _Mechanisms, n_steps: int, independent: np.ndarray, scale: np.ndarray):
        self.mechanisms_at, self.n_steps, self.independent, self.scale = mechanisms_at, n_steps, independent, scale
        self._maps: dict[float, Any] = {}
        #: {value: (scaled state, mechanisms.PeriodRun, its model)} of the last period run at each of
        #: the last KEPT_RUNS values: a branch's orbit is the last state its map ran at that value, and
        #: its observables read that period instead of building the map and running it again
        self._runs: dict[float, tuple[np.ndarray, Any, Any]] = {}

    def at(self, value: float):
        if value not in self._maps:
            if len(self._maps) >= 4:
                self._maps.pop(next(iter(self._maps)))
            mechanism, nominal = self.mechanisms_at.at(value)
            self._maps[value] = mechanisms.PeriodMap(mechanism, n_steps=self.n_steps,
                                                     independent=self.independent, nominal=nominal)
        return self._maps[value]

    @property
    def blocks(self) -> tuple:
        """The scaled state's coordinates, rates and lag states (``periodic.find_orbit``'s ``blocks``)."""
        m = self.independent.size
        return ((0, m), (m, 2 * m)) + (((2 * m, self.scale.size),) if self.scale.size > 2 * m else ())

    def __call__(self, y: np.ndarray, value: float):
        run = self._run(y, value, tangent=True)
        return run.end_state / self.scale, run.monodromy * self.scale[None, :] / self.scale[:, None]

    def end_state(self, y: np.ndarray, value: float) -> np.ndarray:
        """A period without its monodromy (``periodic``'s chord iterations), scaled as ``__call__``."""
        return self._run(y, value, tangent=False).end_state / self.scale

    def _run(self, y: np.ndarray, value: float, *, tangent: bool):
        value = float(value)
        run = self.at(value).run(y * self.scale, tangent=tangent)
        self._runs.pop(value, None)
        if len(self._runs) >= KEPT_RUNS:
            self._runs.pop(next(iter(self._runs)))
        self._runs[value] = (np.array(y, dtype=float), run, self.at(value).model)
        return run

    def observed(self, value: float, y: np.ndarray) -> "_KeptPeriod":
        """The period map at ``value`` for ``orbit_observables`` from the scaled state ``y``: its one
        period the last one run at ``value`` if that was from ``y`` (to ``SAME_STATE`` of its size:
        the continuation's scaled round trip of a state may change its last bits)."""
        value = float(value)
        kept = self._runs.get(value)
        if kept is not None:
            state, run, model = kept
            if float(np.abs(np.asarray(y) - state).max(initial=0.0)) <= SAME_STATE * float(np.abs(state).max()):
                return _KeptPeriod(model, self.n_steps, self.independent, run, lambda: self.at(value))
        period_map = self.at(value)
        return _KeptPeriod(period_map.model, self.n_steps, self.independent, None, lambda: period_map)


class _KeptPeriod:
    """What ``orbit_observables`` reads of a ``mechanisms.PeriodMap`` (``model``, ``n_steps``,
    ``independent``, ``run``): one period from the orbit's state is ``kept`` (the run the continuation
    has just made there, or None); a second period runs on the map ``build()`` returns."""

    def __init__(self, model: Any, n_steps: int, independent: np.ndarray, kept: Any, build: Any):
        self.model, self.n_steps, self.independent, self.kept, self.build = model, n_steps, independent, kept, build

    def run(self, x: np.ndarray, *, tangent: bool = True, n_periods: int = 1):
        if self.kept is not None and n_periods == 1 and not tangent:
            return self.kept
        return self.build().run(x, tangent=tangent, n_periods=n_periods)


class _CoarseOrbits:
    """The period map on N/2 steps given to ``periodic.continue_orbits`` as ``estimate``; it keeps, for
    each parameter value, the last (scaled) state it was called with: the N/2 orbit there, once the
    estimate's Newton has converged on it."""

    def __init__(self, period_map: _ParameterMap):
        self.period_map, self.states = period_map, {}

    def __call__(self, y: np.ndarray, value: float):
        self.states[float(value)] = np.array(y, dtype=float)
        return self.period_map(y, value)

    def end_state(self, y: np.ndarray, value: float) -> np.ndarray:
        self.states[float(value)] = np.array(y, dtype=float)
        return self.period_map.end_state(y, value)

    @property
    def blocks(self) -> tuple:
        return self.period_map.blocks


def nonlinear_sweep(problem: Any, parameter: str = SPEED, *, start: float, stop: float,
                    values: Mapping[str, float] | None = None, n_steps: int = 128, step: float | None = None,
                    method: str = "natural", tol: float | None = None, max_points: int = 100,
                    stop_at_instability: bool = True, transient_periods: int = TRANSIENT_PERIODS,
                    modes: Any = AUTO) -> NonlinearSweep:
    """Follow the nonlinear periodic orbit (``studies.nonlinear_steady_state``'s, ``n_steps`` per
    period) from ``parameter = start`` (started from the linear periodic state there) to ``stop`` with
    ``periodic.continue_orbits`` (``method`` "natural" or "arclength" through folds, ``step`` in units
    of the parameter). Where the orbit loses stability (with ``stop_at_instability`` the branch ends
    there), a transient of ``transient_periods`` periods from the last stable orbit, just past that
    point, says what the machine does instead. The linear response over the range is computed too.

    ``modes`` as for ``studies.nonlinear_steady_state`` (default ``"auto"``: the elastic links reduced to
    the fewest modes the reduction check accepts at ``start``; the linear curves are of the same
    model; ``"full"``: the element models).

    ``tol``: None (default) each natural step's orbit converged once its correction is within
    ``LEVEL_ACCURACY`` of its distance from its N/2 orbit (``periodic.continue_orbits``'
    ``settle_within_error``, the steady state's ``settling_tol``; the error bars widened by that share)
    or its relative residual is at most ``TOL``; a number: every orbit to that residual."""
    check_parameter(problem, parameter)
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a nonlinear sweep")
    check_integer("max_points", max_points, 2)
    check_integer("transient_periods", transient_periods, 4)
    if method not in METHODS:
        raise StudiesError(f"method: expected one of {METHODS}, got {method!r}")
    for name, value in (("start", start), ("stop", stop)):
        if not (isinstance(value, (int, float)) and math.isfinite(value)):
            raise StudiesError(f"{name}: expected a finite value of {parameter!r}, got {value!r}")
    if start == stop:
        raise StudiesError(f"stop: expected a value different from start = {start!r}")
    if parameter.startswith("controllers.") and parameter.endswith(".lag") and 0.0 in (start, stop):
        # a zero lag has no state: the shooting state would change size along the branch
        raise StudiesError(f"start, stop: expected lags {parameter!r} > 0 over the whole range (a lag of 0 "
                           f"removes the controller's state from the orbit), got {start!r} .. {stop!r}")
    started = time.perf_counter()
    tol, settle = settling_tol(tol)
    fixed = {k: v for k, v in (values or {}).items() if k != parameter}
    given, modes = problem, check_modes(modes)
    choice = (choose_model(problem, dict(fixed, **{parameter: start}), modes)
              if getattr(problem, "supports_nonlinear", False) else None)
    if choice is not None and choice.modes and parameter != SPEED and parameter not in choice.problem.parameters:
        # the swept value is no parameter of the reduced scene (its spec writes the section, the
        # damping in other terms): the full element models, said in the message
        choice = dataclasses.replace(choice, problem=problem, values=values, modes={}, error={}, message=(
            f"full element models: {parameter!r} is not a parameter of the reduced scene"))
    if choice is not None and choice.modes:
        # the reduced mechanism carries the fixed values; the speed stays a value of each point
        problem, fixed = choice.problem, {k: v for k, v in fixed.items() if k == SPEED}
    first = shooting_setup(problem, dict(fixed, **{parameter: start}), n_steps)
    m = first.fine.independent.size
    guess = first.guess
    # coordinates, rates and the lagged controllers' states (N m) each by their own size
    scale = np.concatenate([np.full(size, max(np.abs(block).max(initial=0.0), 1e-12)) for block, size in
                            ((guess[:m], m), (guess[m:2 * m], m), (guess[2 * m:], first.fine.n_lags))])
    mechanisms_at = _Mechanisms(problem, parameter, fixed)
    period_map = _ParameterMap(mechanisms_at, n_steps, first.fine.independent, scale)
    # the N/2 map: each orbit's multipliers get error bars, so ok / unstable and the bifurcations rest
    # on them and not on a bare stability_tol (as nonlinear_steady_state's verdict); its orbits to
    # LEVEL_ACCURACY of their distance from the N-step ones, as the steady state's
    coarse = _CoarseOrbits(_ParameterMap(mechanisms_at, n_steps // 2, first.fine.independent, scale))
    # the orbits' periods together (about PERIODS_PER_ORBIT of N steps at each of the points the
    # branch takes at ``step``) decide whether the fused step's compile is repaid, as a long run's do
    given_step = isinstance(step, (int, float)) and math.isfinite(step) and step > 0.0  # else refused there
    points = max(1, min(max_points, math.ceil(abs(stop - start) / step) if given_step else DEFAULT_POINTS))
    with mechanisms.fused_step_for(points * PERIODS_PER_ORBIT * n_steps):
        branch = periodic.continue_orbits(period_map, guess / scale, float(start), float(stop), step=step,
                                          method=method, tol=tol, max_points=max_points,
                                          stop_at_instability=stop_at_instability, estimate=coarse,
                                          error_factor=ERROR_FACTOR, accuracy=LEVEL_ACCURACY,
                                          settle_within_error=settle and method == "natural")
    specs = first.linear.observables
    nonlinear = {spec: [] for spec in specs}
    nonlinear_error = {spec: [] for spec in specs}
    peaks = {spec: [] for spec in specs}
    peak_errors = {spec: [] for spec in specs}
    linear_at = {spec: [] for spec in specs}
    statuses, split = list(branch.statuses), []
    for k, (value, state) in enumerate(zip(branch.parameters, branch.states)):
        linear = problem.linearize(dict(fixed, **{parameter: float(value)}), n_steps=n_steps)
        steady = solve_steady(linear)
        response, _, n_substeps = orbit_observables(linear, period_map.observed(float(value), state),
                                                    state * scale)
        coarse_response, coarse_substeps = _coarse_response(linear, coarse, branch.orbits[k], float(value))
        if n_substeps or coarse_substeps:
            statuses[k] = substep_verdict(statuses[k], "", n_substeps + coarse_substeps, n_steps)[0]
            split.append(f"{value:.6g}")
        # an orbit settled within its error: that share of each difference adds (periodic.find_orbit)
        widened = ERROR_FACTOR + branch.orbits[k].settled_fraction
        for j, spec in enumerate(specs):
            for values, errors, measure in ((nonlinear, nonlinear_error, peak_to_peak), (peaks, peak_errors, peak)):
                values[spec].append(measure(response[spec])[0])
                errors[spec].append(widened * abs(values[spec][-1] - measure(coarse_response[spec])[0])
                                    if coarse_response else math.nan)
            linear_at[spec].append(peak_to_peak(steady.response[:, j])[0])
    linear_values = np.linspace(start, stop, LINEAR_POINTS)
    linear_curve = {spec: [] for spec in specs}
    for value in linear_values:
        steady = solve_steady(problem.linearize(dict(fixed, **{parameter: float(value)}), n_steps=n_steps,
                                                context=False))
        for k, spec in enumerate(specs):
            linear_curve[spec].append(peak_to_peak(steady.response[:, k])[0])
    after, transient_value, transient_t, transient = _after_instability(
        problem, period_map, branch, fixed, parameter, n_steps, transient_periods, specs)
    message = branch.message + (f"; {after}" if after else "")
    shares = [orbit.settled_fraction for orbit in branch.orbits if orbit.settled_fraction > 0.0]
    if shares:
        message += (f"; {len(shares)} of {len(branch.orbits)} orbits settled within their error (up to "
                    f"{max(shares):.2g} of their distance from the N/2 orbit, added to their error bars)")
    if choice is not None and choice.message:
        reduced = ", ".join(f"{k} {v} modes" for k, v in choice.modes.items()) or "model"
        message += f"; {reduced} (checked at {parameter} = {start:g}): {choice.message}"
    status = branch.status
    if split:
        # the bifurcations were detected on these monodromies too: they are as approximate
        status, message = substep_verdict(status, message, len(split), n_steps)
        message += f" (at {parameter} = {', '.join(split)})"
    unit = problem.units.get(parameter, "SI")
    return NonlinearSweep(
        problem=given.name, scene=given.text, parameter=parameter, parameter_unit=unit,
        units=dict(zip(specs, first.linear.units)), values=np.asarray(branch.parameters, dtype=float),
        peak_to_peak={s: np.array(v, dtype=float) for s, v in nonlinear.items()},
        peak_to_peak_error={s: np.array(v, dtype=float) for s, v in nonlinear_error.items()},
        peak={s: np.array(v, dtype=float) for s, v in peaks.items()},
        peak_error={s: np.array(v, dtype=float) for s, v in peak_errors.items()},
        linear_at_branch={s: np.array(v, dtype=float) for s, v in linear_at.items()},
        linear_values=linear_values, linear_peak_to_peak={s: np.array(v) for s, v in linear_curve.items()},
        stable=np.asarray(branch.stable, dtype=bool),
        spectral_radius=np.array([np.abs(m).max() for m in branch.multipliers], dtype=float),
        point_status=np.array(statuses, dtype=str),
        bifurcation_values=np.array([b[0] for b in branch.bifurcations], dtype=float),
        bifurcation_kinds=tuple(b[1] for b in branch.bifurcations), after_instability=after,
        transient_value=transient_value, transient_t=transient_t, transient=transient,
        status=status, message=message, run_time=time.perf_counter() - started,
        settings={"parameter": parameter, "start": start, "stop": stop, "n_steps": n_steps, "method": method,
                  "tol": tol, "max_points": max_points, "stop_at_instability": stop_at_instability,
                  "transient_periods": transient_periods, "modes": modes},
        reduced_modes=dict(choice.modes) if choice is not None else {},
        reduction_error=dict(choice.error) if choice is not None and choice.modes else {})


def _coarse_response(linear: Any, coarse: _CoarseOrbits, orbit: Any, value: float) -> tuple[dict, int]:
    """({spec: (N/2+1,)} observables of the N/2 orbit at ``value``, the steps its run split), ({}, 0)
    where the estimate found no N/2 orbit there (``orbit.state_error`` NaN)."""
    state = coarse.states.get(value)
    if state is None or not np.isfinite(orbit.state_error):
        return {}, 0
    map_ = coarse.period_map
    response, _, n_substeps = orbit_observables(linear, map_.observed(value, state), state * map_.scale)
    return response, n_substeps


def _after_instability(problem, period_map, branch, fixed, parameter, n_steps, periods, specs):
    """(words, parameter value, t, {spec: (n_t,)}) of the transient from the last stable orbit just past
    the first loss of stability; ("", nan, empty, {}) when stability is not lost."""
    if not branch.bifurcations:
        return "", math.nan, np.empty(0), {}
    where, kind = branch.bifurcations[0]
    index = branch.bifurcation_indices[0] if branch.bifurcation_indices[0] >= 0 else len(branch.parameters)
    # the last orbit before the crossing whose verdict is ok (marginal ones count as stable on a branch)
    ok = [i for i in range(min(index, len(branch.parameters))) if branch.statuses[i] == "ok"]
    if not ok:
        return (f"{kind.replace('_', ' ')} at {parameter} = {where:.6g}: no stable orbit before it to start a "
                "transient from"), math.nan, np.empty(0), {}
    last = ok[-1]
    # a quarter of the last step past the located loss of stability
    beyond = where + 0.25 * (where - branch.parameters[last])
    words = f"{kind.replace('_', ' ')} at {parameter} = {where:.6g}; a transient from the last stable orbit " \
            f"({parameter} = {branch.parameters[last]:.6g}) at {parameter} = {beyond:.6g}"
    try:
        run = period_map.at(float(beyond)).run(branch.states[last] * period_map.scale, tangent=False,
                                               n_periods=periods)
    except RuntimeError as error:
        return f"{words} fails ({error}): the machine leaves the model's range", float(beyond), np.empty(0), {}
    linear = problem.linearize(dict(fixed, **{parameter: float(beyond)}), n_steps=n_steps)
    transient = observables_along(linear, period_map.at(float(beyond)).model, run.t, run.s, run.sdot, run.lam,
                                  run.lag_states)
    return f"{words} {_settles(run.period_states)}", float(beyond), run.t, {spec: transient[spec] for spec in specs}


def _settles(states: np.ndarray) -> str:
    """What the shooting states at the period ends (k + 1, 2m) of a transient say: settled on an orbit
    of period T or 2T (from the last quarter of the run), or not settled."""
    tail = states[-max(states.shape[0] // 4, 3):]
    size = max(float(np.abs(tail).max()), np.finfo(float).tiny)
    one = float(np.abs(tail[-1] - tail[-2]).max()) / size
    two = float(np.abs(tail[-1] - tail[-3]).max()) / size
    if one <= SETTLE_TOL:
        return f"settles on an orbit of period T (change over the last period {one:.2g} of its size)"
    if two <= SETTLE_TOL:
        return (f"settles on an orbit of period 2T (period doubling confirmed: states 2T apart agree to "
                f"{two:.2g}, T apart differ by {one:.2g} of their size)")
    if two <= 0.01 * one:
        # slow final approach near the bifurcation (the critical multiplier is close to the unit circle)
        return (f"approaches an orbit of period 2T (period doubling: states 2T apart agree to {two:.2g}, "
                f"T apart differ by {one:.2g} of their size, still converging after {states.shape[0] - 1} "
                "periods)")
    return (f"does not settle in {states.shape[0] - 1} periods (states T apart differ by {one:.2g}, 2T apart "
            f"by {two:.2g} of their size)")


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    missing = [k for k in ("start", "stop") if k not in table]
    if missing:
        raise StudiesError(f"[{where}]: missing {', '.join(missing)} (the parameter range to follow)")
    method = table.get("method", "natural")
    if method not in METHODS:
        raise StudiesError(f"[{where}] method: expected one of {METHODS}, got {method!r}")
    parameter = table.get("parameter", SPEED)
    if not isinstance(parameter, str):
        raise StudiesError(f"[{where}] parameter: expected 'speed' or a dotted scene path, got {parameter!r}")
    start, stop = number(where, "start", table["start"]), number(where, "stop", table["stop"])
    if start == stop:
        raise StudiesError(f"[{where}] stop: expected a value different from start = {start!r} (the "
                           f"range to follow), got {stop!r}")
    return {"parameter": parameter, "start": start, "stop": stop,
            "step": None if "step" not in table else number(where, "step", table["step"], positive=True),
            "method": method,
            "n_steps": integer(where, "n_steps", table.get("n_steps", min(n_steps, 128)), MIN_STEPS,
                               maximum=MAX_STEPS, why=STEPS_WHY),
            # absent: None, each orbit settled within its error (``nonlinear_sweep``'s tol)
            "tol": number(where, "tol", table["tol"], positive=True) if "tol" in table else None,
            "max_points": integer(where, "max_points", table.get("max_points", 100), 2, maximum=MAX_ORBITS,
                                  why=ORBITS_WHY),
            "stop_at_instability": boolean(where, "stop_at_instability", table.get("stop_at_instability", True)),
            "transient_periods": integer(where, "transient_periods",
                                         table.get("transient_periods", TRANSIENT_PERIODS), 4,
                                         maximum=MAX_PERIODS, why=PERIODS_WHY),
            "modes": modes_option(where, table)}


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> NonlinearSweep:
    options = dict(options)
    return nonlinear_sweep(problem, options.pop("parameter"), **options)


def _summary(result: NonlinearSweep) -> str:
    spec = next(iter(result.peak_to_peak), None)
    ratio = ""
    if spec is not None and result.values.size:
        ratios = result.peak_to_peak[spec] / result.linear_at_branch[spec]
        ratio = f"; nonlinear / linear peak to peak of {spec} from {ratios.min():.4g} to {ratios.max():.4g}"
    return (f"{result.status}: {result.values.size} orbits over {result.parameter} "
            f"{result.settings.get('start')} .. {result.settings.get('stop')}{ratio}; {result.message}; "
            f"{result.run_time:.3g} s")


def _headlines(result: NonlinearSweep) -> Summary:
    unit = result.parameter_unit

    def where(index: tuple[int, ...]) -> str:
        return f"{result.parameter} {plain(result.values[index[0]], 3)} {unit}".rstrip()

    rows = [largest_over_grid(f"{spec} largest peak to peak (nonlinear orbit)", values,
                              result.peak_to_peak_error.get(spec), result.units[spec], where)
            for spec, values in result.peak_to_peak.items()]
    losses = [f"{kind.replace('_', ' ')} at {plain(value, 4)} {unit}".rstrip()
              for value, kind in zip(result.bifurcation_values, result.bifurcation_kinds)]
    rows.append(Headline("loss of stability", "; ".join(losses) or "none on the branch"))
    if result.after_instability:
        rows.append(Headline("after it, a transient", result.after_instability))
    return Summary(status=headline(result.status), run_time=float(result.run_time), rows=rows)


def _cost(name, problem, options, workers):
    """``cost.SWEEP_POINT_PERIODS`` periods and two linearisations per orbit of the branch, the linear
    curve's ``LINEAR_POINTS`` and the transient."""
    start, stop, n_steps = options["start"], options["stop"], options["n_steps"]
    axis = (options["parameter"], np.array([start, stop], dtype=float))
    sizes = cost.largest_sizes(problem, [axis])
    step = options["step"] or abs(stop - start) / 50.0  # periodic.continue_orbits' default
    # an empty range (refused by the table check) has the one orbit at start, not a division by zero
    orbits = min(options["max_points"], math.ceil(abs(stop - start) / step) + 1 if step > 0.0 else 1)
    build_bytes, build_seconds = cost.linearisation(n_steps, sizes)
    periods = orbits * cost.SWEEP_POINT_PERIODS + options["transient_periods"]
    seconds = (cost.STUDY_SECONDS + (2 * orbits + LINEAR_POINTS) * (build_seconds + cost.solve_seconds(n_steps, sizes))
               + periods * cost.nonlinear_period_seconds(n_steps, sizes))
    memory = max(build_bytes, cost.tangent_bytes(n_steps, sizes),
                 8.0 * cost.NONLINEAR_DOUBLES * options["transient_periods"] * n_steps * sizes.n)
    return cost.Estimate(name, memory, seconds, f"{orbits} orbits x {cost.SWEEP_POINT_PERIODS:g} periods + "
                                                f"{options['transient_periods']} periods x {n_steps} steps x "
                                                f"{sizes.n} coordinates")


KIND = register_kind(StudyKind(
    name="nonlinear_sweep", result=NonlinearSweep,
    keys=("parameter", "start", "stop", "step", "method", "n_steps", "tol", "max_points", "stop_at_instability",
          "transient_periods", "modes"),
    check=_check, run=_run, summary=_summary, varies=lambda options: (options["parameter"],),
    headlines=_headlines, cost=_cost, warm_up=warm_up_shooting, aliases=("NonlinearSweep",)))
