"""``[studies.stability_chart]``: the spectral radius of the monodromy over two parameters, with its
error estimate; the boundary ``|mu| = 1`` drawn."""

from __future__ import annotations

import time
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

import periodic

from .._budget import (
    ERROR_TOLERANCE,
    NOT_APPLICABLE,
    RADIUS_METHODS,
    check_tolerance,
    grid_radius_mesh,
    radius_budget,
    radius_mesh_words,
    radius_verdict,
)
from .._kind import StudyKind, register_kind
from .._numerics import DEFAULT_SCHEME, study_scheme
from .._plots import Plot, axes_for, cost_line, drawn, label, largest, legend_outside, mark_statuses, plain, radius_norm
from .._result import NoObservables
from .._toolkit import (
    SPEED,
    GridResult,
    Headline,
    StudiesError,
    Summary,
    axis,
    check_grid,
    check_n_steps,
    check_parameter,
    collect,
    combine,
    cost,
    grid_status,
    grid_summary,
    largest_over_grid,
    open_store,
    ranges,
    reduction_check,
    reduction_headlines,
    run_grid,
    steps,
    sub_table,
)

#: The fewest steps per period a stability chart accepts (docs/studies.md).
MIN_STEPS = 32


@dataclass(frozen=True, eq=False)
class StabilityChart(NoObservables, GridResult):
    """Spectral radius over two parameters (the fields every result has: ``studies._result``; no
    observable response, so ``peak``... are empty; those of every grid study: ``GridResult``).

    Attributes
    ----------
    parameters : tuple of str, (2,)
        The two parameters.
    parameter_units : tuple of str, (2,)
        Their units.
    first : ndarray, (n1,), parameter_units[0]
        The values of ``parameters[0]``.
    second : ndarray, (n2,), parameter_units[1]
        The values of ``parameters[1]``.
    spectral_radius, spectral_radius_error : ndarray, (n1, n2), 1
        The spectral radius of each cell and its estimated error (N against N/2 steps).
    spectral_radius_mesh_error : ndarray, (n1, n2), 1, or None
        The radius's mesh term (``studies._budget.grid_radius_mesh``: the headline points'
        relative error applied to every cell); None without elastic links, or in a file written
        before the term.
    is_stable : ndarray of bool, (n1, n2)
        Each cell's stability (unstable only beyond the radius's error bar, marginal within it).
    stability_tol : float, 1
        The tolerance of ``|mu| = 1``.
    error_methods : dict, {term: str}
        How each term of the radius's error budget (``error_budget``) was estimated, in words.
    """

    parameters: tuple[str, str]
    parameter_units: tuple[str, str]
    first: np.ndarray
    second: np.ndarray
    spectral_radius: np.ndarray | None = None
    spectral_radius_error: np.ndarray | None = None
    spectral_radius_mesh_error: np.ndarray | None = None
    stability_tol: float = 1e-6
    is_stable: np.ndarray | None = None
    error_methods: Mapping[str, str] = field(default_factory=lambda: dict(RADIUS_METHODS))

    @property
    def error_budget(self) -> dict[str, dict[str, Any]]:
        """{"spectral_radius": {term: (n1, n2) or words}}: the radius's error budget (``studies._budget``:
        its time step, its mesh term (not applicable without elastic links, not estimated in a file
        written before the term), the linearisation not applicable)."""
        return radius_budget(self.spectral_radius_error, self._mesh_term())

    def _mesh_term(self) -> Any:
        if self.spectral_radius_mesh_error is not None:
            return self.spectral_radius_mesh_error
        return NOT_APPLICABLE if self.error_methods.get("mesh", "").startswith(NOT_APPLICABLE) else None

    def _mesh_words(self) -> str:
        return radius_mesh_words(self._mesh_term())

    _axes = {"first": "@parameters[0]", "second": "@parameters[1]"}
    _units = {"spectral_radius": "1", "spectral_radius_error": "1", "spectral_radius_mesh_error": "1",
              "is_stable": "1", **GridResult._units}

    def _unit(self, name: str, key: str | None = None) -> str:
        if name == "first":
            return self.parameter_units[0]
        if name == "second":
            return self.parameter_units[1]
        return super()._unit(name, key)

    def plot(self, *, axes: Any = None) -> Plot:
        """Spectral radius map (colour: blue stable, red unstable, white |mu| = 1, on a log scale each
        side of 1 so that radii near 1 show beside radii of 1000) with the boundary |mu| = 1 (thick
        black contour)."""
        axes = axes_for(1, axes, height=4.8)
        ax = axes[0]
        radius = np.asarray(self.spectral_radius, dtype=float)
        norm = radius_norm(radius)
        mesh = ax.pcolormesh(self.first, self.second, radius.T, shading="nearest", cmap="RdBu_r", norm=norm)
        artists = {"spectral_radius": [mesh]}
        level = 1.0 + self.stability_tol
        if np.nanmin(radius) < level < np.nanmax(radius) and min(radius.shape) > 1:
            artists["stability_limit"] = [ax.contour(self.first, self.second, radius.T, levels=[level],
                                                     colors="k", linewidths=2.0)]
        colorbar = ax.figure.colorbar(mesh, ax=ax, label="spectral radius |mu|max")
        ticks = radius_ticks(norm)
        colorbar.set_ticks(ticks, labels=[f"{t:g}" for t in ticks])
        artists["colorbar"] = [colorbar]
        # each cell's verdict: unstable cells crossed, marginal / inaccurate ... marked, with a legend
        first, second = np.meshgrid(self.first, self.second, indexing="ij")
        artists["status"] = mark_statuses(ax, first, second, self.point_status)
        if artists["status"]:
            # below the axes: the colour bar takes their right
            legend_outside(ax, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncols=4)
        ax.set_xlabel(label(self.parameters[0], self.parameter_units[0]))
        ax.set_ylabel(label(self.parameters[1], self.parameter_units[1]))
        ax.set_title(
            f"{self.problem}: stability chart (black: |mu| = 1; colours on a log scale each side of 1)\n"
            + cost_line(f"spectral radius to {plain(largest(self.spectral_radius_error))} (time step; "
                        f"mesh {self._mesh_words()})", self.run_time)
            + self.reduction_note(),
            fontsize="small",
        )
        return drawn(axes, artists)


