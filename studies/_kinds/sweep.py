"""``[studies.sweep]``: peak-to-peak response and stability against one parameter, resonances and
parametric instabilities marked."""

from __future__ import annotations

import dataclasses
import math
import time
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

import periodic

from .._budget import (
    ERROR_TOLERANCE,
    FORMAT2_METHODS,
    GRID_CHORD_STEPS,
    NOT_APPLICABLE,
    NOT_ESTIMATED,
    ErrorBudget,
    beside,
    check_tolerance,
    grid_radius_mesh,
    linearisation_terms,
    mesh_terms,
    point_budget,
    radius_mesh_words,
    verdict,
)
from .._kind import StudyKind, register_kind
from .._numerics import (
    DEFAULT_SCHEME,
    crossings,
    frozen_modes,
    peak_summary,
    solve_steady,
    study_scheme,
    unstable_intervals,
)
from .._plots import (
    LABEL_ROW_HEIGHT,
    Plot,
    axes_for,
    cost_line,
    drawn,
    label,
    label_positions,
    largest,
    legend_outside,
    mark_statuses,
    plain,
)
from .._toolkit import (
    AXIS_KEYS,
    HARMONIC_WHY,
    MAX_HARMONIC,
    PEAK_UNITS,
    SPEED,
    GridResult,
    Headline,
    Summary,
    axis,
    check_grid,
    check_integer,
    check_n_steps,
    check_parameter,
    collect,
    combine,
    cost,
    grid_status,
    grid_summary,
    integer,
    largest_over_grid,
    listed,
    open_store,
    ranges,
    reduction_check,
    reduction_headlines,
    run_grid,
    steps,
)

#: Frozen-time eigenproblems per period for the resonance bands of a sweep (the bands of smooth
#: coefficients converge fast in the number of samples; 32 resolves a band edge to well under 1 %
#: for coefficients with a few harmonics).
FROZEN_SAMPLES = 32
#: A sweep point whose peak-to-peak error estimate exceeds this fraction of the value gets the status
#: ``STATUS_INACCURATE`` (its numbers are kept, and flagged).
INACCURATE = 0.1
STATUS_INACCURATE = "inaccurate"
#: The fewest steps per period a sweep accepts (docs/studies.md): N/4 = 4 steps is the coarsest level
#: of the error check.
MIN_STEPS = 16
#: The per-point budget terms a sweep stores ({spec: (n,)} each; ``SweepResult.error_budget``).
BUDGET_FIELDS = ("budget_time_step", "budget_mesh", "budget_linearisation")


