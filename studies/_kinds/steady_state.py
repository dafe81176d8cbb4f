"""``[studies.steady_state]``: the periodic response over one period, Floquet multipliers, error
estimates and run time; figures of the response, the multipliers and the deformed mechanism."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from .._budget import (
    ERROR_TOLERANCE,
    FORMAT2_METHODS,
    LINEARISATION_MARGIN,
    NOT_APPLICABLE,
    QUANTITIES,
    ErrorBudget,
    beside,
    check_tolerance,
    describe,
    format2_budget,
    linearisation_terms,
    mesh_terms,
    point_budget,
    reduction_terms,
    verdict,
)
from .._drawing import draw_mechanism, mechanism_drawing
from .._kind import StudyKind, register_kind
from .._numerics import DEFAULT_SCHEME, peak_summary, solve_steady, study_scheme
from .._plots import Plot, axes_for, cost_line, drawn, headline, label, plain, plot_multipliers, scene_and_point
from .._result import StudyResult
from .._toolkit import (
    Headline,
    Summary,
    check_n_steps,
    combine,
    cost,
    response_rows,
    speed_values,
    steps,
)

#: The fewest steps per period a steady state accepts (docs/studies.md): N/4 = 4 steps is the
#: coarsest level of the error check.
MIN_STEPS = 16


@dataclass(frozen=True, eq=False)
class SteadyStateResult(StudyResult):
    """Periodic steady response over one period, with Floquet multipliers (the fields every result
    has: ``studies._result``).

    Attributes
    ----------
    problem : str
        The problem's name.
    parameters : dict
        {name: value} the parameter values of the point.
    scene : str
        The scene text.
    labels : tuple of str, (m,)
        The independent coordinates.
    units : dict
        {spec: unit} of each observable.
    t : ndarray, (N+1,), s
        The time samples over one period.
    crank_angle : ndarray, (N+1,), rad
        The crank angle at each sample.
    x : ndarray, (N+1, m), SI (see labels)
        The independent coordinates.
    response : dict of ndarray, {spec: (N+1,)}, units[spec]
        The observables (for joint forces, drive torques and stresses: the totals, nominal plus
        elastic change).
    response_error : dict, {spec: float}, units[spec]
        The estimated max abs error of each observable: the total of ``response_error_budget``.
    peak, peak_error, peak_to_peak, peak_to_peak_error : dict, {spec: float}, units[spec]
        The largest magnitude and the peak-to-peak of each observable over the period
        (``studies._numerics.peak_summary``) and their estimated errors: the totals of
        ``peak_error_budget`` and ``error_budget``.
    error_budget : dict, {spec: {term: float or "not applicable"}}, units[spec]
        The peak-to-peak's error budget (``studies._budget``): "time_step" (N against N/2),
        "mesh", "linearisation" (signed: the nonlinear state's value minus the linear one; NaN
        unknown), "reduction" where a link is reduced; the total is the sum of the magnitudes.
    peak_error_budget, response_error_budget : dict, {spec: {term: ...}}, units[spec]
        The same for the peak and the response samples.
    error_methods : dict, {term: str}
        How each term was estimated, in words ("not applicable: ..." where it does not apply).
    error_tolerance : float, 1
        The relative tolerance of the totals deciding ``inaccurate``.
    multipliers : ndarray of complex, (2m,), 1
        The Floquet multipliers.
    spectral_radius, spectral_radius_error : float, 1
        The largest modulus of the resolved modes and its estimated error (``periodic.SteadyState``;
        files of format 2 and older: over all modes).
    unresolved_multipliers : ndarray of complex, (k,), 1
        The multipliers of the modes the step does not resolve, apart from the radius (the
        scheme's values, not the system's; empty in files of format 2 and older).
    error_estimate : float, SI
        The max abs error of ``x``.
    status, message : str
        The verdict (``studies._verdicts``: stability with its error bar, error trust, near
        resonance, unresolved modes, linear range, modal reduction).
    is_stable : bool
        False only where unstable.
    instability_kind : str
        "fold", "period_doubling", "secondary_hopf" or "".
    linear_range : dict, {"<link>.<measure>": float}, 1
        The linear-range measures (empty for problems without links).
    n_steps : int
        Steps per period N.
    run_time : float, s
        Linearisation, N, N/2, N/4 shooting and the reduction check.
    shooting_run_time : float, s
        The shooting alone.
    outlines, rigid_outlines : dict of ndarray, {link: (N+1, n_points, 2)}, m
        Points along each link over the period, with the deflection magnified ``magnification``
        times and without deflection (empty for other problems than mechanisms).
    magnification : float, 1
        The deflection's magnification in the drawings.
    plates : dict of ndarray, {link: (N+1, k, 2)}, m
        The corners of rigid links with named points.
    joints : dict of ndarray, {joint: (N+1, 2)}, m
        The joints' positions (``studies._drawing.mechanism_drawing``).
    ground_joints : tuple of str
        The joints on the ground.
    drive : str
        The joint of the turning drive ("" without one: figures use time as abscissa).
    drive_rate : float, rad/s
        Its rate.
    reduction_error : float, 1
        The modal reduction's error (``linearize.reduction_error`` against the next larger mode set:
        the largest difference of an observable over its peak-to-peak; 0 without a reduced link).
    reduction_run_time : float, s
        Its cost (in ``run_time``).
    scheme : str
        The periodic scheme it was integrated with, by its name in ``periodic.SCHEMES``
        ("trapezoidal" for files written before the studies took a scheme).
    """

    problem: str
    parameters: Mapping[str, float]
    scene: str
    labels: tuple[str, ...]
    units: Mapping[str, str]
    t: np.ndarray
    crank_angle: np.ndarray
    x: np.ndarray
    response: Mapping[str, np.ndarray]
    response_error: Mapping[str, float]
    multipliers: np.ndarray
    spectral_radius: float
    error_estimate: float
    status: str
    message: str
    n_steps: int
    run_time: float
    shooting_run_time: float
    outlines: Mapping[str, np.ndarray] = field(default_factory=dict)
    magnification: float = float("nan")
    is_stable: bool = True
    spectral_radius_error: float = float("nan")
    instability_kind: str = ""
    linear_range: Mapping[str, float] = field(default_factory=dict)
    peak: Mapping[str, float] = field(default_factory=dict)
    peak_error: Mapping[str, float] = field(default_factory=dict)
    peak_to_peak: Mapping[str, float] = field(default_factory=dict)
    peak_to_peak_error: Mapping[str, float] = field(default_factory=dict)
    rigid_outlines: Mapping[str, np.ndarray] = field(default_factory=dict)
    plates: Mapping[str, np.ndarray] = field(default_factory=dict)
    joints: Mapping[str, np.ndarray] = field(default_factory=dict)
    ground_joints: tuple[str, ...] = ()
    drive: str = ""
    drive_rate: float = float("nan")
    reduction_error: float = 0.0
    reduction_run_time: float = 0.0
    scheme: str = DEFAULT_SCHEME
    unresolved_multipliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=complex))
    error_budget: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    peak_error_budget: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    response_error_budget: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    error_methods: Mapping[str, str] = field(default_factory=dict)
    error_tolerance: float = ERROR_TOLERANCE

    @property
    def budget(self) -> ErrorBudget:
        """The peak-to-peak's ``error_budget`` as a ``studies._budget.ErrorBudget`` (total, dominant)."""
        return ErrorBudget(self.error_budget, self.error_methods)

    def _filled(self, group: Any) -> dict[str, Any]:
        """A file of format 2 (before the budget): its errors were the time step's alone."""
        if "error_budget" in group.attrs:
            return {}
        return {"error_budget": format2_budget(self.peak_to_peak_error),
                "peak_error_budget": format2_budget(self.peak_error),
                "response_error_budget": format2_budget(self.response_error),
                "error_methods": dict(FORMAT2_METHODS)}

    @property
    def headline(self) -> str:
        """The verdict in a few words, for titles: "UNSTABLE (period doubling)", "marginal", "ok"."""
        return headline(self.status, self.instability_kind)

    _units = {"t": "s", "crank_angle": "rad", "x": "SI (see labels)", "response": "@observables",
              "multipliers": "1", "unresolved_multipliers": "1", "outlines": "m",
              "rigid_outlines": "m", "plates": "m", "joints": "m"}

    def abscissa(self) -> tuple[np.ndarray, str]:
        """``(values, label)`` the response is drawn against: the turning drive's angle from its
        start in degrees, or time in s when no drive turns (an oscillating arm, a Mathieu problem)."""
        if self.drive and np.isfinite(self.drive_rate):
            return np.degrees(self.drive_rate * (self.t - self.t[0])), f"drive angle at {self.drive} (deg)"
        return self.t - self.t[0], "time (s)"

    def plot(self, *, axes: Any = None) -> Plot:
        """Each observable over one period against the drive angle or time (one axes each) and the
        multipliers (last axes)."""
        specs = list(self.response)
        axes = axes_for(len(specs) + 1, axes)
        artists: dict[str, list] = {}
        abscissa, xlabel = self.abscissa()
        for ax, spec in zip(axes, specs):
            artists[spec] = ax.plot(abscissa, self.response[spec], color="C0")
            ax.set_xlabel(xlabel)
            ax.set_ylabel(label(spec, self.units[spec]))
            words = (describe(self.budget, spec, self.units[spec]) if spec in self.error_budget
                     else f"{plain(self.response_error[spec])} {self.units[spec]}")
            ax.set_title(f"{spec}: peak-to-peak error {words}", fontsize="small", wrap=True)
        axes[0].figure.suptitle(f"{scene_and_point(self)}: {self.headline}", fontsize="medium",
                                color="C3" if self.status != "ok" else "k")
        artists["multipliers"] = plot_multipliers(
            self.multipliers, ax=axes[-1],
            title=f"spectral radius {self.spectral_radius:.6f} ± {plain(self.spectral_radius_error)}\n" + cost_line(
                f"max coordinate error {plain(self.error_estimate)} m or rad (N against N/2)",
                self.run_time))
        return drawn(axes, artists)

    def plot_multipliers(self, *, axes: Any = None) -> Plot:
        """The Floquet multipliers in the complex plane with the unit circle."""
        axes = axes_for(1, axes, width=4.8, height=4.8)
        artists = plot_multipliers(self.multipliers, ax=axes[0],
                                   title=f"{scene_and_point(self)}\nFloquet multipliers, {self.headline}\n"
                                         f"spectral radius {self.spectral_radius:.6f} ± "
                                         f"{plain(self.spectral_radius_error)}")
        return drawn(axes, {"multipliers": artists})

    def plot_mechanism(self, *, axes: Any = None, n_frames: int = 8) -> Plot:
        """The mechanism at ``n_frames`` instants over the period, later frames darker: links (plates
        filled), joints and ground pins; the elastic deflection is magnified ``magnification`` times."""
        if not self.outlines:
            from .._errors import StudiesError

            raise StudiesError(f"{self.problem}: no link outlines to draw (not a mechanism problem)")
        axes = axes_for(1, axes, height=4.8)
        ax = axes[0]
        n_samples = next(iter(self.outlines.values())).shape[0] - 1
        frames = np.linspace(0, n_samples, n_frames, endpoint=False).astype(int)
        artists: dict[str, list] = {}
        for rank, k in enumerate(frames):
            # one colour per link, so each link can be followed; later frames more opaque
            alpha = 0.2 + 0.8 * rank / max(n_frames - 1, 1)
            for name, drawn_now in draw_mechanism(ax, self, k, alpha=alpha, legend=rank == n_frames - 1).items():
                artists.setdefault(name, []).extend(drawn_now)
        ax.legend(fontsize="x-small", title="later frames darker", title_fontsize="x-small",
                  loc="upper left", bbox_to_anchor=(1.01, 1.0))
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_title(f"{scene_and_point(self)}: deformed mechanism over one period\n(deflection x "
                     f"{plain(self.magnification)}), {self.headline}", fontsize="small")
        return drawn(axes, artists)


