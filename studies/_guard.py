"""The resource guard: before any study runs, its memory (bytes) and run time (s) are estimated from
its sizes, and a study above the limits is refused unless forced (docs/studies.md, "Limits").

The cost models are deliberately simple, each a sum of terms with one calibrated constant:

- a linearisation over ``N`` steps of a mechanism with ``n`` coordinates (``m`` of them independent)
  builds arrays of ``(N + 1) n^2`` doubles: its peak is ``LINEARISATION_DOUBLES`` of them and it
  takes ``LINEARISATION_SECONDS`` per ``(N + 1) n^2``; a speed family (grid studies over the speed)
  takes ``FAMILY_FACTOR`` times as long and peaks at ``FAMILY_DOUBLES``; a grid over other
  parameters keeps ``HELD_DOUBLES`` for each further variant cached (up to ``CACHED_FAMILIES``);
- each study has a fixed overhead of ``STUDY_SECONDS`` (the nominal motion, the drawings);
- a periodic solve (shooting at N, N/2 and N/4, Floquet multipliers) takes ``POINT_SECONDS`` plus,
  per step, ``STEP_SECONDS + STEP_M2_SECONDS m^2 + SOLVE_SECONDS m^3``; a frozen-time
  eigenproblem ``EIGEN_SECONDS`` per ``m^3``;
- a nonlinear run takes ``NONLINEAR_STEP_SECONDS + NONLINEAR_STEP_N2_SECONDS n^2`` per step and
  keeps ``NONLINEAR_DOUBLES`` doubles per step and coordinate;
- a nonlinear shooting (``nonlinear_steady_state``) runs ``SHOOTING_PERIODS`` periods of N steps, each
  ``PERIOD_STEP_SECONDS + NONLINEAR_STEP_N2_SECONDS n^2`` per step
  (Newton's period maps with their monodromy, each ``TANGENT_FACTOR`` periods, at N and N/2, and
  the observables' runs) and keeps ``TANGENT_DOUBLES (n + r)^2`` doubles per step for the monodromy's
  iteration matrices; a nonlinear sweep runs ``SWEEP_POINT_PERIODS`` periods per orbit of its
  branch (corrector, tangent, observables; ``|stop - start| / step`` orbits, at most ``max_points``)
  plus two linearisations per orbit and ``LINEAR_POINTS`` for the linear curve, and its transient.

The constants were measured on the development machine (2 cores, 2024) with
``benchmarks/bench_guard.py``, which prints measured over estimated memory and time for a range of
sizes; rerun it on another machine and adjust the constants if the ratios leave about 0.3-3.
An estimate is good to a factor of a few: enough to stop a run that would take a day or exhaust the
memory, not to predict its minute.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ._errors import StudiesError
from ._mechanism import COUNT_KEYS
from ._problem import SPEED

__all__ = ["Estimate", "ResourceError", "estimate", "guard", "memory_limit", "TIME_LIMIT"]

logger = logging.getLogger(__name__)

GIB = 2.0**30
#: The memory limit is the smaller of this and ``MEMORY_FRACTION`` of the machine's RAM (bytes).
MEMORY_LIMIT = 4.0 * GIB
MEMORY_FRACTION = 0.5
#: The longest a single study, or all the studies of a run together, may be estimated to take (s).
TIME_LIMIT = 2.0 * 3600.0

# --- cost-model constants (benchmarks/bench_guard.py) -------------------------------------------------
LINEARISATION_DOUBLES = 12.0
LINEARISATION_SECONDS = 1.5e-6
FAMILY_FACTOR = 3.0
FAMILY_DOUBLES = 24.0
HELD_DOUBLES = 12.0
STUDY_SECONDS = 0.1
CACHED_FAMILIES = 8  # studies._mechanism._CACHE_SIZE
SOLVE_SECONDS = 4.0e-9
STEP_SECONDS = 2.0e-6
STEP_M2_SECONDS = 1.0e-7
POINT_SECONDS = 5.0e-3
EIGEN_SECONDS = 5.0e-9
NONLINEAR_STEP_SECONDS = 2.0e-3
NONLINEAR_STEP_N2_SECONDS = 3.0e-7
NONLINEAR_DOUBLES = 40.0
#: Seconds per step of a period map, besides the n^2 term of a nonlinear run: the integrator alone,
#: without ``mechanisms.simulate``'s error estimate and observables (1.9e-4 s per step measured on
#: four_bar_fem4, n = 21).
PERIOD_STEP_SECONDS = 6.0e-5
#: A period map with its monodromy costs this many plain periods (benchmarks/bench_nonlinear_steady.py:
#: 0.08 s against 0.05 s on four_bar_fem4 at N = 256).
TANGENT_FACTOR = 1.6
#: Periods of one nonlinear shooting: 4 Newton maps at N, 4 at N/2 and 3 at N/4 (half and a quarter
#: as long) with their monodromy, the observables' runs (2-3 Newton steps converge from the linear
#: start at 1e-8; the N/4 orbit checks that the N/2 error estimate can be trusted).
SHOOTING_PERIODS = (4 * 1.5 + 3 * 0.25) * TANGENT_FACTOR + 2.25
#: Periods per orbit of a nonlinear sweep: about 3 corrector maps and the tangent's (with monodromy),
#: the error estimate's 3 Newton maps on N/2 steps (half as long, with monodromy), the observables'
#: runs on N and N/2 steps.
SWEEP_POINT_PERIODS = 4 * TANGENT_FACTOR + 3 * 0.5 * TANGENT_FACTOR + 1.5
#: Doubles per step and (n + r)^2 kept while a monodromy is built (iteration matrices, their inverse).
TANGENT_DOUBLES = 3.0


class ResourceError(StudiesError):
    """A study whose estimated memory or run time exceeds the guard's limits (exit code 2)."""


