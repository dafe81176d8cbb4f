"""``[studies.optimize]``: scene parameters (design values, controller gains) that minimise a measure
of the steady vibration, the worst over an operating range of speeds, under constraints; the optimum
checked by a nonlinear run.

Each evaluation is a sweep over ``speeds`` at one set of parameter values (``problem.linearize`` with
``context=False``: a mechanism with a constant-rate prescribed drive reuses one speed family per
parameter set). The local method minimises the worst value in epigraph form (minimise ``t`` subject
to ``t >= m_i(x)`` at every speed ``i``: smooth pieces instead of the kinked ``max``) with scipy's
SLSQP and forward-difference gradients of the whole sweep; the global method runs scipy's
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

from .._kind import StudyKind, register_kind
from .._mechanism import COUNT_KEYS
from .._numerics import frozen_modes, peak_summary, solve_steady
from .._plots import Plot, axes_for, cost_line, drawn, headline, label, plain
from .._toolkit import (
    HARMONIC_WHY,
    MAX_AXIS_POINTS,
    MAX_HARMONIC,
    MAX_PERIODS,
    PERIODS_WHY,
    SPEED,
    Headline,
    Result,
    StudiesError,
    Summary,
    axis,
    boolean,
    check_integer,
    check_n_steps,
    check_parameter,
    combine,
    cost,
    fraction,
    integer,
    is_numerical_failure,
    number,
    reject_unknown,
    steps,
)

#: The fewest steps per period an optimisation accepts (its steady states' error check uses N/4).
MIN_STEPS = 16
#: The measures an objective may name, ``"<measure>:<observable spec>"``.
MEASURES = ("peak_to_peak", "peak", "rms")
METHODS = ("local", "global")
#: Default relative tolerance of the objective (SLSQP's ``ftol`` on the objective scaled by its start value).
TOL = 1e-8
#: Forward-difference step of the gradients, in the scaled parameters (bounds mapped to [0, 1]).
FD_STEP = 1e-6
#: A constraint (scaled by its limit) counts as met down to this violation.
FEASIBILITY_TOL = 1e-6
#: Most sweeps (evaluations) an optimisation may do (docs/studies.md, "Limits").
MAX_EVALUATIONS = 100_000
EVALUATIONS_WHY = "evaluations, each a steady state at every speed"
#: Frozen-time samples per period of the frequency-separation constraint.
FROZEN_SAMPLES = 32
#: Scene keys that change the number of coordinates: not continuous design parameters.
#: Keys of the ``constraints`` table.
CONSTRAINT_KEYS = ("stability_margin", "torque_limit", "mass_budget", "frequency_separation", "max_harmonic")
TABLE_KEYS = ("objective", "bounds", "speeds", "start", "constraints", "method", "n_steps", "tol",
              "max_evaluations", "map_points", "check", "check_periods", "seed")


# ---------------------------------------------------------------------------------------------------
# constraints
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class StabilityMargin:
    """Spectral radius at most ``1 - margin`` at every speed (``margin`` in [0, 1))."""

    margin: float = 0.0
    name = "stability"

    def limit(self) -> float:
        return 1.0 - self.margin


@dataclass(frozen=True)
class TorqueLimit:
    """Peak total drive torque (N m) at most ``limit`` at every speed, for the drives at ``joints``
    (None: every drive of the mechanism). Several limits on different sets of drives may be given;
    each is named ``"torque"`` (every drive) or ``"torque@<joint>+<joint>..."``."""

    limit: float
    joints: tuple[str, ...] | None = None

    @property
    def name(self) -> str:
        return "torque" if self.joints is None else "torque@" + "+".join(self.joints)


@dataclass(frozen=True)
class MassBudget:
    """Sum of the links' masses (``density * area * length`` for elastic links; kg) at most ``budget``."""

    budget: float
    name = "mass"


@dataclass(frozen=True)
class FrequencySeparation:
    """Every frozen-time natural frequency band (over the crank angle) at least ``fraction * k *
    speed`` away from ``k * speed`` for k = 1 .. ``max_harmonic``, at every speed."""

    fraction: float
    max_harmonic: int = 4
    name = "frequency"


CONSTRAINT_TYPES = (StabilityMargin, TorqueLimit, MassBudget, FrequencySeparation)


