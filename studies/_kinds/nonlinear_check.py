"""``[studies.nonlinear_check]``: the full nonlinear model, started from the linear periodic state
(and optionally from rest), against the linear solution."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .._kind import StudyKind, register_kind
from .._numerics import solve_steady
from .._plots import Plot, axes_for, drawn, headline, label, legend_outside, plain, quantity, scene_and_point
from .._result import DerivedPeaks, StudyResult, peaks_of
from .._toolkit import (
    MAX_AXIS_POINTS,
    MAX_PERIODS,
    PERIODS_WHY,
    SPEED,
    WARM_UP_STEPS,
    Headline,
    StudiesError,
    Summary,
    boolean,
    check_integer,
    check_n_steps,
    combine,
    cost,
    fraction,
    integer,
    is_numerical_failure,
    number,
    speed_values,
    steps,
)

#: The fewest steps per period a nonlinear check accepts (docs/studies.md): the nonlinear run takes
#: the linear grid's steps, and its own error estimate needs them.
MIN_STEPS = 32
#: Default ``tolerance``: the nonlinear and linear results agree when their difference is within the
#: sum of both error estimates plus this fraction of the linear peak-to-peak (what the linear model
#: leaves out, terms of second order in the deflection, is a few per mille of the peak-to-peak of the
#: shipped four-bar at low speed, about 1-2 % at 50-70 rad/s).
TOLERANCE = 0.02
#: Default ``periodic_tol``: the nonlinear run has settled when its periodicity defect over the last
#: period (max |o(t) - o(t - T)|) is within twice its error estimate plus this fraction of the linear
#: peak-to-peak.
PERIODIC_TOL = 0.05
#: The verdicts, most severe first.
VERDICTS = ("failed", "not_periodic", "differs", "agrees")


@dataclass(frozen=True, eq=False)
class NonlinearCheck(DerivedPeaks, StudyResult):
    """The full nonlinear model against the linear periodic solution (the fields every result has:
    ``studies._result``).

    ``verdict``: ``"agrees"`` (every observable's difference within ``linear_error + nonlinear_error +
    tolerance * peak-to-peak``), ``"differs"`` (not so: ``message`` gives the relative difference and
    the linear-range measures that explain it), ``"not_periodic"`` (the periodicity defect exceeds
    ``2 nonlinear_error + periodic_tol * peak-to-peak``: the machine does not settle) or ``"failed"``
    (the nonlinear run failed; ``message`` says why, the nonlinear fields are empty).

    Attributes
    ----------
    problem, scene : str
        The problem's name and scene text.
    parameters : dict
        {name: value} the point checked.
    units : dict
        {spec: unit} of each observable.
    settings : dict
        The study's arguments.
    t_linear : ndarray, (N+1,), s
        The linear steady state's samples over one period.
    linear : dict of ndarray, {spec: (N+1,)}, units[spec]
        The linear steady state.
    linear_error, nonlinear_error : dict, {spec: float}, units[spec]
        The estimated max error of each route (NaN when the integrator gives none).
    t : ndarray, (n_t,), s
        The nonlinear run's samples (from the linear state at t = 0, over ``n_periods``).
    nonlinear : dict of ndarray, {spec: (n_t,)}, units[spec]
        The nonlinear run.
    difference : dict, {spec: float}, units[spec]
        The max over the last period of |nonlinear - linear|.
    relative_difference : dict, {spec: float}, 1
        The same over the linear peak-to-peak.
    periodicity_defect : dict, {spec: float}, units[spec]
        The max |o(t) - o(t - T)| over the last period of the nonlinear run.
    linear_run_time, nonlinear_run_time, rest_run_time : float, s
        The cost of each run (NaN for one not run or failed).
    t_rest : ndarray or None, (n_rest,), s
        The run from rest (when asked).
    rest : dict of ndarray, {spec: (n_rest,)}, units[spec]
        Its observables.
    rest_difference : dict, {spec: float}, units[spec]
        Its difference from the linear state over the last period.
    periods_to_steady : float
        The periods until the periodicity defect fell below ``steady_tol`` times the peak-to-peak
        (NaN if never).
    verdict : str
        See above.
    status, message : str
        The linear steady state's verdict (``failed`` when the run failed), its message first.
    is_stable : bool
        The linear steady state's stability.
    linear_range : dict, {"<link>.<measure>": float}, 1
        The linear solution's linear-range measures.
    run_time : float, s
        Property: the sum of the runs' costs.
    peak, peak_error, peak_to_peak, peak_to_peak_error : dict, {spec: float}, units[spec]
        Properties: over the last period of the nonlinear run, with its error estimate (NaN when it
        failed or gives none).
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
    t_rest: np.ndarray | None = None
    rest: Mapping[str, np.ndarray] = field(default_factory=dict)
    rest_difference: Mapping[str, float] = field(default_factory=dict)
    periods_to_steady: float = float("nan")
    rest_run_time: float = float("nan")
    verdict: str = ""
    status: str = "ok"
    message: str = ""
    is_stable: bool = True
    linear_range: Mapping[str, float] = field(default_factory=dict)

    _units = {"t_linear": "s", "linear": "@observables", "t": "s", "nonlinear": "@observables",
              "t_rest": "s", "rest": "@observables"}

    @property
    def run_time(self) -> float:
        """The study's cost, s: its runs' (linear, nonlinear, from rest) together."""
        return float(np.nansum([self.linear_run_time, self.nonlinear_run_time, self.rest_run_time]))

    def _peaks(self) -> dict[str, dict[str, float]]:
        """Over the last period of the nonlinear run (NaN where it failed)."""
        steps = int(self.settings.get("n_steps", np.size(self.t_linear) - 1))
        last = {spec: np.asarray(self.nonlinear.get(spec, np.full(steps + 1, np.nan)))[-(steps + 1):]
                for spec in self.linear}
        return peaks_of(last, self.nonlinear_error)

    def plot(self, *, axes: Any = None) -> Plot:
        """Nonlinear run from the linear state (and from rest) against the linear periodic solution,
        the verdict in each title."""
        specs = list(self.linear)
        axes = axes_for(len(specs), axes, height=3.2)  # room for a four-line title
        period = self.t_linear[-1]
        # a failed run has no nonlinear samples: the linear solution over one period alone
        t_end = self.t[-1] if self.t is not None and np.size(self.t) else period
        artists: dict[str, list] = {}
        for ax, spec in zip(axes, specs):
            repeats = max(int(round(t_end / period)), 1)
            t_lin = np.concatenate([self.t_linear[:-1] + p * period for p in range(repeats)] + [[t_end]])
            y_lin = np.concatenate([self.linear[spec][:-1]] * repeats + [[self.linear[spec][-1]]])
            lines = []
            if spec in self.nonlinear:
                lines += ax.plot(self.t, self.nonlinear[spec], color="C0", label="nonlinear from linear state")
            lines += ax.plot(t_lin, y_lin, "--", color="C1", label="linear periodic")
            if self.rest:
                lines += ax.plot(self.t_rest, self.rest[spec], color="0.6", lw=0.6, label="nonlinear from rest")
            ax.set_xlabel("time (s)")
            ax.set_ylabel(label(spec, self.units[spec]))
            unit = self.units[spec]
            ax.set_title(f"{spec}: {self.verdict.upper().replace('_', ' ')} (linear: {headline(self.status)})\n"
                         f"max difference {quantity(self.difference.get(spec, float('nan')), unit)} "
                         f"({plain(100 * self.relative_difference.get(spec, float('nan')))} % of peak to peak)\n"
                         f"estimated errors: linear {quantity(self.linear_error.get(spec, float('nan')), unit)}, "
                         f"nonlinear {quantity(self.nonlinear_error.get(spec, float('nan')), unit)}\nrun time linear "
                         f"{plain(self.linear_run_time)} s, nonlinear {plain(self.nonlinear_run_time)} s",
                         fontsize="small")
            legend_outside(ax)
            artists[spec] = lines
        axes[0].figure.suptitle(f"{scene_and_point(self)}: nonlinear model against linear", fontsize="small")
        return drawn(axes, artists)