@dataclass(frozen=True)
class Estimate:
    """What a study is estimated to cost: ``memory`` (bytes, the peak), ``time`` (s, wall time with
    the given workers) and ``sizes``, the sizes they come from in words ("100 speeds x 256 steps x 12
    coordinates")."""

    study: str
    memory: float
    time: float
    sizes: str

    def describe(self) -> str:
        return (f"{self.study}: about {format_bytes(self.memory)} and {format_seconds(self.time)} "
                f"estimated ({self.sizes})")


def memory_limit() -> float:
    """The memory limit in bytes: ``MEMORY_LIMIT`` or ``MEMORY_FRACTION`` of the RAM if smaller."""
    try:
        ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not POSIX: the fixed limit alone
        return MEMORY_LIMIT
    return min(MEMORY_LIMIT, MEMORY_FRACTION * ram)


def _number(value: float) -> str:
    return f"{value:.2g}" if value < 100 else f"{value:.0f}"


def format_bytes(value: float) -> str:
    """Bytes in binary units: "2.3 GiB", "120 MiB"."""
    for unit, size in (("GiB", 2.0**30), ("MiB", 2.0**20), ("KiB", 2.0**10)):
        if value >= size:
            return f"{_number(value / size)} {unit}"
    return f"{value:.0f} B"


def format_seconds(value: float) -> str:
    """Seconds in the largest unit that fits: "3 h", "1.5 days", "40 s"."""
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if value >= size:
            return f"{_number(value / size)} {unit}"
    return f"{_number(value)} s"


# ---------------------------------------------------------------------------------------------------
# sizes of a problem
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Sizes:
    """``n`` coordinates of the assembled model (all, with the constraints') and ``m`` independent
    ones (those the periodic system is written in)."""

    n: int
    m: int


def _sizes(problem: Any, values: Mapping[str, float]) -> _Sizes:
    """The coordinate counts at ``values`` (a mechanism is built there, which checks the values)."""
    if hasattr(problem, "mechanism"):
        import mechanisms

        model = mechanisms.assemble(problem.mechanism(values))
        return _Sizes(n=model.n_coords, m=model.n_coords - model.n_constraints)
    m = len(problem.describe(values).labels)
    return _Sizes(n=m, m=m)