def constraints_from_table(where: str, table: Mapping[str, Any]) -> tuple:
    """The constraint objects of a ``constraints`` table (keys ``CONSTRAINT_KEYS``)."""
    if not isinstance(table, Mapping):
        raise StudiesError(f"[{where}] constraints: expected a table with keys {', '.join(CONSTRAINT_KEYS)}, "
                           f"got {table!r}")
    reject_unknown(f"{where}.constraints", table, CONSTRAINT_KEYS)
    found: list = []
    if "stability_margin" in table:
        found.append(StabilityMargin(fraction(where, "constraints.stability_margin", table["stability_margin"])))
    if "torque_limit" in table:
        found.append(TorqueLimit(number(where, "constraints.torque_limit", table["torque_limit"], positive=True)))
    if "mass_budget" in table:
        found.append(MassBudget(number(where, "constraints.mass_budget", table["mass_budget"], positive=True)))
    if "max_harmonic" in table and "frequency_separation" not in table:
        raise StudiesError(f"[{where}] constraints.max_harmonic: only with frequency_separation")
    if "frequency_separation" in table:
        found.append(FrequencySeparation(
            fraction(where, "constraints.frequency_separation", table["frequency_separation"]),
            integer(where, "constraints.max_harmonic", table.get("max_harmonic", 4), 1,
                    maximum=MAX_HARMONIC, why=HARMONIC_WHY)))
    return tuple(found)


def _check_constraints(constraints: Any) -> tuple:
    if isinstance(constraints, Mapping):
        return constraints_from_table("optimize", constraints)
    constraints = tuple(constraints)
    for item in constraints:
        if not isinstance(item, CONSTRAINT_TYPES):
            raise StudiesError(f"constraints: expected studies.StabilityMargin, TorqueLimit, MassBudget or "
                               f"FrequencySeparation objects (or a table with keys "
                               f"{', '.join(CONSTRAINT_KEYS)}), got {item!r}")
    names = [item.name for item in constraints]
    if len(set(names)) != len(names):
        raise StudiesError(f"constraints: at most one of each kind (torque limits: one per set of joints), "
                           f"got {list(constraints)!r}")
    return constraints