def nonlinear_check(problem: Any, values: Mapping[str, float] | None = None, *, n_steps: int = 256,
                    n_periods: int = 5, from_rest: bool = False, max_periods_from_rest: int = 200,
                    steady_tol: float = 0.01, tolerance: float = TOLERANCE,
                    periodic_tol: float = PERIODIC_TOL, periodic_state: bool = False) -> NonlinearCheck:
    """Run the full nonlinear model from the linear periodic state for ``n_periods`` periods (and
    optionally from rest for up to ``max_periods_from_rest``), compare with the linear solution and
    say the verdict (``agrees``, ``differs``, ``not_periodic``, ``failed``: see :class:`NonlinearCheck`).
    A nonlinear run that fails numerically gives the verdict ``failed`` (status ``failed``), not an
    exception: the linear results are kept.

    With ``periodic_state`` the nonlinear side is the nonlinear periodic state
    (``studies.nonlinear_steady_state``: shooting, with its N/2 error estimate) instead of the
    ``n_periods`` transient, where Newton finds it (else the transient is run as without): sharper (no
    start-up transient left in the compared period) and cheaper. An orbit that is not stable gives
    ``not_periodic`` (the machine does not settle on it)."""
    if not getattr(problem, "supports_nonlinear", False):
        raise StudiesError(f"problem {problem.name!r} has no nonlinear model to check against")
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a nonlinear check")
    check_integer("n_periods", n_periods, 2)
    check_integer("max_periods_from_rest", max_periods_from_rest, 2)
    for name, value in (("tolerance", tolerance), ("periodic_tol", periodic_tol)):
        if not (isinstance(value, (int, float)) and 0.0 <= value < 1.0):
            raise StudiesError(f"{name}: expected a fraction of the peak-to-peak in [0, 1), got {value!r}")
    start = time.perf_counter()
    linear = problem.linearize(values, n_steps=n_steps)
    steady = solve_steady(linear)
    linear_time = time.perf_counter() - start
    specs = linear.observables
    lin = {spec: steady.response[:, k] for k, spec in enumerate(specs)}
    linear_error = {spec: float(steady.response_error[k]) for k, spec in enumerate(specs)}
    scale = {spec: max(float(np.ptp(lin[spec])), np.finfo(float).tiny) for spec in specs}
    common = dict(
        problem=problem.name, scene=problem.text, parameters=problem.resolve(values),
        units=dict(zip(specs, linear.units)),
        settings={"n_steps": n_steps, "n_periods": n_periods, "from_rest": from_rest,
                  "max_periods_from_rest": max_periods_from_rest, "steady_tol": steady_tol,
                  "tolerance": tolerance, "periodic_tol": periodic_tol},
        t_linear=steady.state.t, linear=lin, linear_error=linear_error, linear_run_time=linear_time,
        is_stable=steady.is_stable, linear_range=steady.linear_range)
    linear_words = f"linear steady state {steady.status}" + (f" ({steady.message})" if steady.message else "")
    extra = _from_rest(problem, linear, specs, lin, scale, n_steps, max_periods_from_rest, steady_tol) \
        if from_rest else {}
    if periodic_state:
        found = _against_periodic_state(problem, values, n_steps, common, lin, scale, linear_error, tolerance,
                                        periodic_tol, steady, linear_words, extra)
        if found is not None:
            return found
    try:
        run = problem.simulate(linear, steady.state.x[0], steady.state.v[0], n_periods=n_periods,
                               steps_per_period=n_steps)
    except Exception as error:
        if not is_numerical_failure(error):
            raise
        # the integrator's own advice names its arguments; say what a study table can change
        message = (f"the nonlinear run failed: {type(error).__name__}: {error}. In a [studies."
                   f"nonlinear_check] table: raise n_steps (the run takes n_steps per period, now "
                   f"{n_steps}) or check a lower speed; a linear state far outside the linear range "
                   f"may not be a start the full model can take; {linear_words}")
        return NonlinearCheck(**common, t=np.empty(0), nonlinear={}, nonlinear_error={}, difference={},
                              relative_difference={}, periodicity_defect={}, nonlinear_run_time=float("nan"),
                              verdict="failed", status="failed", message=message)
    difference, relative, defect = {}, {}, {}
    for spec in specs:
        last = run.observables[spec][-(n_steps + 1):]
        previous = run.observables[spec][-(2 * n_steps + 1):-n_steps]
        difference[spec] = float(np.abs(last - lin[spec]).max())
        relative[spec] = difference[spec] / scale[spec]
        defect[spec] = float(np.abs(last - previous).max())
    nonlinear_error = {spec: float(run.error.get(spec, float("nan"))) for spec in specs}
    verdict, words = _verdict(specs, scale, difference, defect, linear_error, nonlinear_error,
                              tolerance, periodic_tol)
    if verdict == "differs" and steady.linear_range:
        words += "; linear-range measures: " + ", ".join(f"{k} {v:.3g}" for k, v in steady.linear_range.items()
                                                         if np.isfinite(v))
    status, message = combine([(steady.status, steady.message)])
    return NonlinearCheck(
        **common, t=run.t, nonlinear=dict(run.observables), nonlinear_error=nonlinear_error,
        difference=difference, relative_difference=relative, periodicity_defect=defect,
        nonlinear_run_time=run.run_time, verdict=verdict, status=status,
        message=f"{words}; {linear_words}", **extra)