#: Colour-bar ticks of the spectral radius, most telling first (1, then round values outwards).
_RADIUS_TICKS = (1.0, 0.5, 2.0, 10.0, 100.0, 1000.0, 1e4, 0.8, 1.2, 0.9, 1.1, 5.0, 0.95, 1.05, 0.99, 1.01)


def radius_ticks(norm: Any, *, spacing: float = 0.08) -> list[float]:
    """Ticks of the colour bar: the values of ``_RADIUS_TICKS`` in range, each at least ``spacing``
    (fraction of the bar) from the ones already taken, so their labels do not collide."""
    taken: list[float] = []
    for tick in _RADIUS_TICKS:
        if norm.vmin <= tick <= norm.vmax and all(abs(float(norm(tick)) - float(norm(t))) >= spacing for t in taken):
            taken.append(tick)
    return sorted(taken)


def chart_point(problem: Any, values: Mapping[str, float], *, n_steps: int, scheme: str = DEFAULT_SCHEME,
                error_tolerance: float = ERROR_TOLERANCE):
    """Spectral radius of the monodromy at one point of a stability chart, with its error estimate;
    an error above ``error_tolerance`` of the radius is ``inaccurate`` (``studies._budget``)."""
    linear = problem.linearize(values, n_steps=n_steps, context=False)
    result = periodic.floquet(linear.system, scheme=study_scheme(scheme), estimate_error=True)
    unresolved = ~result.resolved & (np.abs(result.multipliers) > 1.0 + result.stability_tol)
    status, message = combine([
        (result.status, result.message),
        ("unresolved_stiff_mode" if unresolved.any() else "ok",
         "an unstable multiplier belongs to a mode the step does not resolve: refine n_steps"
         if unresolved.any() else ""),
        radius_verdict(result.spectral_radius, result.spectral_radius_error, error_tolerance)])
    return {"spectral_radius": result.spectral_radius,
            "spectral_radius_error": result.spectral_radius_error,
            "is_stable": float(result.is_stable)}, status, message