# ---------------------------------------------------------------------------------------------------
# the result
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class OptimizeResult(Result):
    """The optimum of an objective over scene parameters, with the path that led there.

    ``names`` (n,) the parameter paths, ``parameter_units`` {path: unit}; ``bounds`` (n, 2), ``x``
    (n,) the optimum and ``x_start`` (n,) the start, in the parameters' units; ``objective`` the
    measure (``"peak_to_peak:coupler.deflection@0.5"``) in ``objective_unit``; ``objective_value``
    its worst value over ``speeds`` (rad/s, (n_s,)) at ``x``, at ``worst_speed``, with
    ``objective_error`` the estimated error there (``studies._numerics.peak_summary``; an RMS is
    within the response's error); ``objective_start`` at ``x_start``; ``per_speed`` (n_s,) the
    measure at each speed at ``x``; ``constraint_values`` and ``constraint_limits`` {name: value}
    at ``x`` (stability: the largest spectral radius; torque: the largest peak drive torque, N m;
    mass: the links' mass, kg; frequency: the smallest distance of a frozen band from ``k * speed``
    over ``k * speed``); ``history_x`` (n_eval, n), ``history_objective`` (n_eval,) (NaN where the
    evaluation failed), ``history_feasible`` (n_eval,) bool and ``history_worst_speed`` (n_eval,)
    every evaluation (finite-difference probes included) in order; ``path`` (n_iter,) the indices
    into the history of the optimiser's iterates; ``map_first``, ``map_second`` (k,), ``map_objective``
    (k, k) the objective on a grid of the first two parameters (``map_points > 0``; None
    otherwise, rows: first parameter); ``n_evaluations``; ``optimizer_message``.

    The nonlinear check at ``check_speed`` (the worst speed, ``studies.nonlinear_check``):
    ``check_verdict`` ("agrees", "differs", "not_periodic", "failed", or "" when not checked) and
    ``check_message``; ``check_t`` (N+1,) s, ``check_linear`` and ``check_nonlinear`` {spec:
    (N+1,)} the last period of both routes; ``check_objective`` the measure of the nonlinear run's
    last period (``check_linear_objective`` the linear one at the same speed).

    ``status`` "ok", or the worst of: the optimiser not converged ("inaccurate": stopped by
    ``max_evaluations`` or a line search that found no descent; "failed": no feasible point, or the
    optimiser failed), the steady states' verdicts at the optimum, and the nonlinear check
    ("differs": ``outside_linear_range``; "not_periodic" or "failed": ``failed``); ``message`` the
    reasons; ``run_time`` s.
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
    map_first: np.ndarray = None
    map_second: np.ndarray = None
    map_objective: np.ndarray = None
    check_verdict: str = ""
    check_message: str = ""
    check_speed: float = float("nan")
    check_t: np.ndarray = None
    check_linear: Mapping[str, np.ndarray] = field(default_factory=dict)
    check_nonlinear: Mapping[str, np.ndarray] = field(default_factory=dict)
    check_objective: float = float("nan")
    check_linear_objective: float = float("nan")
    check_units: Mapping[str, str] = field(default_factory=dict)

    _units = {"bounds": "see parameter_units", "x": "see parameter_units", "x_start": "see parameter_units",
              "history_x": "see parameter_units", "speeds": "rad/s", "per_speed": "@objective_unit",
              "history_objective": "@objective_unit", "history_feasible": "1", "history_worst_speed": "rad/s",
              "path": "1", "map_first": "see parameter_units", "map_second": "see parameter_units",
              "map_objective": "@objective_unit", "check_t": "s", "check_linear": "@check_units",
              "check_nonlinear": "@check_units"}

    def _unit(self, name: str, key: str | None = None) -> str:
        if self._units.get(name) == "@check_units":
            return dict(self.check_units).get(key, "1")
        return super()._unit(name, key)

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
        ax.legend(fontsize="x-small")
        ax.set_title(f"{self.problem}: {headline(self.status)}; {plain(self.objective_start, 3)} -> "
                     f"{plain(self.objective_value, 3)} ± {plain(self.objective_error)} {self.objective_unit} "
                     f"at {plain(self.worst_speed, 3)} rad/s\n"
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
        ax.legend(fontsize="x-small")
        return artists


# ---------------------------------------------------------------------------------------------------
# one evaluation: a sweep over the speeds at one set of parameter values
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Objective:
    measure: str
    spec: str

    @classmethod
    def parse(cls, text: Any) -> "_Objective":
        if not isinstance(text, str) or text.count(":") != 1 or text.split(":")[0] not in MEASURES \
                or not text.split(":")[1]:
            raise StudiesError(f"objective: expected '<measure>:<observable spec>' with measure one of "
                               f"{', '.join(MEASURES)} (e.g. 'peak_to_peak:coupler.deflection@0.5', "
                               f"'peak:drive.O.torque'), got {text!r}")
        measure, spec = text.split(":")
        return cls(measure, spec)

    def of(self, samples: np.ndarray, error: float) -> tuple[float, float]:
        """``(value, error)`` of the measure of a periodic signal (N+1,) whose samples are within
        ``error`` of the truth."""
        peaks = peak_summary(samples[:, None], np.array([error]))
        if self.measure == "rms":  # a norm: within the samples' error of the truth's
            return float(np.sqrt(np.mean(samples[:-1] ** 2))), float(error)
        return float(peaks[self.measure][0]), float(peaks[f"{self.measure}_error"][0])


@dataclass
class _Evaluation:
    """A sweep over the speeds at one parameter set: the measure (n_s,) and its error, each
    constraint's scaled values (n_s,) or (1,) (>= 0 where met) and its reported value, the speeds'
    verdicts; ``failed`` holds the reason when the sweep could not be computed."""

    measure: np.ndarray = None
    error: np.ndarray = None
    scaled: dict = field(default_factory=dict)
    reported: dict = field(default_factory=dict)
    verdicts: list = field(default_factory=list)
    failed: str = ""

    @property
    def worst(self) -> int:
        return int(np.nanargmax(self.measure))

    def feasible(self) -> bool:
        return not self.failed and all(np.min(v) >= -FEASIBILITY_TOL for v in self.scaled.values())


def _drive_joints(problem: Any, constraint: TorqueLimit) -> tuple[str, ...]:
    if not hasattr(problem, "mechanism"):
        raise StudiesError(f"constraints: a torque limit needs a mechanism problem; problem {problem.name!r} "
                           f"has no drives")
    joints = tuple(drive.joint for drive in problem.mechanism().drives)
    chosen = constraint.joints if constraint.joints is not None else joints
    unknown = [joint for joint in chosen if joint not in joints]
    if unknown:
        raise StudiesError(f"constraints: torque limit on joint {unknown[0]!r}, which has no drive "
                           f"(drives at {', '.join(joints)})")
    return tuple(chosen)


def _links_mass(problem: Any, values: Mapping[str, float]) -> float:
    """Sum of the links' masses (kg) of the mechanism at ``values`` (the mechanism knows each:
    ``density * area * length`` of an elastic link, the given or uniform-bar mass of a rigid one)."""
    mechanism = problem.mechanism({k: v for k, v in values.items() if k != SPEED})
    return float(sum(link.mass for link in mechanism.links))


def _separation(system: Any, speed: float, max_harmonic: int) -> float:
    """The smallest distance of a frozen natural-frequency band (over the period) from ``k * speed``,
    k = 1 .. ``max_harmonic``, over ``k * speed`` (0 where a band holds ``k * speed``)."""
    _, frozen, _ = frozen_modes(system, FROZEN_SAMPLES)
    low, high = frozen.min(axis=0), frozen.max(axis=0)
    harmonics = speed * np.arange(1, max_harmonic + 1)[:, None]
    distance = np.maximum(np.maximum(low[None, :] - harmonics, harmonics - high[None, :]), 0.0)
    return float((distance / harmonics).min())


class _BudgetSpent(Exception):
    """Raised inside the optimiser's callbacks when ``max_evaluations`` sweeps are done."""


