"""Grid points through any ``concurrent.futures.Executor``, written to HDF5 as they finish.

A grid study calls a top-level *point function* ``point(problem, values, **options) -> dict`` at each
point (values = parameter overrides). The function runs in a worker (or in-process), and returns
plain arrays; :func:`evaluate` wraps it so that a failing point returns a status and message instead
of aborting the grid (diffrax's ``throw=False``). The parent process alone writes: each finished point
goes into datasets pre-filled with NaN, and a ``done`` mask records which points are complete, so a
killed run leaves a readable file and a re-run computes only the missing points.
"""

from __future__ import annotations

import logging
import time
import traceback
import warnings
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ._errors import StudiesError

from ._store import encode, write_attrs

logger = logging.getLogger(__name__)

STATUS_FAILED = "failed"
#: Grid points are sent to an executor in at most about this many tasks.
MAX_TASKS = 256


@dataclass(frozen=True)
class PointOutcome:
    """What one grid point returned: ``data`` (dict name -> scalar or array), ``status`` ("ok",
    a periodic status such as "near_resonance", or "failed"), ``message``, ``run_time`` (s)."""

    data: Mapping[str, Any]
    status: str
    message: str
    run_time: float


def evaluate(point: Callable, problem: Any, values: Mapping[str, float],
             options: Mapping[str, Any]) -> PointOutcome:
    """Run ``point(problem, values, **options)``; exceptions become a failed outcome.

    The point function returns ``(data, status, message)``. Warnings raised inside are caught and
    appended to the message (a near-resonance warning must not vanish in a worker's stderr).
    """
    start = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            data, status, message = point(problem, dict(values), **options)
    except Exception as error:  # a failed point is data, not a crash: the grid goes on
        logger.debug("point %s failed:\n%s", dict(values), traceback.format_exc())
        return PointOutcome({}, STATUS_FAILED, f"{type(error).__name__}: {error}",
                            time.perf_counter() - start)
    notes = sorted({f"{w.category.__name__}: {w.message}" for w in caught})
    if notes:
        message = "; ".join(([message] if message else []) + notes)
    return PointOutcome(data, status, message, time.perf_counter() - start)


def evaluate_batch(point: Callable, problem: Any,
                   batch: Sequence[tuple[tuple[int, ...], Mapping[str, float]]],
                   options: Mapping[str, Any]) -> list[tuple[tuple[int, ...], PointOutcome]]:
    """:func:`evaluate` at each ``(index, values)`` of ``batch``, in a worker."""
    return [(index, evaluate(point, problem, values, options)) for index, values in batch]