def steady_state(problem: Any, values: Mapping[str, float] | None = None, *, n_steps: int = 256,
                 scheme: str = DEFAULT_SCHEME, error_tolerance: float = ERROR_TOLERANCE,
                 budget: bool = True) -> SteadyStateResult:
    """Periodic response of the problem's observables over one period, Floquet multipliers, the
    error budget (time step: N against N/2 steps; mesh; linearisation; modal reduction:
    ``studies._budget``) and run time; ``scheme`` names the periodic scheme (``periodic.SCHEMES``);
    a total error above ``error_tolerance`` of a peak-to-peak makes the result ``inaccurate``.
    ``budget=False``: the time step's term alone (mesh and linearisation unknown, not judged)."""
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a steady state")
    study_scheme(scheme)
    error_tolerance = check_tolerance(error_tolerance)
    start = time.perf_counter()
    linear = problem.linearize(values, n_steps=n_steps)
    steady = solve_steady(linear, scheme)
    state = steady.state
    reduction = _reduction_error(linear, state.x, n_steps, scheme)
    specs = linear.observables
    time_step = {name: {spec: float(v[k]) for k, spec in enumerate(specs)}
                 for name, v in peak_summary(steady.response, steady.response_error).items()}
    if budget:
        linearisation, lin_method, lin_time, found = linearisation_terms(linear, steady, scheme)
        mesh, mesh_method, mesh_time = mesh_terms(problem, values, specs, n_steps, scheme)
    else:
        skipped = "not estimated: budget=False"
        linearisation, lin_method, lin_time, found = {n: {} for n in QUANTITIES}, skipped, 0.0, None
        mesh, mesh_method, mesh_time = {n: {} for n in QUANTITIES}, skipped, 0.0
    reduced, reduction_method = reduction_terms(reduction, specs)
    methods = {"time_step": f"N = {n_steps} against N/2 steps ({scheme})", "mesh": mesh_method,
               "linearisation": lin_method, "reduction": reduction_method}
    run_times = {"time_step": steady.run_time, "mesh": mesh_time, "linearisation": lin_time,
                 "reduction": reduction.run_time}
    point = point_budget(specs, {"response": {s: float(steady.response_error[k]) for k, s in enumerate(specs)},
                                 "peak": time_step["peak_error"],
                                 "peak_to_peak": time_step["peak_to_peak_error"]},
                         mesh=mesh, linearisation=linearisation, reduction=reduced, methods=methods,
                         run_times=run_times, found=found)
    if reduced == NOT_APPLICABLE:
        del methods["reduction"], run_times["reduction"]
    peaks = {"peak": time_step["peak"], "peak_to_peak": time_step["peak_to_peak"],
             "peak_error": point.totals("peak"), "peak_to_peak_error": point.totals("peak_to_peak")}
    status, message = combine([(steady.status, steady.message),
                               (reduction.status, reduction.message),
                               beside(steady.status, verdict(point.budgets["peak_to_peak"],
                                                             peaks["peak_to_peak"], error_tolerance))
                               if budget else ("ok", "")])
    if not budget:
        peaks["peak_error"], peaks["peak_to_peak_error"] = time_step["peak_error"], time_step["peak_to_peak_error"]
    drawing = {}
    if hasattr(problem, "outlines"):
        outlines, magnification = problem.outlines(linear, state.x)
        drawing = {"outlines": outlines, "magnification": magnification,
                   **mechanism_drawing(linear.context)}
    return SteadyStateResult(
        problem=problem.name, parameters=problem.resolve(values), scene=problem.text,
        labels=tuple(linear.labels), units=dict(zip(linear.observables, linear.units)),
        t=state.t, crank_angle=np.asarray(linear.crank_angle, dtype=float), x=state.x,
        response={spec: steady.response[:, k] for k, spec in enumerate(linear.observables)},
        response_error=point.totals("response") if budget else dict(zip(specs, map(float, steady.response_error))),
        multipliers=state.multipliers, spectral_radius=state.spectral_radius,
        error_estimate=steady.error_estimate, status=status, message=message,
        n_steps=n_steps, run_time=time.perf_counter() - start, shooting_run_time=steady.run_time,
        is_stable=steady.is_stable, spectral_radius_error=steady.spectral_radius_error,
        instability_kind=steady.instability_kind, linear_range=steady.linear_range, **peaks,
        reduction_error=reduction.error, reduction_run_time=reduction.run_time, scheme=scheme,
        unresolved_multipliers=state.unresolved_multipliers,
        error_budget=point.budgets["peak_to_peak"].terms, peak_error_budget=point.budgets["peak"].terms,
        response_error_budget=point.budgets["response"].terms, error_methods=methods,
        error_tolerance=error_tolerance, **drawing)