class _Evaluator:
    """Sweeps at scaled parameters ``u`` in [0, 1]^n, cached (the optimiser asks for the objective,
    the constraints and their gradients at the same points), with the history of every sweep."""

    def __init__(self, problem, names, bounds, speeds, objective, constraints, n_steps, max_evaluations):
        self.problem, self.names, self.bounds = problem, names, bounds
        self.speeds, self.objective, self.constraints = speeds, objective, constraints
        self.n_steps, self.max_evaluations = n_steps, max_evaluations
        self.cache: dict[bytes, _Evaluation] = {}
        self.history: list[tuple[np.ndarray, _Evaluation]] = []
        self.path: list[int] = []
        self.torque_specs = {c.name: tuple(f"drive.{j}.torque" for j in _drive_joints(problem, c))
                             for c in constraints if isinstance(c, TorqueLimit)}
        self.scale = 1.0

    def values(self, u: np.ndarray) -> dict[str, float]:
        x = self.bounds[:, 0] + np.clip(u, 0.0, 1.0) * (self.bounds[:, 1] - self.bounds[:, 0])
        return {name: float(value) for name, value in zip(self.names, x)}

    def __call__(self, u: np.ndarray) -> _Evaluation:
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        key = u.tobytes()
        if key not in self.cache:
            if len(self.history) >= self.max_evaluations:
                raise _BudgetSpent()
            self.cache[key] = found = self._sweep(self.values(u))
            self.history.append((u.copy(), found))
        return self.cache[key]

    def _sweep(self, values: dict[str, float]) -> _Evaluation:
        n_s = self.speeds.size
        found = _Evaluation(measure=np.empty(n_s), error=np.empty(n_s))
        radius, separation = np.empty(n_s), np.empty(n_s)
        torque = {name: np.zeros(n_s) for name in self.torque_specs}   # each torque limit's own drives
        speeds_given = not np.isnan(self.speeds).all()
        try:
            for i, speed in enumerate(self.speeds):
                at = dict(values) if np.isnan(speed) else dict(values, **{SPEED: float(speed)})
                linear = self.problem.linearize(at, n_steps=self.n_steps, context=False)
                steady = solve_steady(linear)
                k = linear.observables.index(self.objective.spec)
                found.measure[i], found.error[i] = self.objective.of(steady.response[:, k],
                                                                     steady.response_error[k])
                where = f"at {speed:.4g} rad/s: " if speeds_given else ""
                found.verdicts.append((steady.status, where + steady.message if steady.message else ""))
                radius[i] = steady.state.spectral_radius
                for name, specs in self.torque_specs.items():
                    rows = [linear.observables.index(spec) for spec in specs]
                    torque[name][i] = max(peak_summary(steady.response[:, rows], steady.response_error[rows])["peak"])
                for constraint in self.constraints:
                    if isinstance(constraint, FrequencySeparation):
                        separation[i] = _separation(linear.system, 2.0 * math.pi / linear.system.period,
                                                    constraint.max_harmonic)
            for constraint in self.constraints:
                if isinstance(constraint, StabilityMargin):
                    found.scaled[constraint.name] = constraint.limit() - radius
                    found.reported[constraint.name] = float(radius.max())
                elif isinstance(constraint, TorqueLimit):
                    found.scaled[constraint.name] = 1.0 - torque[constraint.name] / constraint.limit
                    found.reported[constraint.name] = float(torque[constraint.name].max())
                elif isinstance(constraint, MassBudget):
                    mass = _links_mass(self.problem, values)
                    found.scaled[constraint.name] = np.array([1.0 - mass / constraint.budget])
                    found.reported[constraint.name] = mass
                else:
                    found.scaled[constraint.name] = separation - constraint.fraction
                    found.reported[constraint.name] = float(separation.min())
        except Exception as error:
            if not is_numerical_failure(error):
                raise
            found.failed = f"{type(error).__name__}: {error}"
        return found

    # --- what the optimisers see --------------------------------------------------------------
    def worst(self, u: np.ndarray) -> float:
        """The scaled worst measure over the speeds (a failed sweep: a value above every other)."""
        found = self(u)
        return self._penalty() if found.failed else float(found.measure.max()) / self.scale

    def _penalty(self) -> float:
        finite = [f.measure.max() for _, f in self.history if not f.failed]
        return 10.0 * (max(finite) / self.scale if finite else 1.0) + 1.0

    def constraint_vector(self, u: np.ndarray) -> np.ndarray:
        found = self(u)
        if found.failed:
            return -np.ones(sum(np.size(v) for v in self._shape().values()))
        return np.concatenate([np.atleast_1d(v) for v in found.scaled.values()]) if found.scaled else np.empty(0)

    def _shape(self) -> dict:
        return next((f.scaled for _, f in self.history if not f.failed), {})

    def measures(self, u: np.ndarray) -> np.ndarray:
        found = self(u)
        return np.full(self.speeds.size, self._penalty()) if found.failed else found.measure / self.scale

    def jacobian(self, function, u: np.ndarray) -> np.ndarray:
        """Forward differences of ``function`` (u -> (k,)) at ``u``, backward at the upper bound."""
        base = np.atleast_1d(function(u))
        columns = []
        for j in range(u.size):
            step = FD_STEP if u[j] + FD_STEP <= 1.0 else -FD_STEP
            probe = u.copy()
            probe[j] += step
            columns.append((np.atleast_1d(function(probe)) - base) / step)
        return np.array(columns).T.reshape(base.size, u.size)

    def mark_iterate(self, u: np.ndarray) -> None:
        key = np.clip(np.asarray(u, dtype=float), 0.0, 1.0).tobytes()
        for index in range(len(self.history) - 1, -1, -1):
            if self.history[index][0].tobytes() == key:
                if not self.path or self.path[-1] != index:
                    self.path.append(index)
                return


