"""The studies as plain functions of a problem (see ``studies._problem``) returning result objects.

Grid studies (``sweep``, ``campbell``, ``stability_chart``) evaluate a top-level point function per
grid point through ``studies._grid.run_grid`` (in-process, any ``concurrent.futures`` executor, or a
Dask cluster's executor); with ``out`` (an open h5py File or Group) each point is written as it
finishes and a re-run with the same settings computes only the missing points.
"""

from __future__ import annotations

import logging
import math
import time
from concurrent.futures import Executor
from typing import Any, Mapping, Sequence

import numpy as np

import periodic

from ._grid import STATUS_FAILED, GridStore, run_grid
from ._numerics import (characteristic_frequencies, crossings, frozen_modes, peak_to_peak, solve_steady, track_modes,
                        unstable_intervals)
from ._problem import SPEED
from ._results import (CampbellResult, ErrorCostResult, NonlinearCheck, StabilityChart, SteadyStateResult,
                       SweepResult)

logger = logging.getLogger(__name__)

#: Frozen-time eigenproblems per period for the resonance bands of a sweep (the bands of smooth
#: coefficients converge fast in the number of samples; 32 resolves a band edge to well under 1 %
#: for coefficients with a few harmonics).
FROZEN_SAMPLES = 32
#: A sweep point whose peak-to-peak error estimate exceeds this fraction of the value gets the status
#: ``STATUS_INACCURATE`` (its numbers are kept, and flagged).
INACCURATE = 0.1
STATUS_INACCURATE = "inaccurate"


def _check_n_steps(n_steps: Any) -> int:
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 4 \
            or n_steps % 2:
        raise ValueError(f"n_steps: expected an even integer >= 4 (the error estimate halves it), "
                         f"got {n_steps!r}")
    return int(n_steps)


def _check_grid(name: str, values: Any) -> np.ndarray:
    array = np.array(values, dtype=float).reshape(-1) if np.size(values) else np.empty(0)
    if array.size == 0 or not np.isfinite(array).all():
        raise ValueError(f"{name}: expected a non-empty sequence of finite numbers, got {values!r}")
    return array


