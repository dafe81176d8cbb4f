"""The search of ``studies.optimize``: the objective, one evaluation (a sweep over the speeds at one
set of parameter values, cached, with the history of every sweep) and the optimisers driving it
(SLSQP on the epigraph of the worst value; differential evolution polished by it).

Gradients of the local method: the sensitivities of each speed's steady state (``studies._derivatives``:
direct differentiation of the periodic problem, reusing the sweep's own linearisation and shooting) where
the objective and every constraint offer them (a constraint's ``gradient_at_speed`` and
``judged_gradient``), else forward differences of whole sweeps (``FD_STEP``); ``Evaluator.gradient_words``
says which.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._derivatives import headline_derivatives, point_derivatives
from .._errors import StudiesError, is_numerical_failure
from .._numerics import DEFAULT_SCHEME, peak_summary, solve_steady
from .._problem import SPEED

#: The measures an objective may name, ``"<measure>:<observable spec>"``.
MEASURES = ("peak_to_peak", "peak", "rms")
#: Forward-difference step of the gradients, in the scaled parameters (bounds mapped to [0, 1]).
FD_STEP = 1e-6
#: A constraint (scaled by its limit) counts as met down to this violation.
FEASIBILITY_TOL = 1e-6
#: The sweeps whose linearisations and steady states are kept for their gradients (SLSQP asks for the
#: gradient at the point it has just evaluated).
KEPT_POINTS = 3


@dataclass(frozen=True)
class Objective:
    measure: str
    spec: str

    @classmethod
    def parse(cls, text: Any) -> "Objective":
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

    def gradient(self, samples: np.ndarray, derivative: np.ndarray) -> np.ndarray:
        """d measure / d p (P,) of the periodic signal (N+1,) with derivatives (P, N+1), by the envelope rule."""
        found, _ = headline_derivatives(samples[:, None], derivative[:, :, None])
        return found[self.measure][:, 0]


@dataclass
class Evaluation:
    """A sweep over the speeds at one parameter set: the measure (n_s,) and its error, each
    constraint's scaled values (n_s,) or (1,) (>= 0 where met) and its reported value, the speeds'
    verdicts, ``peaks`` {name: {spec: (n_s,)}} the observables' summaries (``studies._result``);
    ``failed`` holds the reason when the sweep could not be computed."""

    measure: np.ndarray | None = None
    error: np.ndarray | None = None
    scaled: dict = field(default_factory=dict)
    reported: dict = field(default_factory=dict)
    verdicts: list = field(default_factory=list)
    failed: str = ""
    peaks: dict = field(default_factory=dict)
    #: per speed (linear, steady) while the gradient may still be asked for (dropped after)
    points: list = field(default_factory=list)
    #: d measure / d u (n_s, P) and each constraint's d scaled / d u, once computed
    gradient: np.ndarray | None = None
    constraint_gradients: dict | None = None

    @property
    def worst(self) -> int:
        return int(np.nanargmax(self.measure))

    def feasible(self) -> bool:
        return not self.failed and all(np.min(v) >= -FEASIBILITY_TOL for v in self.scaled.values())



class BudgetSpent(Exception):
    """Raised inside the optimiser's callbacks when ``max_evaluations`` sweeps are done."""