# ---------------------------------------------------------------------------------------------------
# the optimisers
# ---------------------------------------------------------------------------------------------------
def _local(evaluator: _Evaluator, u0: np.ndarray, tol: float) -> tuple[str, str]:
    """SLSQP on the epigraph: minimise t over (u, t) with t >= measure_i(u) at every speed and the
    constraints >= 0. Returns ``(status, message)`` of the optimiser."""
    from scipy.optimize import minimize

    n = u0.size
    t0 = float(evaluator.measures(u0).max())
    evaluator.mark_iterate(u0)

    def epigraph(v):
        return v[n] - evaluator.measures(v[:n])

    def epigraph_jacobian(v):
        return np.hstack([-evaluator.jacobian(evaluator.measures, v[:n]), np.ones((evaluator.speeds.size, 1))])

    constraints = [{"type": "ineq", "fun": epigraph, "jac": epigraph_jacobian}]
    if evaluator.constraints:
        constraints.append({"type": "ineq", "fun": lambda v: evaluator.constraint_vector(v[:n]),
                            "jac": lambda v: np.hstack([evaluator.jacobian(evaluator.constraint_vector, v[:n]),
                                                        np.zeros((evaluator.constraint_vector(v[:n]).size, 1))])})
    objective_gradient = np.zeros(n + 1)
    objective_gradient[n] = 1.0
    try:
        found = minimize(lambda v: v[n], np.append(u0, t0), jac=lambda v: objective_gradient, method="SLSQP",
                         bounds=[(0.0, 1.0)] * n + [(None, None)], constraints=constraints,
                         callback=lambda v: evaluator.mark_iterate(v[:n]),
                         options={"ftol": tol, "maxiter": 10 * evaluator.max_evaluations})
    except _BudgetSpent:
        return "inaccurate", (f"the optimiser stopped after max_evaluations = {evaluator.max_evaluations} "
                              f"evaluations before converging; raise max_evaluations or loosen tol")
    evaluator.mark_iterate(found.x[:n])
    if found.success:
        return "ok", f"SLSQP converged: {found.message}"
    if found.status in (8, 9):  # no descent direction in the line search; iteration limit
        return "inaccurate", (f"SLSQP stopped before converging: {found.message} (typically the "
                              f"objective's numerical noise at the tolerance asked: loosen tol = {tol:g})")
    return "failed", f"SLSQP failed: {found.message}"