def _from_rest(problem, linear, specs, lin, scale, n_steps, max_periods_from_rest, steady_tol) -> dict[str, Any]:
    """The run from rest: its observables, difference from the linear state over the last period and the
    periods until successive periods agree to ``steady_tol`` of the peak-to-peak."""
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
    return dict(t_rest=rest.t, rest=dict(rest.observables),
                rest_difference={s: float(np.abs(rest.observables[s][-(n_steps + 1):] - lin[s]).max())
                                 for s in specs},
                periods_to_steady=periods, rest_run_time=rest.run_time)


def _against_periodic_state(problem, values, n_steps, common, lin, scale, linear_error, tolerance, periodic_tol,
                            steady, linear_words, extra):
    """The check against the nonlinear periodic state, or None when Newton does not find it."""
    from .nonlinear_steady_state import nonlinear_steady_state

    orbit = nonlinear_steady_state(problem, values, n_steps=n_steps, modes="full")  # the linear route's model
    if orbit.status == "failed":
        return None
    specs = list(lin)
    difference = {spec: float(np.abs(orbit.response[spec] - lin[spec]).max()) for spec in specs}
    relative = {spec: difference[spec] / scale[spec] for spec in specs}
    defect = {spec: 0.0 for spec in specs}   # a periodic orbit, to its Newton residual
    nonlinear_error = {spec: float(orbit.response_error[spec]) for spec in specs}
    verdict, words = _verdict(specs, scale, difference, defect, linear_error, nonlinear_error, tolerance,
                              periodic_tol, unknown_error="refine n_steps")
    if not orbit.is_stable:
        verdict, words = "not_periodic", (f"the nonlinear periodic orbit is not stable ({orbit.headline}): the "
                                          f"machine does not settle on it; {words}")
    # an orbit whose numbers are not trusted (inaccurate) makes the comparison untrusted too
    status, message = combine([(steady.status, steady.message), (orbit.status, orbit.message)])
    return NonlinearCheck(
        **dict(common, settings=dict(common["settings"], periodic_state=True)), t=orbit.t,
        nonlinear=dict(orbit.response), nonlinear_error=nonlinear_error, difference=difference,
        relative_difference=relative, periodicity_defect=defect, nonlinear_run_time=orbit.shooting_run_time,
        verdict=verdict, status=status,
        message=f"{words}; against the nonlinear periodic state ({orbit.message}); {linear_words}", **extra)