class Evaluator:
    """Sweeps at scaled parameters ``u`` in [0, 1]^n, cached (the optimiser asks for the objective,
    the constraints and their gradients at the same points), with the history of every sweep."""

    def __init__(self, problem, names, bounds, speeds, objective, constraints, n_steps, max_evaluations):
        self.problem, self.names, self.bounds = problem, names, bounds
        self.speeds, self.objective, self.constraints = speeds, objective, constraints
        self.n_steps, self.max_evaluations = n_steps, max_evaluations
        self.cache: dict[bytes, Evaluation] = {}
        self.history: list[tuple[np.ndarray, Evaluation]] = []
        self.path: list[int] = []
        #: the observables each constraint reads, by its name
        self.specs = {constraint.name: constraint.needs(problem) for constraint in constraints}
        self.scale = 1.0
        #: the sensitivities' gradients in the local method (False: forward differences of sweeps)
        self.gradients = False
        self.gradient_evaluations = 0
        self.fallbacks = 0
        lacking = [c.name for c in constraints if not hasattr(c, "judged_gradient")]
        self.gradient_words = ("forward differences of whole sweeps (constraints without gradients: "
                               f"{', '.join(lacking)})") if lacking else "sensitivities (direct differentiation)"
        self.can_differentiate = not lacking
        #: {parameter: whether it leaves the kinematics alone}, decided at the first point
        self.forward: dict = {}
        self.needs_radius = any(getattr(c, "needs_radius", False) for c in constraints)

    def values(self, u: np.ndarray) -> dict[str, float]:
        x = self.bounds[:, 0] + np.clip(u, 0.0, 1.0) * (self.bounds[:, 1] - self.bounds[:, 0])
        return {name: float(value) for name, value in zip(self.names, x)}

    def __call__(self, u: np.ndarray) -> Evaluation:
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        key = u.tobytes()
        if key not in self.cache:
            if len(self.history) >= self.max_evaluations:
                raise BudgetSpent()
            self.cache[key] = found = self._sweep(self.values(u))
            self.history.append((u.copy(), found))
            if len(self.history) > KEPT_POINTS:   # keep the linearisations of the last few sweeps only
                self.history[-1 - KEPT_POINTS][1].points = []
        return self.cache[key]

    def _sweep(self, values: dict[str, float]) -> Evaluation:
        n_s = self.speeds.size
        found = Evaluation(measure=np.empty(n_s), error=np.empty(n_s))
        per_speed = {constraint.name: np.empty(n_s) for constraint in self.constraints}
        speeds_given = not np.isnan(self.speeds).all()
        try:
            for i, speed in enumerate(self.speeds):
                at = dict(values) if np.isnan(speed) else dict(values, **{SPEED: float(speed)})
                # the sensitivities need the linearisation's nominal motion (does a parameter move it?)
                linear = self.problem.linearize(at, n_steps=self.n_steps, context=self.gradients)
                steady = solve_steady(linear)
                if self.gradients:
                    found.points.append((at, linear, steady))
                k = linear.observables.index(self.objective.spec)
                found.measure[i], found.error[i] = self.objective.of(steady.response[:, k],
                                                                     steady.response_error[k])
                where = f"at {speed:.4g} rad/s: " if speeds_given else ""
                found.verdicts.append((steady.status, where + steady.message if steady.message else ""))
                for name, summary in peak_summary(steady.response, steady.response_error).items():
                    for j, spec in enumerate(linear.observables):
                        found.peaks.setdefault(name, {}).setdefault(spec, np.full(n_s, np.nan))[i] = summary[j]
                for constraint in self.constraints:
                    per_speed[constraint.name][i] = constraint.at_speed(self, linear, steady)
            for constraint in self.constraints:
                found.scaled[constraint.name], found.reported[constraint.name] = constraint.judged(
                    per_speed[constraint.name], self, values)
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

    def _differentiate(self, u: np.ndarray) -> Evaluation:
        """The evaluation at ``u`` with its gradients (d/du of the scaled measures and constraints)."""
        found = self(u)
        if found.gradient is not None or found.failed:
            return found
        points = found.points
        if not points:   # evicted, or evaluated before the gradients were on: the sweep again (not counted)
            was, self.gradients = self.gradients, True
            points = self._sweep(self.values(np.clip(u, 0.0, 1.0))).points
            self.gradients = was
        width = self.bounds[:, 1] - self.bounds[:, 0]
        gradient = np.empty((self.speeds.size, len(self.names)))
        per_speed = {c.name: np.empty((self.speeds.size, len(self.names))) for c in self.constraints}
        for i, (at, linear, steady) in enumerate(points):
            point = point_derivatives(self.problem, at, self.names, n_steps=self.n_steps, scheme=DEFAULT_SCHEME,
                                      linear=linear, steady=steady, estimate_error=False,
                                      multiplier=self.needs_radius, forward=self.forward)
            k = linear.observables.index(self.objective.spec)
            gradient[i] = self.objective.gradient(point.response[:, k], point.derivative[:, :, k])
            for constraint in self.constraints:
                per_speed[constraint.name][i] = constraint.gradient_at_speed(self, linear, steady, point)
        found.points = []
        constraint_gradients = {
            c.name: np.atleast_2d(c.judged_gradient(per_speed[c.name], self)) * width for c in self.constraints}
        if not (np.isfinite(gradient).all() and all(np.isfinite(g).all() for g in constraint_gradients.values())):
            # a derivative not defined here (a repeated multiplier, an unresolved mode holding the radius)
            self.fallbacks += 1
            return found
        found.gradient = gradient * width / self.scale
        found.constraint_gradients = constraint_gradients
        self.gradient_evaluations += 1
        return found

    def measure_jacobian(self, u: np.ndarray) -> np.ndarray:
        """d measures / du (n_s, P): the sensitivities' where on, else forward differences."""
        if self.gradients:
            found = self._differentiate(u)
            if found.gradient is not None:
                return found.gradient
        return self.jacobian(self.measures, u)

    def constraint_jacobian(self, u: np.ndarray) -> np.ndarray:
        if self.gradients:
            found = self._differentiate(u)
            if found.gradient is not None:
                rows = [found.constraint_gradients[c.name] for c in self.constraints]
                return np.vstack(rows) if rows else np.empty((0, u.size))
        return self.jacobian(self.constraint_vector, u)

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