@dataclass(frozen=True, eq=False)
class SweepResult(GridResult):
    """Peak-to-peak response and stability against one parameter (the fields every result has:
    ``studies._result``; those of every grid study: ``GridResult``).

    Attributes
    ----------
    parameter : str
        The swept parameter ("speed" or a scene path).
    parameter_unit : str
        Its unit.
    labels : tuple of str, (m,)
        The independent coordinates.
    units : dict
        {spec: unit} of each observable.
    values : ndarray, (n,), parameter_unit
        The swept values.
    speed : ndarray, (n,), rad/s
        The crank speed at each point.
    peak_to_peak, peak_to_peak_error : dict of ndarray, {spec: (n,)}, units[spec]
        Each observable's peak-to-peak over the period and its estimated error (twice the max error
        estimate plus the sampling correction of the extremes).
    peak, peak_error : dict of ndarray, {spec: (n,)}, units[spec]
        The largest magnitude over the period and its error (``studies._numerics.peak_summary``; for
        joint forces, drive torques and stresses the totals, nominal plus elastic change).
    spectral_radius, spectral_radius_error : ndarray, (n,), 1
        The monodromy's spectral radius over the resolved modes and its time-step error (format 2
        and older files: over all modes; the unresolved modes' multipliers are among
        ``multipliers``).
    spectral_radius_mesh_error : ndarray, (n,), 1, or None
        The radius's mesh term (``studies._budget.grid_radius_mesh``: the headline speeds' largest
        relative error applied to every point, as a stability chart's); None without elastic links,
        with ``budget=False``, or in a file written before the term (not estimated).
    is_stable : ndarray of bool, (n,)
        Each point's stability verdict: False where unstable beyond the radius's error bar, and
        wherever the radius has converged above 1 whatever the point's status word.
    multipliers : ndarray of complex, (n, 2m), 1
        The Floquet multipliers.
    error_estimate : ndarray, (n,), SI (see labels)
        The max error of the coordinates.
    frozen_min, frozen_max, frozen_mean : ndarray, (n, m), rad/s
        The band of each frozen-time natural frequency (ascending order) over the period.
    resonances : tuple of (k, mode, value)
        Where ``k * speed`` crosses the mean of frozen frequency ``mode`` (0-based).
    instabilities : tuple of (start, end)
        Parameter intervals where the spectral radius exceeds 1 beyond its error bar.
    linear_range : dict of ndarray, {"<link>.<measure>": (n,)}, 1
        The linear-range measures (mechanisms).
    """

    parameter: str
    parameter_unit: str
    labels: tuple[str, ...]
    units: Mapping[str, str]
    values: np.ndarray
    speed: np.ndarray | None = None
    peak_to_peak: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_to_peak_error: Mapping[str, np.ndarray] = field(default_factory=dict)
    spectral_radius: np.ndarray | None = None
    multipliers: np.ndarray | None = None
    error_estimate: np.ndarray | None = None
    frozen_min: np.ndarray | None = None
    frozen_max: np.ndarray | None = None
    frozen_mean: np.ndarray | None = None
    resonances: tuple = ()
    instabilities: tuple = ()
    spectral_radius_error: np.ndarray | None = None
    spectral_radius_mesh_error: np.ndarray | None = None
    is_stable: np.ndarray | None = None
    linear_range: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak: Mapping[str, np.ndarray] = field(default_factory=dict)
    peak_error: Mapping[str, np.ndarray] = field(default_factory=dict)
    budget_time_step: Mapping[str, np.ndarray] = field(default_factory=dict)
    budget_mesh: Mapping[str, np.ndarray] = field(default_factory=dict)
    budget_linearisation: Mapping[str, np.ndarray] = field(default_factory=dict)
    error_methods: Mapping[str, str] = field(default_factory=dict)

    @property
    def error_budget(self) -> dict[str, dict[str, Any]]:
        """{spec: {term: (n,) or "not applicable"}}: the peak-to-peak's budget at each point
        (``studies._budget``; a file of format 2 held the time step's error alone, the other terms
        read as unknown)."""
        if not self.budget_time_step:
            return {spec: {"time_step": self.peak_to_peak_error[spec],
                           "mesh": np.full_like(self.peak_to_peak_error[spec], np.nan),
                           "linearisation": np.full_like(self.peak_to_peak_error[spec], np.nan)}
                    for spec in self.peak_to_peak_error}
        return {spec: {"time_step": self.budget_time_step[spec],
                       "mesh": self.budget_mesh.get(spec, NOT_APPLICABLE),
                       "linearisation": self.budget_linearisation.get(spec, NOT_APPLICABLE)}
                for spec in self.budget_time_step}

    @property
    def budget(self) -> ErrorBudget:
        """``error_budget`` as a ``studies._budget.ErrorBudget`` (totals and dominant terms)."""
        methods = self.error_methods or (FORMAT2_METHODS if not self.budget_time_step else {})
        return ErrorBudget(self.error_budget, dict(methods))

    _axes = {"values": "@parameter"}
    _units = {
        "peak": "@observables",
        "peak_error": "@observables",
        "budget_time_step": "@observables",
        "budget_mesh": "@observables",
        "budget_linearisation": "@observables",
        "spectral_radius_error": "1",
        "spectral_radius_mesh_error": "1",
        "is_stable": "1",
        "linear_range": "1",
        "values": "@parameter_unit",
        "speed": "rad/s",
        "peak_to_peak": "@observables",
        "peak_to_peak_error": "@observables",
        "spectral_radius": "1",
        "multipliers": "1",
        "error_estimate": "SI (see labels)",
        "frozen_min": "rad/s",
        "frozen_max": "rad/s",
        "frozen_mean": "rad/s",
        **GridResult._units,
    }

    def _radius_mesh_words(self) -> str:
        """The radius's mesh term in words: "up to 0.0012", "not applicable", "not estimated"."""
        if self.spectral_radius_mesh_error is not None:
            return radius_mesh_words(self.spectral_radius_mesh_error)
        words = self.error_methods.get("spectral_radius_mesh", "")
        return NOT_APPLICABLE if words.startswith(NOT_APPLICABLE) else NOT_ESTIMATED

    def _dominant_words(self) -> str:
        """" (mostly linearisation)": the budget term that dominates the most points' total error."""
        if not self.budget_time_step:
            return " (time step only)"
        found = self.budget
        names = [str(name) for spec in found for name in np.atleast_1d(found.dominant(spec))]
        if not names:
            return ""
        most = max(set(names), key=names.count)
        return f" (mostly {most.replace('_', ' ')})"

    def plot(self, *, axes: Any = None) -> Plot:
        """Peak-to-peak of each observable and the spectral radius against the swept parameter, with
        resonances (dotted lines, labelled k:mode) and parametric instabilities (shaded)."""
        specs = list(self.peak_to_peak)
        axes = axes_for(len(specs) + 1, axes)
        x = self.values
        artists: dict[str, list] = {}
        xlabel = label(self.parameter, self.parameter_unit)
        for ax, spec in zip(axes, specs):
            artists[spec] = ax.semilogy(x, self.peak_to_peak[spec], ".-", color="C0", label="peak to peak")
            # a long name on two lines: a label longer than the 2.6 in axes is clipped
            ax.set_ylabel(label(f"{spec}{chr(10) if len(spec) > 12 else ' '}peak to peak", self.units[spec]))
        if self.spectral_radius is not None:
            artists["spectral_radius"] = axes[-1].plot(x, self.spectral_radius, ".-", color="C1")
            artists["stability_limit"] = [axes[-1].axhline(1.0, color="k", lw=1.2)]
            if largest(self.spectral_radius) > 10.0:  # a linear scale to 1000 would hide |mu| near 1
                axes[-1].set_yscale("log")
        axes[-1].set_ylabel("spectral radius |mu|max")
        # each point's verdict: unstable, marginal, inaccurate, outside the linear range ... marked
        curves = [self.peak_to_peak[spec] for spec in specs] + [self.spectral_radius]
        artists["status"] = []
        for ax, y in zip(axes, curves):
            if y is not None:
                artists["status"] += mark_statuses(ax, x, y, self.point_status)
        if artists["status"]:
            # below the lowest axes, under its label: all axes keep the full width
            legend_outside(axes[-1], loc="upper center", bbox_to_anchor=(0.5, -0.3), ncols=4)
        for ax in axes:
            ax.set_xlabel(xlabel)
            for start, end in self.instabilities:
                artists.setdefault("instabilities", []).append(ax.axvspan(start, end, color="C3", alpha=0.2))
        for _k, _mode, value in self.resonances:
            for ax in axes:
                artists.setdefault("resonances", []).append(ax.axvline(value, color="0.5", ls=":", lw=0.8))
        # the k:mode labels in staggered rows above the top axes, the lowest harmonics first (the
        # strongest resonances); labels that would collide are left out
        strongest = sorted(self.resonances, key=lambda item: (item[0], item[1]))
        artists["resonance_labels"], rows = label_positions(
            axes[0], [value for _, _, value in strongest], [f"{k}:{mode + 1}" for k, mode, _ in strongest])
        relative = [np.asarray(self.peak_to_peak_error.get(spec), dtype=float)
                    / np.asarray(self.peak_to_peak[spec], dtype=float)
                    for spec in specs if self.peak_to_peak_error.get(spec) is not None]
        axes[0].set_title(cost_line(f"{self.problem}: {len(x)} points over {self.parameter}\nlargest estimated error "
                                    f"{plain(100 * largest(relative))} % of peak to peak"
                                    + self._dominant_words(), self.run_time)
                          + self.reduction_note()
                          + ("\nresonances: harmonic k : mode (k x speed = mode frequency)" if rows else ""),
                          fontsize="small", pad=4 + rows * LABEL_ROW_HEIGHT)
        return drawn(axes, artists)