@dataclass
class GridStore:
    """The HDF5 group of one grid study (parent process only).

    Datasets: ``done`` (grid shape, bool), ``status`` and ``message`` (grid shape, UTF-8 strings),
    ``point_run_time`` (grid shape, s), and one dataset per output name of shape
    ``grid shape + value shape``, created at the first successful point, pre-filled with NaN, with a
    ``units`` attribute from ``units`` (looked up by the name, then by its first path component).
    """

    group: Any
    shape: tuple[int, ...]
    units: Mapping[str, str] = field(default_factory=dict)

    @classmethod
    def open(cls, parent: Any, name: str, shape: tuple[int, ...], *, kind: str,
             settings: Mapping[str, Any], units: Mapping[str, str],
             header: Mapping[str, Any]) -> "GridStore":
        """Create the group, or reopen it for a resume when its settings match exactly. ``header``:
        the result's descriptive fields (problem, scene, labels, ...) written as attributes at once,
        so that an interrupted file loads."""
        text = encode(settings)
        if name in parent:
            group = parent[name]
            if group.attrs.get("kind") != kind or group.attrs.get("settings") != text:
                raise StudiesError(
                    f"{parent.file.filename}: group {name!r} holds a {group.attrs.get('kind')!r} study "
                    f"with other settings ({group.attrs.get('settings')}); to resume, run with exactly "
                    f"the same settings, else write to a new file or another study name")
            return cls(group, shape, units)
        import h5py

        group = parent.create_group(name)
        group.attrs["kind"] = kind
        group.attrs["settings"] = text
        group.attrs["complete"] = False
        write_attrs(group, header)
        group.create_dataset("done", shape=shape, dtype=bool, fillvalue=False)
        strings = h5py.string_dtype()
        group.create_dataset("status", shape=shape, dtype=strings)
        group.create_dataset("message", shape=shape, dtype=strings)
        run_time = group.create_dataset("point_run_time", shape=shape, dtype=float,
                                        fillvalue=np.nan)
        run_time.attrs["units"] = "s"
        return cls(group, shape, units)

    @property
    def done(self) -> np.ndarray:
        return np.asarray(self.group["done"][()], dtype=bool)

    def write(self, index: tuple[int, ...], outcome: PointOutcome) -> None:
        for key, value in outcome.data.items():
            value = np.asarray(value)
            if key not in self.group:
                shape = self.shape + value.shape
                if np.iscomplexobj(value):  # HDF5 has no complex fill value: fill explicitly
                    dataset = self.group.create_dataset(key, data=np.full(shape, complex(np.nan, np.nan)))
                else:
                    dataset = self.group.create_dataset(key, shape=shape, dtype=float, fillvalue=np.nan)
                dataset.attrs["units"] = self.unit(key)
            self.group[key][index] = value
        self.group["status"][index] = outcome.status
        self.group["message"][index] = outcome.message
        self.group["point_run_time"][index] = outcome.run_time
        self.group["done"][index] = True
        self.group.file.flush()

    def unit(self, key: str) -> str:
        if key in self.units:
            return self.units[key]
        head = key.split("/")[0]
        if head in self.units:
            return self.units[head]
        raise KeyError(f"no unit declared for grid output {key!r}")

    def read(self, index: tuple[int, ...]) -> PointOutcome:
        data = {key: self.group[key][index] for key in _dataset_names(self.group) if key in self.units}
        return PointOutcome(data, _text(self.group["status"][index]), _text(self.group["message"][index]),
                            float(self.group["point_run_time"][index]))


def _text(value: Any) -> str:
    return value.decode() if isinstance(value, bytes) else str(value)


def _dataset_names(group: Any) -> list[str]:
    import h5py

    names: list[str] = []
    group.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
    return names


def run_grid(point: Callable, problem: Any, points: Sequence[tuple[tuple[int, ...], Mapping[str, float]]],
             options: Mapping[str, Any], *, executor: Executor | None = None,
             store: GridStore | None = None, progress: bool = False,
             description: str = "") -> dict[tuple[int, ...], PointOutcome]:
    """Evaluate ``point`` at each ``(index, values)``; return ``{index: outcome}``.

    ``executor=None`` runs in-process, in order. Points already ``done`` in ``store`` are read back,
    not recomputed. Each finished point is written to ``store`` at once (in this process).
    """
    outcomes: dict[tuple[int, ...], PointOutcome] = {}
    todo = list(points)
    if store is not None:
        done = store.done
        for index, _ in points:
            if done[index]:
                outcomes[index] = store.read(index)
        todo = [(index, values) for index, values in points if not done[index]]
        if outcomes:
            logger.info("%s: %d of %d points read back from the file", description, len(outcomes),
                        len(points))
    bar = _progress(len(points), len(outcomes), description, progress)
    try:
        def finish(index, outcome):
            if outcome.status == STATUS_FAILED:
                logger.warning("%s: point %s failed: %s", description, index, outcome.message)
            if store is not None:
                store.write(index, outcome)
            outcomes[index] = outcome
            bar.update(1)

        if executor is None:
            for index, values in todo:
                finish(index, evaluate(point, problem, values, options))
        else:
            # Batches amortise the cost of a task (pickling the problem, inter-process messages)
            # over several cheap points; at most ~MAX_TASKS tasks keep the workers evenly loaded.
            size = max(1, len(todo) // MAX_TASKS)
            batches = [todo[i:i + size] for i in range(0, len(todo), size)]
            futures = [executor.submit(evaluate_batch, point, problem, batch, options) for batch in batches]
            try:
                for future in as_completed(futures):
                    for index, outcome in future.result():
                        finish(index, outcome)
            finally:
                for future in futures:
                    future.cancel()
    finally:
        bar.close()
    return outcomes


def _progress(total: int, initial: int, description: str, enabled: bool):
    from ._console import progress_bar

    return progress_bar(total=total, initial=initial, desc=description, unit="point", enabled=enabled,
                        leave=False)
