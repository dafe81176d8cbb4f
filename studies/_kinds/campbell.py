"""``[studies.campbell]``: frozen-time natural frequency bands and Floquet characteristic
frequencies against the crank speed, modes tracked by MAC."""

from __future__ import annotations

import dataclasses
import time
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

import periodic

from .._budget import (
    ERROR_TOLERANCE,
    NOT_APPLICABLE,
    NOT_ESTIMATED,
    RADIUS_METHODS,
    check_tolerance,
    grid_frequency_mesh,
    grid_radius_mesh,
    radius_budget,
    radius_mesh_words,
    radius_verdict,
)
from .._kind import StudyKind, register_kind
from .._mesh_error import MESH_FROZEN_SAMPLES
from .._numerics import (
    DEFAULT_SCHEME,
    characteristic_frequencies,
    crossings,
    frozen_modes,
    mode_targets,
    multiplier_modes,
    pooled_frequencies,
    study_scheme,
    track_modes,
    unstable_intervals,
)
from .._plots import Plot, axes_for, cost_line, drawn, largest, legend_outside, mark_statuses, plain
from .._result import NoObservables
from .._toolkit import (
    HARMONIC_WHY,
    MAX_HARMONIC,
    SPEED,
    GridResult,
    Headline,
    StudiesError,
    Summary,
    axis,
    check_grid,
    check_integer,
    check_n_steps,
    collect,
    combine,
    cost,
    grid_status,
    grid_summary,
    integer,
    listed,
    open_store,
    ranges,
    reduction_check,
    reduction_headlines,
    run_grid,
    steps,
)

#: The fewest steps per period a Campbell diagram accepts (docs/studies.md).
MIN_STEPS = 32
#: Default frozen-time samples per period (at most n_steps: they are taken among the steps).
FROZEN_SAMPLES = 64


