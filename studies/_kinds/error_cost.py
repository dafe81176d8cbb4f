"""``[studies.error_cost]``: the error of the steady response against run time, over steps per
period and optionally a resolution parameter (e.g. a number of elements)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

import periodic

from .._kind import StudyKind, register_kind
from .._numerics import DEFAULT_SCHEME, peak_summary, solve_steady, study_scheme
from .._plots import Plot, axes_for, drawn, legend_outside, plain, tidy_log_axes
from .._result import PEAK_FIELDS, StudyResult, unknown_peaks
from .._toolkit import (
    MAX_STEPS,
    STEPS_WHY,
    Headline,
    StudiesError,
    Summary,
    axis,
    check_grid,
    check_n_steps,
    check_parameter,
    cost,
    integer,
    speed_values,
    sub_table,
)


@dataclass(frozen=True, eq=False)
class ErrorCostResult(StudyResult):
    """Error against run time (the fields every result has: ``studies._result``; the grid is
    resolutions x step counts, (n_r, n_s)). The reference is the finest resolution with
    ``reference_steps`` steps and Richardson extrapolation.

    Attributes
    ----------
    problem, scene : str
        The problem's name and scene text.
    resolution_parameter : str
        The parameter of ``resolutions`` (e.g. a number of elements; "" when only the steps vary).
    units : dict
        {spec: unit} of each observable.
    settings : dict
        The study's arguments (the periodic scheme's name under "scheme"; absent in files written
        before the studies took a scheme: the trapezoidal rule).
    resolutions : ndarray, (n_r,)
        The values of ``resolution_parameter``.
    n_steps : ndarray of int, (n_s,)
        Steps per period.
    n_dof : ndarray, (n_r,)
        The size of the linear system at each resolution.
    error : dict of ndarray, {spec: (n_r, n_s)}, 1
        The max abs difference from the reference over the period, over the reference's
        peak-to-peak.
    error_estimate : dict of ndarray, {spec: (n_r, n_s)}, 1
        The self-estimated error (same scaling).
    point_run_time : ndarray, (n_r, n_s), s
        Linearisation plus shooting at each point (``run_time`` in files written before the results
        shared their field names).
    reference_steps : int
        The reference's steps per period.
    reference_run_time : float, s
        The reference's cost.
    run_time : float, s
        The whole study (reference and points).
    status, message : str
        The reference's verdict (the errors are measured against it; "ok" and a note in files
        written before results had a status).
    point_status, point_message : ndarray of str, (n_r, n_s)
        Each point's steady-state verdict (coarse points may well be ``inaccurate``: that is what
        the study shows).
    peak, peak_error, peak_to_peak, peak_to_peak_error : dict of ndarray, {spec: (n_r, n_s)}, units[spec]
        Each point's observable summaries (``studies._numerics.peak_summary``).
    """

    problem: str
    scene: str
    resolution_parameter: str
    units: Mapping[str, str]
    settings: Mapping[str, Any]
    resolutions: np.ndarray
    n_steps: np.ndarray
    n_dof: np.ndarray
    error: Mapping[str, np.ndarray]
    error_estimate: Mapping[str, np.ndarray]
    point_run_time: np.ndarray
    reference_steps: int
    reference_run_time: float
    run_time: float = float("nan")
    status: str = "ok"
    message: str = ""
    point_status: np.ndarray | None = None
    point_message: np.ndarray | None = None
    peak: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_error: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_to_peak: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_to_peak_error: Mapping[str, np.ndarray] = field(default_factory=dict)

    # before results shared their field names, the points' run times were "run_time"
    _stored_as = {"point_run_time": ("point_run_time", "run_time")}
    _axes = {"resolutions": "@resolution_parameter", "n_steps": "n_steps"}
    _units = {"resolutions": "1", "n_steps": "1", "n_dof": "1", "error": "1", "error_estimate": "1",
              "point_run_time": "s", "point_status": "1", "point_message": "1", "peak": "@observables",
              "peak_error": "@observables", "peak_to_peak": "@observables", "peak_to_peak_error": "@observables"}

    def _filled(self, group: Any) -> dict[str, Any]:
        if "point_run_time" in group:
            return {}
        shape = np.shape(self.point_run_time)
        return {"run_time": float(self.reference_run_time + np.nansum(self.point_run_time)),
                "message": "written before error_cost results had a status: the reference was not judged",
                "point_status": np.full(shape, "missing"), "point_message": np.full(shape, ""),
                **unknown_peaks(self.error, shape)}

    def plot(self, *, axes: Any = None) -> Plot:
        """Relative error of each observable against run time, one line per resolution."""
        axes = axes_for(1, axes, height=4.8)
        ax = axes[0]
        artists: dict[str, list] = {}
        for spec in self.error:
            artists[spec] = []
            for i, level in enumerate(self.resolutions):
                name = f"{spec}" + (f", {self.resolution_parameter} = {level:g}" if self.resolution_parameter
                                    else "")
                artists[spec] += ax.loglog(self.point_run_time[i], self.error[spec][i], "o-", label=name)
                for n, x, y in zip(self.n_steps, self.point_run_time[i], self.error[spec][i]):
                    ax.annotate(f"N={n}", (x, y), fontsize="x-small")
        ax.set_xlabel("run time (s)")
        ax.set_ylabel("relative error (1)")
        tidy_log_axes(ax)
        legend_outside(ax)
        ax.set_title(f"{self.problem}: error against run time; reference {self.reference_steps} steps per period "
                     f"(run time {plain(self.reference_run_time)} s), {self.status}", fontsize="small")
        return drawn(axes, artists)


def check_step_counts(n_steps: Sequence[int], reference_steps: int | None) -> tuple[list[int], int]:
    """``(steps, reference_steps)`` checked: increasing even step counts, each a multiple of the
    first, and the reference (default 4 x the largest) a multiple of the first too."""
    steps = [check_n_steps(n, minimum=4, multiple=2, study="an error-against-cost study") for n in n_steps]
    if sorted(steps) != steps or len(set(steps)) != len(steps):
        raise StudiesError(f"n_steps: expected increasing step counts, got {n_steps!r}")
    base = steps[0]
    if any(n % base for n in steps):
        raise StudiesError(f"n_steps: every entry must be a multiple of the first ({base}) so the "
                           f"responses can be compared on common samples, got {n_steps!r}")
    reference_steps = check_n_steps(reference_steps or 4 * steps[-1], minimum=4, multiple=2,
                                    study="an error-against-cost study")
    if reference_steps % base:
        raise StudiesError(f"reference_steps: must be a multiple of {base}, got {reference_steps}")
    return steps, reference_steps


def error_cost(problem: Any, values: Mapping[str, float] | None = None, *,
               n_steps: Sequence[int] = (32, 64, 128, 256), resolution: tuple[str, Sequence[float]] | None = None,
               reference_steps: int | None = None, scheme: str = DEFAULT_SCHEME) -> ErrorCostResult:
    """Error of the steady response against run time, over steps per period and (optionally) a
    resolution parameter such as a number of elements ``("links.coupler.discretisation.n_elements",
    (1, 2, 4))``. The reference is the finest resolution at ``reference_steps`` (default 4 x the
    largest ``n_steps``) with Richardson extrapolation (order 4). Runs in-process so the times are
    comparable. ``scheme`` names the periodic scheme (``periodic.SCHEMES``)."""
    scheme_used = study_scheme(scheme)
    if not scheme_used.symmetric:   # refused before any work, not by the reference's shooting
        raise StudiesError(f"error_cost: scheme {scheme!r} is not symmetric, and the reference is a "
                           f"Richardson extrapolation that gains two orders only for a symmetric scheme; "
                           f"use a symmetric one (e.g. 'trapezoidal')")
    steps, reference_steps = check_step_counts(n_steps, reference_steps)
    base = steps[0]
    if resolution is None:
        name, levels = "", np.array([0.0])
    else:
        name = check_parameter(problem, resolution[0])
        levels = check_grid("resolution values", resolution[1])

    def at(level: float) -> dict[str, float]:
        merged = dict(values or {})
        if name:
            merged[name] = level
        return merged

    start = time.perf_counter()
    reference_linear = problem.linearize(at(levels[-1]), n_steps=reference_steps)
    reference_state = periodic.steady_state(reference_linear.system, scheme=scheme_used, extrapolate=True)
    reference = reference_linear.observe(reference_state.x)[:: reference_steps // base]
    reference_time = time.perf_counter() - start
    specs = reference_linear.observables
    scale = np.maximum(np.ptp(reference, axis=0), np.finfo(float).tiny)
    error = {s: np.full((levels.size, len(steps)), np.nan) for s in specs}
    estimate = {s: np.full((levels.size, len(steps)), np.nan) for s in specs}
    run_time = np.full((levels.size, len(steps)), np.nan)
    point_status = np.full(run_time.shape, "missing", dtype=object)
    point_message = np.full(run_time.shape, "", dtype=object)
    peaks = {measure: {s: np.full(run_time.shape, np.nan) for s in specs} for measure in PEAK_FIELDS}
    n_dof = np.zeros(levels.size)
    for i, level in enumerate(levels):
        for j, n in enumerate(steps):
            tick = time.perf_counter()
            linear = problem.linearize(at(level), n_steps=n)
            steady = solve_steady(linear, scheme)
            run_time[i, j] = time.perf_counter() - tick
            n_dof[i] = linear.system.n_dof
            point_status[i, j], point_message[i, j] = steady.status, steady.message
            for measure, summary in peak_summary(steady.response, steady.response_error).items():
                for k, spec in enumerate(specs):
                    peaks[measure][spec][i, j] = summary[k]
            response = steady.response[:: n // base]
            for k, spec in enumerate(specs):
                error[spec][i, j] = np.abs(response[:, k] - reference[:, k]).max() / scale[k]
                estimate[spec][i, j] = steady.response_error[k] / scale[k]
    return ErrorCostResult(
        problem=problem.name, scene=problem.text, resolution_parameter=name,
        units=dict(zip(specs, reference_linear.units)),
        settings={"values": dict(values or {}), "n_steps": steps, "reference_steps": reference_steps,
                  "resolution": [name, levels] if name else None, "scheme": scheme},
        resolutions=levels, n_steps=np.array(steps), n_dof=n_dof, error=error, error_estimate=estimate,
        point_run_time=run_time, reference_steps=reference_steps, reference_run_time=reference_time,
        run_time=time.perf_counter() - start, status=reference_state.status, message=reference_state.message,
        point_status=point_status.astype(str), point_message=point_message.astype(str), **peaks)


#: The most step counts an error-cost study compares (each is a run of its own).
MAX_STEP_COUNTS = 16


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    # here n_steps is the list of step counts compared, not the [studies] default
    step_list = table.get("n_steps", [32, 64, 128, 256])
    if not isinstance(step_list, list) or not step_list or len(step_list) > MAX_STEP_COUNTS:
        raise StudiesError(f"[{where}] n_steps: expected a list of at most {MAX_STEP_COUNTS} even step "
                           f"counts, got {step_list!r}"[:300])
    resolution = None
    if "resolution" in table:
        resolution = axis(f"{where}.resolution",
                          sub_table(where, table, "resolution", "{parameter = ..., values = [...]}"))
    reference = table.get("reference_steps")
    options = {"values": speed_values(where, table),
               "n_steps": tuple(integer(where, "n_steps", n, 4, even=True, maximum=MAX_STEPS, why=STEPS_WHY)
                                for n in step_list),
               "resolution": resolution,
               "reference_steps": None if reference is None else
               integer(where, "reference_steps", reference, 4, even=True, maximum=4 * MAX_STEPS,
                       why="4 times the largest n_steps")}
    try:  # how the counts fit together, checked before anything runs
        check_step_counts(options["n_steps"], options["reference_steps"])
    except StudiesError as error:
        raise StudiesError(f"[{where}] {error}") from None
    return options


def _run(problem: Any, options: Mapping[str, Any], **_: Any) -> ErrorCostResult:
    # the [studies] error_tolerance judges a result's error budget; this study measures errors
    return error_cost(problem, **{k: v for k, v in options.items() if k != "error_tolerance"})


def _summary(result: ErrorCostResult) -> str:
    best = ", ".join(f"{k} {v[-1, -1]:.2g}" for k, v in result.error.items())
    return (f"{len(result.n_steps)} step counts x {len(result.resolutions)} resolutions; finest relative "
            f"error {best} in {result.point_run_time[-1, -1]:.3g} s")


def _headlines(result: ErrorCostResult) -> Summary:
    level = (f", {result.resolution_parameter} = {plain(result.resolutions[-1], 3)}"
             if result.resolution_parameter else "")
    rows = [Headline(f"{spec} relative error at N = {result.n_steps[-1]}{level}", float(values[-1, -1]), "1",
                     where=f"(estimated {plain(result.error_estimate[spec][-1, -1])}; "
                           f"{plain(result.point_run_time[-1, -1])} s)")
            for spec, values in result.error.items()]
    return Summary(status=result.status, run_time=float(result.run_time), rows=rows)


def _varies(options: Mapping[str, Any]) -> tuple[str, ...]:
    return () if options["resolution"] is None else (options["resolution"][0],)


def _cost(name, problem, options, workers):
    """A linearisation and periodic solve per step count and resolution, and the reference (N and
    N/2 with Richardson) at the finest resolution."""
    values = dict(options["values"])
    resolution = options["resolution"]
    grids = [float(v) for v in resolution[1]] if resolution is not None else [None]
    step_counts = list(options["n_steps"])
    reference = options["reference_steps"] or 4 * max(step_counts)
    memory, seconds = 0.0, cost.STUDY_SECONDS
    largest = cost.Sizes(0, 0)
    for index, value in enumerate(grids):
        at = values if value is None else dict(values, **{resolution[0]: value})
        sizes = cost.sizes_at(problem, at)
        largest = max(largest, sizes, key=lambda s: s.m)
        # the finest resolution (the last) also computes the reference, with Richardson (N and N/2)
        counts = step_counts + ([reference, reference // 2] if index == len(grids) - 1 else [])
        for n_steps in counts:
            build_bytes, build_seconds = cost.linearisation(n_steps, sizes)
            memory = max(memory, build_bytes)
            seconds += build_seconds + cost.solve_seconds(n_steps, sizes)
    return cost.Estimate(name, memory, seconds, f"{len(step_counts)} step counts up to {reference} x "
                                                f"{len(grids)} resolutions x {largest.m} coordinates")


KIND = register_kind(StudyKind(
    name="error_cost", result=ErrorCostResult, keys=("speed", "n_steps", "reference_steps", "resolution"),
    check=_check, run=_run, summary=_summary, varies=_varies, headlines=_headlines, cost=_cost, schemes=True,
    demo={"speed": 0.7, "n_steps": [16, 32, 64, 128]}, aliases=("ErrorCostResult",)))