def sweep_point(problem: Any, values: Mapping[str, float], *, n_steps: int, frozen_samples: int,
                scheme: str = DEFAULT_SCHEME, error_tolerance: float = ERROR_TOLERANCE,
                mesh_relative: Mapping[str, float] | None = None, budget: bool = True):
    """One sweep point: steady state, multipliers, frozen frequency bands, the error budget of each
    peak-to-peak (time step, the point's own linearisation term, the mesh term as ``mesh_relative``
    {spec: relative error of the headline point} times the value: ``studies._budget``) (a top-level
    function so that process pools and Dask can pickle it). ``budget=False``: the time step's term
    alone (the others unknown), without the linearisation's cost."""
    linear = problem.linearize(values, n_steps=n_steps, context=False)
    steady = solve_steady(linear, scheme)
    _, frozen, _ = frozen_modes(linear.system, frozen_samples)
    response = steady.response
    data = {
        "speed": 2.0 * math.pi / linear.system.period,
        "spectral_radius": steady.state.spectral_radius,
        "spectral_radius_error": steady.spectral_radius_error,
        "is_stable": float(steady.is_stable),
        "multipliers": steady.state.multipliers,
        "error_estimate": steady.error_estimate,
        "frozen_min": frozen.min(axis=0),
        "frozen_max": frozen.max(axis=0),
        "frozen_mean": frozen.mean(axis=0),
    }
    data.update({f"linear_range/{name}": value for name, value in steady.linear_range.items()})
    verdicts = [(steady.status, steady.message)]
    peaks = peak_summary(response, steady.response_error)
    specs = linear.observables
    time_step = {"response": dict(zip(specs, map(float, steady.response_error))),
                 "peak": dict(zip(specs, map(float, peaks["peak_error"]))),
                 "peak_to_peak": dict(zip(specs, map(float, peaks["peak_to_peak_error"])))}
    linearisation: Any = math.nan   # unknown: not estimated
    if budget:
        linearisation, _, _, _ = linearisation_terms(linear, steady, scheme, max_steps=GRID_CHORD_STEPS)
    mesh: Any = NOT_APPLICABLE
    if mesh_relative:
        mesh = {name: {spec: abs(float(mesh_relative.get(spec, math.nan))) * float(peaks[name][k])
                       for k, spec in enumerate(specs)} for name in ("peak", "peak_to_peak")}
        mesh["response"] = mesh["peak"]
    point = point_budget(specs, time_step, mesh=mesh, linearisation=(
        linearisation if budget else {name: {} for name in time_step}))
    ptp_budget = point.budgets["peak_to_peak"]
    for k, spec in enumerate(specs):
        for name, values in peaks.items():
            data[f"{name}/{spec}"] = float(values[k])
        data[f"budget_time_step/{spec}"] = time_step["peak_to_peak"][spec]
        if isinstance(linearisation, dict):
            data[f"budget_linearisation/{spec}"] = float(linearisation["peak_to_peak"][spec])
        if mesh != NOT_APPLICABLE:
            data[f"budget_mesh/{spec}"] = float(mesh["peak_to_peak"][spec])
        if budget:
            data[f"peak_to_peak_error/{spec}"] = float(ptp_budget.total(spec))
            data[f"peak_error/{spec}"] = float(point.budgets["peak"].total(spec))
        value, error = peaks["peak_to_peak"][k], peaks["peak_to_peak_error"][k]
        if not error <= INACCURATE * value:
            verdicts.append((STATUS_INACCURATE,
                             f"{spec}: peak-to-peak error estimate {error:.3g} exceeds {INACCURATE:.0%} of "
                             f"the value {value:.3g}; refine n_steps (typically near a resonance)"))
    if budget:
        verdicts.append(beside(steady.status, verdict(
            ptp_budget, dict(zip(specs, map(float, peaks["peak_to_peak"]))), error_tolerance)))
    status, message = combine(verdicts)
    return data, status, message