@dataclass(frozen=True, eq=False)
class CampbellResult(NoObservables, GridResult):
    """Campbell diagram: frozen-time natural frequencies against crank speed (the fields every
    result has: ``studies._result``; no observable response, so ``peak``... are empty; those of every
    grid study: ``GridResult``).

    Attributes
    ----------
    labels : tuple of str, (m,)
        The independent coordinates.
    speeds : ndarray, (n,), rad/s
        The crank speeds.
    crank_angle : ndarray, (n_frozen,), rad
        The crank angles at which the frozen systems are taken.
    frozen : ndarray, (n, n_frozen, m), rad/s
        The frozen-time natural frequencies, ascending at each sample.
    shapes : ndarray, (n, m, m), 1
        The mode shapes at crank angle 0 (columns).
    multipliers, multipliers_coarse : ndarray of complex, (n, 2m), 1
        The Floquet multipliers with N and N/2 steps.
    multiplier_modes : ndarray, (n, 2m), 1, or None
        The frozen mode each multiplier belongs to (``studies._numerics.multiplier_modes``: its Floquet
        mode split into the frozen mode shapes at crank angle 0): a column of ``frozen`` at that speed
        (-1 unassigned); None in a file written before it.
    spectral_radius, spectral_radius_error : ndarray, (n,), 1
        The spectral radius at each speed and its estimated error.
    spectral_radius_mesh_error : ndarray, (n,), 1, or None
        The radius's mesh term (``studies._budget.grid_radius_mesh``: the headline speeds'
        relative error applied to every speed); None without elastic links, or in a file written
        before the term.
    is_stable : ndarray of bool, (n,)
        The stability verdict at each speed.
    period : ndarray, (n,), s
        The period at each speed.
    order : ndarray of int, (n, m)
        Tracked mode j is frequency column ``order[i, j]`` at speed i (MAC tracking).
    tracking_mac : ndarray, (n, m), 1
        The MAC of each tracking step.
    band_min, band_max, band_mean : ndarray, (n, m), rad/s
        The band of each tracked mode over the crank angle.
    characteristic, characteristic_error : ndarray, (n, 2m), rad/s
        The Floquet characteristic frequencies, each unfolded to the mean frozen frequency of the mode
        it belongs to (``multiplier_modes``), and their time-step error (N against N/2: the nearest
        N/2 multiplier unfolded to the same mode).
    characteristic_mesh_error : ndarray, (n, 2m), rad/s, or None
        The frequencies' mesh term (``studies._budget.grid_frequency_mesh``: each mode's relative
        error at the headline speeds, its multipliers matched to the refined model's, applied to its
        frequencies at every speed; NaN where unknown); None without elastic links, or in a file
        written before the term (not estimated).
    mode_labels : tuple of str, (m,)
        The tracked modes' names.
    harmonics : tuple of int
        The k of the lines ``k * speed``.
    error_methods : dict, {term: str}
        How each term of the error budget (``error_budget``) was estimated, in words.
    """

    labels: tuple[str, ...]
    speeds: np.ndarray
    crank_angle: np.ndarray | None = None
    frozen: np.ndarray | None = None
    shapes: np.ndarray | None = None
    multipliers: np.ndarray | None = None
    multipliers_coarse: np.ndarray | None = None
    multiplier_modes: np.ndarray | None = None
    spectral_radius: np.ndarray | None = None
    spectral_radius_error: np.ndarray | None = None
    spectral_radius_mesh_error: np.ndarray | None = None
    is_stable: np.ndarray | None = None
    period: np.ndarray | None = None
    order: np.ndarray | None = None
    tracking_mac: np.ndarray | None = None
    band_min: np.ndarray | None = None
    band_max: np.ndarray | None = None
    band_mean: np.ndarray | None = None
    characteristic: np.ndarray | None = None
    characteristic_error: np.ndarray | None = None
    characteristic_mesh_error: np.ndarray | None = None
    mode_labels: tuple = ()
    harmonics: tuple = ()
    error_methods: Mapping[str, str] = field(default_factory=lambda: dict(CAMPBELL_METHODS))

    @property
    def error_budget(self) -> dict[str, dict[str, Any]]:
        """{quantity: {term: array or words}} (``studies._budget``): "spectral_radius" (n,) and
        "characteristic" (n, 2m), each of its time step (N against N/2), the mesh (each estimated at
        the headline speeds: ``spectral_radius_mesh_error``, ``characteristic_mesh_error``; not
        applicable without elastic links, not estimated in a file written before the term) and the
        linearisation not applicable (small vibrations about the nominal motion are the linear
        system's)."""
        return {**radius_budget(self.spectral_radius_error, self._mesh_term()),
                "characteristic": {"time_step": self.characteristic_error,
                                   "mesh": self._frequency_mesh_term(),
                                   "linearisation": NOT_APPLICABLE}}

    def _frequency_mesh_term(self) -> Any:
        if self.characteristic_mesh_error is not None:
            return self.characteristic_mesh_error
        return NOT_APPLICABLE if isinstance(self._mesh_term(), str) else NOT_ESTIMATED

    def _frequency_words(self, shown: Any = True) -> str:
        """The characteristic frequencies' error among ``shown`` (bool mask of ``characteristic``) in
        a phrase: the total's largest, its terms' (the mesh's words where it is not a number)."""
        time_step = np.where(shown, self.characteristic_error, np.nan)
        mesh = self._frequency_mesh_term()
        if isinstance(mesh, str):
            return f"frequencies' time-step error up to {plain(largest(time_step))} rad/s (mesh: {mesh})"
        mesh = np.where(shown, mesh, np.nan)
        counted = np.isfinite(time_step)
        unknown = int((np.isnan(mesh) & counted).sum())
        if unknown == int(counted.sum()):   # no total to state: the time step's, the mesh unknown
            return f"frequencies' time-step error up to {plain(largest(time_step))} rad/s (mesh unknown)"
        if unknown:   # a total where the mesh is unknown would read as a bound: the terms apart
            return (f"frequencies' time-step error up to {plain(largest(time_step))} rad/s, mesh up to "
                    f"{plain(largest(mesh))} ({unknown} of {int(counted.sum())} unknown)")
        return (f"frequencies' error up to {plain(largest(np.abs(time_step) + np.abs(mesh)))} rad/s "
                f"(time step {plain(largest(time_step))}, mesh {plain(largest(mesh))})")

    def _mesh_term(self) -> Any:
        if self.spectral_radius_mesh_error is not None:
            return self.spectral_radius_mesh_error
        return NOT_APPLICABLE if self.error_methods.get("mesh", "").startswith(NOT_APPLICABLE) else None

    _axes = {"speeds": "speed"}
    _units = {"speeds": "rad/s", "crank_angle": "rad", "frozen": "rad/s", "shapes": "1",
              "multipliers": "1", "multipliers_coarse": "1", "multiplier_modes": "1", "period": "s",
              "order": "1", "tracking_mac": "1", "characteristic_error": "rad/s", "characteristic_mesh_error": "rad/s",
              "band_min": "rad/s",
              "band_max": "rad/s", "band_mean": "rad/s", "characteristic": "rad/s", "spectral_radius": "1",
              "spectral_radius_error": "1", "spectral_radius_mesh_error": "1", "is_stable": "1", **GridResult._units}

    def plot(self, *, axes: Any = None) -> Plot:
        """Frozen-frequency bands of the tracked modes (shaded), their mean (line), Floquet
        characteristic frequencies (dots) and the lines k * speed."""
        axes = axes_for(1, axes, height=4.8)
        ax = axes[0]
        artists: dict[str, list] = {}
        speeds = self.speeds
        hidden: list[str] = []
        if self.band_min is not None:
            # Show the range the harmonics reach (where resonances can occur) and at least the lowest
            # mode; higher modes (e.g. axial) would squash the interesting part: they are left out,
            # of the legend too, and named in the title.
            top = 1.15 * max(max(self.harmonics) * speeds[-1], np.nanmax(self.band_max[:, 0]))
            for j, name in enumerate(self.mode_labels):
                if not np.nanmin(self.band_min[:, j]) < top:
                    hidden.append(name.split(" (")[0])
                    continue
                artists[name] = [ax.fill_between(speeds, self.band_min[:, j], self.band_max[:, j],
                                                 color=f"C{j % 10}", alpha=0.25, lw=0)]
                artists[name] += ax.plot(speeds, self.band_mean[:, j], color=f"C{j % 10}", label=name)
            artists["characteristic"] = ax.plot(np.repeat(speeds, self.characteristic.shape[1]),
                                                self.characteristic.reshape(-1), ".", color="k", ms=2,
                                                label="Floquet characteristic")
            artists["harmonics"] = []
            for k in self.harmonics:
                artists["harmonics"] += ax.plot(speeds, k * speeds, color="0.6", lw=0.7, ls="--")
                ax.annotate(f"{k}x", (speeds[-1], min(k * speeds[-1], top)), fontsize="x-small")
            ax.set_ylim(0.0, top)
            # the speeds whose verdict is not ok (unstable, marginal, ...) marked along the axis
            artists["status"] = mark_statuses(ax, speeds, np.full(speeds.shape, 0.02 * top), self.point_status)
            legend_outside(ax)
        ax.set_xlabel("speed (rad/s)")  # 2 pi / period: the crank speed of a four-bar
        ax.set_ylabel("frequency (rad/s)")
        # The error of the characteristic frequencies drawn (an unresolved axial mode far above the
        # plotted range would otherwise set it).
        words = "frequencies' error: none computed"
        if self.characteristic_error is not None:
            words = self._frequency_words(np.asarray(self.characteristic) <= ax.get_ylim()[1])
        above = "" if not hidden else f"\n({', '.join(hidden)} above the range shown)" if len(hidden) < 3 \
            else f"\n({hidden[0]} to {hidden[-1].removeprefix('mode ')} above the range shown)"
        ax.set_title(f"{self.problem}: Campbell diagram, speeds {speeds[0]:.4g}–{speeds[-1]:.4g} "
                     f"rad/s{above}\n" + cost_line(words, self.run_time)
                     + self.reduction_note(), fontsize="small")
        return drawn(axes, artists)