def _global(evaluator: _Evaluator, u0: np.ndarray, tol: float, seed: int) -> tuple[str, str]:
    """Differential evolution over the box (constraints as scipy ``NonlinearConstraint``), then the
    local method from its best point."""
    from scipy.optimize import NonlinearConstraint, differential_evolution

    n = u0.size
    evaluator.mark_iterate(u0)
    constraints = ()
    if evaluator.constraints:
        constraints = (NonlinearConstraint(evaluator.constraint_vector, 0.0, np.inf),)
    try:
        found = differential_evolution(evaluator.worst, [(0.0, 1.0)] * n, constraints=constraints, tol=tol,
                                       seed=seed, polish=False, x0=u0, init="sobol",
                                       callback=lambda xk, convergence=None: evaluator.mark_iterate(xk),
                                       maxiter=max(1, evaluator.max_evaluations // (15 * n)))
        words = f"differential evolution: {found.message}"
        start = found.x
    except _BudgetSpent:
        words = f"differential evolution stopped after max_evaluations = {evaluator.max_evaluations} evaluations"
        start = _best(evaluator)[0]
    evaluator.mark_iterate(start)
    evaluator.max_evaluations += max(50, 20 * n)  # the polish's own budget
    status, message = _local(evaluator, start, tol)
    return status, f"{words}; polished: {message}"


def _best(evaluator: _Evaluator) -> tuple[np.ndarray, _Evaluation]:
    """The evaluated point of least worst measure among those meeting every constraint (None's
    evaluation when none does)."""
    feasible = [(u, f) for u, f in evaluator.history if f.feasible()]
    if not feasible:
        return None, None
    return min(feasible, key=lambda item: float(item[1].measure.max()))


# ---------------------------------------------------------------------------------------------------
# the study
# ---------------------------------------------------------------------------------------------------
def default_evaluations(method: str, n: int) -> int:
    """The default ``max_evaluations`` for ``n`` parameters: a local method's iterations each take
    n + 1 sweeps (the point and its forward differences), a global one's generations 15 n."""
    return 40 + 40 * n if method == "local" else 300 * n


def _check_bounds(problem: Any, bounds: Any) -> tuple[tuple[str, ...], np.ndarray]:
    if not isinstance(bounds, Mapping) or not bounds:
        raise StudiesError(f"bounds: expected a mapping of parameter paths to (low, high), e.g. "
                           f"{{'links.coupler.thickness': (1e-3, 3e-3)}}, got {bounds!r}")
    names, rows = [], []
    for name, pair in bounds.items():
        if not isinstance(name, str):
            raise StudiesError(f"bounds: expected parameter paths (str) as keys, got {name!r}")
        if name.split(".")[-1] in COUNT_KEYS:
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
             check_periods: int = 5, seed: int = 0) -> OptimizeResult:
    """Minimise ``objective`` over the parameters of ``bounds`` ({path: (low, high)}: scene paths
    such as ``"links.coupler.thickness"`` or ``"drive.kp"``, or a ``PeriodicProblem``'s parameters).

    ``objective``: ``"<measure>:<observable spec>"``, measure ``peak_to_peak``, ``peak`` (largest
    magnitude: peak stress, peak drive torque ``drive.<J>.torque``) or ``rms`` over one period of
    the steady state; with ``speeds`` (rad/s) its worst value over them, else at the problem's speed.
    ``constraints``: :class:`StabilityMargin`, :class:`TorqueLimit`, :class:`MassBudget`,
    :class:`FrequencySeparation` objects, or a table with keys ``stability_margin``,
    ``torque_limit``, ``mass_budget``, ``frequency_separation``, ``max_harmonic``; each holds at
    every speed. ``method``: "local" (SLSQP on the epigraph of the worst value, forward-difference
    gradients) or "global" (differential evolution, then the local method). ``start``: the start
    values (default: the problem's values, clipped into the bounds); ``tol``: relative tolerance of
    the objective; ``max_evaluations``: most sweeps (default 40 + 40 n local, 300 n global);
    ``map_points``: a grid of this many values per axis of the first two parameters for the figure
    (0: none); ``check``: the nonlinear check at the worst speed of the optimum with
    ``check_periods`` periods (where the problem has a nonlinear model); ``seed`` of the global
    method. See :class:`OptimizeResult`."""
    started = time.perf_counter()
    goal = _Objective.parse(objective)
    names, box = _check_bounds(problem, bounds)
    if method not in METHODS:
        raise StudiesError(f"method: expected one of {', '.join(map(repr, METHODS))}, got {method!r}")
    if speeds is not None and SPEED in names:
        raise StudiesError("bounds: 'speed' is the operating range given by speeds; optimise it only without speeds")
    chosen = _check_constraints(constraints)
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="an optimisation")
    if not (isinstance(tol, (int, float)) and 0.0 < tol < 1.0):
        raise StudiesError(f"tol: expected a relative tolerance in (0, 1), got {tol!r}")
    n = len(names)
    if max_evaluations is None:
        max_evaluations = default_evaluations(method, n)
    check_integer("max_evaluations", max_evaluations, 2)
    check_integer("map_points", map_points, 0)
    check_integer("check_periods", check_periods, 2)
    needs = [goal.spec] + [f"drive.{j}.torque" for c in chosen if isinstance(c, TorqueLimit)
                           for j in _drive_joints(problem, c)]
    problem = _with_needs(problem, names, needs)
    if any(isinstance(c, MassBudget) for c in chosen) and not hasattr(problem, "mechanism"):
        raise StudiesError(f"constraints: a mass budget needs a mechanism problem; problem {problem.name!r} "
                           f"has no links")
    grid = np.array([np.nan]) if speeds is None else np.asarray(speeds, dtype=float).reshape(-1)
    if speeds is not None and (grid.size == 0 or not np.isfinite(grid).all() or (grid <= 0).any()):
        raise StudiesError(f"speeds: expected a non-empty sequence of positive crank speeds (rad/s), got {speeds!r}")
    nominal = problem.resolve(start)
    x_start = np.clip([nominal[name] for name in names], box[:, 0], box[:, 1])
    u_start = (x_start - box[:, 0]) / (box[:, 1] - box[:, 0])
    evaluator = _Evaluator(problem, names, box, grid, goal, chosen, n_steps, max_evaluations)
    first = evaluator(u_start)
    if first.failed:
        raise StudiesError(f"the start {evaluator.values(u_start)} cannot be evaluated ({first.failed}); "
                           f"choose another start or bounds")
    evaluator.scale = max(float(np.abs(first.measure).max()), np.finfo(float).tiny)
    if method == "local":
        optimiser_status, optimiser_message = _local(evaluator, u_start, tol)
    else:
        optimiser_status, optimiser_message = _global(evaluator, u_start, tol, seed)
    u_best, best = _best(evaluator)
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
    checked = _nonlinear_check(problem, values, worst_speed, goal, n_steps, check_periods) if check else {}
    if checked.get("check_verdict") in ("differs",):
        verdicts.append(("outside_linear_range", f"the nonlinear check at the optimum differs: "
                                                 f"{checked['check_message']}"))
    elif checked.get("check_verdict") in ("not_periodic", "failed"):
        verdicts.append(("failed", f"the nonlinear check at the optimum: {checked['check_verdict']}: "
                                   f"{checked['check_message']}"))
    mapped = _map(evaluator, map_points) if map_points and n >= 2 else {}
    status, message = combine(verdicts)
    history_x = np.array([evaluator.values(u)[name] for u, _ in evaluator.history for name in names]).reshape(-1, n)
    return OptimizeResult(
        problem=problem.name, scene=problem.text,
        settings={"objective": objective, "bounds": {k: list(v) for k, v in zip(names, box)},
                  "speeds": None if speeds is None else grid, "constraints": [_describe(c) for c in chosen],
                  "method": method, "n_steps": n_steps, "tol": tol, "max_evaluations": max_evaluations,
                  "map_points": map_points, "check": check, "check_periods": check_periods, "seed": seed,
                  "start": {k: float(v) for k, v in zip(names, x_start)}},
        names=names, parameter_units={name: problem.units[name] for name in names}, bounds=box,
        x=np.array([values[name] for name in names]), x_start=x_start, objective=objective,
        objective_unit=dict(zip(problem.describe().observables, problem.describe().units))[goal.spec],
        objective_value=float(best.measure[worst]) if not best.failed else float("nan"),
        objective_error=float(best.error[worst]) if not best.failed else float("nan"),
        objective_start=float(first.measure.max()), worst_speed=worst_speed,
        speeds=grid, per_speed=best.measure if not best.failed else np.full(grid.shape, np.nan),
        constraint_values=dict(best.reported),
        constraint_limits={c.name: _limit(c) for c in chosen},
        history_x=history_x,
        history_objective=np.array([np.nan if f.failed else float(f.measure.max()) for _, f in evaluator.history]),
        history_feasible=np.array([f.feasible() for _, f in evaluator.history], dtype=bool),
        history_worst_speed=np.array([np.nan if f.failed or speeds is None else float(grid[f.worst])
                                      for _, f in evaluator.history]),
        path=np.array(evaluator.path, dtype=np.int64), n_evaluations=len(evaluator.history),
        optimizer_message=optimiser_message, status=status, message=message,
        run_time=time.perf_counter() - started, **mapped, **checked)