def stability_chart(problem: Any, first: tuple[str, Sequence[float]], second: tuple[str, Sequence[float]],
                    *, n_steps: int = 128, executor: Executor | None = None, out: Any = None,
                    name: str = "stability_chart", progress: bool = False,
                    scheme: str = DEFAULT_SCHEME, error_tolerance: float = ERROR_TOLERANCE) -> StabilityChart:
    """Spectral radius of the monodromy, and its error estimate (N against N/2 steps), over a grid of
    two parameters ``(name, values)``; the boundary ``|mu| = 1`` is drawn by ``plot``. ``scheme``
    names the periodic scheme (``periodic.SCHEMES``); a cell whose radius error (its budget,
    ``error_budget``) exceeds ``error_tolerance`` of the radius is ``inaccurate``."""
    start = time.perf_counter()
    study_scheme(scheme)
    error_tolerance = check_tolerance(error_tolerance)
    if not (isinstance(first, tuple) and len(first) == 2 and isinstance(second, tuple) and len(second) == 2):
        raise TypeError(f"first, second: expected (parameter name, values) pairs, got {first!r}, {second!r}")
    names = (check_parameter(problem, first[0]), check_parameter(problem, second[0]))
    if names[0] == names[1]:
        raise StudiesError(f"stability_chart: the two parameters must differ, got {names[0]!r} twice")
    axes = (check_grid(f"{names[0]} values", first[1]), check_grid(f"{names[1]} values", second[1]))
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a stability chart")
    shape = (axes[0].size, axes[1].size)
    settings = {"parameters": names, "first": axes[0], "second": axes[1], "n_steps": int(n_steps),
                "scene": problem.text, "scheme": scheme, "error_tolerance": error_tolerance}
    units = (problem.units[names[0]], problem.units[names[1]])
    header = dict(problem=problem.name, scene=problem.text, parameters=names, parameter_units=units,
                  stability_tol=periodic.STABILITY_TOL)
    store = open_store(out, name, shape, StabilityChart, settings,
                       {"spectral_radius": "1", "spectral_radius_error": "1", "is_stable": "1"}, header,
                       {"first": (axes[0], units[0]), "second": (axes[1], units[1])})
    # The crank speed varies fastest, so that consecutive points (and a worker's batch) share the
    # other parameter and reuse one speed family of the linearisation.
    speed_first = names[0] == SPEED
    points = [((i, j), {names[0]: float(axes[0][i]), names[1]: float(axes[1][j])})
              for outer in range(shape[1 if speed_first else 0])
              for inner in range(shape[0 if speed_first else 1])
              for i, j in [(inner, outer) if speed_first else (outer, inner)]]
    outcomes = run_grid(chart_point, problem, points, {"n_steps": int(n_steps), "scheme": scheme,
                                                       "error_tolerance": error_tolerance}, executor=executor,
                        store=store, progress=progress, description=f"{name}")
    fields = collect(outcomes, shape)
    if "is_stable" in fields:
        fields["is_stable"] = fields["is_stable"] == 1.0
    mesh, mesh_method = grid_radius_mesh(problem, fields, points, n_steps=int(n_steps), scheme=scheme,
                                         tolerance=error_tolerance)
    reduction = reduction_check(problem, n_steps=int(n_steps))
    result = StabilityChart(**header, settings=settings, first=axes[0], second=axes[1],
                            run_time=time.perf_counter() - start, **fields, **reduction,
                            spectral_radius_mesh_error=None if isinstance(mesh, str) else mesh,
                            error_methods={**RADIUS_METHODS, "mesh": mesh_method})
    if store is not None:
        result.to_hdf5(store.group)
    return result


def _summary(result: StabilityChart) -> str:
    (a, b), (ua, ub) = result.parameters, result.parameter_units
    return grid_summary(result, point=lambda index: f"{a} {result.first[index[0]]:.4g} {ua}, "
                                                    f"{b} {result.second[index[1]]:.4g} {ub}")