def _check_parameter(problem: Any, name: str) -> str:
    if name not in problem.parameters:
        import difflib

        close = difflib.get_close_matches(str(name), list(problem.parameters), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ValueError(f"parameter {name!r} is not a parameter of problem {problem.name!r}{hint} "
                         f"(parameters: {sorted(problem.parameters)})")
    return name


def _open(out: Any, name: str, shape: tuple[int, ...], kind: str, settings: Mapping[str, Any],
          units: Mapping[str, str], header: Mapping[str, Any],
          axes: Mapping[str, tuple[np.ndarray, str]]) -> GridStore | None:
    """The resumable store of a grid study in ``out`` (None without a file), with its axes written."""
    if out is None:
        return None
    store = GridStore.open(out, name, shape, kind=kind, settings=settings, units=units,
                           header=dict(header, settings=settings))
    for axis, (values, unit) in axes.items():
        if axis not in store.group:
            store.group.create_dataset(axis, data=values).attrs["units"] = unit
    return store


# ---------------------------------------------------------------------------------------------------
# steady state
# ---------------------------------------------------------------------------------------------------
def steady_state(problem: Any, values: Mapping[str, float] | None = None, *, n_steps: int = 256
                 ) -> SteadyStateResult:
    """Periodic response of the problem's observables over one period, Floquet multipliers, error
    estimates (N against N/2 steps) and run time."""
    n_steps = _check_n_steps(n_steps)
    start = time.perf_counter()
    linear = problem.linearize(values, n_steps=n_steps)
    steady = solve_steady(linear)
    state = steady.state
    drawing = {}
    if hasattr(problem, "outlines"):
        outlines, magnification = problem.outlines(linear, state.x)
        drawing = {"outlines": outlines, "magnification": magnification}
    return SteadyStateResult(
        problem=problem.name, parameters=problem.resolve(values), scene=problem.text,
        labels=tuple(linear.labels), units=dict(zip(linear.observables, linear.units)),
        t=state.t, crank_angle=np.asarray(linear.crank_angle, dtype=float), x=state.x,
        response={spec: steady.response[:, k] for k, spec in enumerate(linear.observables)},
        response_error={spec: float(steady.response_error[k])
                        for k, spec in enumerate(linear.observables)},
        multipliers=state.multipliers, spectral_radius=state.spectral_radius,
        error_estimate=steady.error_estimate, status=state.status, message=state.message,
        n_steps=n_steps, run_time=time.perf_counter() - start, shooting_run_time=steady.run_time,
        **drawing)


# ---------------------------------------------------------------------------------------------------
# sweep
# ---------------------------------------------------------------------------------------------------
def sweep_point(problem: Any, values: Mapping[str, float], *, n_steps: int, frozen_samples: int):
    """One sweep point: steady state, multipliers, frozen frequency bands (a top-level function so
    that process pools and Dask can pickle it)."""
    linear = problem.linearize(values, n_steps=n_steps, context=False)
    steady = solve_steady(linear)
    _, frozen, _ = frozen_modes(linear.system, frozen_samples)
    response = steady.response
    data = {
        "speed": 2.0 * math.pi / linear.system.period,
        "spectral_radius": steady.state.spectral_radius,
        "multipliers": steady.state.multipliers,
        "error_estimate": steady.error_estimate,
        "frozen_min": frozen.min(axis=0),
        "frozen_max": frozen.max(axis=0),
        "frozen_mean": frozen.mean(axis=0),
    }
    status, message = steady.state.status, steady.state.message
    for k, spec in enumerate(linear.observables):
        value, sampling = peak_to_peak(response[:, k])
        data[f"peak_to_peak/{spec}"] = value
        # The extremes of two functions each within e of the truth differ by at most 2 e; the
        # sampling correction of the extremes is added as a bound on what the refinement leaves.
        error = 2.0 * float(steady.response_error[k]) + sampling
        data[f"peak_to_peak_error/{spec}"] = error
        if status == "ok" and not error <= INACCURATE * value:
            status = STATUS_INACCURATE
            message = (f"{spec}: peak-to-peak error estimate {error:.3g} exceeds {INACCURATE:.0%} of the "
                       f"value {value:.3g}; refine n_steps (typically near a resonance)")
    return data, status, message


def sweep(problem: Any, parameter: str, values: Sequence[float], *, n_steps: int = 256,
          max_harmonic: int = 4, executor: Executor | None = None, out: Any = None,
          name: str = "sweep", progress: bool = False) -> SweepResult:
    """Sweep ``parameter`` (e.g. ``"speed"``) over ``values``: peak-to-peak of each observable and its
    error, spectral radius, multipliers, frozen frequency bands; resonances ``k * speed`` (k = 1 ..
    ``max_harmonic``) crossing a mean frozen frequency and parametric instabilities (spectral radius
    above 1) marked. ``out``: h5py File/Group to write into (resumable)."""
    start = time.perf_counter()
    parameter = _check_parameter(problem, parameter)
    grid = _check_grid("values", values)
    n_steps = _check_n_steps(n_steps)
    if isinstance(max_harmonic, bool) or not isinstance(max_harmonic, int) or max_harmonic < 1:
        raise ValueError(f"max_harmonic: expected an integer >= 1, got {max_harmonic!r}")
    probe = problem.linearize({parameter: float(grid[0])}, n_steps=4)
    obs_units = dict(zip(probe.observables, probe.units))
    settings = {"parameter": parameter, "values": grid, "n_steps": n_steps, "scene": problem.text,
                "frozen_samples": FROZEN_SAMPLES}
    units = {"speed": "rad/s", "spectral_radius": "1", "multipliers": "1",
             "error_estimate": "SI (see labels)", "frozen_min": "rad/s", "frozen_max": "rad/s",
             "frozen_mean": "rad/s"}
    units.update({f"peak_to_peak/{s}": u for s, u in obs_units.items()})
    units.update({f"peak_to_peak_error/{s}": u for s, u in obs_units.items()})
    header = dict(problem=problem.name, scene=problem.text, parameter=parameter,
                  parameter_unit=problem.units[parameter], labels=tuple(probe.labels), units=obs_units)
    store = _open(out, name, grid.shape, "SweepResult", settings, units, header,
                  {"values": (grid, problem.units[parameter])})
    points = [((i,), {parameter: float(v)}) for i, v in enumerate(grid)]
    outcomes = run_grid(sweep_point, problem, points,
                        {"n_steps": n_steps, "frozen_samples": FROZEN_SAMPLES}, executor=executor,
                        store=store, progress=progress, description=f"{name} over {parameter}")
    fields = _collect(outcomes, grid.shape)
    peak = {spec: fields.pop(f"peak_to_peak/{spec}") for spec in obs_units if f"peak_to_peak/{spec}" in fields}
    peak_error = {spec: fields.pop(f"peak_to_peak_error/{spec}") for spec in obs_units
                  if f"peak_to_peak_error/{spec}" in fields}
    resonances, instabilities = (), ()
    if "spectral_radius" in fields:
        resonances = _resonances(grid, fields["speed"], fields["frozen_mean"], max_harmonic)
        instabilities = tuple(unstable_intervals(grid, fields["spectral_radius"],
                                                 tol=periodic.STABILITY_TOL))
    result = SweepResult(**header, settings=settings, values=grid, peak_to_peak=peak,
                         peak_to_peak_error=peak_error, resonances=resonances,
                         instabilities=instabilities, run_time=time.perf_counter() - start, **fields)
    if store is not None:
        result.to_hdf5(store.group)
    return result


def _resonances(grid: np.ndarray, speed: np.ndarray, frozen_mean: np.ndarray, max_harmonic: int):
    found = []
    for mode in range(frozen_mean.shape[1]):
        for k in range(1, max_harmonic + 1):
            for _, value in crossings(grid, k * speed - frozen_mean[:, mode]):
                found.append((k, mode, value))
    return tuple(sorted(found, key=lambda item: item[2]))


def _collect(outcomes: Mapping[tuple[int, ...], Any], shape: tuple[int, ...]) -> dict[str, np.ndarray]:
    """Stack point outcomes into grid arrays (NaN where a point failed or is missing)."""
    done = np.zeros(shape, dtype=bool)
    status = np.full(shape, "missing", dtype=object)
    message = np.full(shape, "", dtype=object)
    run_time = np.full(shape, np.nan)
    arrays: dict[str, np.ndarray] = {}
    for index, outcome in outcomes.items():
        done[index] = True
        status[index] = outcome.status
        message[index] = outcome.message
        run_time[index] = outcome.run_time
        for key, value in outcome.data.items():
            value = np.asarray(value)
            if key not in arrays:
                arrays[key] = np.full(shape + value.shape, np.nan,
                                      dtype=complex if np.iscomplexobj(value) else float)
            if outcome.status != STATUS_FAILED:
                arrays[key][index] = value
    arrays.update(done=done, status=status.astype(str), message=message.astype(str),
                  point_run_time=run_time)
    return arrays


# ---------------------------------------------------------------------------------------------------
# Campbell diagram
# ---------------------------------------------------------------------------------------------------
def campbell_point(problem: Any, values: Mapping[str, float], *, n_steps: int, frozen_samples: int):
    """One speed of a Campbell diagram: frozen frequencies over the crank angle, mode shapes at crank
    angle 0, Floquet multipliers."""
    linear = problem.linearize(values, n_steps=n_steps, context=False)
    index, frozen, shapes = frozen_modes(linear.system, frozen_samples)
    result = periodic.floquet(linear.system)
    coarse = periodic.floquet(linear.system.coarsened())
    status = "ok" if result.resolved.all() else "unresolved_mode"
    message = "" if status == "ok" else (f"{int((~result.resolved).sum())} multipliers belong to modes "
                                         f"the {n_steps} steps do not resolve")
    return ({"frozen": frozen, "shapes": shapes, "multipliers": result.multipliers,
             "multipliers_coarse": coarse.multipliers,
             "period": linear.system.period, "crank_angle": np.asarray(linear.crank_angle)[index]},
            status, message)


def campbell(problem: Any, speeds: Sequence[float], *, n_steps: int = 256, frozen_samples: int = 64,
             max_harmonic: int = 6, executor: Executor | None = None, out: Any = None,
             name: str = "campbell", progress: bool = False) -> CampbellResult:
    """Campbell diagram over crank ``speeds`` (rad/s): frozen-time natural frequency bands over the
    crank angle, Floquet characteristic frequencies, lines ``k * speed`` (k <= ``max_harmonic``),
    modes tracked across speeds by MAC of their shapes at crank angle 0 and labelled."""
    start = time.perf_counter()
    grid = _check_grid("speeds", speeds)
    if (grid <= 0).any() or (np.diff(grid) <= 0).any():
        raise ValueError(f"speeds: expected positive, increasing crank speeds (rad/s), got {speeds!r}")
    n_steps = _check_n_steps(n_steps)
    probe = problem.linearize({SPEED: float(grid[0])}, n_steps=4)
    settings = {"speeds": grid, "n_steps": n_steps, "frozen_samples": frozen_samples,
                "scene": problem.text}
    units = {"frozen": "rad/s", "shapes": "1", "multipliers": "1", "multipliers_coarse": "1", "period": "s",
             "crank_angle": "rad"}
    header = dict(problem=problem.name, scene=problem.text, labels=tuple(probe.labels))
    store = _open(out, name, grid.shape, "CampbellResult", settings, units, header,
                  {"speeds": (grid, "rad/s")})
    points = [((i,), {SPEED: float(v)}) for i, v in enumerate(grid)]
    outcomes = run_grid(campbell_point, problem, points,
                        {"n_steps": n_steps, "frozen_samples": frozen_samples}, executor=executor,
                        store=store, progress=progress, description=f"{name} over speed")
    fields = _collect(outcomes, grid.shape)
    extra: dict[str, Any] = {}
    if "frozen" in fields:
        fields["crank_angle"] = fields["crank_angle"][np.flatnonzero(fields["done"])[0]]
        order, confidence = track_modes(fields["shapes"])
        rows = np.arange(grid.size)[:, None]
        band_min = fields["frozen"].min(axis=1)[rows, order]
        band_max = fields["frozen"].max(axis=1)[rows, order]
        band_mean = fields["frozen"].mean(axis=1)[rows, order]
        characteristic, characteristic_error = [], []
        for i in range(grid.size):
            fine = characteristic_frequencies(fields["multipliers"][i], fields["period"][i], band_mean[i])
            halved = characteristic_frequencies(fields["multipliers_coarse"][i], fields["period"][i],
                                                band_mean[i])
            characteristic.append(fine)
            # order 2 in the step: the N/2 difference over 3 estimates the error of the N-step value
            characteristic_error.append(np.array([np.nanmin(np.abs(halved - f)) / 3.0 if np.isfinite(f)
                                                  else np.nan for f in fine]))
        characteristic, characteristic_error = np.array(characteristic), np.array(characteristic_error)
        first = fields["shapes"][0]
        labels = tuple(f"mode {j + 1} ({probe.labels[int(np.argmax(np.abs(first[:, j])))]})"
                       if np.isfinite(first[:, j]).all() else f"mode {j + 1}"
                       for j in range(first.shape[1]))
        extra = dict(order=order, tracking_mac=confidence, band_min=band_min, band_max=band_max,
                     band_mean=band_mean, characteristic=characteristic,
                     characteristic_error=characteristic_error, mode_labels=labels,
                     harmonics=tuple(range(1, max_harmonic + 1)))
    result = CampbellResult(**header, settings=settings, speeds=grid, run_time=time.perf_counter() - start,
                            **fields, **extra)
    if store is not None:
        result.to_hdf5(store.group)
    return result


# ---------------------------------------------------------------------------------------------------
# stability chart
# ---------------------------------------------------------------------------------------------------
def chart_point(problem: Any, values: Mapping[str, float], *, n_steps: int):
    """Spectral radius of the monodromy at one point of a stability chart, with its error estimate."""
    linear = problem.linearize(values, n_steps=n_steps, context=False)
    result = periodic.floquet(linear.system)
    coarse = periodic.floquet(linear.system.coarsened())
    unresolved = ~result.resolved & (np.abs(result.multipliers) > 1.0 + result.stability_tol)
    status = "unresolved_mode" if unresolved.any() else "ok"
    message = ("an unstable multiplier belongs to a mode the step does not resolve: refine n_steps"
               if unresolved.any() else "")
    # Newmark's multipliers converge at order 2: the N/2 difference over 3 estimates the N-step error.
    error = abs(result.spectral_radius - coarse.spectral_radius) / 3.0
    return {"spectral_radius": result.spectral_radius, "spectral_radius_error": error}, status, message


def stability_chart(problem: Any, first: tuple[str, Sequence[float]], second: tuple[str, Sequence[float]],
                    *, n_steps: int = 128, executor: Executor | None = None, out: Any = None,
                    name: str = "stability_chart", progress: bool = False) -> StabilityChart:
    """Spectral radius of the monodromy, and its error estimate (N against N/2 steps), over a grid of
    two parameters ``(name, values)``; the boundary ``|mu| = 1`` is drawn by ``plot``."""
    start = time.perf_counter()
    if not (isinstance(first, tuple) and len(first) == 2 and isinstance(second, tuple) and len(second) == 2):
        raise TypeError(f"first, second: expected (parameter name, values) pairs, got {first!r}, {second!r}")
    names = (_check_parameter(problem, first[0]), _check_parameter(problem, second[0]))
    if names[0] == names[1]:
        raise ValueError(f"stability_chart: the two parameters must differ, got {names[0]!r} twice")
    axes = (_check_grid(f"{names[0]} values", first[1]), _check_grid(f"{names[1]} values", second[1]))
    n_steps = _check_n_steps(n_steps)
    shape = (axes[0].size, axes[1].size)
    settings = {"parameters": names, "first": axes[0], "second": axes[1], "n_steps": int(n_steps),
                "scene": problem.text}
    units = (problem.units[names[0]], problem.units[names[1]])
    header = dict(problem=problem.name, scene=problem.text, parameters=names, parameter_units=units,
                  stability_tol=periodic.STABILITY_TOL)
    store = _open(out, name, shape, "StabilityChart", settings,
                  {"spectral_radius": "1", "spectral_radius_error": "1"}, header,
                  {"first": (axes[0], units[0]), "second": (axes[1], units[1])})
    # The crank speed varies fastest, so that consecutive points (and a worker's batch) share the
    # other parameter and reuse one speed family of the linearisation.
    speed_first = names[0] == SPEED
    points = [((i, j), {names[0]: float(axes[0][i]), names[1]: float(axes[1][j])})
              for outer in range(shape[1 if speed_first else 0])
              for inner in range(shape[0 if speed_first else 1])
              for i, j in [(inner, outer) if speed_first else (outer, inner)]]
    outcomes = run_grid(chart_point, problem, points, {"n_steps": int(n_steps)}, executor=executor,
                        store=store, progress=progress, description=f"{name}")
    fields = _collect(outcomes, shape)
    result = StabilityChart(**header, settings=settings, first=axes[0], second=axes[1],
                            run_time=time.perf_counter() - start, **fields)
    if store is not None:
        result.to_hdf5(store.group)
    return result


# ---------------------------------------------------------------------------------------------------
# nonlinear check
# ---------------------------------------------------------------------------------------------------
def nonlinear_check(problem: Any, values: Mapping[str, float] | None = None, *, n_steps: int = 256,
                    n_periods: int = 5, from_rest: bool = False, max_periods_from_rest: int = 200,
                    steady_tol: float = 0.01) -> NonlinearCheck:
    """Run the full nonlinear model from the linear periodic state for ``n_periods`` periods (and
    optionally from rest for up to ``max_periods_from_rest``) and compare with the linear solution."""
    if not getattr(problem, "supports_nonlinear", False):
        raise ValueError(f"problem {problem.name!r} has no nonlinear model to check against")
    n_steps = _check_n_steps(n_steps)
    for key, value, low in (("n_periods", n_periods, 2), ("max_periods_from_rest", max_periods_from_rest, 2)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{key}: expected an integer >= {low}, got {value!r}")
    start = time.perf_counter()
    linear = problem.linearize(values, n_steps=n_steps)
    steady = solve_steady(linear)
    linear_time = time.perf_counter() - start
    specs = linear.observables
    run = problem.simulate(linear, steady.state.x[0], steady.state.v[0], n_periods=n_periods,
                           steps_per_period=n_steps, values=values)
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
        rest = problem.simulate(linear, zero, zero, n_periods=max_periods_from_rest,
                                steps_per_period=n_steps, values=values)
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


# ---------------------------------------------------------------------------------------------------
# error against run time
# ---------------------------------------------------------------------------------------------------
def error_cost(problem: Any, values: Mapping[str, float] | None = None, *,
               n_steps: Sequence[int] = (32, 64, 128, 256), resolution: tuple[str, Sequence[float]] | None = None,
               reference_steps: int | None = None) -> ErrorCostResult:
    """Error of the steady response against run time, over steps per period and (optionally) a
    resolution parameter such as a number of elements ``("links.coupler.discretisation.n_elements",
    (1, 2, 4))``. The reference is the finest resolution at ``reference_steps`` (default 4 x the
    largest ``n_steps``) with Richardson extrapolation (order 4). Runs in-process so the times are
    comparable."""
    steps = [_check_n_steps(n) for n in n_steps]
    if sorted(steps) != steps or len(set(steps)) != len(steps):
        raise ValueError(f"n_steps: expected increasing step counts, got {n_steps!r}")
    base = steps[0]
    if any(n % base for n in steps):
        raise ValueError(f"n_steps: every entry must be a multiple of the first ({base}) so the "
                         f"responses can be compared on common samples, got {n_steps!r}")
    reference_steps = _check_n_steps(reference_steps or 4 * steps[-1])
    if reference_steps % base:
        raise ValueError(f"reference_steps: must be a multiple of {base}, got {reference_steps}")
    if resolution is None:
        name, levels = "", np.array([0.0])
    else:
        name = _check_parameter(problem, resolution[0])
        levels = _check_grid("resolution values", resolution[1])

    def at(level: float) -> dict[str, float]:
        merged = dict(values or {})
        if name:
            merged[name] = level
        return merged

    start = time.perf_counter()
    reference_linear = problem.linearize(at(levels[-1]), n_steps=reference_steps)
    reference_state = periodic.steady_state(reference_linear.system, extrapolate=True)
    reference = reference_linear.observe(reference_state.x)[:: reference_steps // base]
    reference_time = time.perf_counter() - start
    specs = reference_linear.observables
    scale = np.maximum(np.ptp(reference, axis=0), np.finfo(float).tiny)
    error = {s: np.full((levels.size, len(steps)), np.nan) for s in specs}
    estimate = {s: np.full((levels.size, len(steps)), np.nan) for s in specs}
    run_time = np.full((levels.size, len(steps)), np.nan)
    n_dof = np.zeros(levels.size)
    for i, level in enumerate(levels):
        for j, n in enumerate(steps):
            tick = time.perf_counter()
            linear = problem.linearize(at(level), n_steps=n)
            steady = solve_steady(linear)
            run_time[i, j] = time.perf_counter() - tick
            n_dof[i] = linear.system.n_dof
            response = steady.response[:: n // base]
            for k, spec in enumerate(specs):
                error[spec][i, j] = np.abs(response[:, k] - reference[:, k]).max() / scale[k]
                estimate[spec][i, j] = steady.response_error[k] / scale[k]
    return ErrorCostResult(
        problem=problem.name, scene=problem.text, resolution_parameter=name,
        units=dict(zip(specs, reference_linear.units)),
        settings={"values": dict(values or {}), "n_steps": steps, "reference_steps": reference_steps,
                  "resolution": [name, levels] if name else None},
        resolutions=levels, n_steps=np.array(steps), n_dof=n_dof, error=error, error_estimate=estimate,
        run_time=run_time, reference_steps=reference_steps, reference_run_time=reference_time)