def sweep(problem: Any, parameter: str, values: Sequence[float], *, n_steps: int = 256,
          max_harmonic: int = 4, executor: Executor | None = None, out: Any = None,
          name: str = "sweep", progress: bool = False, scheme: str = DEFAULT_SCHEME,
          error_tolerance: float = ERROR_TOLERANCE, budget: bool = True) -> SweepResult:
    """Sweep ``parameter`` (e.g. ``"speed"``) over ``values``: peak-to-peak of each observable and its
    error, spectral radius, multipliers, frozen frequency bands; resonances ``k * speed`` (k = 1 ..
    ``max_harmonic``) crossing a mean frozen frequency and parametric instabilities (spectral radius
    above 1) marked. ``out``: h5py File/Group to write into (resumable). ``scheme`` names the
    periodic scheme (``periodic.SCHEMES``). Each point's peak-to-peak error is the total of its
    budget (``error_budget``: time step, its own linearisation term, the mesh term of the scene's
    point applied relatively); a total above ``error_tolerance`` of the value is ``inaccurate``. The
    spectral radius carries its mesh term too (``spectral_radius_mesh_error``, from the headline
    speeds: ``studies._budget.grid_radius_mesh``), each point's radius judged on its total as a
    stability chart's cell is.
    ``budget=False``: the time step's error alone, as before the budget (the other terms
    unknown: the points are not judged by them)."""
    start = time.perf_counter()
    study_scheme(scheme)
    error_tolerance = check_tolerance(error_tolerance)
    parameter = check_parameter(problem, parameter)
    grid = check_grid("values", values)
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a sweep")
    max_harmonic = check_integer("max_harmonic", max_harmonic, 1)
    names = problem.describe({parameter: float(grid[0])})
    obs_units = dict(zip(names.observables, names.units))
    # the frozen samples are taken among the steps: at most n_steps of them, and the file records
    # the number used
    frozen_samples = min(FROZEN_SAMPLES, n_steps)
    mesh_relative, mesh_method, scene_radius = (({}, "", None) if not budget else
                                                _mesh_headline(problem, names.observables, n_steps, scheme))
    settings = {"parameter": parameter, "values": grid, "n_steps": n_steps, "scene": problem.text,
                "frozen_samples": frozen_samples, "scheme": scheme, "error_tolerance": error_tolerance,
                "budget": bool(budget)}
    units = {"speed": "rad/s", "spectral_radius": "1", "spectral_radius_error": "1", "is_stable": "1",
             "linear_range": "1", "multipliers": "1",
             "error_estimate": "SI (see labels)", "frozen_min": "rad/s", "frozen_max": "rad/s",
             "frozen_mean": "rad/s"}
    units.update({f"peak_to_peak/{s}": u for s, u in obs_units.items()})
    units.update({f"{name}/{s}": u for s, u in obs_units.items()
                  for name in ("peak_to_peak_error", "peak", "peak_error") + BUDGET_FIELDS})
    header = dict(problem=problem.name, scene=problem.text, parameter=parameter,
                  parameter_unit=problem.units[parameter], labels=names.labels, units=obs_units)
    store = open_store(out, name, grid.shape, SweepResult, settings, units, header,
                       {"values": (grid, problem.units[parameter])})
    points = [((i,), {parameter: float(v)}) for i, v in enumerate(grid)]
    outcomes = run_grid(sweep_point, problem, points,
                        {"n_steps": n_steps, "frozen_samples": frozen_samples, "scheme": scheme,
                         "error_tolerance": error_tolerance, "mesh_relative": mesh_relative,
                         "budget": bool(budget)},
                        executor=executor,
                        store=store, progress=progress, description=f"{name} over {parameter}")
    fields = collect(outcomes, grid.shape)
    per_observable = {name: {spec: fields.pop(f"{name}/{spec}") for spec in obs_units
                             if f"{name}/{spec}" in fields}
                      for name in ("peak_to_peak", "peak_to_peak_error", "peak", "peak_error") + BUDGET_FIELDS}
    ranges = {name: fields.pop(f"linear_range/{name}") for name in
              [key.split("/", 1)[1] for key in fields if key.startswith("linear_range/")]}
    reduction = reduction_check(problem, n_steps=n_steps)
    resonances, instabilities = (), ()
    if "is_stable" in fields:
        fields["is_stable"] = fields["is_stable"] == 1.0
    if "spectral_radius" in fields:
        resonances = _resonances(grid, fields["speed"], fields["frozen_mean"], max_harmonic)
        # unstable where the radius exceeds 1 beyond its own error bar (periodic.stability_verdict)
        lower = fields["spectral_radius"] - np.nan_to_num(fields.get("spectral_radius_error", 0.0))
        instabilities = tuple(unstable_intervals(grid, lower, tol=periodic.STABILITY_TOL))
    # the radius's mesh term at the headline speeds, each point's verdict judged with the total (as a
    # stability chart's: studies._budget.grid_radius_mesh)
    radius_mesh: Any = None
    radius_method = "not estimated: the sweep ran with budget=False (the time step's error alone)"
    if budget and "spectral_radius" in fields:
        radius_mesh, radius_method = grid_radius_mesh(problem, fields, points, n_steps=n_steps, scheme=scheme,
                                                      tolerance=error_tolerance, scene_radius=scene_radius)
        radius_mesh = None if isinstance(radius_mesh, str) else radius_mesh
    result = SweepResult(**header, settings=settings, values=grid, **per_observable,
                         resonances=resonances, linear_range=ranges,
                         instabilities=instabilities, run_time=time.perf_counter() - start, **fields,
                         spectral_radius_mesh_error=radius_mesh,
                         error_methods={**_methods(n_steps, scheme, mesh_method,
                                                   bool(per_observable["budget_linearisation"]), budget),
                                        "spectral_radius_mesh": radius_method},
                         **reduction)
    if store is not None:
        result.to_hdf5(store.group)
    return result


