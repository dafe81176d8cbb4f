"""What ``[studies.optimize]`` reports at its optimum beside the search: the objective's error budget
(the steady state there), the observables' summaries over the speeds, the map of the first two
parameters for the figure, and the nonlinear check."""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from .._budget import ErrorBudget, verdict
from .._result import PEAK_FIELDS
from .._toolkit import SPEED
from ._optimize_search import Evaluator, best_feasible


def optimum_budget(problem: Any, values: Mapping[str, float], goal: Any, n_steps: int, tolerance: float,
                    value: float) -> dict[str, Any]:
    """The objective's error budget at the optimum's worst speed ``values``, from the steady state
    there with its budget (``studies._budget``; the RMS takes the response samples'): the fields
    ``error_budget``, ``error_methods``, ``objective_error`` (the total) and the ``verdict``."""
    from .steady_state import steady_state

    found = steady_state(problem, values, n_steps=n_steps, error_tolerance=tolerance)
    terms = {"peak_to_peak": found.error_budget, "peak": found.peak_error_budget,
             "rms": found.response_error_budget}[goal.measure][goal.spec]
    budget = ErrorBudget({goal.spec: dict(terms)}, dict(found.error_methods))
    return {"error_budget": budget.terms, "error_methods": budget.methods,
            "objective_error": float(budget.total(goal.spec)),
            "verdict": verdict(budget, {goal.spec: value}, tolerance, quantity=goal.measure.replace("_", "-"))}


def optimum_peaks(best: Any, shape: tuple[int, ...]) -> dict[str, dict[str, np.ndarray]]:
    """The observables' summaries at the optimum over the speeds (NaN where its evaluation failed)."""
    return {name: {spec: np.full(shape, np.nan) if best.failed else values
                   for spec, values in best.peaks.get(name, {}).items()} for name in PEAK_FIELDS}


def objective_map(evaluator: Evaluator, points: int) -> dict[str, np.ndarray]:
    """The worst measure on a ``points`` x ``points`` grid of the first two parameters (the others
    at the optimum), for the figure; not part of the history."""
    u_best = best_feasible(evaluator)[0]
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


def optimum_check(problem, values, speed, goal, n_steps, n_periods) -> dict[str, Any]:
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