def _largest_sizes(problem: Any, axes: Sequence[tuple[str, np.ndarray]]) -> _Sizes:
    """The coordinate counts at the largest value of each size key on the axes (the scene's
    otherwise); every axis end is built once first, so that a value the scene cannot take is
    refused before anything runs."""
    if hasattr(problem, "mechanism"):
        for parameter, grid in axes:
            for value in (float(np.min(grid)), float(np.max(grid))):
                problem.mechanism({parameter: value})
    largest = {parameter: float(np.max(grid)) for parameter, grid in axes
               if parameter.split(".")[-1] in COUNT_KEYS}
    return _sizes(problem, largest)


# ---------------------------------------------------------------------------------------------------
# cost models
# ---------------------------------------------------------------------------------------------------
def _linearisation(n_steps: int, sizes: _Sizes) -> tuple[float, float]:
    """(peak bytes, seconds) of one linearisation."""
    samples = (n_steps + 1) * sizes.n**2
    return 8.0 * LINEARISATION_DOUBLES * samples, LINEARISATION_SECONDS * samples


def _solve_seconds(n_steps: int, sizes: _Sizes, frozen: int = 0) -> float:
    """Seconds of one periodic solve (and ``frozen`` frozen-time eigenproblems)."""
    per_step = STEP_SECONDS + STEP_M2_SECONDS * sizes.m**2 + SOLVE_SECONDS * sizes.m**3
    return POINT_SECONDS + n_steps * per_step + EIGEN_SECONDS * frozen * sizes.m**3


def _grid(name: str, problem: Any, axes: Sequence[tuple[str, np.ndarray]], n_steps: int, *,
          frozen: int = 0, point_doubles: Callable[[_Sizes], float] = lambda s: 4.0 * s.m,
          workers: int = 1, words: Sequence[str], done: np.ndarray | None = None) -> Estimate:
    """A grid study over ``axes``: one periodic solve per point; one speed family per combination of
    the other parameters' values when the speed is an axis, else one linearisation per combination.
    ``done``: the points already saved (bool, grid shape), neither solved nor linearised again."""
    sizes = _largest_sizes(problem, axes)
    total = math.prod(len(grid) for _, grid in axes)
    shape = tuple(len(grid) for _, grid in axes)
    if done is None or np.shape(done) != shape:  # no mask is allocated for a grid not yet started
        points = total
        variants = math.prod(len(np.unique(grid)) for parameter, grid in axes if parameter != SPEED)
        left = []
    else:
        todo = ~np.asarray(done, dtype=bool)
        points = int(np.count_nonzero(todo))
        variants = _variants(axes, todo)
        left = [f"{points} of {total} points left"]
    family = FAMILY_FACTOR if any(parameter == SPEED for parameter, _ in axes) else 1.0
    build_bytes, build_seconds = _linearisation(n_steps, sizes)
    held = HELD_DOUBLES * (min(max(variants, 1), CACHED_FAMILIES) - 1)
    peak = (FAMILY_DOUBLES if family > 1.0 else LINEARISATION_DOUBLES) + held
    parallel = max(1, min(workers, points))
    per_process = 8.0 * peak * (n_steps + 1) * sizes.n**2
    # the collected arrays of every point (the saved ones are read back), kept in the main process
    results = 8.0 * total * point_doubles(sizes)
    # each worker process builds the linearisations its points need (a speed family once per process)
    seconds = (STUDY_SECONDS + variants * family * build_seconds / max(1, min(parallel, variants))
               + points * _solve_seconds(n_steps, sizes, frozen) / parallel)
    memory = per_process * parallel + results
    return Estimate(name, memory, seconds, " x ".join(list(words) + [f"{n_steps} steps",
                                                                      f"{sizes.m} coordinates"])
                    + "".join(f" ({note})" for note in left))


def _variants(axes: Sequence[tuple[str, np.ndarray]], todo: np.ndarray) -> int:
    """Distinct combinations of the values of the axes other than the speed among the points
    ``todo`` (bool, grid shape): each needs a linearisation (a speed family) of its own."""
    where = np.nonzero(todo)
    columns = [np.asarray(grid, dtype=float)[where[axis]] for axis, (parameter, grid) in enumerate(axes)
               if parameter != SPEED]
    if not columns:
        return min(1, where[0].size)
    return len(np.unique(np.stack(columns, axis=1), axis=0))