#: How the terms of a Campbell diagram's budget are estimated (its spectral radius's, its frequencies').
CAMPBELL_METHODS = {**RADIUS_METHODS,
                    "time_step": "N against N/2 steps (periodic.floquet; the frequencies unfolded from both)"}


def campbell_point(problem: Any, values: Mapping[str, float], *, n_steps: int, frozen_samples: int,
                   scheme: str = DEFAULT_SCHEME, error_tolerance: float = ERROR_TOLERANCE):
    """One speed of a Campbell diagram: frozen frequencies over the crank angle, mode shapes at crank
    angle 0, Floquet multipliers; a spectral radius error above ``error_tolerance`` of the radius is
    ``inaccurate`` (``studies._budget``)."""
    linear = problem.linearize(values, n_steps=n_steps, context=False)
    index, frozen, shapes = frozen_modes(linear.system, frozen_samples)
    result = periodic.floquet(linear.system, scheme=study_scheme(scheme), estimate_error=True)
    unresolved = int((~result.resolved).sum())
    status, message = combine([
        (result.status, result.message),
        ("unresolved_stiff_mode" if unresolved else "ok",
         f"{unresolved} multipliers belong to modes the {n_steps} steps do not resolve (stiff modes; "
         f"refine n_steps to see their characteristic frequencies)" if unresolved else ""),
        radius_verdict(result.spectral_radius, result.spectral_radius_error, error_tolerance)])
    modes, _ = multiplier_modes(result.eigenvectors, shapes)
    return ({"frozen": frozen, "shapes": shapes, "multipliers": result.multipliers,
             "multipliers_coarse": result.multipliers_coarse, "multiplier_modes": modes.astype(float),
             "spectral_radius": result.spectral_radius,
             "spectral_radius_error": result.spectral_radius_error, "is_stable": float(result.is_stable),
             "period": linear.system.period, "crank_angle": np.asarray(linear.crank_angle)[index]},
            status, message)