def _reduction_error(linear: Any, x: np.ndarray, n_steps: int, scheme: str) -> Any:
    """``linearize.reduction_error`` of a mechanism problem's steady state ``x`` (N+1, m) against the
    next larger mode set (only that reference is solved: the response is this one's); error 0 at
    once for a mechanism without reduced links and for problems without a mechanism."""
    import linearize

    lin = linear.context
    if getattr(lin, "mechanism", None) is None:   # not a mechanism: nothing is reduced
        return linearize.ReductionCheck("next", {}, {}, {}, 0.0, linearize.REDUCTION_TOL, "ok",
                                        "no reduced link", 0.0)
    return linearize.reduction_error(lin.mechanism, n_steps=n_steps, observables=lin.observables,
                                     response=lin.observe(x), scheme=study_scheme(scheme))


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    return {"values": speed_values(where, table),
            "n_steps": steps(where, table, n_steps, minimum=MIN_STEPS)}


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> SteadyStateResult:
    return steady_state(problem, options["values"], n_steps=options["n_steps"],
                        scheme=options.get("scheme", DEFAULT_SCHEME),
                        error_tolerance=options.get("error_tolerance", ERROR_TOLERANCE))


def _summary(result: SteadyStateResult) -> str:
    errors = ", ".join(f"{k} peak to peak +- {describe(result.budget, k, result.units[k])}"
                       for k in result.error_budget)
    words = f"{result.headline}: {result.message}" if result.message else result.headline
    unresolved = np.abs(np.asarray(result.unresolved_multipliers))
    apart = (f" of the resolved modes ({unresolved.size} unresolved apart, largest |mu| {unresolved.max():.3g})"
             if unresolved.size else "")
    return (f"{words}; spectral radius {result.spectral_radius:.6f} +- "
            f"{result.spectral_radius_error:.2g}{apart}; errors {errors}; {result.run_time:.3g} s")