def _axis_words(parameter: str, grid: np.ndarray) -> str:
    return f"{len(grid)} {'speeds' if parameter == SPEED else 'values of ' + parameter}"


def _steady_state(name, problem, options, workers):
    sizes = _sizes(problem, options["values"])
    n_steps = options["n_steps"]
    build_bytes, build_seconds = _linearisation(n_steps, sizes)
    seconds = STUDY_SECONDS + build_seconds + _solve_seconds(n_steps, sizes)
    found = Estimate(name, build_bytes, seconds, f"{n_steps} steps x {sizes.m} coordinates")
    return _with_reduction_check(found, problem, options["values"], n_steps, extra_solve=False)


def _with_reduction_check(found: Estimate, problem: Any, values: Mapping[str, float], n_steps: int, *,
                          extra_solve: bool = True) -> Estimate:
    """``found`` plus the modal reduction's check where a link is reduced: a linearisation and a solve
    at modes + 2 (and, for a grid study, which checks once at the scene's values, the reduced solve it
    compares with: ``extra_solve``)."""
    reference = _reduction_reference_sizes(problem, values)
    if reference is None:
        return found
    reference_bytes, reference_seconds = _linearisation(n_steps, reference)
    seconds = reference_seconds + _solve_seconds(n_steps, reference)
    if extra_solve:
        sizes = _sizes(problem, values)
        seconds += _linearisation(n_steps, sizes)[1] + _solve_seconds(n_steps, sizes)
    return Estimate(found.study, max(found.memory, reference_bytes), found.time + seconds,
                    f"{found.sizes} + the reduction check at {reference.m}")


def _reduction_reference_sizes(problem: Any, values: Mapping[str, float]) -> _Sizes | None:
    """The coordinate counts of the reference the steady state checks a modal reduction against
    (``linearize.reduction_error``: every reduced link at ``modes + 2``); None without a reduced
    link (or a mechanism)."""
    if not hasattr(problem, "mechanism"):
        return None
    import linearize
    import mechanisms

    mechanism = problem.mechanism(values)
    if not linearize.reduced_links(mechanism):
        return None
    reference, _ = linearize.reference_mechanism(mechanism)
    model = mechanisms.assemble(reference)
    return _Sizes(n=model.n_coords, m=model.n_coords - model.n_constraints)


def _sweep(name, problem, options, workers, done=None):
    axis = (options["parameter"], np.asarray(options["values"]))
    found = _grid(name, problem, [axis], options["n_steps"], workers=workers, frozen=32, done=done,
                  point_doubles=lambda s: 8.0 * s.m + 4.0, words=[_axis_words(*axis)])
    return _with_reduction_check(found, problem, {}, options["n_steps"])


def _campbell(name, problem, options, workers, done=None):
    axis = (SPEED, np.asarray(options["speeds"]))
    frozen = options["frozen_samples"]
    found = _grid(name, problem, [axis], options["n_steps"], frozen=frozen, workers=workers, done=done,
                  point_doubles=lambda s: (frozen + s.m + 8.0) * s.m,
                  words=[_axis_words(*axis), f"{frozen} frozen samples"])
    return _with_reduction_check(found, problem, {}, options["n_steps"])


def _stability_chart(name, problem, options, workers, done=None):
    axes = [(parameter, np.asarray(grid)) for parameter, grid in (options["first"], options["second"])]
    found = _grid(name, problem, axes, options["n_steps"], workers=workers, done=done,
                  point_doubles=lambda s: 4.0 * s.m + 4.0, words=[_axis_words(*axis) for axis in axes])
    return _with_reduction_check(found, problem, {}, options["n_steps"])