def _verdict(specs, scale, difference, defect, linear_error, nonlinear_error, tolerance, periodic_tol, *,
             unknown_error: str = ""):
    """The worst verdict over the observables and its words. With ``unknown_error`` (advice), a NaN
    nonlinear error estimate is unknown, not zero: an observable that would agree only with a zero
    error is not said to agree (``differs``, with the advice)."""
    def known(value):  # an error estimate the integrator does not give counts as zero
        return value if np.isfinite(value) else 0.0

    found = []
    for spec in specs:
        if unknown_error and not np.isfinite(nonlinear_error[spec]) and difference[spec] <= (
                known(linear_error[spec]) + tolerance * scale[spec]):
            found.append(("differs", f"{spec}: agreement not shown: the nonlinear error estimate is unknown "
                          f"(NaN), the difference is {100 * difference[spec] / scale[spec]:.3g} % of the "
                          f"linear peak to peak; {unknown_error}"))
            continue
        settle = 2.0 * known(nonlinear_error[spec]) + periodic_tol * scale[spec]
        allowed = known(linear_error[spec]) + known(nonlinear_error[spec]) + tolerance * scale[spec]
        if not defect[spec] <= settle:
            found.append(("not_periodic", f"{spec}: the nonlinear run does not settle: periodicity defect "
                          f"{defect[spec]:.3g} over the last period is {defect[spec] / scale[spec]:.3g} of the "
                          f"linear peak to peak (allowed {settle / scale[spec]:.3g})"))
        elif not difference[spec] <= allowed:
            found.append(
                (
                    "differs",
                    f"{spec}: nonlinear and linear differ by {100 * difference[spec] / scale[spec]:.3g} % "
                    f"of the linear peak to peak (allowed: the two error estimates and the "
                    f"tolerance, {100 * allowed / scale[spec]:.3g} %)",
                )
            )
        else:
            found.append(("agrees", f"{spec}: agrees within {100 * difference[spec] / scale[spec]:.3g} % of the "
                          f"peak to peak (allowed {100 * allowed / scale[spec]:.3g} %)"))
    verdict = min((v for v, _ in found), key=VERDICTS.index, default="agrees")
    return verdict, "; ".join(words for v, words in found if v == verdict)


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    if "speed" in table and "speeds" in table:
        raise StudiesError(f"[{where}]: give either speed or speeds, not both")
    speeds = table.get("speeds")
    if speeds is not None and (not isinstance(speeds, list) or not speeds or len(speeds) > MAX_AXIS_POINTS):
        raise StudiesError(f"[{where}] speeds: expected a non-empty list of at most {MAX_AXIS_POINTS} crank "
                           f"speeds (rad/s), got {speeds!r}"[:300])
    return {"values": speed_values(where, table),
            "speeds": None if speeds is None else tuple(number(where, "speeds", v, positive=True) for v in speeds),
            "n_steps": steps(where, table, n_steps, minimum=MIN_STEPS),
            "tolerance": fraction(where, "tolerance", table.get("tolerance", TOLERANCE)),
            "periodic_tol": fraction(where, "periodic_tol", table.get("periodic_tol", PERIODIC_TOL)),
            "n_periods": integer(where, "n_periods", table.get("n_periods", 5), 2, maximum=MAX_PERIODS,
                                 why=PERIODS_WHY),
            "from_rest": boolean(where, "from_rest", table.get("from_rest", False)),
            "max_periods_from_rest": integer(where, "max_periods_from_rest",
                                             table.get("max_periods_from_rest", 200), 2,
                                             maximum=MAX_PERIODS, why=PERIODS_WHY),
            "steady_tol": fraction(where, "steady_tol", table.get("steady_tol", 0.01)),
            "periodic_state": boolean(where, "periodic_state", table.get("periodic_state", False))}