def _mesh_headline(problem: Any, specs: Any, n_steps: int, scheme: str
                   ) -> tuple[dict[str, float], str, float | None]:
    """The mesh term at the scene's own point, relative to its peak-to-peak ({spec: relative}, empty
    where it does not apply), and its words: the sweep applies it to every point; and the spectral
    radius there (None where the term does not apply), a headline point of the radius's term."""
    mesh, method, _ = mesh_terms(problem, None, specs, n_steps, scheme)
    if mesh == NOT_APPLICABLE:
        return {}, method, None
    steady = solve_steady(problem.linearize(None, n_steps=n_steps, context=False), scheme)
    values = peak_summary(steady.response, steady.response_error)["peak_to_peak"]
    relative = {spec: float(mesh["peak_to_peak"].get(spec, math.nan)) / max(float(values[k]), 1e-300)
                for k, spec in enumerate(specs)}
    return (relative, f"{method}, at the scene's point, applied to every point relatively",
            float(steady.state.spectral_radius))


def _methods(n_steps: int, scheme: str, mesh_method: str, linearised: bool, budget: bool) -> dict[str, str]:
    skipped = "not estimated: the sweep ran with budget=False (the time step's error alone)"
    return {"time_step": f"N = {n_steps} against N/2 steps ({scheme})",
            "mesh": mesh_method if budget else skipped,
            "linearisation": (skipped if not budget else
                              "chord steps of the nonlinear periodic problem at each point"
                              if linearised else "not applicable: the problem is linear as written")}