def campbell(problem: Any, speeds: Sequence[float], *, n_steps: int = 256, frozen_samples: int = FROZEN_SAMPLES,
             max_harmonic: int = 6, executor: Executor | None = None, out: Any = None,
             name: str = "campbell", progress: bool = False, scheme: str = DEFAULT_SCHEME,
             error_tolerance: float = ERROR_TOLERANCE) -> CampbellResult:
    """Campbell diagram over crank ``speeds`` (rad/s): frozen-time natural frequency bands over the
    crank angle, Floquet characteristic frequencies, lines ``k * speed`` (k <= ``max_harmonic``),
    modes tracked across speeds by MAC of their shapes at crank angle 0 and labelled. The frozen
    samples are taken among the steps: ``min(frozen_samples, n_steps)`` of them, the number recorded
    in ``settings``. ``scheme`` names the periodic scheme (``periodic.SCHEMES``). The error budget
    (``error_budget``): a speed whose spectral radius error exceeds ``error_tolerance`` of the radius
    is ``inaccurate``; the frequencies' time-step term is reported (``characteristic_error``)."""
    start = time.perf_counter()
    error_tolerance = check_tolerance(error_tolerance)
    error_factor = study_scheme(scheme).error_factor
    grid = check_grid("speeds", speeds)
    if (grid <= 0).any() or (np.diff(grid) <= 0).any():
        raise StudiesError(f"speeds: expected positive, increasing crank speeds (rad/s), got {speeds!r}")
    n_steps = check_n_steps(n_steps, minimum=MIN_STEPS, study="a Campbell diagram")
    frozen_samples = min(check_integer("frozen_samples", frozen_samples, 2), n_steps)
    labels = problem.describe({SPEED: float(grid[0])}).labels
    settings = {"speeds": grid, "n_steps": n_steps, "frozen_samples": frozen_samples,
                "scene": problem.text, "scheme": scheme, "error_tolerance": error_tolerance}
    units = {"frozen": "rad/s", "shapes": "1", "multipliers": "1", "multipliers_coarse": "1",
             "multiplier_modes": "1", "period": "s",
             "crank_angle": "rad", "spectral_radius": "1", "spectral_radius_error": "1", "is_stable": "1"}
    header = dict(problem=problem.name, scene=problem.text, labels=labels)
    store = open_store(out, name, grid.shape, CampbellResult, settings, units, header,
                       {"speeds": (grid, "rad/s")})
    points = [((i,), {SPEED: float(v)}) for i, v in enumerate(grid)]
    outcomes = run_grid(campbell_point, problem, points,
                        {"n_steps": n_steps, "frozen_samples": frozen_samples, "scheme": scheme,
                         "error_tolerance": error_tolerance}, executor=executor,
                        store=store, progress=progress, description=f"{name} over speed")
    fields = collect(outcomes, grid.shape)
    if "is_stable" in fields:
        fields["is_stable"] = fields["is_stable"] == 1.0
    extra: dict[str, Any] = reduction_check(problem, n_steps=n_steps)
    frequency_method = ""
    if "frozen" in fields:
        fields["crank_angle"] = fields["crank_angle"][np.flatnonzero(fields["done"])[0]]
        order, confidence = track_modes(fields["shapes"])
        rows = np.arange(grid.size)[:, None]
        band_min = fields["frozen"].min(axis=1)[rows, order]
        band_max = fields["frozen"].max(axis=1)[rows, order]
        band_mean = fields["frozen"].mean(axis=1)[rows, order]
        characteristic, characteristic_error, unfolded_to = [], [], []
        for i in range(grid.size):
            fine, halved, targets = unfold_point(fields, i, band_mean[i])
            characteristic.append(fine)
            unfolded_to.append(targets)
            # the N/2 difference times the scheme's error factor estimates the error of the N-step value
            characteristic_error.append(np.abs(halved - fine) * error_factor)
        characteristic, characteristic_error = np.array(characteristic), np.array(characteristic_error)
        first = fields["shapes"][0]
        mode_labels = _mode_labels(first, labels)
        # the frequencies' mesh term at the radius's headline speeds (first: its refined solves, with
        # their frozen frequencies, serve the radius's term below from the cache)
        frequency_mesh, frequency_method = grid_frequency_mesh(problem, fields, points, characteristic,
                                                               band_mean, n_steps=n_steps, scheme=scheme,
                                                               unfolded_to=np.array(unfolded_to))
        extra.update(characteristic_mesh_error=None if isinstance(frequency_mesh, str) else frequency_mesh)
        extra.update(order=order, tracking_mac=confidence, band_min=band_min, band_max=band_max,
                     band_mean=band_mean, characteristic=characteristic,
                     characteristic_error=characteristic_error, mode_labels=mode_labels,
                     harmonics=tuple(range(1, max_harmonic + 1)))
    mesh, mesh_method = grid_radius_mesh(problem, fields, points, n_steps=n_steps, scheme=scheme,
                                         tolerance=error_tolerance)
    extra.update(spectral_radius_mesh_error=None if isinstance(mesh, str) else mesh,
                 error_methods={**CAMPBELL_METHODS, "mesh": mesh_method if isinstance(mesh, str) or not frequency_method
                                else f"spectral radius: {mesh_method}; characteristic frequencies: {frequency_method}"})
    result = CampbellResult(**header, settings=settings, speeds=grid, run_time=time.perf_counter() - start,
                            **fields, **extra)
    if store is not None:
        result.to_hdf5(store.group)
    return result