def _nonlinear_check(name, problem, options, workers):
    sizes = _sizes(problem, options["values"])
    n_steps = options["n_steps"]
    periods = options["n_periods"] + (options["max_periods_from_rest"] if options["from_rest"] else 0)
    build_bytes, build_seconds = _linearisation(n_steps, sizes)
    steps = periods * n_steps
    seconds = (STUDY_SECONDS + build_seconds + _solve_seconds(n_steps, sizes)
               + steps * (NONLINEAR_STEP_SECONDS + NONLINEAR_STEP_N2_SECONDS * sizes.n**2))
    memory = max(build_bytes, 8.0 * NONLINEAR_DOUBLES * steps * sizes.n)
    return Estimate(name, memory, seconds, f"{periods} periods x {n_steps} steps x {sizes.n} coordinates")


def _nonlinear_period_seconds(n_steps: int, sizes: _Sizes) -> float:
    """Seconds of one period of ``mechanisms.PeriodMap`` (no monodromy, no observables)."""
    return n_steps * (PERIOD_STEP_SECONDS + NONLINEAR_STEP_N2_SECONDS * sizes.n**2)


def _tangent_bytes(n_steps: int, sizes: _Sizes) -> float:
    """Peak bytes of one monodromy: the iteration matrices of size n + r at every step."""
    return 8.0 * TANGENT_DOUBLES * n_steps * (2 * sizes.n - sizes.m) ** 2


def _nonlinear_steady_state(name, problem, options, workers):
    sizes = _sizes(problem, options["values"])
    n_steps = options["n_steps"]
    build_bytes, build_seconds = _linearisation(n_steps, sizes)
    seconds = (STUDY_SECONDS + build_seconds + _solve_seconds(n_steps, sizes)
               + SHOOTING_PERIODS * _nonlinear_period_seconds(n_steps, sizes))
    memory = max(build_bytes, _tangent_bytes(n_steps, sizes))
    return Estimate(name, memory, seconds, f"{SHOOTING_PERIODS:g} periods x {n_steps} steps x {sizes.n} "
                                           "coordinates")


def _nonlinear_sweep(name, problem, options, workers):
    from ._kinds.nonlinear_sweep import LINEAR_POINTS

    start, stop, n_steps = options["start"], options["stop"], options["n_steps"]
    axis = (options["parameter"], np.array([start, stop], dtype=float))
    sizes = _largest_sizes(problem, [axis])
    step = options["step"] or abs(stop - start) / 50.0  # periodic.continue_orbits' default
    # an empty range (refused by the table check) has the one orbit at start, not a division by zero
    orbits = min(options["max_points"], math.ceil(abs(stop - start) / step) + 1 if step > 0.0 else 1)
    build_bytes, build_seconds = _linearisation(n_steps, sizes)
    periods = orbits * SWEEP_POINT_PERIODS + options["transient_periods"]
    seconds = (STUDY_SECONDS + (2 * orbits + LINEAR_POINTS) * (build_seconds + _solve_seconds(n_steps, sizes))
               + periods * _nonlinear_period_seconds(n_steps, sizes))
    memory = max(build_bytes, _tangent_bytes(n_steps, sizes),
                 8.0 * NONLINEAR_DOUBLES * options["transient_periods"] * n_steps * sizes.n)
    return Estimate(name, memory, seconds, f"{orbits} orbits x {SWEEP_POINT_PERIODS:g} periods + "
                                           f"{options['transient_periods']} periods x {n_steps} steps x "
                                           f"{sizes.n} coordinates")


def _control_comparison(name, problem, options, workers):
    """Two cases (with and without feedback), each a run of ``n_periods`` periods at N steps and its
    twin at N/2 for the error estimate (together what one ``simulate`` with its error estimate costs),
    one after the other."""
    sizes = _sizes(problem, options["values"])
    steps = options["n_periods"] * options["n_steps"]
    seconds = STUDY_SECONDS + len(("with", "without")) * steps * (NONLINEAR_STEP_SECONDS
                                                                  + NONLINEAR_STEP_N2_SECONDS * sizes.n**2)
    memory = 8.0 * NONLINEAR_DOUBLES * steps * sizes.n
    return Estimate(name, memory, seconds, f"2 runs x {options['n_periods']} periods x {options['n_steps']} "
                                           f"steps x {sizes.n} coordinates")