def local_search(evaluator: Evaluator, u0: np.ndarray, tol: float) -> tuple[str, str]:
    """SLSQP on the epigraph: minimise t over (u, t) with t >= measure_i(u) at every speed and the
    constraints >= 0, with the sensitivities' gradients where every constraint offers one (else forward
    differences of sweeps). Returns ``(status, message)`` of the optimiser."""
    evaluator.gradients = evaluator.can_differentiate
    try:
        return _slsqp(evaluator, u0, tol)
    finally:
        evaluator.gradients = False


def _slsqp(evaluator: Evaluator, u0: np.ndarray, tol: float) -> tuple[str, str]:
    from scipy.optimize import minimize

    n = u0.size
    t0 = float(evaluator.measures(u0).max())
    evaluator.mark_iterate(u0)

    def epigraph(v):
        return v[n] - evaluator.measures(v[:n])

    def epigraph_jacobian(v):
        return np.hstack([-evaluator.measure_jacobian(v[:n]), np.ones((evaluator.speeds.size, 1))])

    constraints = [{"type": "ineq", "fun": epigraph, "jac": epigraph_jacobian}]
    if evaluator.constraints:
        constraints.append({"type": "ineq", "fun": lambda v: evaluator.constraint_vector(v[:n]),
                            "jac": lambda v: np.hstack([evaluator.constraint_jacobian(v[:n]),
                                                        np.zeros((evaluator.constraint_vector(v[:n]).size, 1))])})
    objective_gradient = np.zeros(n + 1)
    objective_gradient[n] = 1.0
    try:
        found = minimize(lambda v: v[n], np.append(u0, t0), jac=lambda v: objective_gradient, method="SLSQP",
                         bounds=[(0.0, 1.0)] * n + [(None, None)], constraints=constraints,
                         callback=lambda v: evaluator.mark_iterate(v[:n]),
                         options={"ftol": tol, "maxiter": 10 * evaluator.max_evaluations})
    except BudgetSpent:
        return "inaccurate", (f"the optimiser stopped after max_evaluations = {evaluator.max_evaluations} "
                              f"evaluations before converging; raise max_evaluations or loosen tol")
    evaluator.mark_iterate(found.x[:n])
    if found.success:
        return "ok", f"SLSQP converged: {found.message}"
    if found.status in (8, 9):  # no descent direction in the line search; iteration limit
        return "inaccurate", (f"SLSQP stopped before converging: {found.message} (typically the "
                              f"objective's numerical noise at the tolerance asked: loosen tol = {tol:g})")
    return "failed", f"SLSQP failed: {found.message}"


def global_search(evaluator: Evaluator, u0: np.ndarray, tol: float, seed: int) -> tuple[str, str]:
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
    except BudgetSpent:
        words = f"differential evolution stopped after max_evaluations = {evaluator.max_evaluations} evaluations"
        start = best_feasible(evaluator)[0]
    evaluator.mark_iterate(start)
    evaluator.max_evaluations += max(50, 20 * n)  # the polish's own budget
    status, message = local_search(evaluator, start, tol)
    return status, f"{words}; polished: {message}"


def best_feasible(evaluator: Evaluator) -> tuple[np.ndarray, Evaluation]:
    """The evaluated point of least worst measure among those meeting every constraint (None's
    evaluation when none does)."""
    feasible = [(u, f) for u, f in evaluator.history if f.feasible()]
    if not feasible:
        return None, None
    return min(feasible, key=lambda item: float(item[1].measure.max()))



def gradient_words(evaluator: Evaluator) -> str:
    """How the local method's gradients were taken, for the result's message."""
    if not evaluator.can_differentiate:
        return evaluator.gradient_words
    words = f"{evaluator.gradient_words} at {evaluator.gradient_evaluations} points"
    if evaluator.fallbacks:
        words += (f", forward differences of sweeps at {evaluator.fallbacks} where a derivative was not defined "
                  f"(a repeated multiplier, or an unresolved mode holding the spectral radius)")
    return words


def default_evaluations(method: str, n: int) -> int:
    """The default ``max_evaluations`` for ``n`` parameters: a local method's iterations each take
    n + 1 sweeps (the point and its forward differences), a global one's generations 15 n."""
    return 40 + 40 * n if method == "local" else 300 * n