def _limit(constraint: Any) -> float:
    if isinstance(constraint, StabilityMargin):
        return constraint.limit()
    if isinstance(constraint, TorqueLimit):
        return constraint.limit
    if isinstance(constraint, MassBudget):
        return constraint.budget
    return constraint.fraction


def _describe(constraint: Any) -> dict[str, Any]:
    return {"kind": type(constraint).__name__, **{k: getattr(constraint, k) for k in constraint.__dataclass_fields__}}


def _map(evaluator: _Evaluator, points: int) -> dict[str, np.ndarray]:
    """The worst measure on a ``points`` x ``points`` grid of the first two parameters (the others
    at the optimum), for the figure; not part of the history."""
    u_best = _best(evaluator)[0]
    u_best = evaluator.history[0][0] if u_best is None else u_best
    axis_values = np.linspace(0.0, 1.0, points)
    table = np.full((points, points), np.nan)
    for i, a in enumerate(axis_values):
        for j, b in enumerate(axis_values):
            u = u_best.copy()
            u[0], u[1] = a, b
            found = evaluator._sweep(evaluator.values(u))
            table[i, j] = np.nan if found.failed else float(found.measure.max())
    box = evaluator.bounds
    return {"map_first": box[0, 0] + axis_values * (box[0, 1] - box[0, 0]),
            "map_second": box[1, 0] + axis_values * (box[1, 1] - box[1, 0]), "map_objective": table}