def _resonances(grid: np.ndarray, speed: np.ndarray, frozen_mean: np.ndarray, max_harmonic: int):
    found = []
    for mode in range(frozen_mean.shape[1]):
        for k in range(1, max_harmonic + 1):
            for _, value in crossings(grid, k * speed - frozen_mean[:, mode]):
                found.append((k, mode, value))
    return tuple(sorted(found, key=lambda item: item[2]))


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    parameter, grid = axis(where, table)
    return {"parameter": parameter, "values": grid,
            "max_harmonic": integer(where, "max_harmonic", table.get("max_harmonic", 4), 1,
                                    maximum=MAX_HARMONIC, why=HARMONIC_WHY),
            "n_steps": steps(where, table, n_steps, minimum=MIN_STEPS)}


def _run(problem: Any, options: Mapping[str, Any], *, out: Any, executor: Any, progress: bool) -> SweepResult:
    return sweep(problem, options["parameter"], options["values"], n_steps=options["n_steps"],
                 max_harmonic=options["max_harmonic"], executor=executor, out=out, name=KIND.name,
                 progress=progress, scheme=options.get("scheme", DEFAULT_SCHEME),
                 error_tolerance=options.get("error_tolerance", ERROR_TOLERANCE))


def _summary(result: SweepResult) -> str:
    unit = result.parameter_unit if result.parameter_unit not in ("", "1") else ""
    intervals = ", ".join(f"{a:.4g}-{b:.4g}" for a, b in result.instabilities)
    return grid_summary(result, f"; {len(result.resonances)} resonances, {len(result.instabilities)} "
                                f"unstable intervals" + (f" ({result.parameter} {intervals} {unit})"
                                                         if intervals else ""),
                        point=lambda index: f"{result.parameter} {result.values[index]:.4g} {unit}".rstrip())


