"""``[studies.control_comparison]``: the start-up of a machine with and without its controller's
feedback, run by the full nonlinear model from the same start (issue 11, the thesis's chapter 3).

Both runs start from the rigid nominal state at t = 0 (elastic coordinates and their rates zero: the
start-up) and run ``n_periods`` periods of ``mechanisms.simulate``; the second run is the same
machine with every feedback removed (``Mechanism.without_feedback()``: feedforward torque and motor
kept). Reported per case and quantity: the time history, the steady peak (largest magnitude over the
last period) with its error estimate, and the settling time (:func:`settling_time`).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .._budget import ERROR_TOLERANCE, ErrorBudget, check_tolerance, describe, nonlinear_run_budget
from .._kind import StudyKind, register_kind
from .._mechanism import coordinate_parts, deviations_along
from .._plots import Plot, axes_for, drawn, headline, label, legend_outside, plain, quantity, scene_and_point
from .._result import DerivedPeaks, StudyResult, peaks_of
from .._toolkit import (
    MAX_PERIODS,
    PERIODS_WHY,
    SPEED,
    ComputationError,
    Headline,
    StudiesError,
    Summary,
    check_integer,
    check_n_steps,
    combine,
    cost,
    fraction,
    integer,
    is_numerical_failure,
    speed_values,
    steps,
)
from ._settling import BAND, settling_time

logger = logging.getLogger(__name__)

#: The two runs compared, in this order everywhere (keys of the per-case fields).
CASES = ("with", "without")
#: The fewest steps per period: the error estimate compares the run with one of N/2 steps.
MIN_STEPS = 32
#: A steady peak whose error estimate exceeds this fraction of it is ``inaccurate`` (as a sweep
#: point's peak-to-peak, docs/studies.md).
INACCURATE_FRACTION = 0.1
#: Richardson's divisor for the error of a second-order method from runs at h and 2h: 2^2 - 1.
RICHARDSON = 3.0
#: The saturation record of each case (``ControlComparison.saturation``).
SATURATION_KEYS = ("peak_demanded_torque", "peak_command", "clipped_fraction", "clipped_until")


# ---------------------------------------------------------------------------------------------------
# the result
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ControlComparison(DerivedPeaks, StudyResult):
    """The start-up with and without feedback (``CASES = ("with", "without")``; the fields every
    result has: ``studies._result``).

    The quantities, by ``roles`` {quantity: role}: ``"elastic"``, the scene's observables of the
    coordinates (the coupler's midspan deflection by default), deviations from the rigid nominal
    motion; ``"speed"``, ``drive.<J>.rate`` the controlled drive's relative rate minus its nominal
    (rad/s, the crank speed fluctuation); ``"output"``, the output's deviation from its nominal (the
    output link's angle, rad, or a point's displacement, m); ``"torque"``, ``drive.<J>.torque`` the
    drive's total torque (N m).

    ``status``, the worst of: ``failed`` (a run failed: the message says which and why; the other
    is kept); ``unstable`` (a quantity with control grows period after period); ``outside_linear_range``
    (the drive saturates in the steady state of either run: the last period is clipped at a limit);
    ``inaccurate`` (a steady peak's error estimate above ``INACCURATE_FRACTION`` of it or unknown:
    refine ``n_steps``; or a quantity with control not settled: raise ``n_periods``); else ``ok``.
    ``message`` also says which quantities do not settle without feedback, the elastic settling
    times and a saturation during the start-up only.

    Attributes
    ----------
    problem, scene : str
        The problem's name and scene text.
    parameters : dict
        {name: value} the point.
    quantities : tuple of str
        The quantities' names in report order.
    units : dict
        {quantity: unit}.
    roles : dict
        {quantity: role} (see above).
    settings : dict
        The study's arguments.
    t : ndarray, (n_t,), s
        The samples, ``n_t = n_periods * n_steps + 1``.
    with_control, without_control : dict of ndarray, {quantity: (n_t,)}, units[quantity]
        Each quantity's time history (NaN after the time a run failed).
    steady_peak : dict, {case: {quantity: float}}, units[quantity]
        The max |q| over the last period.
    steady_peak_error : dict, {case: {quantity: float}}, units[quantity]
        Its error estimate, ``max |q_N - q_N/2| / 3`` over the last period (a run with half the
        steps; NaN when that run failed).
    settling_time : dict, {case: {quantity: float}}, s
        :func:`settling_time` (NaN when not settled or failed).
    settling_time_error : dict, {case: {quantity: float}}, s
        ``|t_s(N) - t_s(N/2)|``.
    settled : dict, {case: {quantity: bool}}
        Whether each quantity settled.
    run_time : float, s
        The whole study (both cases).
    case_run_time : dict, {case: float}, s
        Each case's two runs.
    failed : dict, {case: str}
        The failure's message, or "".
    saturation : dict, {case: {key: float}}
        The controlled drive's saturation (``SATURATION_KEYS``; NaN when the run failed):
        ``peak_demanded_torque`` N m, the largest |torque| the unsaturated law asks for over the last
        period; ``peak_command`` N m, the largest motor command |tau + c theta'| over it;
        ``clipped_fraction``, the fraction of the last period's samples where the drive saturates;
        ``clipped_until`` s, the time of the last saturated sample (NaN: never).
    torque_limit, command_limit : float, N m
        The drive's torque limit and ``G stall_torque`` (inf where the drive has none).
    status, message : str
        See above.
    peak, peak_error, peak_to_peak, peak_to_peak_error : dict, {quantity: float}, units[quantity]
        Properties: over the last period of the run with control (the machine as designed), with
        ``steady_peak_error["with"]`` as the samples' error.
    """

    problem: str
    scene: str
    parameters: Mapping[str, float]
    quantities: tuple[str, ...]
    units: Mapping[str, str]
    roles: Mapping[str, str]
    settings: Mapping[str, Any]
    t: np.ndarray
    with_control: Mapping[str, np.ndarray]
    without_control: Mapping[str, np.ndarray]
    steady_peak: Mapping[str, Mapping[str, float]]
    steady_peak_error: Mapping[str, Mapping[str, float]]
    settling_time: Mapping[str, Mapping[str, float]]
    settling_time_error: Mapping[str, Mapping[str, float]]
    settled: Mapping[str, Mapping[str, bool]]
    run_time: float
    failed: Mapping[str, str] = field(default_factory=dict)
    saturation: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    torque_limit: float = math.inf
    command_limit: float = math.inf
    status: str = "ok"
    message: str = ""
    case_run_time: Mapping[str, float] = field(default_factory=dict)
    #: {quantity: {term: ...}} the steady peaks' budget with control (``studies._budget``; format 2: {})
    error_budget: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    error_methods: Mapping[str, str] = field(default_factory=dict)
    error_tolerance: float = ERROR_TOLERANCE

    _units = {"t": "s", "with_control": "@observables", "without_control": "@observables"}

    def _peaks(self) -> dict[str, dict[str, float]]:
        steps = int(self.settings.get("n_steps", 0)) or max(np.size(self.t) - 1, 2)
        last = {name: np.asarray(self.with_control[name])[-(steps + 1):] for name in self.quantities}
        # the samples' error: the budget's total (a file of format 2: the time step's alone)
        budget = ErrorBudget(self.error_budget)
        return peaks_of(last, {q: budget.total(q) for q in budget} or self.steady_peak_error.get("with", {}))

    def _filled(self, group: Any) -> dict[str, Any]:
        if "case_run_time" in group.attrs:
            return {}
        # written when run_time was the cases' {case: s}
        cases = dict(self.run_time) if isinstance(self.run_time, Mapping) else {}
        return {"case_run_time": cases, "run_time": float(np.nansum(list(cases.values())))}

    def history(self, case: str) -> Mapping[str, np.ndarray]:
        """The time histories of ``case`` ("with" or "without")."""
        if case not in CASES:
            raise StudiesError(f"case: expected one of {CASES}, got {case!r}")
        return self.with_control if case == "with" else self.without_control

    def quantity(self, role: str) -> list[str]:
        """The quantities of ``role`` ("elastic", "speed", "output", "torque"), in order."""
        return [name for name in self.quantities if self.roles[name] == role]

    def plot(self, *, axes: Any = None) -> Plot:
        """One axes per quantity, the run with control over the one without, each settling time a
        dashed line and the steady peaks and settling times in the title."""
        quantities = list(self.quantities)
        axes = axes_for(len(quantities), axes, height=3.1)
        styles = {"with": dict(color="C0", lw=0.9, label="with control"),
                  "without": dict(color="C3", lw=0.7, alpha=0.8, label="without feedback")}
        artists: dict[str, list] = {}
        for ax, name in zip(axes, quantities):
            lines = []
            for case in CASES:
                values = self.history(case).get(name)
                if values is None:
                    continue
                lines += ax.plot(self.t, values, **styles[case])
                settle = self.settling_time[case].get(name, float("nan"))
                if math.isfinite(settle):
                    lines.append(ax.axvline(settle, color=styles[case]["color"], ls="--", lw=0.8))
            ax.set_xlabel("time (s)")
            ax.set_ylabel(label(name, self.units[name]))
            words = [f"{case} {'control' if case == 'with' else 'feedback'}: peak "
                     f"{quantity(self.steady_peak[case].get(name, float('nan')), self.units[name])}, "
                     f"settles {_settle_words(self, case, name)}" for case in CASES]
            if name in self.error_budget:
                budget_words = describe(ErrorBudget(self.error_budget), name, self.units[name], terms=False)
                words.append(f"error with control {budget_words}")
            # one line per case: the legend on the right narrows the axes, and the title with them
            ax.set_title(f"{name}\n" + "\n".join(words), fontsize="small")
            legend_outside(ax)
            artists[name] = lines
        axes[0].figure.suptitle(f"{scene_and_point(self)}: with and without feedback: {headline(self.status)}",
                                fontsize="small")
        return drawn(axes, artists)


def _settle_words(result: ControlComparison, case: str, name: str) -> str:
    if result.failed.get(case):
        return "(run failed)"
    value = result.settling_time[case].get(name, float("nan"))
    return f"at {plain(value)} s" if math.isfinite(value) else "not"


# ---------------------------------------------------------------------------------------------------
# the study
# ---------------------------------------------------------------------------------------------------
def control_comparison(problem: Any, values: Mapping[str, float] | None = None, *, n_periods: int = 20,
                       n_steps: int = 256, band: float = BAND, output: str | None = None,
                       error_tolerance: float = ERROR_TOLERANCE) -> ControlComparison:
    """Run the machine of ``problem`` (a ``studies.MechanismProblem``) at ``values`` from the start-up
    (the rigid nominal state at t = 0) for ``n_periods`` periods of ``n_steps`` steps, with its
    controller and without its feedback, and compare (see :class:`ControlComparison`).

    ``band``: the settling band above the steady peak (:func:`settling_time`); ``output``: the
    observable spec of the output whose deviation from the nominal motion is reported (default: the
    angle of the last link pivoted on the ground other than the driven one, e.g. ``"rocker.angle"``,
    else the displacement of the last link's end, ``"<link>.point_error@1.0"``). A run that fails
    numerically gives status ``failed`` with the reason, not an exception; the other run is kept. The
    steady peaks with control carry an error budget (``error_budget``); a total above
    ``error_tolerance`` of a peak is ``inaccurate``."""
    started = time.perf_counter()
    if not hasattr(problem, "mechanism"):
        raise StudiesError(f"problem {getattr(problem, 'name', problem)!r}: a control comparison needs a "
                           f"mechanism (studies.MechanismProblem) whose drive has a controller")
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a control comparison")
    check_integer("n_periods", n_periods, 3)
    error_tolerance = check_tolerance(error_tolerance)
    if isinstance(band, bool) or not isinstance(band, (int, float)) or not 0.0 < band < 1.0:
        raise StudiesError(f"band: expected a fraction of the steady peak in (0, 1), got {band!r}")
    params = problem.resolve(values)
    nominal_values = problem.parameters
    mechanism = problem.mechanism({k: v for k, v in params.items() if v != nominal_values[k]})
    without = _without_feedback(problem, mechanism)
    plan = _quantities(problem, mechanism, without, output)
    results = {case: _case(machine, plan, n_periods, n_steps, band)
               for case, machine in zip(CASES, (mechanism, without))}
    t = np.arange(n_periods * n_steps + 1) * (mechanism.period / n_steps)
    status, message = _verdict(results, plan, n_periods)
    budget: dict[str, Any] = {}
    if not results["with"]["failed"]:   # by severity; beside an ok, the notes of _verdict's message kept
        budget["error_budget"], budget["error_methods"], found = nonlinear_run_budget(
            problem, values, results["with"]["steady_peak"], results["with"]["steady_peak_error"],
            [q for q in plan.units if plan.roles[q] == "elastic"], n_steps=n_steps, tolerance=error_tolerance)
        status, message = (combine([(status, message), found]) if status != "ok" else
                           (found[0], "; ".join(m for m in (found[1], message) if m)))
    per_case = {key: {case: results[case][key] for case in CASES}
                for key in ("steady_peak", "steady_peak_error", "settling_time", "settling_time_error", "settled",
                            "saturation")}
    return ControlComparison(
        problem=problem.name, scene=problem.text, parameters=params, quantities=tuple(plan.units),
        units=plan.units, roles=plan.roles,
        settings={"n_steps": n_steps, "n_periods": n_periods, "band": band, "output": plan.output},
        t=t, with_control=results["with"]["history"], without_control=results["without"]["history"],
        **per_case, run_time=time.perf_counter() - started,
        case_run_time={case: results[case]["run_time"] for case in CASES},
        failed={case: results[case]["failed"] for case in CASES}, torque_limit=plan.torque_limit,
        command_limit=plan.command_limit, status=status, message=message, error_tolerance=error_tolerance,
        **budget)


@dataclass(frozen=True)
class _Plan:
    """What each run reports: ``units`` and ``roles`` by quantity (in report order), the controlled
    ``drive_index``, the link it turns (``driven``) and the relative angle it turns (``turns``:
    ``(link, coefficient)`` of its joint's ``drive_terms``, frame angles, the ground left out), the
    ``output`` spec and the coordinate observables' specs to evaluate (``direct``); the drive's
    ``joint``, ``torque_limit`` and ``command_limit`` (N m, inf where none) and the motor's
    back-EMF damping ``back_emf`` (N m s/rad at the joint, 0 without a motor)."""

    units: dict[str, str]
    roles: dict[str, str]
    drive_index: int
    driven: str
    turns: tuple[tuple[str, float], ...]
    output: str
    direct: tuple[str, ...]
    joint: str
    torque_limit: float
    command_limit: float
    back_emf: float


def _quantities(problem: Any, mechanism: Any, without: Any, output: str | None) -> _Plan:
    import mechanisms

    from .._mechanism import of_coordinates

    # the controlled drive: the first whose own gains or whose joint's controllers are removed
    controlled = {controller.joint for controller in mechanism.controllers}
    changed = [i for i, (a, b) in enumerate(zip(mechanism.drives, without.drives))
               if a != b or a.joint in controlled]
    drive_index = changed[0] if changed else 0
    drive = mechanism.drives[drive_index]
    joint = mechanism.joint(drive.joint)
    turns = tuple((term.link, float(term.coefficient)) for term in joint.drive_terms())   # driven first
    output = _default_output(mechanism, joint) if output is None else output
    model = mechanisms.assemble(mechanism)
    specs = getattr(problem, "observable_specs", None) or mechanisms.default_observables(mechanism)
    elastic, skipped = [], []
    for spec in specs:
        (elastic if of_coordinates(model.observable(spec)) else skipped).append(spec)
    if skipped:
        logger.info("control comparison: %s not reported (not functions of the coordinates)", ", ".join(skipped))
    _check_output("output", output)
    observer = model.observable(output)   # an unknown link or fraction raises naming the spec
    found = coordinate_parts(observer)
    if found is None:   # a registered position quantity that reads more than the coordinates
        raise StudiesError(f"output: expected the observable spec of a position, a function of the "
                           f"coordinates; {output!r} is not one")
    speed, torque = f"drive.{drive.joint}.rate", f"drive.{drive.joint}.torque"
    units = {spec: model.observable(spec).unit for spec in elastic}
    units.update({speed: "rad/s", output: observer.unit, torque: "N m"})
    roles = {spec: "elastic" for spec in elastic}
    roles.update({speed: "speed", output: "output", torque: "torque"})
    direct = tuple(dict.fromkeys(elastic + [part.spec for part in found[0]]))
    motor = getattr(drive, "motor", None)
    return _Plan(units=units, roles=roles, drive_index=drive_index, driven=turns[0][0],
                 turns=turns, output=output, direct=direct, joint=drive.joint,
                 torque_limit=float(getattr(drive, "torque_limit", math.inf)),
                 command_limit=motor.peak_command if motor is not None else math.inf,
                 back_emf=motor.back_emf_damping if motor is not None else 0.0)


def _check_output(where: str, output: Any) -> None:
    """An ``output`` must be the spec of a position, ``<link>.<quantity>`` with a quantity that
    declares itself one (``mechanisms.position_quantities()``: ``angle``, a point's displacement,
    registered ones); its deviation from the nominal motion is the output error."""
    import mechanisms

    positions = mechanisms.position_quantities()
    kind = output.partition("@")[0].rpartition(".")[2] if isinstance(output, str) else None
    if kind not in positions or output.startswith(("drive.", "joint.")):
        raise StudiesError(f"{where}: expected the observable spec of a position, '<link>.<quantity>' with "
                           f"a quantity in {list(positions)} (mechanisms.position_quantities), e.g. "
                           f"'rocker.angle' or '<link>.point_error@p', got {output!r}")


def _default_output(mechanism: Any, drive_joint: Any) -> str:
    """The angle of the last link pinned to the ground (a joint whose ``coincident_points`` hold a
    point of it to a ground point) by a joint other than the driven one (a four-bar's rocker), else
    the displacement of the last link's end (a slider's pin, an arm's tip)."""
    import mechanisms

    driven = drive_joint.drive_terms()[0].link
    pivoted = []
    for joint in mechanism.joints:
        sides = [link for link, _ in joint.coincident_points()] if joint.name != drive_joint.name else []
        if mechanisms.GROUND in sides:
            pivoted += [link for link in sides if link != mechanisms.GROUND]
    names = [link.name for link in mechanism.links if link.name != driven]
    for name in reversed(names):
        if name in pivoted:
            return f"{name}.angle"
    return f"{(names or [driven])[-1]}.point_error@1.0"


def _case(machine: Any, plan: _Plan, n_periods: int, n_steps: int, band: float) -> dict[str, Any]:
    """One case: the run at ``n_steps`` and its N/2 twin, the quantities, peaks and settling times."""
    import mechanisms

    start = time.perf_counter()
    n_t = n_periods * n_steps + 1
    empty = {name: np.full(n_t, np.nan) for name in plan.units}
    nan = {name: float("nan") for name in plan.units}
    found = dict(history=empty, steady_peak=dict(nan), steady_peak_error=dict(nan), settling_time=dict(nan),
                 settling_time_error=dict(nan), settled={name: False for name in plan.units},
                 growing={name: False for name in plan.units}, failed="", coarse_failed="",
                 saturation={key: float("nan") for key in SATURATION_KEYS})
    try:
        nominal = mechanisms.nominal_motion(machine, n_steps=n_steps)
        model = mechanisms.integrated_model(machine)   # with the feedforward simulate() applies
        fine = _run(model, nominal, plan, n_periods, n_steps)
    except Exception as error:
        if not is_numerical_failure(error):
            raise
        partial = getattr(error, "partial", None)
        found.update(failed=f"{type(error).__name__}: {error}", run_time=time.perf_counter() - start)
        if partial is not None:
            for name, values in partial.items():
                found["history"][name][:values.size] = values
        return found
    fine_settling = {name: settling_time(fine["t"], fine[name], n_steps, band) for name in plan.units}
    try:
        coarse = _run(model, nominal, plan, n_periods, n_steps // 2, stride=2)
        coarse_settling = {name: settling_time(coarse["t"], coarse[name], n_steps // 2, band)
                           for name in plan.units}
    except Exception as error:
        if not is_numerical_failure(error):
            raise
        logger.info("control comparison: the N/2 run for the error estimate failed: %s", error)
        coarse, coarse_settling = None, None
        found["coarse_failed"] = f"{type(error).__name__}: {error}"
    found["saturation"] = _saturation(fine, plan, n_steps)
    for name in plan.units:
        found["history"][name] = fine[name]
        found["steady_peak"][name] = fine_settling[name].steady_peak
        found["settling_time"][name] = fine_settling[name].time
        found["settled"][name] = fine_settling[name].settled
        found["growing"][name] = fine_settling[name].growing
        if coarse is not None:
            last = slice(-(n_steps // 2 + 1), None)
            found["steady_peak_error"][name] = float(np.abs(fine[name][::2][last] - coarse[name][last]).max()
                                                     / RICHARDSON)
            found["settling_time_error"][name] = abs(fine_settling[name].time - coarse_settling[name].time)
    found["run_time"] = time.perf_counter() - start
    return found


def _saturation(run: Mapping[str, np.ndarray], plan: _Plan, n_steps: int) -> dict[str, float]:
    """The drive's saturation along ``run`` (``_run``'s quantities, ``n_steps`` samples per period):
    ``SATURATION_KEYS``, the peaks over the last period. A sample is saturated where the unsaturated
    law's command exceeds the motor's limit or its torque the torque limit (the order in which
    ``Model.drive_torque_terms`` clips them)."""
    demanded, command = run["demanded_torque"], run["command"]
    clipped = (np.abs(command) > plan.command_limit) | (np.abs(demanded) > plan.torque_limit)
    last = slice(-(n_steps + 1), None)
    times = run["t"][clipped]
    return {"peak_demanded_torque": float(np.abs(demanded[last]).max()),
            "peak_command": float(np.abs(command[last]).max()),
            "clipped_fraction": float(clipped[last].mean()),
            "clipped_until": float(times[-1] - run["t"][0]) if times.size else float("nan")}


class _RunFailed(ComputationError):
    """A nonlinear run stopped early; ``partial`` holds the quantities up to its last step."""

    def __init__(self, message: str, partial: Mapping[str, np.ndarray]):
        super().__init__(message)
        self.partial = partial


def _run(model: Any, nominal: Any, plan: _Plan, n_periods: int, steps_per_period: int, *,
         stride: int = 1) -> dict[str, np.ndarray]:
    """``mechanisms.simulate`` of ``model`` (``mechanisms.integrated_model`` of the machine) from the
    rigid nominal state at t = 0 with ``steps_per_period``; the quantities of ``plan`` along it
    (``stride``: the nominal motion's samples per run step)."""
    import mechanisms

    run = mechanisms.simulate(model, n_periods=n_periods, steps_per_period=steps_per_period,
                              s0=nominal.s[0], sdot0=nominal.sdot[0], observables=plan.direct,
                              estimate_error=False, throw=False)
    quantities = _along(run, model, nominal.s[::stride], nominal.sdot[::stride], plan)
    if not run.success:
        raise _RunFailed(run.message, quantities)
    quantities["t"] = run.t
    # what the drive's unsaturated law asks for, and the motor's command u = tau + c theta'
    quantities["demanded_torque"] = model.drive_torque_terms(plan.joint, run.t, run.s, run.sdot, saturate=False)[0]
    joint_rate = run.sdot @ model.drive_gradient(plan.joint)
    quantities["command"] = quantities["demanded_torque"] + plan.back_emf * joint_rate
    return quantities


def _along(run: Any, model: Any, nominal_s: np.ndarray, nominal_sdot: np.ndarray, plan: _Plan
           ) -> dict[str, np.ndarray]:
    """The quantities of ``plan`` along ``run`` (its samples, k T / N from t = 0): deviations from
    the nominal motion (one period of N + 1 samples, repeated), the drive's total torque."""
    n = nominal_s.shape[0] - 1
    phase = np.arange(run.t.size) % n   # the nominal sample of each run sample

    def deviation(spec: str) -> np.ndarray:   # a function of the coordinates or composed of such
        return deviations_along(model.observable(spec), model, nominal_s, run.t, run.s, run.observables)

    labels = list(model.coord_labels)
    rows = [labels.index(f"{link}.theta") for link, _ in plan.turns]
    signs = [coefficient for _, coefficient in plan.turns]

    def relative_rate(sdot: np.ndarray) -> np.ndarray:
        return sum(sign * sdot[:, row] for sign, row in zip(signs, rows))

    quantities = {}
    for name, role in plan.roles.items():
        if role == "speed":
            quantities[name] = relative_rate(run.sdot) - relative_rate(nominal_sdot[:-1])[phase]
        elif role == "torque":
            # a lagged controller's torque is a state of the run, not a function of (s, s', t)
            lags = run.lag_states if run.lag_states is not None else [None] * run.t.size
            quantities[name] = np.array([model.drive_torques(s, v, t, lam, lag_states=y)[plan.drive_index]
                                         for s, v, t, lam, y in zip(run.s, run.sdot, run.t, run.lam, lags)])
        else:
            quantities[name] = deviation(name)
    return quantities


def _verdict(results: Mapping[str, Mapping[str, Any]], plan: _Plan, n_periods: int) -> tuple[str, str]:
    """``(status, message)``: the worst of the cases' verdicts (:class:`ControlComparison`), their
    messages most severe first, then what only informs (quantities without feedback that do not
    settle, elastic settling times, saturation during the start-up)."""
    verdicts: list[tuple[str, str]] = []
    notes: list[str] = []
    for case in CASES:
        found = results[case]
        who = "with control" if case == "with" else "without feedback"
        if found["failed"]:
            verdicts.append(("failed", f"the run {who} failed: {found['failed']}"))
            continue
        if found["coarse_failed"]:
            verdicts.append(("inaccurate", f"{who}: the run with n_steps / 2 for the error estimates failed "
                                           f"({found['coarse_failed']}): no error estimate; refine n_steps"))
        for name in plan.units:
            peak, error = found["steady_peak"][name], found["steady_peak_error"][name]
            if not found["coarse_failed"] and not error <= INACCURATE_FRACTION * peak:   # NaN too
                verdicts.append(("inaccurate", f"{who}: {name} steady peak {peak:.3g} has error estimate "
                                               f"{error:.3g} (over {100 * INACCURATE_FRACTION:g} %); refine n_steps"))
            if found["settled"][name]:
                if plan.roles[name] == "elastic":
                    notes.append(f"{who}: {name} settles at {found['settling_time'][name]:.3g} s")
            elif found["growing"][name]:
                words = f"{who}: {name} grows period after period (peak {peak:.3g} in the last)"
                if case == "with":
                    verdicts.append(("unstable", words + ": the controlled machine is unstable; lower the "
                                                         "feedback gains"))
                else:
                    notes.append(words)
            elif case == "with":
                verdicts.append(("inaccurate", f"{who}: {name} does not settle within {n_periods} periods, its "
                                               f"steady peak is not steady yet; raise n_periods"))
            else:
                notes.append(f"{who}: {name} does not settle within {n_periods} periods")
        saturated = _saturation_words(found["saturation"], plan)
        if found["saturation"]["clipped_fraction"] > 0.0:
            verdicts.append(("outside_linear_range",
                             f"{who}: the drive at {plan.joint} saturates in the steady state "
                             f"({100 * found['saturation']['clipped_fraction']:.3g} % of the last period's steps"
                             f"{saturated}): the clipped torque is not the law the controller was designed with"))
        elif math.isfinite(found["saturation"]["clipped_until"]):
            notes.append(f"{who}: the drive at {plan.joint} saturates during the start-up (until "
                         f"{found['saturation']['clipped_until']:.3g} s)")
    status, message = combine(verdicts)
    return status, "; ".join([message] * bool(message) + notes)


def _saturation_words(saturation: Mapping[str, float], plan: _Plan) -> str:
    """``": peak demanded torque ... > torque_limit ..."`` for each limit the last period exceeds."""
    words = []
    if saturation["peak_demanded_torque"] > plan.torque_limit:
        words.append(f"peak demanded torque {saturation['peak_demanded_torque']:.4g} N m > torque_limit "
                     f"{plan.torque_limit:.4g} N m")
    if saturation["peak_command"] > plan.command_limit:
        words.append(f"peak motor command {saturation['peak_command']:.4g} N m > G stall_torque "
                     f"{plan.command_limit:.4g} N m")
    return ": " + ", ".join(words) if words else ""


# ---------------------------------------------------------------------------------------------------
# the [studies.control_comparison] table
# ---------------------------------------------------------------------------------------------------
def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    output = table.get("output")
    if output is not None:
        _check_output(f"[{where}] output", output)
    band = fraction(where, "band", table.get("band", BAND))
    if band <= 0.0:
        raise StudiesError(f"[{where}] band: expected a fraction in (0, 1), got {band!r}")
    return {"values": speed_values(where, table),
            "n_steps": steps(where, table, n_steps, minimum=MIN_STEPS),
            "n_periods": integer(where, "n_periods", table.get("n_periods", 20), 3, maximum=MAX_PERIODS,
                                 why=PERIODS_WHY),
            "band": band, "output": output,
            **({"error_tolerance": check_tolerance(table["error_tolerance"], f"[{where}] error_tolerance")}
               if "error_tolerance" in table else {})}


def _without_feedback(problem: Any, mechanism: Any) -> Any:
    """``mechanism.without_feedback()``, refused when there is no feedback to remove."""
    without = mechanism.without_feedback()
    if without == mechanism:
        raise StudiesError(f"scene {problem.name!r}: its drives have no feedback to remove (a prescribed "
                           f"drive, or a torque drive with kp = kd = 0 and no [controllers]): nothing to "
                           f"compare; declare the drive with type = \"torque\" and a [controllers.<name>] "
                           f"table or kp, kd (docs/scenes.md)")
    return without


def _validate(problem: Any, options: Mapping[str, Any]) -> None:
    """Before any study is written: the problem must be a mechanism whose drives have feedback."""
    if not hasattr(problem, "mechanism"):
        raise StudiesError(f"[studies.control_comparison]: problem {getattr(problem, 'name', problem)!r} has "
                           f"no mechanism; a control comparison needs a scene whose drive has a controller")
    _without_feedback(problem, problem.mechanism())


def _run_kind(problem: Any, options: Mapping[str, Any], **_: Any) -> ControlComparison:
    return control_comparison(problem, **options)


def _case_words(result: ControlComparison, case: str) -> str:
    if result.failed.get(case):
        return "failed"
    parts = []
    for name in result.quantities:
        value = result.settling_time[case][name]
        parts.append(f"{name} peak {plain(result.steady_peak[case][name])}"
                     + (f" settles {plain(value)} s" if math.isfinite(value) else " not settled"))
    return ", ".join(parts)


def _summary(result: ControlComparison) -> str:
    speed = result.parameters.get(SPEED, float("nan"))
    return (f"{headline(result.status).upper()} at speed {speed:.4g} rad/s: {result.message}\n"
            f"    with control: {_case_words(result, 'with')}\n"
            f"    without feedback: {_case_words(result, 'without')}")


def _headlines(result: ControlComparison) -> Summary:
    rows = []
    for name in result.quantities:
        unit = result.units[name]
        without = Headline("", result.steady_peak["without"][name], unit).shown()[0]
        budget = ErrorBudget(result.error_budget)
        error = budget.total(name) if name in budget.terms else result.steady_peak_error["with"][name]
        words = f"; error {describe(budget, name, unit)}" if name in budget.terms else ""
        rows.append(Headline(f"{name} steady peak with control", result.steady_peak["with"][name], unit,
                             error, f"(without feedback: {without}{words})"))
    for name in result.quantity("elastic"):
        without = result.settling_time["without"][name]
        rows.append(Headline(f"{name} settling time with control", result.settling_time["with"][name], "s",
                             result.settling_time_error["with"][name], "(without feedback: "
                             f"{plain(without, 3) + ' s' if math.isfinite(without) else 'not settled'})"))
    speed = result.parameters.get(SPEED, float("nan"))
    return Summary(status=f"{headline(result.status)} at speed {plain(speed, 3)} rad/s",
                   run_time=float(result.run_time), rows=rows)


def _cost(name, problem, options, workers):
    """Two cases (with and without feedback), each a run of ``n_periods`` periods at N steps and its
    twin at N/2 for the error estimate (together what one ``simulate`` with its error estimate costs),
    one after the other; the error budget's mesh term at the point."""
    sizes = cost.sizes_at(problem, options["values"])
    steps = options["n_periods"] * options["n_steps"]
    seconds = cost.STUDY_SECONDS + len(("with", "without")) * steps * (cost.NONLINEAR_STEP_SECONDS
                                                                  + cost.NONLINEAR_STEP_N2_SECONDS * sizes.n**2)
    memory = 8.0 * cost.NONLINEAR_DOUBLES * steps * sizes.n
    found = cost.Estimate(name, memory, seconds, f"2 runs x {options['n_periods']} periods x {options['n_steps']} "
                                                 f"steps x {sizes.n} coordinates")
    return cost.with_mesh_term(found, problem, options["values"], options["n_steps"])


KIND = register_kind(StudyKind(
    name="control_comparison", result=ControlComparison, check=_check, run=_run_kind, summary=_summary,
    keys=("speed", "n_periods", "n_steps", "band", "output", "error_tolerance"), headlines=_headlines,
    cost=_cost, aliases=("ControlComparison",), validate=_validate))
