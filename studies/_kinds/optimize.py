"""``[studies.optimize]``: scene parameters (design values, controller gains) that minimise a measure
of the steady vibration, the worst over an operating range of speeds, under constraints; the optimum
checked by a nonlinear run.

Each evaluation is a sweep over ``speeds`` at one set of parameter values (``problem.linearize`` with
``context=False``: a mechanism with a constant-rate prescribed drive reuses one speed family per
parameter set). The local method minimises the worst value in epigraph form (minimise ``t`` subject
to ``t >= m_i(x)`` at every speed ``i``: smooth pieces instead of the kinked ``max``) with scipy's
SLSQP and the gradients of each speed's sensitivities (``studies._derivatives``: direct
differentiation, reusing the sweep's linearisation and shooting; forward differences of the whole
sweep where a constraint offers no gradient, said in ``gradients``); the global method runs scipy's
differential evolution and polishes its best point with the local method. Parameters are scaled to
``[0, 1]`` between their bounds and the objective by its value at the start, so that one tolerance
serves any units.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np

from .._budget import ERROR_TOLERANCE, FORMAT2_METHODS, WORDS, ErrorBudget, check_tolerance, format2_budget
from .._kind import StudyKind, register_kind
from .._mechanism import count_keys
from .._plots import Plot, axes_for, cost_line, drawn, headline, label, legend_outside, plain
from .._result import StudyResult, unknown_peaks
from .._toolkit import (
    MAX_AXIS_POINTS,
    MAX_PERIODS,
    PERIODS_WHY,
    SPEED,
    Headline,
    StudiesError,
    Summary,
    axis,
    boolean,
    check_integer,
    check_n_steps,
    check_parameter,
    combine,
    cost,
    integer,
    number,
    reject_unknown,
    steps,
)
from ._optimize_constraints import (
    FrequencySeparation,
    MassBudget,
    StabilityMargin,
    TorqueLimit,
    check_constraints,
    constraints_from_table,
    describe,
    register_constraint,
)
from ._optimize_optimum import objective_map, optimum_budget, optimum_check, optimum_peaks
from ._optimize_search import (
    Evaluator,
    Objective,
    best_feasible,
    default_evaluations,
    global_search,
    gradient_words,
    local_search,
)

__all__ = ["OptimizeResult", "optimize", "StabilityMargin", "TorqueLimit", "MassBudget", "FrequencySeparation",
           "register_constraint", "default_evaluations"]

#: The fewest steps per period an optimisation accepts (its steady states' error check uses N/4).
MIN_STEPS = 16
METHODS = ("local", "global")
#: How the local method takes its gradients: the sensitivities (direct differentiation, where every
#: constraint offers one) or forward differences of whole sweeps.
GRADIENTS = ("sensitivities", "differences")
#: Default relative tolerance of the objective (SLSQP's ``ftol`` on the objective scaled by its start value).
TOL = 1e-8
#: Most sweeps (evaluations) an optimisation may do (docs/studies.md, "Limits").
MAX_EVALUATIONS = 100_000
EVALUATIONS_WHY = "evaluations, each a steady state at every speed"
TABLE_KEYS = ("objective", "bounds", "speeds", "start", "constraints", "method", "n_steps", "tol",
              "max_evaluations", "map_points", "check", "check_periods", "seed", "error_tolerance")


# ---------------------------------------------------------------------------------------------------
# the result
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class OptimizeResult(StudyResult):
    """The optimum of an objective over scene parameters, with the path that led there (the fields
    every result has: ``studies._result``; the grid is the speeds).

    ``status`` is "ok", or the worst of: the optimiser not converged ("inaccurate": stopped by
    ``max_evaluations`` or a line search that found no descent; "failed": no feasible point, or the
    optimiser failed), the steady states' verdicts at the optimum, and the nonlinear check
    ("differs": ``outside_linear_range``; "not_periodic" or "failed": ``failed``); ``message`` the
    reasons.

    Attributes
    ----------
    problem, scene : str
        The problem's name and scene text.
    settings : dict
        The study's arguments.
    names : tuple of str, (n,)
        The parameter paths.
    parameter_units : dict
        {path: unit}.
    bounds : ndarray, (n, 2), parameter_units
        The bounds.
    x, x_start : ndarray, (n,), parameter_units
        The optimum and the start.
    objective : str
        The measure, e.g. ``"peak_to_peak:coupler.deflection@0.5"``.
    objective_unit : str
        Its unit.
    objective_value : float, objective_unit
        Its worst value over ``speeds`` at ``x``, at ``worst_speed``.
    objective_error : float, objective_unit
        The estimated error there: the total of ``error_budget`` (an RMS is within the response's
        error).
    objective_start : float, objective_unit
        The worst value at ``x_start``.
    worst_speed : float, rad/s
        Where the optimum's value is worst.
    speeds : ndarray, (n_s,), rad/s
        The operating speeds (NaN: the problem's own).
    per_speed : ndarray, (n_s,), objective_unit
        The measure at each speed at ``x``.
    constraint_values, constraint_limits : dict, {name: float}
        Each constraint at ``x`` and its limit (stability: the largest spectral radius; torque: the
        largest peak drive torque, N m; mass: the links' mass, kg; frequency: the smallest distance
        of a frozen band from ``k * speed`` over ``k * speed``).
    history_x : ndarray, (n_eval, n), parameter_units
        Every evaluation (finite-difference probes included), in order.
    history_objective : ndarray, (n_eval,), objective_unit
        Their worst values (NaN where the evaluation failed).
    history_feasible : ndarray of bool, (n_eval,)
        Whether each met every constraint.
    history_worst_speed : ndarray, (n_eval,), rad/s
        Where each was worst.
    path : ndarray of int, (n_iter,)
        The indices into the history of the optimiser's iterates.
    n_evaluations : int
        The evaluations done.
    optimizer_message : str
        The optimiser's own words.
    gradients : str
        How the local method's gradients were taken: the sensitivities of each speed's steady state
        (direct differentiation, ``studies.sensitivity``'s numerics) at how many points, or forward
        differences of whole sweeps where a constraint offers no gradient (named) or a derivative was not
        defined ("" in files written before the gradients).
    status, message : str
        See above.
    run_time : float, s
        The whole study.
    map_first, map_second : ndarray or None, (k,), parameter_units
        A grid of the first two parameters (``map_points > 0``; None otherwise).
    map_objective : ndarray or None, (k, k), objective_unit
        The objective on it (rows: first parameter).
    check_verdict : str
        The nonlinear check at ``check_speed`` (``studies.nonlinear_check``): "agrees", "differs",
        "not_periodic", "failed", or "" when not checked.
    check_message : str
        Its message.
    check_speed : float, rad/s
        The worst speed, where it is run.
    check_t : ndarray or None, (N+1,), s
        The last period's samples.
    check_linear, check_nonlinear : dict of ndarray, {spec: (N+1,)}, check_units[spec]
        The last period of both routes.
    check_objective, check_linear_objective : float, objective_unit
        The measure of the nonlinear run's last period, and of the linear one at the same speed.
    check_units : dict
        {spec: unit} of the check's observables.
    units : dict
        {spec: unit} of the problem's observables.
    peak, peak_error, peak_to_peak, peak_to_peak_error : dict of ndarray, {spec: (n_s,)}, units
        The observables' summaries of the steady states at ``x``, at each speed (NaN where the
        evaluation failed; in a file written before they were recorded, NaN for the objective's).
    error_budget : dict, {spec: {term: float or "not applicable"}}, objective_unit
        The objective's error budget at the optimum's worst speed (``studies._budget``: time step,
        mesh, linearisation, reduction where a link is reduced), from the steady state there.
    error_methods : dict, {term: str}
        How each term was estimated, in words.
    error_tolerance : float, 1
        The relative tolerance of the total deciding ``inaccurate``.
    """

    problem: str
    scene: str
    settings: Mapping[str, Any]
    names: tuple[str, ...]
    parameter_units: Mapping[str, str]
    bounds: np.ndarray
    x: np.ndarray
    x_start: np.ndarray
    objective: str
    objective_unit: str
    objective_value: float
    objective_error: float
    objective_start: float
    worst_speed: float
    speeds: np.ndarray
    per_speed: np.ndarray
    constraint_values: Mapping[str, float]
    constraint_limits: Mapping[str, float]
    history_x: np.ndarray
    history_objective: np.ndarray
    history_feasible: np.ndarray
    history_worst_speed: np.ndarray
    path: np.ndarray
    n_evaluations: int
    optimizer_message: str
    status: str
    message: str
    run_time: float
    map_first: np.ndarray | None = None
    map_second: np.ndarray | None = None
    map_objective: np.ndarray | None = None
    check_verdict: str = ""
    check_message: str = ""
    gradients: str = ""
    check_speed: float = float("nan")
    check_t: np.ndarray | None = None
    check_linear: Mapping[str, np.ndarray] = field(default_factory=dict)
    check_nonlinear: Mapping[str, np.ndarray] = field(default_factory=dict)
    check_objective: float = float("nan")
    check_linear_objective: float = float("nan")
    check_units: Mapping[str, str] = field(default_factory=dict)
    units: Mapping[str, str] = field(default_factory=dict)
    peak: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_error: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_to_peak: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_to_peak_error: Mapping[str, np.ndarray] = field(default_factory=dict)
    error_budget: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    error_methods: Mapping[str, str] = field(default_factory=dict)
    error_tolerance: float = ERROR_TOLERANCE

    _axes = {"speeds": "speed"}
    _units = {"bounds": "see parameter_units", "x": "see parameter_units", "x_start": "see parameter_units",
              "history_x": "see parameter_units", "speeds": "rad/s", "per_speed": "@objective_unit",
              "history_objective": "@objective_unit", "history_feasible": "1", "history_worst_speed": "rad/s",
              "path": "1", "map_first": "see parameter_units", "map_second": "see parameter_units",
              "map_objective": "@objective_unit", "check_t": "s", "check_linear": "@check_units",
              "check_nonlinear": "@check_units", "peak": "@observables", "peak_error": "@observables",
              "peak_to_peak": "@observables", "peak_to_peak_error": "@observables"}

    def _filled(self, group: Any) -> dict[str, Any]:
        spec = Objective.parse(self.objective).spec
        # a file of format 2 (before the budget): the objective's error was the time step's alone
        filled = {} if "error_budget" in group.attrs else {
            "error_budget": format2_budget({spec: self.objective_error}), "error_methods": dict(FORMAT2_METHODS)}
        if "units" in group.attrs:
            return filled
        return {**filled, **unknown_peaks([spec], np.shape(self.speeds)), "units": {spec: self.objective_unit}}

    def _unit(self, name: str, key: str | None = None) -> str:
        if self._units.get(name) == "@check_units":
            return dict(self.check_units).get(key, "1")
        return super()._unit(name, key)

    def _dominant_words(self) -> str:
        """" (error mostly linearisation)": the objective's largest budget term ("" without a budget)."""
        spec = Objective.parse(self.objective).spec
        dominant = ErrorBudget(self.error_budget).dominant(spec) if spec in self.error_budget else ""
        return f" (error mostly {WORDS.get(dominant, dominant)})" if dominant else ""

    @property
    def values(self) -> dict[str, float]:
        """The optimum as ``{path: value}``."""
        return {name: float(value) for name, value in zip(self.names, self.x)}

    def plot(self, *, axes: Any = None) -> Plot:
        """The objective against the evaluation (every evaluation a dot, open where a constraint is
        not met, the optimiser's iterates joined); for two parameters also the map of the objective
        (computed with ``map_points``, else the evaluations coloured by their value) with the path
        from the start to the optimum."""
        two = len(self.names) == 2
        axes = axes_for(2 if two else 1, axes, height=3.2)
        ax = axes[0]
        artists: dict[str, list] = {}
        number = np.arange(self.history_objective.size)
        feasible = np.asarray(self.history_feasible, dtype=bool)
        artists["evaluations"] = ax.plot(number[feasible], self.history_objective[feasible], ".", color="0.6",
                                         label="evaluations")
        artists["infeasible"] = ax.plot(number[~feasible], self.history_objective[~feasible], "o", mfc="none",
                                        color="C3", ms=4, label="constraint not met")
        path = np.asarray(self.path, dtype=int)
        artists["iterates"] = ax.plot(path, self.history_objective[path], "-o", color="C0", ms=3,
                                      label="optimiser's iterates")
        artists["optimum"] = [ax.axhline(self.objective_value, color="C2", lw=0.8, ls="--", label="optimum")]
        positive = self.history_objective[np.isfinite(self.history_objective)]
        if positive.size and positive.min() > 0 and positive.max() > 20 * positive.min():
            ax.set_yscale("log")
        ax.set_xlabel("evaluation (one steady state per speed)")
        ax.set_ylabel(label(self.objective, self.objective_unit))
        legend_outside(ax)
        ax.set_title(f"{self.problem}: {headline(self.status)}; {plain(self.objective_start, 3)} -> "
                     f"{plain(self.objective_value, 3)} ± {plain(self.objective_error)} {self.objective_unit} "
                     f"at {plain(self.worst_speed, 3)} rad/s{self._dominant_words()}\n"
                     + cost_line(f"{self.n_evaluations} evaluations; nonlinear check: "
                                 f"{self.check_verdict.replace('_', ' ') or 'not run'}", self.run_time),
                     fontsize="small")
        if two:
            artists.update(self._plot_map(axes[1]))
        return drawn(axes, artists)

    def _plot_map(self, ax: Any) -> dict[str, list]:
        artists: dict[str, list] = {}
        if self.map_objective is not None:
            artists["map"] = [ax.contourf(self.map_first, self.map_second, np.asarray(self.map_objective).T,
                                          levels=20, cmap="viridis")]
            ax.figure.colorbar(artists["map"][0], ax=ax, label=label(self.objective, self.objective_unit))
        else:
            finite = np.isfinite(self.history_objective)
            artists["map"] = [ax.scatter(self.history_x[finite, 0], self.history_x[finite, 1],
                                         c=self.history_objective[finite], s=10, cmap="viridis")]
            ax.figure.colorbar(artists["map"][0], ax=ax, label=label(self.objective, self.objective_unit))
        path = np.asarray(self.path, dtype=int)
        artists["path"] = ax.plot(self.history_x[path, 0], self.history_x[path, 1], "-o", color="w", ms=3,
                                  mec="k", lw=1.0)
        artists["start"] = ax.plot(*self.x_start, "s", color="C1", label="start")
        artists["optimum_point"] = ax.plot(*self.x, "*", color="C3", ms=12, label="optimum")
        ax.set_xlim(*self.bounds[0])
        ax.set_ylim(*self.bounds[1])
        ax.set_xlabel(label(self.names[0], self.parameter_units[self.names[0]]))
        ax.set_ylabel(label(self.names[1], self.parameter_units[self.names[1]]))
        # below the axes: the colour bar takes their right
        legend_outside(ax, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncols=2)
        return artists



# ---------------------------------------------------------------------------------------------------
# the study
# ---------------------------------------------------------------------------------------------------
def _check_bounds(problem: Any, bounds: Any) -> tuple[tuple[str, ...], np.ndarray]:
    if not isinstance(bounds, Mapping) or not bounds:
        raise StudiesError(f"bounds: expected a mapping of parameter paths to (low, high), e.g. "
                           f"{{'links.coupler.thickness': (1e-3, 3e-3)}}, got {bounds!r}")
    names, rows = [], []
    for name, pair in bounds.items():
        if not isinstance(name, str):
            raise StudiesError(f"bounds: expected parameter paths (str) as keys, got {name!r}")
        if name.split(".")[-1] in count_keys():
            raise StudiesError(f"bounds: {name!r} is a count (it changes the number of coordinates), not a "
                               f"continuous design parameter; optimise continuous values only")
        try:
            low, high = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise StudiesError(f"bounds[{name!r}]: expected (low, high), two numbers, got {pair!r}") from None
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise StudiesError(f"bounds[{name!r}]: expected finite low < high, got {pair!r}")
        names.append(name)
        rows.append((low, high))
    return tuple(names), np.array(rows)


def _with_needs(problem: Any, names: Sequence[str], specs: Sequence[str]) -> Any:
    """The problem able to vary ``names`` and report ``specs``: a mechanism problem is remade with
    the missing parameter paths and the observables the study needs; any other problem must have
    them."""
    if hasattr(problem, "parameter_paths") and hasattr(problem, "observable_specs"):
        paths = tuple(problem.parameter_paths) + tuple(n for n in names if n != SPEED and n not in problem.parameters)
        changes = {}
        if paths != tuple(problem.parameter_paths):
            changes["parameter_paths"] = paths
        if problem.observable_specs is None or any(s not in problem.observable_specs for s in specs):
            changes["observable_specs"] = tuple(dict.fromkeys(specs))
        if changes:
            problem = replace(problem, **changes)
    for name in names:
        check_parameter(problem, name)
    available = problem.describe().observables
    for spec in specs:
        if spec not in available:
            raise StudiesError(f"objective: problem {problem.name!r} has no observable {spec!r} "
                               f"(observables: {', '.join(available)})")
    return problem


def optimize(problem: Any, bounds: Mapping[str, tuple[float, float]], *, objective: str,
             speeds: Sequence[float] | None = None, constraints: Any = (), method: str = "local",
             n_steps: int = 256, start: Mapping[str, float] | None = None, tol: float = TOL,
             max_evaluations: int | None = None, map_points: int = 0, check: bool = True,
             check_periods: int = 5, seed: int = 0, gradient: str = "sensitivities",
             error_tolerance: float = ERROR_TOLERANCE) -> OptimizeResult:
    """Minimise ``objective`` over the parameters of ``bounds`` ({path: (low, high)}: scene paths
    such as ``"links.coupler.thickness"`` or ``"drive.kp"``, or a ``PeriodicProblem``'s parameters).

    ``objective``: ``"<measure>:<observable spec>"``, measure ``peak_to_peak``, ``peak`` (largest
    magnitude: peak stress, peak drive torque ``drive.<J>.torque``) or ``rms`` over one period of
    the steady state; with ``speeds`` (rad/s) its worst value over them, else at the problem's speed.
    ``constraints``: :class:`StabilityMargin`, :class:`TorqueLimit`, :class:`MassBudget`,
    :class:`FrequencySeparation` objects, or a table with keys ``stability_margin``,
    ``torque_limit``, ``mass_budget``, ``frequency_separation``, ``max_harmonic``; each holds at
    every speed. ``method``: "local" (SLSQP on the epigraph of the worst value, gradients from the
    sensitivities) or "global" (differential evolution, then the local method). ``start``: the start
    values (default: the problem's values, clipped into the bounds); ``tol``: relative tolerance of
    the objective; ``max_evaluations``: most sweeps (default 40 + 40 n local, 300 n global);
    ``map_points``: a grid of this many values per axis of the first two parameters for the figure
    (0: none); ``check``: the nonlinear check at the worst speed of the optimum with
    ``check_periods`` periods (where the problem has a nonlinear model); ``seed`` of the global
    method; ``gradient``: "sensitivities" (default: each speed's steady state differentiated directly, forward
    differences of sweeps only where a constraint offers no gradient) or "differences" (forward differences
    of whole sweeps throughout). The objective's error at the optimum is the total of its error budget (the
    steady state at the worst speed, ``studies._budget``), above ``error_tolerance`` of the value
    ``inaccurate``. See :class:`OptimizeResult`."""
    started = time.perf_counter()
    goal = Objective.parse(objective)
    names, box = _check_bounds(problem, bounds)
    if gradient not in GRADIENTS:
        raise StudiesError(f"gradient: expected one of {', '.join(map(repr, GRADIENTS))}, got {gradient!r}")
    if method not in METHODS:
        raise StudiesError(f"method: expected one of {', '.join(map(repr, METHODS))}, got {method!r}")
    if speeds is not None and SPEED in names:
        raise StudiesError("bounds: 'speed' is the operating range given by speeds; optimise it only without speeds")
    chosen = check_constraints(constraints)
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="an optimisation")
    if not (isinstance(tol, (int, float)) and 0.0 < tol < 1.0):
        raise StudiesError(f"tol: expected a relative tolerance in (0, 1), got {tol!r}")
    n = len(names)
    if max_evaluations is None:
        max_evaluations = default_evaluations(method, n)
    check_integer("max_evaluations", max_evaluations, 2)
    check_integer("map_points", map_points, 0)
    check_integer("check_periods", check_periods, 2)
    error_tolerance = check_tolerance(error_tolerance)
    needs = [goal.spec] + [spec for constraint in chosen for spec in constraint.needs(problem)]
    problem = _with_needs(problem, names, needs)
    grid = np.array([np.nan]) if speeds is None else np.asarray(speeds, dtype=float).reshape(-1)
    if speeds is not None and (grid.size == 0 or not np.isfinite(grid).all() or (grid <= 0).any()):
        raise StudiesError(f"speeds: expected a non-empty sequence of positive crank speeds (rad/s), got {speeds!r}")
    nominal = problem.resolve(start)
    x_start = np.clip([nominal[name] for name in names], box[:, 0], box[:, 1])
    u_start = (x_start - box[:, 0]) / (box[:, 1] - box[:, 0])
    evaluator = Evaluator(problem, names, box, grid, goal, chosen, n_steps, max_evaluations)
    if gradient == "differences":
        evaluator.can_differentiate = False
        evaluator.gradient_words = "forward differences of whole sweeps (gradient = 'differences')"
    evaluator.gradients = method == "local" and evaluator.can_differentiate   # the start keeps what they need
    first = evaluator(u_start)
    if first.failed:
        raise StudiesError(f"the start {evaluator.values(u_start)} cannot be evaluated ({first.failed}); "
                           f"choose another start or bounds")
    evaluator.scale = max(float(np.abs(first.measure).max()), np.finfo(float).tiny)
    if method == "local":
        optimiser_status, optimiser_message = local_search(evaluator, u_start, tol)
    else:
        optimiser_status, optimiser_message = global_search(evaluator, u_start, tol, seed)
    u_best, best = best_feasible(evaluator)
    verdicts = [(optimiser_status, optimiser_message if optimiser_status != "ok" else "")]
    if best is None:
        verdicts.append(("failed", "no evaluated point meets every constraint: widen the bounds or relax the "
                                   "constraints"))
        u_best, best = evaluator.history[0]
    else:
        verdicts += best.verdicts
    values = evaluator.values(u_best)
    worst = best.worst if not best.failed else 0
    worst_speed = float(grid[worst]) if speeds is not None else float(problem.resolve(values)[SPEED])
    checked = optimum_check(problem, values, worst_speed, goal, n_steps, check_periods) if check else {}
    if checked.get("check_verdict") in ("differs",):
        verdicts.append(("outside_linear_range", f"the nonlinear check at the optimum differs: "
                                                 f"{checked['check_message']}"))
    elif checked.get("check_verdict") in ("not_periodic", "failed"):
        verdicts.append(("failed", f"the nonlinear check at the optimum: {checked['check_verdict']}: "
                                   f"{checked['check_message']}"))
    mapped = objective_map(evaluator, map_points) if map_points and n >= 2 else {}
    budgeted = {} if best.failed else optimum_budget(
        problem, {**values, **({SPEED: worst_speed} if speeds is not None else {})}, goal, n_steps, error_tolerance,
        float(best.measure[worst]))
    if budgeted:
        verdicts.append(budgeted.pop("verdict"))
    status, message = combine(verdicts)
    described = problem.describe()
    units = dict(zip(described.observables, described.units))
    history_x = np.array([evaluator.values(u)[name] for u, _ in evaluator.history for name in names]).reshape(-1, n)
    return OptimizeResult(
        problem=problem.name, scene=problem.text,
        settings={"objective": objective, "bounds": {k: list(v) for k, v in zip(names, box)},
                  "speeds": None if speeds is None else grid, "constraints": [describe(c) for c in chosen],
                  "method": method, "n_steps": n_steps, "tol": tol, "max_evaluations": max_evaluations,
                  "map_points": map_points, "check": check, "check_periods": check_periods, "seed": seed,
                  "start": {k: float(v) for k, v in zip(names, x_start)}},
        names=names, parameter_units={name: problem.units[name] for name in names}, bounds=box,
        x=np.array([values[name] for name in names]), x_start=x_start, objective=objective,
        objective_unit=units[goal.spec], units=units,
        objective_value=float(best.measure[worst]) if not best.failed else float("nan"),
        objective_error=budgeted.pop("objective_error", float("nan")),
        objective_start=float(first.measure.max()), worst_speed=worst_speed,
        speeds=grid, per_speed=best.measure if not best.failed else np.full(grid.shape, np.nan),
        constraint_values=dict(best.reported),
        constraint_limits={c.name: c.bound() for c in chosen},
        history_x=history_x,
        history_objective=np.array([np.nan if f.failed else float(f.measure.max()) for _, f in evaluator.history]),
        history_feasible=np.array([f.feasible() for _, f in evaluator.history], dtype=bool),
        history_worst_speed=np.array([np.nan if f.failed or speeds is None else float(grid[f.worst])
                                      for _, f in evaluator.history]),
        path=np.array(evaluator.path, dtype=np.int64), n_evaluations=len(evaluator.history),
        optimizer_message=optimiser_message, status=status, message=message, gradients=gradient_words(evaluator),
        run_time=time.perf_counter() - started, **mapped, **checked, **optimum_peaks(best, grid.shape),
        error_tolerance=error_tolerance, **budgeted)


# ---------------------------------------------------------------------------------------------------
# the scene table
# ---------------------------------------------------------------------------------------------------
def _flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"drive": {"kp": [..]}}`` (TOML's reading of an unquoted dotted key) as ``{"drive.kp": [..]}``."""
    flat = {}
    for key, value in table.items():
        path = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(_flatten(value, path + "."))
        else:
            flat[path] = value
    return flat


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    if "objective" not in table:
        raise StudiesError(f"[{where}]: missing objective (e.g. objective = 'peak_to_peak:coupler.deflection@0.5')")
    Objective.parse(table["objective"])
    raw = table.get("bounds")
    if not isinstance(raw, Mapping) or not raw:
        raise StudiesError(f"[{where}] bounds: expected a table of parameter paths and [low, high], e.g. "
                           f"bounds = {{ \"drive.kp\" = [1.0, 100.0] }}, got {raw!r}")
    bounds = {}
    for path, pair in _flatten(raw).items():
        if not isinstance(pair, list) or len(pair) != 2:
            raise StudiesError(f"[{where}] bounds.{path}: expected [low, high], got {pair!r}")
        low, high = (number(where, f"bounds.{path}", v) for v in pair)
        if not low < high:
            raise StudiesError(f"[{where}] bounds.{path}: expected low < high, got {pair!r}")
        bounds[path] = (low, high)
    speeds = None
    if "speeds" in table:
        value = table["speeds"]
        if isinstance(value, list):
            if not value or len(value) > MAX_AXIS_POINTS:
                raise StudiesError(f"[{where}] speeds: expected a non-empty list of at most {MAX_AXIS_POINTS} "
                                   f"crank speeds (rad/s), got {value!r}"[:300])
            speeds = np.array([number(where, "speeds", v, positive=True) for v in value])
        elif isinstance(value, Mapping):
            reject_unknown(f"{where}.speeds", value, ("start", "stop", "count", "values", "spacing"))
            speeds = axis(f"{where}.speeds", value, parameter=False)[1]
            if (speeds <= 0).any():
                raise StudiesError(f"[{where}] speeds: expected positive crank speeds (rad/s)")
        else:
            raise StudiesError(f"[{where}] speeds: expected a list of speeds or a table start, stop, count, got "
                               f"{value!r}")
    start = {path: number(where, f"start.{path}", v) for path, v in _flatten(table.get("start", {})).items()} \
        if isinstance(table.get("start", {}), Mapping) else None
    if start is None:
        raise StudiesError(f"[{where}] start: expected a table of parameter paths and values, got {table['start']!r}")
    constraints = table.get("constraints", {})
    constraints_from_table(where, constraints)
    method = table.get("method", "local")
    if method not in METHODS:
        raise StudiesError(f"[{where}] method: expected one of {', '.join(map(repr, METHODS))}, got {method!r}")
    tol = number(where, "tol", table.get("tol", TOL), positive=True)
    if tol >= 1.0:
        raise StudiesError(f"[{where}] tol: expected a relative tolerance below 1, got {tol!r}")
    return {"objective": table["objective"], "bounds": bounds, "speeds": speeds, "start": start,
            "constraints": dict(constraints), "method": method,
            "n_steps": steps(where, table, n_steps, minimum=MIN_STEPS), "tol": tol,
            "max_evaluations": None if "max_evaluations" not in table else integer(
                where, "max_evaluations", table["max_evaluations"], 2, maximum=MAX_EVALUATIONS,
                why=EVALUATIONS_WHY),
            "map_points": integer(where, "map_points", table.get("map_points", 0), 0, maximum=100,
                                  why="values per axis of the figure's map, each a sweep"),
            "check": boolean(where, "check", table.get("check", True)),
            "check_periods": integer(where, "check_periods", table.get("check_periods", 5), 2,
                                     maximum=MAX_PERIODS, why=PERIODS_WHY),
            "seed": integer(where, "seed", table.get("seed", 0), 0),
            # the [studies] error_tolerance where the table does not set its own (studies.cli._scene)
            **({"error_tolerance": check_tolerance(table["error_tolerance"], f"[{where}] error_tolerance")}
               if "error_tolerance" in table else {})}


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> OptimizeResult:
    return optimize(problem, options["bounds"], **{k: v for k, v in options.items() if k != "bounds"})


def _summary(result: OptimizeResult) -> str:
    found = ", ".join(f"{name} = {plain(value, 4)}" for name, value in result.values.items())
    check = f"; nonlinear check {result.check_verdict.upper()}" if result.check_verdict else ""
    words = f"{headline(result.status)}: {result.message}" if result.message else headline(result.status)
    return (f"{words}\n    {result.objective} {plain(result.objective_start, 3)} -> "
            f"{plain(result.objective_value, 3)} {result.objective_unit} at {found}; {result.n_evaluations} "
            f"evaluations{check}; {result.run_time:.3g} s")


def _headlines(result: OptimizeResult) -> Summary:
    at = f"at speed {plain(result.worst_speed, 3)} rad/s" if math.isfinite(result.worst_speed) else ""
    at += result._dominant_words()
    rows = [Headline(f"{result.objective} at the optimum (worst speed)", result.objective_value,
                     result.objective_unit, result.objective_error, at.strip()),
            Headline(f"{result.objective} at the start", result.objective_start, result.objective_unit)]
    rows += [Headline(f"optimum {name}", float(value), result.parameter_units[name])
             for name, value in zip(result.names, result.x)]
    units = {"stability": "1", "torque": "N m", "mass": "kg", "frequency": "1"}
    words = {"stability": "largest spectral radius", "torque": "largest peak drive torque",
             "mass": "links' mass", "frequency": "least distance of a frozen band from k x speed / (k x speed)"}
    for name, value in result.constraint_values.items():
        kind, _, joints = name.partition("@")   # a torque limit on some drives: "torque@O+A"
        rows.append(Headline(words[kind] + (f" at {joints.replace('+', ', ')}" if joints else ""), float(value),
                             units[kind], where=f"(limit {plain(result.constraint_limits[name], 3)})"))
    if result.check_verdict:
        rows.append(Headline(f"{result.objective}, nonlinear run at the optimum", result.check_objective,
                             result.objective_unit, where=f"({result.check_verdict.replace('_', ' ')})"))
    rows.append(Headline("evaluations", float(result.n_evaluations)))
    return Summary(status=headline(result.status), run_time=result.run_time, rows=rows)


def _varies(options: Mapping[str, Any]) -> tuple[str, ...]:
    return tuple(options["bounds"])


def _cost(name, problem, options, workers):
    """At most ``max_evaluations`` sweeps over the speeds, each a linearisation and a periodic solve
    per speed (an upper bound: a speed family makes the linearisations cheaper), the map's sweeps, the
    steady state with its error budget and the nonlinear check at the optimum."""
    from .nonlinear_check import nonlinear_check_cost

    bounds = options["bounds"]
    axes = [(path, np.array(pair, dtype=float)) for path, pair in bounds.items()]
    sizes = cost.largest_sizes(problem, axes)
    speeds = 1 if options["speeds"] is None else len(options["speeds"])
    evaluations = options["max_evaluations"] or default_evaluations(options["method"], len(bounds))
    sweeps = evaluations + (options["map_points"] ** 2 if len(bounds) >= 2 else 0)
    build_bytes, build_seconds = cost.linearisation(options["n_steps"], sizes)
    frozen = 32 if "frequency_separation" in options["constraints"] else 0
    solve = cost.solve_seconds(options["n_steps"], sizes, frozen)
    seconds = cost.STUDY_SECONDS + sweeps * speeds * (build_seconds + solve)
    memory = cost.FAMILY_DOUBLES / cost.LINEARISATION_DOUBLES * build_bytes
    budget = cost.steady_solves(name, problem, [{}], options["n_steps"], budget=True)   # at the optimum
    seconds, memory = seconds + budget.time, max(memory, budget.memory)
    if options["check"]:
        check = nonlinear_check_cost(name, problem, {"values": {}, "n_steps": options["n_steps"],
                                                     "n_periods": options["check_periods"], "from_rest": False,
                                                     "max_periods_from_rest": 0}, workers)
        seconds, memory = seconds + check.time, max(memory, check.memory)
    return cost.Estimate(name, memory, seconds, f"at most {sweeps} evaluations x {speeds} speeds x "
                                                f"{options['n_steps']} steps x {sizes.m} coordinates")


def _validate(problem: Any, options: Mapping[str, Any]) -> None:
    """Before any study is written: the bounds are continuous parameters of the problem."""
    try:
        names, _ = _check_bounds(problem, options["bounds"])
        _with_needs(problem, list(names), [])
    except StudiesError as error:
        raise StudiesError(f"[studies.optimize] {error}") from None


KIND = register_kind(StudyKind(
    name="optimize", result=OptimizeResult, keys=TABLE_KEYS, check=_check, run=_run, summary=_summary,
    varies=_varies, headlines=_headlines, cost=_cost, validate=_validate,
    demo={"objective": "rms:x", "bounds": {"natural_frequency": [1.2, 2.0]}, "speeds": [1.0, 2.0],
          "constraints": {"stability_margin": 0.01}, "n_steps": 64},
    aliases=("OptimizeResult",)))