def _headlines(result: SweepResult) -> Summary:
    unit = result.parameter_unit
    suffix = f" {unit}" if unit not in ("", "1") else ""

    def point(index: tuple) -> str:
        return f"{result.parameter} {plain(result.values[index], 3)}{suffix}"

    # The headline response is the curve's highest peak (its largest local maximum: a resonance, not
    # the last point before a threshold), at a point whose linear periodic solution is what the
    # machine does (not failed, unstable or outside the linear range; a near_resonance or inaccurate
    # point is a peak's own), with that point's status. A higher peak at a point outside the linear
    # range (a resonance just past a limit) is shown beside it with its status, and the largest over
    # all points when it sits at a point that is not "ok".
    statuses = np.asarray(result.point_status)
    done = np.asarray(result.done, dtype=bool)
    trusted = done & (statuses == "ok")
    reached = done & ~np.isin(statuses, ("failed", "unstable", "outside_linear_range"))
    periodic = done & ~np.isin(statuses, ("failed", "unstable"))

    def largest(name: str, values: Any, errors: Any, unit_of_values: str) -> list[Headline]:
        values = np.asarray(values, dtype=float)
        rows = [highest_peak(f"{name}, highest peak", values, errors, unit_of_values, reached, statuses,
                             point)]
        beyond = highest_peak(f"{name}, highest peak outside the linear range", values, errors, unit_of_values,
                              periodic, statuses, point)
        if np.isfinite(beyond.value) and not beyond.value <= rows[0].value and "no interior" not in beyond.where:
            rows.append(beyond)
        if np.isfinite(values).any():
            index = np.unravel_index(np.nanargmax(values), values.shape)
            if not trusted[index]:
                rows.append(Headline(f"largest {name}, any point", float(values[index]), unit_of_values,
                                     where=f"at {point(index)}: {statuses[index]}, not a trustworthy "
                                           f"steady state"))
        return rows

    rows = [row for spec, values in result.peak_to_peak.items()
            for row in largest(f"{spec} peak to peak", values, result.peak_to_peak_error.get(spec),
                               result.units[spec])]
    if result.budget_time_step:
        rows.append(Headline("error budget", f"total of time step, mesh, linearisation{result._dominant_words()}"))
    # the peak force or stress over the sweep, where the result holds peaks (see PEAK_UNITS)
    peaks = getattr(result, "peak", None) or {}
    peak_errors = getattr(result, "peak_error", None) or {}
    rows += [row for spec, values in peaks.items() if result.units.get(spec) in PEAK_UNITS
             for row in largest(f"{spec} peak", values, peak_errors.get(spec), result.units[spec])]
    resonances = [f"{k}:{mode + 1} at {plain(value, 3)}" for k, mode, value in result.resonances]
    rows.append(Headline(f"resonances, harmonic:mode at {label(result.parameter, unit)}", listed(resonances)))
    rows.append(Headline(f"unstable {result.parameter} ranges", ranges(result.instabilities, unit)))
    if result.spectral_radius is not None:
        # its error bar the budget's total: the time step's and, where estimated, the mesh term
        total = np.asarray(result.spectral_radius_error, dtype=float)
        if result.spectral_radius_mesh_error is not None:
            total = total + np.abs(np.asarray(result.spectral_radius_mesh_error, dtype=float))
        mesh = result._radius_mesh_words()
        rows.append(largest_over_grid("largest spectral radius" + ("" if result.spectral_radius_mesh_error is not None
                                                                   else f" (time-step error; mesh {mesh})"),
                                      result.spectral_radius, total, "1", point))
        rows.append(Headline("spectral radius error budget", f"time step, mesh {mesh} (linearisation not applicable)"))
    return Summary(status=grid_status(result), run_time=result.run_time, rows=rows + reduction_headlines(result))