def _nonlinear_check(problem, values, speed, goal, n_steps, n_periods) -> dict[str, Any]:
    """The nonlinear check of the optimum at ``speed``: its verdict, last periods and the measure of
    both routes there."""
    from .nonlinear_check import nonlinear_check

    if not getattr(problem, "supports_nonlinear", False):
        return {"check_verdict": "", "check_message": f"problem {problem.name!r} has no nonlinear model: not checked"}
    at = dict(values, **{SPEED: speed}) if math.isfinite(speed) else dict(values)
    try:  # against the nonlinear periodic state: no start-up transient left in the compared period
        found = nonlinear_check(problem, at, n_steps=n_steps, n_periods=n_periods, periodic_state=True)
    except (ValueError, RuntimeError):  # e.g. a magnitude observable the shooting cannot report
        found = nonlinear_check(problem, at, n_steps=n_steps, n_periods=n_periods)
    out = {"check_verdict": found.verdict, "check_message": found.message, "check_speed": speed,
           "check_t": found.t_linear, "check_linear": dict(found.linear), "check_units": dict(found.units)}
    if found.nonlinear:
        last = {spec: samples[-(n_steps + 1):] for spec, samples in found.nonlinear.items()}
        out["check_nonlinear"] = last
        out["check_objective"] = goal.of(last[goal.spec], found.nonlinear_error.get(goal.spec, 0.0))[0]
    out["check_linear_objective"] = goal.of(found.linear[goal.spec], found.linear_error[goal.spec])[0]
    return out


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
    _Objective.parse(table["objective"])
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
            "seed": integer(where, "seed", table.get("seed", 0), 0)}


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
    rows = [Headline(f"{result.objective} at the optimum (worst speed)", result.objective_value,
                     result.objective_unit, result.objective_error, at),
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
    """At most ``max_evaluations`` sweeps over the speeds, each a cost.linearisation and a periodic solve
    per speed (an upper bound: a speed family makes the linearisations cheaper), the map's sweeps and
    the nonlinear check at the optimum."""
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
    if options["check"]:
        check = nonlinear_check_cost(name, problem, {"values": {}, "n_steps": options["n_steps"],
                                                     "n_periods": options["check_periods"], "from_rest": False,
                                                     "max_periods_from_rest": 0}, workers)
        seconds, memory = seconds + check.time, max(memory, check.memory)
    return cost.Estimate(name, memory, seconds, f"at most {sweeps} evaluations x {speeds} speeds x "
                                                f"{options['n_steps']} steps x {sizes.m} coordinates")


KIND = register_kind(StudyKind(
    name="optimize", result=OptimizeResult, keys=TABLE_KEYS, check=_check, run=_run, summary=_summary,
    varies=_varies, headlines=_headlines, cost=_cost,
    demo={"objective": "rms:x", "bounds": {"natural_frequency": [1.2, 2.0]}, "speeds": [1.0, 2.0],
          "constraints": {"stability_margin": 0.01}, "n_steps": 64},
    aliases=("OptimizeResult",)))
