"""What a study costs: the helpers each study kind's cost model (``StudyKind.cost``) is written with,
and :func:`estimate`, which asks a kind's model. The resource guard (``studies._guard``)
refuses a run whose estimates exceed its limits (docs/studies.md, "Limits").

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
  plus two linearisations per orbit and ``LINEAR_POINTS`` for the linear curve, and its transient;
- the error budget (``studies._budget``) adds, at each point of a linearised mechanism, its
  linearisation term, ``BUDGET_SOLVES`` periodic solves (:func:`budget_seconds`), and at each
  headline point its mesh term, a linearisation and a solve with every elastic link refined once,
  sized at twice the coordinates (:func:`with_mesh_term`).

The constants were measured on the development machine (2 cores, 2024) with
``benchmarks/bench_guard.py``, which prints measured over estimated memory and time for a range of
sizes; rerun it on another machine and adjust the constants if the ratios leave about 0.3-3.
An estimate is good to a factor of a few: enough to stop a run that would take a day or exhaust the
memory, not to predict its minute.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ._kind import kind_named
from ._mechanism import count_keys
from ._problem import SPEED

__all__ = ["Estimate", "estimate", "format_bytes", "format_seconds", "steady_solves"]

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
#: four_bar_fem4, n = 21, in 2024; raised from 6e-5 with the error budget (issue 22): the nonlinear
#: steady state of four_bar_fem4 at 128 steps took 1.42 s against 0.52 s estimated, while the linear
#: steady state took 0.135 s against 0.2 s, on the loaded machine; now 0.91 s estimated).
PERIOD_STEP_SECONDS = 3.0e-4
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
#: The error budget's linearisation term at a point, in periodic solves (``solve_seconds``): 1-5
#: residuals of the full equations on 64+ samples and two single-column marches per chord step
#: (benchmarks/bench_guard.py with the budget; benchmarks/bench_budget.py: a point costs 1.2-2.2x
#: its solve without the budget).
BUDGET_SOLVES = 1.0
#: The mesh term's refined model against the scene's, in coordinates (n and m): every elastic link's
#: elements doubled (or two more modes): four_bar_fem4 21 -> 33 coordinates (8 elements on the coupler).
MESH_REFINEMENT = 1.5


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
class Sizes:
    """``n`` coordinates of the assembled model (all, with the constraints') and ``m`` independent
    ones (those the periodic system is written in)."""

    n: int
    m: int


def sizes_at(problem: Any, values: Mapping[str, float]) -> Sizes:
    """The coordinate counts at ``values`` (a mechanism is built there, which checks the values)."""
    if hasattr(problem, "mechanism"):
        import mechanisms

        model = mechanisms.assemble(problem.mechanism(values))
        return Sizes(n=model.n_coords, m=model.n_coords - model.n_constraints)
    m = len(problem.describe(values).labels)
    return Sizes(n=m, m=m)


def largest_sizes(problem: Any, axes: Sequence[tuple[str, np.ndarray]]) -> Sizes:
    """The coordinate counts at the largest value of each size key on the axes (the scene's
    otherwise); every axis end is built once first, so that a value the scene cannot take is
    refused before anything runs."""
    if hasattr(problem, "mechanism"):
        for parameter, grid in axes:
            for value in (float(np.min(grid)), float(np.max(grid))):
                problem.mechanism({parameter: value})
    counts = count_keys()
    largest = {parameter: float(np.max(grid)) for parameter, grid in axes
               if parameter.split(".")[-1] in counts}
    return sizes_at(problem, largest)


# ---------------------------------------------------------------------------------------------------
# cost models
# ---------------------------------------------------------------------------------------------------
def linearisation(n_steps: int, sizes: Sizes) -> tuple[float, float]:
    """(peak bytes, seconds) of one linearisation."""
    samples = (n_steps + 1) * sizes.n**2
    return 8.0 * LINEARISATION_DOUBLES * samples, LINEARISATION_SECONDS * samples


def solve_seconds(n_steps: int, sizes: Sizes, frozen: int = 0) -> float:
    """Seconds of one periodic solve (and ``frozen`` frozen-time eigenproblems)."""
    per_step = STEP_SECONDS + STEP_M2_SECONDS * sizes.m**2 + SOLVE_SECONDS * sizes.m**3
    return POINT_SECONDS + n_steps * per_step + EIGEN_SECONDS * frozen * sizes.m**3


def steady_solves(name: str, problem: Any, points: Sequence[Mapping[str, float]], n_steps: int, *,
                  budget: bool = False) -> Estimate:
    """One study of a linearisation and a periodic solve (shooting at N, N/2 and N/4, multipliers) at
    each parameter values of ``points`` ({parameter: value}; ``{}`` the scene's), one after the
    other: a steady state, or a kind that computes a few (a public helper for a new kind's cost);
    ``budget``: each with its error budget (linearisation term and mesh term, ``with_mesh_term``)."""
    if not points:
        raise ValueError("steady_solves: expected at least one point")
    memory, seconds, largest = 0.0, STUDY_SECONDS, Sizes(0, 0)
    for values in points:
        sizes = sizes_at(problem, values)
        largest = max(largest, sizes, key=lambda s: s.m)
        build_bytes, build_seconds = linearisation(n_steps, sizes)
        memory = max(memory, build_bytes)
        seconds += build_seconds + solve_seconds(n_steps, sizes)
        if budget:
            seconds += budget_seconds(problem, n_steps, sizes)
            meshed = with_mesh_term(Estimate(name, memory, 0.0, ""), problem, values, n_steps, held=build_bytes)
            memory, seconds = meshed.memory, seconds + meshed.time
    count = f"{len(points)} steady states x " if len(points) > 1 else ""
    return Estimate(name, memory, seconds, f"{count}{n_steps} steps x {largest.m} coordinates")


def grid_cost(name: str, problem: Any, axes: Sequence[tuple[str, np.ndarray]], n_steps: int, *,
          frozen: int = 0, point_doubles: Callable[[Sizes], float] = lambda s: 4.0 * s.m,
          workers: int = 1, words: Sequence[str], done: np.ndarray | None = None,
          budget: bool = False) -> Estimate:
    """A grid study over ``axes``: one periodic solve per point; one speed family per combination of
    the other parameters' values when the speed is an axis, else one linearisation per combination.
    ``done``: the points already saved (bool, grid shape), neither solved nor linearised again;
    ``budget``: each point also estimates its error budget's linearisation term (``budget_seconds``)."""
    sizes = largest_sizes(problem, axes)
    total = math.prod(len(grid) for _, grid in axes)
    shape = tuple(len(grid) for _, grid in axes)
    if done is None or np.shape(done) != shape:  # no mask is allocated for a grid not yet started
        points = total
        variants = math.prod(len(np.unique(grid)) for parameter, grid in axes if parameter != SPEED)
        left = []
    else:
        todo = ~np.asarray(done, dtype=bool)
        points = int(np.count_nonzero(todo))
        variants = grid_variants(axes, todo)
        left = [f"{points} of {total} points left"]
    family = FAMILY_FACTOR if any(parameter == SPEED for parameter, _ in axes) else 1.0
    build_bytes, build_seconds = linearisation(n_steps, sizes)
    held = HELD_DOUBLES * (min(max(variants, 1), CACHED_FAMILIES) - 1)
    peak = (FAMILY_DOUBLES if family > 1.0 else LINEARISATION_DOUBLES) + held
    parallel = max(1, min(workers, points))
    per_process = 8.0 * peak * (n_steps + 1) * sizes.n**2
    # the collected arrays of every point (the saved ones are read back), kept in the main process
    results = 8.0 * total * point_doubles(sizes)
    # each worker process builds the linearisations its points need (a speed family once per process)
    seconds = (STUDY_SECONDS + variants * family * build_seconds / max(1, min(parallel, variants))
               + points * solve_seconds(n_steps, sizes, frozen) / parallel
               + (budget_seconds(problem, n_steps, sizes, points) / parallel if budget else 0.0))
    memory = per_process * parallel + results
    return Estimate(name, memory, seconds, " x ".join(list(words) + [f"{n_steps} steps",
                                                                      f"{sizes.m} coordinates"])
                    + "".join(f" ({note})" for note in left))


def budget_seconds(problem: Any, n_steps: int, sizes: Sizes, points: int = 1) -> float:
    """Seconds of the error budget's linearisation term at ``points`` points (0 for a problem that
    is linear as written, a ``PeriodicProblem``: the term does not apply)."""
    if not hasattr(problem, "mechanism"):
        return 0.0
    return points * BUDGET_SOLVES * solve_seconds(n_steps, sizes)


def with_mesh_term(found: Estimate, problem: Any, values: Mapping[str, float], n_steps: int, *,
                   held: float = 0.0, relative: bool = False) -> Estimate:
    """``found`` plus the error budget's mesh term at ``values`` (``studies._mesh_error``: a
    linearisation and a solve of the model with every elastic link refined once, sized at
    ``MESH_REFINEMENT`` times the coordinates), its memory on top of ``held`` bytes still held (the
    point's own linearisation); ``relative``: and the steady state at ``values`` it is taken relative
    to (a sweep's). A problem without elastic links (no mechanism) has none."""
    if not hasattr(problem, "mechanism"):
        return found
    sizes = sizes_at(problem, values)
    refined = Sizes(n=MESH_REFINEMENT * sizes.n, m=MESH_REFINEMENT * sizes.m)
    refined_bytes, refined_seconds = linearisation(n_steps, refined)
    seconds = refined_seconds + solve_seconds(n_steps, refined)
    if relative:
        seconds += linearisation(n_steps, sizes)[1] + solve_seconds(n_steps, sizes)
    return Estimate(found.study, max(found.memory, held + refined_bytes), found.time + seconds, found.sizes)


def grid_variants(axes: Sequence[tuple[str, np.ndarray]], todo: np.ndarray) -> int:
    """Distinct combinations of the values of the axes other than the speed among the points
    ``todo`` (bool, grid shape): each needs a linearisation (a speed family) of its own."""
    where = np.nonzero(todo)
    columns = [np.asarray(grid, dtype=float)[where[axis]] for axis, (parameter, grid) in enumerate(axes)
               if parameter != SPEED]
    if not columns:
        return min(1, where[0].size)
    return len(np.unique(np.stack(columns, axis=1), axis=0))


def axis_words(parameter: str, grid: np.ndarray) -> str:
    return f"{len(grid)} {'speeds' if parameter == SPEED else 'values of ' + parameter}"


def with_reduction_check(found: Estimate, problem: Any, values: Mapping[str, float], n_steps: int, *,
                          extra_solve: bool = True) -> Estimate:
    """``found`` plus the modal reduction's check where a link is reduced: a linearisation and a solve
    at modes + 2 (and, for a grid study, which checks once at the scene's values, the reduced solve it
    compares with: ``extra_solve``)."""
    reference = reduction_reference_sizes(problem, values)
    if reference is None:
        return found
    reference_bytes, reference_seconds = linearisation(n_steps, reference)
    seconds = reference_seconds + solve_seconds(n_steps, reference)
    if extra_solve:
        sizes = sizes_at(problem, values)
        seconds += linearisation(n_steps, sizes)[1] + solve_seconds(n_steps, sizes)
    return Estimate(found.study, max(found.memory, reference_bytes), found.time + seconds,
                    f"{found.sizes} + the reduction check at {reference.m}")


def reduction_reference_sizes(problem: Any, values: Mapping[str, float]) -> Sizes | None:
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
    return Sizes(n=model.n_coords, m=model.n_coords - model.n_constraints)


def nonlinear_period_seconds(n_steps: int, sizes: Sizes) -> float:
    """Seconds of one period of ``mechanisms.PeriodMap`` (no monodromy, no observables)."""
    return n_steps * (PERIOD_STEP_SECONDS + NONLINEAR_STEP_N2_SECONDS * sizes.n**2)


def tangent_bytes(n_steps: int, sizes: Sizes) -> float:
    """Peak bytes of one monodromy: the iteration matrices of size n + r at every step."""
    return 8.0 * TANGENT_DOUBLES * n_steps * (2 * sizes.n - sizes.m) ** 2



def estimate(problem: Any, kind: str, options: Mapping[str, Any], *, name: str | None = None,
             workers: int = 1, done: np.ndarray | None = None) -> Estimate:
    """The estimated cost of one run of the registered study kind ``kind`` with checked ``options``
    (one of the runs its table declares) on ``problem``, by the kind's own cost model, with ``workers``
    processes for a grid study; ``done`` (bool, the grid's shape; grid studies only): the points
    already saved, which a resumed run reads back."""
    study = kind_named(kind)
    saved = {} if done is None or not study.grid else {"done": done}  # only the grid models take it
    return study.cost(name or kind, problem, options, max(1, int(workers)), **saved)
