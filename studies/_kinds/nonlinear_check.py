"""``[studies.nonlinear_check]``: the full nonlinear model, started from the linear periodic state
(and optionally from rest), against the linear solution."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .._errors import StudiesError
from .._kind import StudyKind, boolean, integer, number, speed_values, steps
from .._numerics import solve_steady
from .._plots import Plot, axes_for, drawn, label
from .._store import Result, register
from .._studies import check_integer, check_n_steps


@register
@dataclass(frozen=True, eq=False)
class NonlinearCheck(Result):
    """The full nonlinear model against the linear periodic solution.

    ``t_linear`` (N+1,) s and ``linear`` {spec: (N+1,)}: the linear steady state over one period;
    ``t`` (n_t,) s and ``nonlinear`` {spec: (n_t,)}: the nonlinear run from the linear state at t = 0
    over ``n_periods``; ``linear_error`` and ``nonlinear_error`` {spec: float} the estimated max
    error of each route (NaN when the integrator gives none); ``difference`` {spec: float} max over
    the last period of |nonlinear - linear|; ``relative_difference`` {spec: float} the same over the
    linear peak-to-peak; ``periodicity_defect`` {spec: float} max |o(t) - o(t - T)| over the last
    period of the nonlinear run; from rest (when asked): ``t_rest``, ``rest`` {spec: (n_rest,)},
    ``rest_difference`` {spec: float} over the last period, ``periods_to_steady`` (periods until the
    periodicity defect fell below ``steady_tol`` times the peak-to-peak, NaN if never); costs
    ``linear_run_time``, ``nonlinear_run_time``, ``rest_run_time`` s.
    """

    problem: str
    scene: str
    parameters: Mapping[str, float]
    units: Mapping[str, str]
    settings: Mapping[str, Any]
    t_linear: np.ndarray
    linear: Mapping[str, np.ndarray]
    linear_error: Mapping[str, float]
    t: np.ndarray
    nonlinear: Mapping[str, np.ndarray]
    nonlinear_error: Mapping[str, float]
    difference: Mapping[str, float]
    relative_difference: Mapping[str, float]
    periodicity_defect: Mapping[str, float]
    linear_run_time: float
    nonlinear_run_time: float
    t_rest: np.ndarray = None
    rest: Mapping[str, np.ndarray] = field(default_factory=dict)
    rest_difference: Mapping[str, float] = field(default_factory=dict)
    periods_to_steady: float = float("nan")
    rest_run_time: float = float("nan")

    _units = {"t_linear": "s", "linear": "@observables", "t": "s", "nonlinear": "@observables",
              "t_rest": "s", "rest": "@observables"}

    def plot(self, *, axes: Any = None) -> Plot:
        """Nonlinear run from the linear state (and from rest) against the linear periodic solution."""
        specs = list(self.linear)
        axes = axes_for(len(specs), axes)
        period = self.t_linear[-1]
        artists: dict[str, list] = {}
        for ax, spec in zip(axes, specs):
            repeats = int(round(self.t[-1] / period))
            t_lin = np.concatenate([self.t_linear[:-1] + p * period for p in range(repeats)] + [[self.t[-1]]])
            y_lin = np.concatenate([self.linear[spec][:-1]] * repeats + [[self.linear[spec][-1]]])
            lines = ax.plot(self.t, self.nonlinear[spec], color="C0", label="nonlinear from linear state")
            lines += ax.plot(t_lin, y_lin, "--", color="C1", label="linear periodic")
            if self.rest:
                lines += ax.plot(self.t_rest, self.rest[spec], color="0.6", lw=0.6, label="nonlinear from rest")
            ax.set_xlabel("time (s)")
            ax.set_ylabel(label(spec, self.units[spec]))
            ax.set_title(f"{spec}: max difference {self.difference[spec]:.2g} "
                         f"({100 * self.relative_difference[spec]:.2g} % of peak to peak)\n"
                         f"estimated errors: linear {self.linear_error.get(spec, float('nan')):.2g}, "
                         f"nonlinear {self.nonlinear_error.get(spec, float('nan')):.2g}; run time "
                         f"linear {self.linear_run_time:.3g} s, nonlinear "
                         f"{self.nonlinear_run_time:.3g} s", fontsize="small")
            ax.legend(fontsize="x-small")
            artists[spec] = lines
        return drawn(axes, artists)


def nonlinear_check(problem: Any, values: Mapping[str, float] | None = None, *, n_steps: int = 256,
                    n_periods: int = 5, from_rest: bool = False, max_periods_from_rest: int = 200,
                    steady_tol: float = 0.01) -> NonlinearCheck:
    """Run the full nonlinear model from the linear periodic state for ``n_periods`` periods (and
    optionally from rest for up to ``max_periods_from_rest``) and compare with the linear solution."""
    if not getattr(problem, "supports_nonlinear", False):
        raise StudiesError(f"problem {problem.name!r} has no nonlinear model to check against")
    n_steps = check_n_steps(n_steps)
    check_integer("n_periods", n_periods, 2)
    check_integer("max_periods_from_rest", max_periods_from_rest, 2)
    start = time.perf_counter()
    linear = problem.linearize(values, n_steps=n_steps)
    steady = solve_steady(linear)
    linear_time = time.perf_counter() - start
    specs = linear.observables
    run = problem.simulate(linear, steady.state.x[0], steady.state.v[0], n_periods=n_periods,
                           steps_per_period=n_steps)
    lin = {spec: steady.response[:, k] for k, spec in enumerate(specs)}
    scale = {spec: max(float(np.ptp(lin[spec])), np.finfo(float).tiny) for spec in specs}
    difference, relative, defect = {}, {}, {}
    for spec in specs:
        last = run.observables[spec][-(n_steps + 1):]
        previous = run.observables[spec][-(2 * n_steps + 1):-n_steps]
        difference[spec] = float(np.abs(last - lin[spec]).max())
        relative[spec] = difference[spec] / scale[spec]
        defect[spec] = float(np.abs(last - previous).max())
    extra: dict[str, Any] = {}
    if from_rest:
        zero = np.zeros(linear.system.n_dof)
        rest = problem.simulate(linear, zero, zero, n_periods=max_periods_from_rest, steps_per_period=n_steps)
        periods = float("nan")
        for p in range(1, max_periods_from_rest):
            window = slice(p * n_steps, (p + 1) * n_steps + 1)
            before = slice((p - 1) * n_steps, p * n_steps + 1)
            if all(np.abs(rest.observables[s][window] - rest.observables[s][before]).max()
                   <= steady_tol * scale[s] for s in specs):
                periods = float(p + 1)
                break
        extra = dict(t_rest=rest.t, rest=dict(rest.observables),
                     rest_difference={s: float(np.abs(rest.observables[s][-(n_steps + 1):] - lin[s]).max())
                                      for s in specs},
                     periods_to_steady=periods, rest_run_time=rest.run_time)
    return NonlinearCheck(
        problem=problem.name, scene=problem.text, parameters=problem.resolve(values),
        units=dict(zip(specs, linear.units)),
        settings={"n_steps": n_steps, "n_periods": n_periods, "from_rest": from_rest,
                  "max_periods_from_rest": max_periods_from_rest, "steady_tol": steady_tol},
        t_linear=steady.state.t, linear=lin,
        linear_error={spec: float(steady.response_error[k]) for k, spec in enumerate(specs)},
        t=run.t, nonlinear=dict(run.observables),
        nonlinear_error={spec: float(run.error.get(spec, float("nan"))) for spec in specs},
        difference=difference, relative_difference=relative,
        periodicity_defect=defect, linear_run_time=linear_time, nonlinear_run_time=run.run_time, **extra)


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    return {"values": speed_values(where, table), "n_steps": steps(where, table, n_steps),
            "n_periods": integer(where, "n_periods", table.get("n_periods", 5), 2),
            "from_rest": boolean(where, "from_rest", table.get("from_rest", False)),
            "max_periods_from_rest": integer(where, "max_periods_from_rest",
                                             table.get("max_periods_from_rest", 200), 2),
            "steady_tol": number(where, "steady_tol", table.get("steady_tol", 0.01), positive=True)}


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> NonlinearCheck:
    # looked up when called, so that a test can replace the study function
    return nonlinear_check(problem, **options)


def _summary(result: NonlinearCheck) -> str:
    diffs = ", ".join(f"{k} {100 * v:.3g} %" for k, v in result.relative_difference.items())
    return (f"nonlinear - linear: {diffs} of peak to peak; {result.nonlinear_run_time:.3g} s "
            f"nonlinear vs {result.linear_run_time:.3g} s linear")


KIND = StudyKind(name="nonlinear_check", result=NonlinearCheck,
                 keys=("speed", "n_periods", "from_rest", "max_periods_from_rest", "steady_tol", "n_steps"),
                 check=_check, run=_run, summary=_summary, default=lambda nominal_speed: {"n_periods": 3})
