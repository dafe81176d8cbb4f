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
import time
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from . import _verdicts as verdicts
from ._errors import StudiesError
from ._grid import STATUS_FAILED, GridStore
from ._plots import plain
from ._result import StudyResult
from ._store import write_array
from ._summary import Headline
from ._writes import owner_of


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


def open_store(out: Any, name: str, shape: tuple[int, ...], kind: type, settings: Mapping[str, Any],
               units: Mapping[str, str], header: Mapping[str, Any],
               axes: Mapping[str, tuple[np.ndarray, str]]) -> GridStore | None:
    """The resumable store of a grid study in ``out`` (None without a file), with its axes written;
    ``kind`` the result class."""
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
        store.seal()   # its checksum, with the axes (studies._integrity)
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
    arrays.update(done=done, point_status=status.astype(str), point_message=message.astype(str),
                  point_run_time=run_time)
    return arrays


@dataclass(frozen=True, eq=False)
class GridResult(StudyResult):
    """Fields shared by the grid studies (the common ones in ``studies._result``).

    Attributes
    ----------
    problem : str
        The problem's name.
    scene : str
        The scene text (TOML), or the equation of a ``PeriodicProblem``.
    settings : dict
        The study's arguments (JSON-like).
    done : ndarray of bool, grid shape
        Whether each point was computed (False where an interrupted run did not get).
    point_status : ndarray of str, grid shape
        Each point's verdict ("ok", a periodic status, "inaccurate" or "failed"; "missing" where not
        done); stored as the dataset ``status``.
    point_message : ndarray of str, grid shape
        Each point's message; stored as the dataset ``message``.
    point_run_time : ndarray of float, grid shape, s
        Each point's wall time.
    run_time : float, s
        The whole study's wall time (grid, reduction check and the stacking of the points).
    reduction_error : float, 1
        The modal reduction's check (``reduction_check``, once per study at the scene's own values):
        the largest difference of an observable from the next larger mode set over its
        peak-to-peak; 0 without a reduced link.
    reduction_status : str
        "ok", "inaccurate", or "failed" when the check could not be solved.
    reduction_message : str
        "" without a reduced link.
    reduction_run_time : float, s
        The check's cost (in ``run_time``).
    status : str
        Property: the worst of the done points' statuses and the reduction check's.
    message : str
        Property: the count of each status, the worst points and the reduction check's message.
    """

    problem: str
    scene: str
    settings: Mapping[str, Any]
    done: np.ndarray
    point_status: np.ndarray
    point_message: np.ndarray
    point_run_time: np.ndarray
    # keyword-only, so that the kinds' own fields without defaults may follow
    run_time: float = field(default=float("nan"), kw_only=True)
    reduction_error: float = field(default=0.0, kw_only=True)
    reduction_status: str = field(default="ok", kw_only=True)
    reduction_message: str = field(default="", kw_only=True)
    reduction_run_time: float = field(default=0.0, kw_only=True)

    is_grid = True
    # the grid store (``studies._grid.GridStore``) writes the points' verdicts as "status", "message"
    _stored_as = {"point_status": ("status",), "point_message": ("message",)}
    _units = {"done": "1", "point_status": "1", "point_message": "1", "point_run_time": "s",
              "reduction_error": "1", "reduction_run_time": "s"}
    #: Scalars written as 0-d datasets, so that they carry their ``units`` like the arrays.
    _scalars_with_units = ("reduction_error", "reduction_run_time")

    def _write(self, group: Any) -> None:
        super()._write(group)
        for name in self._scalars_with_units:
            if name in group.attrs:
                del group.attrs[name]
            write_array(group, name, np.asarray(float(getattr(self, name))), self._unit(name))

    @property
    def status(self) -> str:
        """The study's status: the worst of its points' (done ones) and its reduction check's."""
        done = np.asarray(self.done, dtype=bool)
        return verdicts.combine([(str(status), "") for status in np.asarray(self.point_status)[done]]
                                + [(self.reduction_status, self.reduction_message)])[0]

    @property
    def message(self) -> str:
        """The count of each point status, the worst points (when not ``ok``) and the reduction
        check's verdict when it is not ``ok``."""
        done = np.asarray(self.done, dtype=bool)
        words = [f"{int(done.sum())}/{done.size} points: {status_counts(np.asarray(self.point_status)[done])}"]
        worst = worst_cases(np.where(done, self.point_status, "missing"), self.point_message,
                            point_name)
        words += [f"worst: {worst}"] if worst else []
        words += [f"modal reduction {self.reduction_status}: {self.reduction_message}"] \
            if self.reduction_status != "ok" else []
        return "; ".join(words)

    def reduction_note(self) -> str:
        """A line for the figures' titles when the reduction check is not ``ok`` ("" otherwise)."""
        if self.reduction_status == "ok":
            return ""
        return f"\nmodal reduction {self.reduction_status}: {plain(100 * self.reduction_error)} % in every point"