def unfold_point(fields: Mapping[str, np.ndarray], i: int, band_mean: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The characteristic frequencies (2m,) rad/s at speed ``i`` of a Campbell diagram's ``fields``
    with N steps and N/2 steps, and the mean frozen frequency (2m,) rad/s each was unfolded to: each
    multiplier unfolded to the mean frozen frequency of its mode
    (``multiplier_modes``), each N/2 one the nearest to an N-step multiplier unfolded to that one's
    mode. Fields without ``multiplier_modes`` (a point saved by an earlier version) unfold to the
    nearest of the tracked means ``band_mean`` (m,) (ambiguous where the speed is small against the
    modes' spacing)."""
    multipliers, coarse, period = fields["multipliers"][i], fields["multipliers_coarse"][i], fields["period"][i]
    modes = fields.get("multiplier_modes")
    nearest = np.abs(multipliers[:, None] - coarse[None, :]).argmin(axis=1)
    if modes is None or not np.all(np.isfinite(modes[i])):
        fine = pooled_frequencies(multipliers, period, band_mean)
        targets = fine
    else:
        targets = mode_targets(modes[i], fields["frozen"][i].mean(axis=0))
        fine = characteristic_frequencies(multipliers, period, targets)
    return fine, characteristic_frequencies(coarse[nearest], period, targets), targets


def _check(where: str, table: Mapping[str, Any], n_steps: int) -> dict[str, Any]:
    _, grid = axis(where, table, parameter=False)
    if (grid <= 0).any() or (np.diff(grid) <= 0).any():
        raise StudiesError(f"[{where}]: expected positive, increasing crank speeds (rad/s), got "
                           f"{np.array2string(grid, threshold=8)}")
    n_steps = steps(where, table, n_steps, minimum=MIN_STEPS)
    # frozen samples are taken among the steps: the default is capped at n_steps, a larger value
    # asked for explicitly is refused (the file records the number used)
    frozen = (integer(where, "frozen_samples", table["frozen_samples"], 2, maximum=n_steps,
                      why=f"samples are taken among the n_steps = {n_steps} steps per period")
              if "frozen_samples" in table else min(FROZEN_SAMPLES, n_steps))
    return {"speeds": grid, "n_steps": n_steps, "frozen_samples": frozen,
            "max_harmonic": integer(where, "max_harmonic", table.get("max_harmonic", 6), 1,
                                    maximum=MAX_HARMONIC, why=HARMONIC_WHY)}


def _run(problem: Any, options: Mapping[str, Any], *, out: Any, executor: Any, progress: bool
         ) -> CampbellResult:
    return campbell(problem, options["speeds"], n_steps=options["n_steps"],
                    frozen_samples=options["frozen_samples"], max_harmonic=options["max_harmonic"],
                    executor=executor, out=out, name=KIND.name, progress=progress,
                    scheme=options.get("scheme", DEFAULT_SCHEME),
                    error_tolerance=options.get("error_tolerance", ERROR_TOLERANCE))


def _summary(result: CampbellResult) -> str:
    return grid_summary(result, point=lambda index: f"speed {result.speeds[index]:.4g} rad/s")


def _mode_labels(shapes: np.ndarray, labels: Sequence[str]) -> tuple[str, ...]:
    """A name per mode (columns of ``shapes`` (m, m) at crank angle 0): "mode 1 (coupler.b1)", its
    largest coordinate; where several modes share their largest coordinate (the end slope of
    finite elements), "mode 2 (coupler, 2nd)": the link of that coordinate and the mode's rank on it,
    so no two modes carry the same name."""
    dominant = [labels[int(np.argmax(np.abs(shapes[:, j])))] if np.isfinite(shapes[:, j]).all() else ""
                for j in range(shapes.shape[1])]
    names, rank = [], {}
    for j, coordinate in enumerate(dominant):
        if not coordinate:
            names.append(f"mode {j + 1}")
        elif dominant.count(coordinate) == 1:
            names.append(f"mode {j + 1} ({coordinate})")
        else:
            link = coordinate.rpartition(".")[0] or coordinate
            rank[link] = rank.get(link, 0) + 1
            names.append(f"mode {j + 1} ({link}, {_ordinal(rank[link])})")
    return tuple(names)


def _ordinal(n: int) -> str:
    return f"{n}{'th' if 10 <= n % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(n % 10, 'th')}"


def _headlines(result: CampbellResult) -> Summary:
    rows = []
    if result.band_mean is not None:
        speeds = result.speeds
        for j, name in enumerate(result.mode_labels[:3]):  # the lowest modes: what a design meets first
            low = np.nanmin(result.band_min[:, j])
            # a negative frozen frequency is sign(lam) sqrt(|lam|): the frozen stiffness is not
            # positive at some instant (statically unstable frozen system), say so in words
            # (no negative band: its magnitude is a growth rate, named as one)
            high = plain(np.nanmax(result.band_max[:, j]), 3)
            rows.append(Headline(f"{name} frozen frequency band",
                                 f"{plain(low, 3)}–{high} rad/s" if low >= 0 else f"0–{high} rad/s",
                                 where=f"(frozen stiffness negative at some instant: statically unstable "
                                       f"there, growth rate up to {plain(-low, 3)} 1/s)" if low < 0 else ""))
        found = sorted((value, k, j) for j in range(result.band_mean.shape[1]) for k in result.harmonics
                       for _, value in crossings(speeds, k * speeds - result.band_mean[:, j]))
        rows.append(Headline("resonances, harmonic:mode at speed (rad/s)",
                             listed([f"{k}:{j + 1} at {plain(value, 3)}" for value, k, j in found])))
    if result.spectral_radius is not None:
        lower = result.spectral_radius - np.nan_to_num(result.spectral_radius_error)
        rows.append(Headline("unstable speeds",
                             ranges(unstable_intervals(result.speeds, lower, tol=periodic.STABILITY_TOL), "rad/s")))
        rows.append(Headline("error budget", f"time step, the radius's mesh {radius_mesh_words(result._mesh_term())} "
                                             f"(linearisation not applicable: frequencies of small vibrations)"))
    if result.characteristic_error is not None and result.band_max is not None:
        # the frequencies up to the lowest modes' bands (an unresolved stiff mode far above sets no bar)
        shown = np.asarray(result.characteristic) <= np.nanmax(result.band_max[:, :3])
        rows.append(Headline("characteristic frequencies of the lowest modes",
                             result._frequency_words(shown).removeprefix("frequencies' ")))
    return Summary(status=grid_status(result), run_time=result.run_time, rows=rows + reduction_headlines(result))


def _default(nominal_speed: float) -> dict[str, Any]:
    """40 speeds from 0.2 to 4 times the scene's."""
    return {"start": 0.2 * abs(nominal_speed), "stop": 4.0 * abs(nominal_speed), "count": 40}


def _cost(name, problem, options, workers, done=None):
    """A periodic solve and ``frozen_samples`` frozen-time eigenproblems per speed."""
    axis = (SPEED, np.asarray(options["speeds"]))
    frozen = options["frozen_samples"]
    found = cost.grid_cost(name, problem, [axis], options["n_steps"], frozen=frozen, workers=workers, done=done,
                      point_doubles=lambda s: (frozen + s.m + 8.0) * s.m,
                      words=[cost.axis_words(*axis), f"{frozen} frozen samples"])
    # the radius's and the frequencies' mesh terms at three headline speeds (studies._budget.
    # grid_radius_mesh, grid_frequency_mesh: one refined solve each, shared, and for the frequencies
    # a Floquet solve of the user's model there, on the grid's speed family, with its frozen
    # frequencies) (after the grid: its points' linearisations released; none where every point is
    # saved, a complete study's fixed cost covering the three refined solves)
    if done is None or np.shape(done) != (len(options["speeds"]),) or not np.asarray(done).all():
        for _ in range(3):
            found = cost.with_mesh_term(found, problem, {}, options["n_steps"])
        if hasattr(problem, "mechanism"):
            seconds = 3.0 * cost.solve_seconds(options["n_steps"], cost.sizes_at(problem, {}),
                                               frozen=MESH_FROZEN_SAMPLES)
            found = dataclasses.replace(found, time=found.time + seconds)
    return cost.with_reduction_check(found, problem, {}, options["n_steps"])


KIND = register_kind(StudyKind(
    name="campbell", result=CampbellResult,
    keys=("start", "stop", "count", "values", "spacing", "frozen_samples", "max_harmonic", "n_steps"),
    check=_check, run=_run, summary=_summary, grid=True, point=campbell_point, default=_default,
    headlines=_headlines, cost=_cost, schemes=True, demo={"start": 0.2, "stop": 3.0, "count": 15},
    aliases=("CampbellResult",)))