def highest_peak(name: str, values: np.ndarray, errors: Any, unit: str, eligible: np.ndarray,
                 statuses: np.ndarray, point: Any) -> Headline:
    """The row of the largest local maximum of a sweep's curve ``values`` (n,) among the
    ``eligible`` points (n,) (a point at least as large as its finite neighbours, every done point
    counted as a neighbour), with its error and status; where the curve has no such peak (it rises
    to the end of the grid or to a point that is not eligible), its largest eligible point, said so."""
    values = np.asarray(values, dtype=float)
    finite = np.isfinite(values)
    left = np.concatenate(([-np.inf], np.where(finite[:-1], values[:-1], -np.inf)))
    right = np.concatenate((np.where(finite[1:], values[1:], -np.inf), [-np.inf]))
    interior = np.ones(values.shape, dtype=bool)
    interior[[0, -1]] = False
    peaks = eligible & finite & interior & (values >= left) & (values >= right)
    note = ""
    if not peaks.any():
        peaks = eligible & finite
        note = " (no interior peak: the largest point)"
    if not peaks.any():
        return Headline(name, math.nan, unit)
    index = (int(np.nanargmax(np.where(peaks, values, np.nan))),)
    error = math.nan if errors is None else float(np.asarray(errors, dtype=float)[index])
    return Headline(name, float(values[index]), unit, error, f"at {point(index)}: {statuses[index]}{note}")


def _default(nominal_speed: float) -> dict[str, Any]:
    """100 speeds from 0.2 to 4 times the scene's."""
    return {"parameter": SPEED, "start": 0.2 * abs(nominal_speed), "stop": 4.0 * abs(nominal_speed),
            "count": 100}


def _cost(name, problem, options, workers, done=None):
    """A periodic solve, its error budget and 32 frozen-time eigenproblems per point
    (``studies._cost.grid_cost``), the mesh term at the scene's point, the radius's mesh term at three
    headline speeds (``studies._budget.grid_radius_mesh``: the refined model's linearisation and a
    refined Floquet solve at each; measured 0.19 s on four_bar_fem4's 200-speed sweep at 256 steps,
    estimated 0.44 s)."""
    axis = (options["parameter"], np.asarray(options["values"]))
    found = cost.grid_cost(name, problem, [axis], options["n_steps"], workers=workers, frozen=32, done=done,
                      point_doubles=lambda s: 8.0 * s.m + 4.0, words=[cost.axis_words(*axis)], budget=True)
    found = cost.with_mesh_term(found, problem, {}, options["n_steps"], relative=True, held=found.memory)
    # (after the grid, as a stability chart's; run again on a resumed sweep: every point re-judged)
    found = cost.with_mesh_term(found, problem, {}, options["n_steps"])
    if hasattr(problem, "mechanism"):
        sizes = cost.sizes_at(problem, {})
        refined = cost.Sizes(n=cost.MESH_REFINEMENT * sizes.n, m=cost.MESH_REFINEMENT * sizes.m)
        found = dataclasses.replace(found, time=found.time + 2.0 * cost.solve_seconds(options["n_steps"], refined))
    return cost.with_reduction_check(found, problem, {}, options["n_steps"])


KIND = register_kind(StudyKind(
    name="sweep", result=SweepResult, keys=AXIS_KEYS + ("max_harmonic", "n_steps"), check=_check, run=_run,
    summary=_summary, grid=True, point=sweep_point, varies=lambda options: (options["parameter"],),
    default=_default, headlines=_headlines, cost=_cost, schemes=True,
    demo={"parameter": "speed", "start": 0.2, "stop": 3.0, "count": 57}, aliases=("SweepResult",)))