def reduction_check(problem: Any, *, n_steps: int) -> dict[str, Any]:
    """The ``GridResult`` reduction fields of ``problem``: ``linearize.reduction_error`` of its
    mechanism at the scene's own values (every parameter, speed included, at its nominal) against
    the next larger mode set, with ``n_steps`` steps. Empty (the defaults: error 0, ``ok``) at once
    for a problem without a mechanism or without a reduced link. One check per study, not per point:
    the reduction is the scene's, and its error at the scene's values is the one every point's
    numbers carry (a grid over ``modes`` itself changes it point by point: docs/studies.md)."""
    if not hasattr(problem, "mechanism"):
        return {}
    import linearize

    mechanism = problem.mechanism()
    if not linearize.reduced_links(mechanism):
        return {}
    started = time.perf_counter()
    try:
        found = linearize.reduction_error(mechanism, n_steps=n_steps,
                                          observables=getattr(problem, "observable_specs", None))
    except RuntimeError as error:   # a numerical failure of either steady state: say so, keep the grid
        return {"reduction_error": float("nan"), "reduction_status": "failed",
                "reduction_message": f"modal reduction check at the scene's values failed ({error}); "
                                     f"the points' reduction error is unknown",
                "reduction_run_time": time.perf_counter() - started}
    message = f"at the scene's values, {found.message}"
    if found.status != "ok":
        message += "; every point's numbers carry this reduction error"
    return {"reduction_error": float(found.error), "reduction_status": found.status,
            "reduction_message": message, "reduction_run_time": found.run_time}


def grid_status(result: GridResult) -> str:
    """The status column of a grid study: the count of each point status, and the reduction check's
    verdict when it is not ``ok``."""
    counts = status_counts(result.point_status[result.done])
    return counts if result.reduction_status == "ok" else f"{counts}; modal reduction {result.reduction_status}"


def reduction_headlines(result: GridResult) -> list[Headline]:
    """The reduction check's row of the summary table (none without a reduced link)."""
    if not result.reduction_message:
        return []
    return [Headline("modal reduction error (relative, at the scene's values)",
                     float(result.reduction_error), "1",
                     where="" if result.reduction_status == "ok" else f"({result.reduction_status}: "
                                                                      f"carried by every point)")]


def grid_summary(result: GridResult, extra: str = "", *, point: Any = None) -> str:
    """``flexvib run``'s line for a grid study: points done, the count of each status, ``extra``, run
    time, and the worst cases (``point(index) -> str`` names a grid point, e.g. "speed 185")."""
    done = int(result.done.sum())
    line = f"{done}/{result.done.size} points: {status_counts(result.point_status[result.done])}{extra}; " \
           f"{result.run_time:.3g} s"
    worst = worst_cases(result.point_status, result.point_message, point or point_name)
    line += f"\n    worst: {worst}" if worst else ""
    return line + (f"\n    {result.reduction_status}: {result.reduction_message}" if result.reduction_message else "")


def point_name(index: tuple) -> str:
    """"point (3, 1)": a grid point named by its index."""
    return f"point {tuple(int(i) for i in index)}"


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