def _runs(options: Mapping[str, Any]) -> dict[str, dict[str, Any]]:
    """One check per speed of ``speeds`` (groups ``nonlinear_check@<speed>``), else one."""
    single = {k: v for k, v in options.items() if k != "speeds"}
    if not options.get("speeds"):
        return {"": single}
    return {f"@{speed:g}": dict(single, values={SPEED: speed}) for speed in options["speeds"]}


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> NonlinearCheck:
    # looked up when called, so that a test can replace the study function
    return nonlinear_check(problem, **options)


def _summary(result: NonlinearCheck) -> str:
    speed = result.parameters.get(SPEED, float("nan"))
    diffs = ", ".join(f"{k} {100 * v:.3g} %" for k, v in result.relative_difference.items())
    numbers = (f"nonlinear - linear: {diffs} of peak to peak; {result.nonlinear_run_time:.3g} s nonlinear vs "
               f"{result.linear_run_time:.3g} s linear" if diffs else f"{result.linear_run_time:.3g} s linear")
    return f"{result.verdict.upper()} at speed {speed:.4g} rad/s: {result.message}\n    {numbers}"


def _headlines(result: NonlinearCheck) -> Summary:
    speed = result.parameters.get(SPEED, float("nan"))
    rows = []
    for spec, difference in result.difference.items():
        error = result.linear_error.get(spec, float("nan")) + result.nonlinear_error.get(spec, float("nan"))
        rows.append(Headline(f"{spec} max |nonlinear - linear|", difference, result.units[spec], error,
                             f"({plain(100 * result.relative_difference[spec])} % of peak to peak)"))
    if np.isfinite(result.periods_to_steady):
        rows.append(Headline("periods to steady state from rest", result.periods_to_steady))
    words = f"{result.verdict.replace('_', ' ')} at speed {plain(speed, 3)} rad/s (linear: {headline(result.status)})"
    return Summary(status=words, run_time=result.run_time, rows=rows)