def _headlines(result: SteadyStateResult) -> Summary:
    rows = response_rows(result.response, result.response_error, result.units,
                         budget=result.budget if result.error_budget else None)
    for spec, terms in result.error_budget.items():
        # what the nonlinear periodic state gives, by the chord steps of the linearisation term
        shift = terms.get("linearisation")
        if isinstance(shift, float) and np.isfinite(shift) and spec in result.peak_to_peak:
            rows.append(Headline(f"{spec} peak to peak, nonlinear state (chord estimate)",
                                 result.peak_to_peak[spec] + shift / LINEARISATION_MARGIN, result.units[spec]))
    rows.append(Headline("spectral radius", float(result.spectral_radius), "1",
                         float(result.spectral_radius_error)))
    return Summary(status=result.headline, run_time=result.run_time, rows=rows)


def _figures(result: SteadyStateResult) -> dict[str, Any]:
    figures = {"": result.plot, "_multipliers": result.plot_multipliers}
    if result.outlines:
        figures["_mechanism"] = result.plot_mechanism
    return figures


def _cost(name, problem, options, workers):
    """A linearisation and a periodic solve with its error budget, and the modal reduction's check
    where a link is reduced."""
    found = cost.steady_solves(name, problem, [options["values"]], options["n_steps"], budget=True)
    return cost.with_reduction_check(found, problem, options["values"], options["n_steps"], extra_solve=False)


KIND = register_kind(StudyKind(
    name="steady_state", result=SteadyStateResult, keys=("speed", "n_steps"), check=_check, run=_run,
    summary=_summary, default=lambda nominal_speed: {}, figures=_figures, headlines=_headlines, cost=_cost,
    demo={"speed": 0.7}, schemes=True, aliases=("SteadyStateResult",)))