def _headlines(result: StabilityChart) -> Summary:
    (a, b), (ua, ub) = result.parameters, result.parameter_units

    def point(index: tuple) -> str:
        return (f"{a} {plain(result.first[index[0]], 3)} {ua}, ".replace(" 1,", ",")
                + f"{b} {plain(result.second[index[1]], 3)} {ub}".removesuffix(" 1"))

    unstable = (result.point_status == "unstable") & result.done
    rows = [Headline("unstable points", f"{int(unstable.sum())} of {int(result.done.sum())}")]
    if unstable.any():
        i, j = np.nonzero(unstable)
        rows.append(Headline(f"unstable {a} range", ranges([(result.first[i].min(), result.first[i].max())], ua)))
        rows.append(Headline(f"unstable {b} range", ranges([(result.second[j].min(), result.second[j].max())], ub)))
    if result.spectral_radius is not None:
        # its error bar the budget's total: the time step's and, where estimated, the mesh term
        total = np.asarray(result.spectral_radius_error, dtype=float)
        if result.spectral_radius_mesh_error is not None:
            total = total + np.abs(np.asarray(result.spectral_radius_mesh_error, dtype=float))
        rows.append(largest_over_grid("largest spectral radius", result.spectral_radius, total, "1", point))
        rows.append(Headline("spectral radius error budget", f"time step, mesh {result._mesh_words()} "
                                                             f"(linearisation not applicable)"))
    return Summary(status=grid_status(result), run_time=result.run_time, rows=rows + reduction_headlines(result))


_AXIS_TABLE = "{parameter = ..., start = ..., stop = ..., count = ...}"


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    first, second = (axis(f"{where}.{key}", sub_table(where, table, key, _AXIS_TABLE)) for key in ("x", "y"))
    if first[0] == second[0]:
        raise StudiesError(f"[{where}]: x and y must vary different parameters, got {first[0]!r} twice")
    # a chart has its own default (128 steps), not the [studies] n_steps
    return {"first": first, "second": second, "n_steps": steps(where, table, 128, minimum=MIN_STEPS)}


def _run(problem: Any, options: Mapping[str, Any], *, out: Any, executor: Any, progress: bool
         ) -> StabilityChart:
    return stability_chart(problem, options["first"], options["second"], n_steps=options["n_steps"],
                           executor=executor, out=out, name=KIND.name, progress=progress,
                           scheme=options.get("scheme", DEFAULT_SCHEME),
                           error_tolerance=options.get("error_tolerance", ERROR_TOLERANCE))


def _cost(name, problem, options, workers, done=None):
    """A periodic solve per point of the two axes."""
    axes = [(parameter, np.asarray(grid)) for parameter, grid in (options["first"], options["second"])]
    found = cost.grid_cost(name, problem, axes, options["n_steps"], workers=workers, done=done,
                      point_doubles=lambda s: 4.0 * s.m + 4.0, words=[cost.axis_words(*axis) for axis in axes])
    # the radius's mesh term at three headline points (studies._budget.grid_radius_mesh)
    # (after the grid: its points' linearisations released; none where every point is saved, a
    # complete study's fixed cost covering the three refined solves)
    shape = (len(options["first"][1]), len(options["second"][1]))
    if done is None or np.shape(done) != shape or not np.asarray(done).all():
        for _ in range(3):
            found = cost.with_mesh_term(found, problem, {}, options["n_steps"])
    return cost.with_reduction_check(found, problem, {}, options["n_steps"])


KIND = register_kind(StudyKind(
    name="stability_chart", result=StabilityChart, keys=("x", "y", "n_steps"), check=_check, run=_run,
    summary=_summary, grid=True, point=chart_point, schemes=True,
    varies=lambda options: (options["first"][0], options["second"][0]), headlines=_headlines, cost=_cost,
    demo={"x": {"parameter": "speed", "start": 0.5, "stop": 3.0, "count": 26},
          "y": {"parameter": "epsilon", "start": 0.0, "stop": 0.8, "count": 9}, "n_steps": 64},
    aliases=("StabilityChart",)))