def nonlinear_check_cost(name, problem, options, workers):
    """A linearisation and periodic solve, and the nonlinear run over its periods (from rest too)."""
    sizes = cost.sizes_at(problem, options["values"])
    n_steps = options["n_steps"]
    periods = options["n_periods"] + (options["max_periods_from_rest"] if options["from_rest"] else 0)
    build_bytes, build_seconds = cost.linearisation(n_steps, sizes)
    steps = periods * n_steps
    seconds = (cost.STUDY_SECONDS + build_seconds + cost.solve_seconds(n_steps, sizes)
               + steps * (cost.NONLINEAR_STEP_SECONDS + cost.NONLINEAR_STEP_N2_SECONDS * sizes.n**2))
    memory = max(build_bytes, 8.0 * cost.NONLINEAR_DOUBLES * steps * sizes.n)
    return cost.Estimate(name, memory, seconds, f"{periods} periods x {n_steps} steps x {sizes.n} coordinates")



def _warm_up(problem: Any) -> None:
    """A two-period nonlinear check on the JIT warm-up's tiny grid (the integrator's kernels)."""
    if getattr(problem, "supports_nonlinear", False):
        nonlinear_check(problem, n_steps=WARM_UP_STEPS, n_periods=2)


KIND = register_kind(StudyKind(
    name="nonlinear_check", result=NonlinearCheck,
    keys=("speed", "speeds", "n_periods", "from_rest", "max_periods_from_rest", "steady_tol", "tolerance",
          "periodic_tol", "n_steps", "periodic_state"),
    check=_check, run=_run, summary=_summary, runs=_runs, default=lambda nominal_speed: {"n_periods": 3},
    headlines=_headlines, cost=nonlinear_check_cost, demo={"speed": 0.7, "n_periods": 3}, warm_up=_warm_up,
    aliases=("NonlinearCheck",)))
