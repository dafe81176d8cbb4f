"""What the study functions share: argument checks, the fields and HDF5 store of grid studies, and
the stacking of grid points into arrays. The studies themselves live one per module in
``studies._kinds``.

Grid studies (``sweep``, ``campbell``, ``stability_chart``) evaluate a top-level point function per
grid point through ``studies._grid.run_grid`` (in-process, any ``concurrent.futures`` executor, or a
Dask cluster's executor); with ``out`` (an open h5py File or Group) each point is written as it
finishes and a re-run with the same settings computes only the missing points.
"""

from __future__ import annotations

import contextlib
import difflib
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from . import _verdicts as verdicts
from ._errors import StudiesError
from ._grid import STATUS_FAILED, GridStore
from ._store import Result, owner_of


def check_n_steps(n_steps: Any, *, minimum: int = 16, multiple: int = 4, study: str = "this study") -> int:
    """``n_steps`` as an int: a multiple of ``multiple`` (4 where the error check compares N, N/2 and
    N/4 steps; 2 where it compares N and N/2) and at least ``minimum`` (docs/studies.md lists each
    study's minimum: below it the N/2 error estimate is far from the true error)."""
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < minimum \
            or n_steps % multiple:
        reason = ("compares N, N/2 and N/4 steps" if multiple == 4 else "compares N and N/2 steps")
        raise StudiesError(f"n_steps: expected an integer, a multiple of {multiple} and at least "
                           f"{minimum} for {study} (its error estimate {reason}; the minimum is in "
                           f"docs/studies.md), got {n_steps!r}")
    return int(n_steps)


def check_grid(name: str, values: Any) -> np.ndarray:
    array = np.array(values, dtype=float).reshape(-1) if np.size(values) else np.empty(0)
    if array.size == 0 or not np.isfinite(array).all():
        raise StudiesError(f"{name}: expected a non-empty sequence of finite numbers, got {values!r}")
    return array


def check_integer(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise StudiesError(f"{name}: expected an integer >= {minimum}, got {value!r}")
    return value


def check_parameter(problem: Any, name: str) -> str:
    if name not in problem.parameters:
        close = difflib.get_close_matches(str(name), list(problem.parameters), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        advice = getattr(problem, "parameter_advice", None)  # a mechanism problem says how to add it
        raise StudiesError(f"parameter {name!r} is not a parameter of problem {problem.name!r}{hint} "
                           f"(parameters: {sorted(problem.parameters)})"
                           + (f"; {advice(name)}" if advice is not None else ""))
    return name


def open_store(out: Any, name: str, shape: tuple[int, ...], kind: str, settings: Mapping[str, Any],
               units: Mapping[str, str], header: Mapping[str, Any],
               axes: Mapping[str, tuple[np.ndarray, str]]) -> GridStore | None:
    """The resumable store of a grid study in ``out`` (None without a file), with its axes written."""
    if out is None:
        return None
    owner = owner_of(out)
    # one write: a commit (on an interrupt) never sees the group without its axes
    with owner.writing() if owner is not None else contextlib.nullcontext():
        store = GridStore.open(out, name, shape, kind=kind, settings=settings, units=units,
                               header=dict(header, settings=settings))
        for axis, (values, unit) in axes.items():
            if axis not in store.group:
                store.group.create_dataset(axis, data=values).attrs["units"] = unit
    return store


def collect(outcomes: Mapping[tuple[int, ...], Any], shape: tuple[int, ...]) -> dict[str, np.ndarray]:
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


@dataclass(frozen=True, eq=False)
class GridResult(Result):
    """Fields shared by the grid studies: ``problem`` name, ``scene`` text, ``settings``; per grid
    point ``done`` (bool; False where an interrupted run did not get), ``status`` ("ok", a periodic
    status, "inaccurate" or "failed"), ``message`` (str) and ``point_run_time`` (s)."""

    problem: str
    scene: str
    settings: Mapping[str, Any]
    done: np.ndarray
    status: np.ndarray
    message: np.ndarray
    point_run_time: np.ndarray

    _units = {"done": "1", "status": "1", "message": "1", "point_run_time": "s"}


def grid_summary(result: GridResult, extra: str = "", *, point: Any = None) -> str:
    """``flexvib run``'s line for a grid study: points done, the count of each status, ``extra``, run
    time, and the worst cases (``point(index) -> str`` names a grid point, e.g. "speed 185")."""
    done = int(result.done.sum())
    line = f"{done}/{result.done.size} points: {status_counts(result.status[result.done])}{extra}; " \
           f"{result.run_time:.3g} s"
    worst = worst_cases(result.status, result.message, point or (lambda index: f"point {index}"))
    return line + (f"\n    worst: {worst}" if worst else "")


def status_counts(status: np.ndarray) -> str:
    """"40 ok, 10 unstable, 7 marginal": the count of each status, most severe first."""
    names, counts = np.unique(np.asarray(status, dtype=str), return_counts=True)
    order = sorted(range(names.size), key=lambda i: verdicts.severity(str(names[i])))
    return ", ".join(f"{counts[i]} {names[i]}" for i in order) or "none"


def worst_cases(status: np.ndarray, message: np.ndarray, point: Any, *, count: int = 3,
                width: int = 160) -> str:
    """The ``count`` points of the most severe status (not ``ok``) with their messages, shortened to
    ``width`` characters each."""
    status, message = np.asarray(status, dtype=str), np.asarray(message, dtype=str)
    ranks = np.vectorize(verdicts.severity, otypes=[int])(status) if status.size else np.array([])
    if not status.size or ranks.min() >= verdicts.severity("ok"):
        return ""
    chosen = np.argwhere(ranks == ranks.min())
    cases = []
    for index in map(tuple, chosen[:count]):
        text = str(message[index]).removeprefix(f"{status[index]}: ")
        text = text if len(text) <= width else text[:width - 3] + "..."
        cases.append(f"{point(index)}: {status[index]}" + (f" ({text})" if text else ""))
    more = f"; and {len(chosen) - count} more" if len(chosen) > count else ""
    return "; ".join(cases) + more