def _error_cost(name, problem, options, workers):
    values = dict(options["values"])
    resolution = options["resolution"]
    grids = [float(v) for v in resolution[1]] if resolution is not None else [None]
    step_counts = list(options["n_steps"])
    reference = options["reference_steps"] or 4 * max(step_counts)
    memory, seconds = 0.0, STUDY_SECONDS
    largest = _Sizes(0, 0)
    for index, value in enumerate(grids):
        at = values if value is None else dict(values, **{resolution[0]: value})
        sizes = _sizes(problem, at)
        largest = max(largest, sizes, key=lambda s: s.m)
        # the finest resolution (the last) also computes the reference, with Richardson (N and N/2)
        counts = step_counts + ([reference, reference // 2] if index == len(grids) - 1 else [])
        for n_steps in counts:
            build_bytes, build_seconds = _linearisation(n_steps, sizes)
            memory = max(memory, build_bytes)
            seconds += build_seconds + _solve_seconds(n_steps, sizes)
    return Estimate(name, memory, seconds, f"{len(step_counts)} step counts up to {reference} x "
                                           f"{len(grids)} resolutions x {largest.m} coordinates")


def _optimize(name, problem, options, workers):
    """At most ``max_evaluations`` sweeps over the speeds, each a linearisation and a periodic solve
    per speed (an upper bound: a speed family makes the linearisations cheaper), the map's sweeps and
    the nonlinear check at the optimum."""
    from ._kinds.optimize import default_evaluations

    bounds = options["bounds"]
    axes = [(path, np.array(pair, dtype=float)) for path, pair in bounds.items()]
    sizes = _largest_sizes(problem, axes)
    speeds = 1 if options["speeds"] is None else len(options["speeds"])
    evaluations = options["max_evaluations"] or default_evaluations(options["method"], len(bounds))
    sweeps = evaluations + (options["map_points"] ** 2 if len(bounds) >= 2 else 0)
    build_bytes, build_seconds = _linearisation(options["n_steps"], sizes)
    frozen = 32 if "frequency_separation" in options["constraints"] else 0
    seconds = STUDY_SECONDS + sweeps * speeds * (build_seconds + _solve_seconds(options["n_steps"], sizes, frozen))
    memory = FAMILY_DOUBLES / LINEARISATION_DOUBLES * build_bytes
    if options["check"]:
        check = _nonlinear_check(name, problem, {"values": {}, "n_steps": options["n_steps"],
                                                 "n_periods": options["check_periods"], "from_rest": False,
                                                 "max_periods_from_rest": 0}, workers)
        seconds, memory = seconds + check.time, max(memory, check.memory)
    return Estimate(name, memory, seconds, f"at most {sweeps} evaluations x {speeds} speeds x "
                                           f"{options['n_steps']} steps x {sizes.m} coordinates")


#: The cost model of each study kind, by name; a kind without one is sized as a steady state.
_MODELS: dict[str, Callable[[str, Any, Mapping[str, Any], int], Estimate]] = {
    "steady_state": _steady_state,
    "sweep": _sweep,
    "campbell": _campbell,
    "stability_chart": _stability_chart,
    "nonlinear_check": _nonlinear_check,
    "error_cost": _error_cost,
    "nonlinear_steady_state": _nonlinear_steady_state,
    "nonlinear_sweep": _nonlinear_sweep,
    "control_comparison": _control_comparison,
    "optimize": _optimize,
}


def estimate(problem: Any, kind: str, options: Mapping[str, Any], *, name: str | None = None,
             workers: int = 1, done: np.ndarray | None = None) -> Estimate:
    """The estimated cost of one study of ``kind`` with checked ``options`` (what ``studies._plan.plan``
    returns for it) on ``problem``, with ``workers`` processes for a grid study; ``done`` (bool, the
    grid's shape; grid studies only): the points already saved, which a resumed run reads back."""
    model = _MODELS.get(kind)
    if model is None:
        n_steps = options.get("n_steps", 256)
        return _steady_state(name or kind, problem, {"values": options.get("values") or {},
                                                     "n_steps": n_steps}, workers)
    saved = {} if done is None else {"done": done}  # only the grid models take it
    return model(name or kind, problem, options, max(1, int(workers)), **saved)


@dataclass(frozen=True)
class _Saved:
    """What a result file already holds of the declared runs: the names of those ``complete`` (with
    the same options) and, for a grid study partly saved, its ``done`` mask (bool, grid shape)."""

    complete: frozenset[str] = frozenset()
    done: Mapping[str, np.ndarray] = field(default_factory=dict)


def _saved(path: str | os.PathLike | None, problem: Any, runs: Sequence[tuple[str, Any, Any]]) -> _Saved:
    """What the result file ``path`` holds of ``runs`` (``(name, kind, options)``), judged as
    ``studies._plan.run_plan`` judges it: the file's scene identity must be this problem's (else the
    run refuses the file), and a study's ``request_hash`` the digest of its options; nothing for a
    missing or unreadable file (the run reports those)."""
    if path is None or not os.path.isfile(path):
        return _Saved()
    import h5py

    from ._plan import scene_identity
    from ._store import digest

    complete, done = set(), {}
    try:
        with h5py.File(path, "r", locking=False) as handle:  # the last commit; a run may be writing
            if handle.attrs.get("scene_hash") != digest(scene_identity(problem)):
                return _Saved()
            for name, kind, options in runs:
                group = handle.get(name)
                if group is None or group.attrs.get("request_hash") != digest(options):
                    continue
                if group.attrs.get("complete"):
                    complete.add(name)
                elif kind.grid and "done" in group:
                    done[name] = np.asarray(group["done"][()], dtype=bool)
    except OSError:  # not HDF5, unreadable: the result file's own checks say so
        return _Saved()
    return _Saved(frozenset(complete), done)


def guard(problem: Any, studies: Mapping[str, Mapping[str, Any]], *, force: bool = False,
          workers: int = 1, result_file: str | os.PathLike | None = None) -> list[Estimate]:
    """Estimate every declared study (``{kind: options}`` as ``plan`` returns them, each of the runs
    it declares) and raise :class:`ResourceError` for the first above the memory or time limit, or
    when all together exceed the time limit; ``force=True`` logs the estimates and raises nothing.
    Also builds the scene at the ends of every axis, so that a value it cannot take is refused (a
    ``MechanismError``) before anything is written. Returns the estimates.

    ``result_file``: the file the run will resume (None for a new file or one started afresh). A
    study it holds complete with the same options is skipped by the run, so it is neither estimated
    nor refused (a run started with ``--force`` resumes without it); a grid study partly saved is
    estimated for its missing points only."""
    from ._kinds import KINDS

    limit_memory, limit_time = memory_limit(), TIME_LIMIT
    limits = f"limits {format_bytes(limit_memory)}, {format_seconds(limit_time)}"
    advice = "pass --force (force=True from Python) to run anyway"
    runs = [(kind + suffix, KINDS[kind], each) for kind, options in studies.items()
            for suffix, each in KINDS[kind].runs(options).items()]
    saved = _saved(result_file, problem, runs)
    estimates = []
    for name, study_kind, each in runs:
        if name in saved.complete:
            logger.debug("%s: complete in %s, not estimated", name, result_file)
            continue
        found = estimate(problem, study_kind.name, each, name=name, workers=workers,
                         done=saved.done.get(name))
        over = found.memory > limit_memory or found.time > limit_time
        if over and not force:
            raise ResourceError(f"{found.describe()}; {limits}; {advice}")
        if over:
            logger.warning("%s; %s; running anyway (--force)", found.describe(), limits)
        else:
            logger.debug("%s", found.describe())
        estimates.append(found)
    total = sum(found.time for found in estimates)
    if not force and total > limit_time:
        raise ResourceError(f"all studies together: about {format_seconds(total)} estimated "
                            f"({', '.join(f'{e.study} {format_seconds(e.time)}' for e in estimates)}); "
                            f"{limits}; {advice}")
    return estimates
