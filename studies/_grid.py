"""Grid points through any ``concurrent.futures.Executor``, written to HDF5 as they finish.

A grid study calls a top-level *point function* ``point(problem, values, **options) -> dict`` at each
point (values = parameter overrides). The function runs in a worker (or in-process), and returns
plain arrays; :func:`evaluate` wraps it so that a failing point returns a status and message instead
of aborting the grid (diffrax's ``throw=False``). The parent process alone writes: each finished point
goes into datasets pre-filled with NaN, and a ``done`` mask records which points are complete, so a
killed run leaves a readable file and a re-run computes only the missing points.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import sys
import threading
import time
import traceback
import warnings
from concurrent.futures import Executor, as_completed
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ._errors import StudiesError
from ._identity import differing_paths, digest, scene_numbers
from ._integrity import DIGEST, POINT_DIGEST, POINT_MARK, POINT_OUTPUTS, dataset_layout, point_digest, seal
from ._store import FORMAT_VERSION, encode, stored_name, write_attrs
from ._threads import THREAD_VARIABLES  # what BLAS and OpenMP read as they load (the command's list)
from ._writes import deferred_interrupts, owner_of

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


class GridStore:
    """The HDF5 group of one grid study (parent process only).

    Datasets: ``done`` (grid shape, bool), ``status`` and ``message`` (grid shape, UTF-8 strings),
    ``point_run_time`` (grid shape, s), and one dataset per output name of shape
    ``grid shape + value shape``, created at the first successful point, pre-filled with NaN, with a
    ``units`` attribute from ``units`` (looked up by the name, then by its first path component).
    In a ``studies._resultfile.ResultFile`` the finished points wait in memory and are written together
    before each commit (every few seconds; an interrupt waits for the write's end) and at the grid's
    end; in a plain h5py file each point is written and flushed.
    """

    def __init__(self, group: Any, shape: tuple[int, ...], units: Mapping[str, str] | None = None) -> None:
        self.shape = tuple(shape)
        self.units = dict(units or {})
        self._owner = owner_of(group)
        self._group = None if self._owner is not None else group
        self._name = group.name
        # h5py dataset objects by name, valid while the file handle they came from is open: a
        # lookup by name costs about as much as the write itself, and a grid writes each dataset
        # once per point (a commit reopens the working copy, which empties this cache)
        self._datasets: dict[str, Any] = {}
        self._datasets_of: Any = None
        self._point_digests: bool | None = None   # whether the group has them (format 3), looked up once
        self._pending: list[tuple[tuple[int, ...], PointOutcome]] = []   # finished, not yet written

    @property
    def group(self) -> Any:
        """The study's h5py group (looked up again after a commit reopened the working copy)."""
        return self._owner.handle[self._name] if self._owner is not None else self._group

    def _writing(self, extra: int = 0):
        return self._owner.writing(extra) if self._owner is not None else contextlib.nullcontext()

    @classmethod
    def open(cls, parent: Any, name: str, shape: tuple[int, ...], *, kind: type,
             settings: Mapping[str, Any], units: Mapping[str, str],
             header: Mapping[str, Any]) -> "GridStore":
        """Create the group, or reopen it for a resume when its settings match: the same values, the
        same scene numbers (the scene's name, description and studies may differ) and the same
        outputs. ``kind``: the result class (the group's ``kind`` is its registered name).
        ``header``: the result's descriptive fields (problem, scene, labels, ...) written as
        attributes at once, so that an interrupted file loads."""
        kind = stored_name(kind)
        identity = digest(grid_identity(settings, units))
        group = parent.get(name)
        if group is not None and "kind" in group.attrs:  # a group made by a plan has no kind yet
            stored = group.attrs.get("settings_hash")
            same = (stored == identity if stored is not None
                    else group.attrs.get("settings") == encode(settings))  # an older file
            if group.attrs.get("kind") != kind or not same:
                raise StudiesError(
                    f"{parent.file.filename}: group {name!r} holds a {group.attrs.get('kind')!r} study "
                    f"with other settings (differing: {', '.join(_differing_settings(group, settings))}); "
                    f"to resume, run with exactly the same settings, else write to a new file or "
                    f"another study name")
            return cls(group, shape, units)
        import h5py

        owner = owner_of(parent)
        with owner.writing() if owner is not None else contextlib.nullcontext():
            group = parent.require_group(name)
            group.attrs["kind"] = kind
            group.attrs["format_version"] = FORMAT_VERSION
            group.attrs["settings_hash"] = identity
            group.attrs["complete"] = False
            write_attrs(group, header)
            if owner is not None:  # what the plan asked of this study (studies.cli._run)
                write_attrs(group, owner.study_attrs.get(name, {}))
            group.attrs["settings"] = encode(settings)
            group.create_dataset("done", shape=shape, dtype=bool, fillvalue=False)
            strings = h5py.string_dtype()
            group.create_dataset("status", shape=shape, dtype=strings)
            group.create_dataset("message", shape=shape, dtype=strings)
            run_time = group.create_dataset("point_run_time", shape=shape, dtype=float,
                                            fillvalue=np.nan)
            run_time.attrs["units"] = "s"
            # each point's checksum (studies._integrity), and the outputs it covers
            group.create_dataset(POINT_DIGEST, shape=shape, dtype=np.uint64, fillvalue=0)
            group.attrs[POINT_OUTPUTS] = json.dumps(sorted(units))
        return cls(group, shape, units)

    def seal(self) -> None:
        """Checksum the group's attributes and its datasets other than the points' (its axes), once,
        when it is made (``studies._studies.open_store`` after writing the axes)."""
        if DIGEST not in self.group.attrs:
            with self._writing():
                seal(self.group)

    @property
    def done(self) -> np.ndarray:
        self.flush()
        return np.asarray(self.group["done"][()], dtype=bool)

    def write(self, index: tuple[int, ...], outcome: PointOutcome) -> None:
        """Record the finished point ``index``. In a ``ResultFile`` the point waits in memory for the
        next commit (or :meth:`flush`), which writes every waiting point at once: a point is durable
        only once committed anyway, and one write per dataset per commit costs a fraction of one per
        point (16 ms a point of a sweep, about 60 % of it h5py's per-call overhead). In a plain h5py
        file each point is written and flushed at once."""
        if self._owner is None:
            self._write_points([(index, outcome)])
            self._group.file.flush()
            return
        self._pending.append((index, outcome))
        self._owner.before_commit(self.flush)
        self._owner.maybe_commit()

    def flush(self) -> None:
        """Write the points waiting in memory (a grid's end, a commit, a read of the group)."""
        if self._pending:
            pending, self._pending = self._pending, []
            self._write_points(pending)

    def _write_points(self, points: Sequence[tuple[tuple[int, ...], PointOutcome]]) -> None:
        """Write ``points`` ``[(index, outcome)]``, each point's digest and ``done``: per dataset one
        read and one write of the block of the grid that holds them (a sweep's points since the last
        commit are one such block). Strings are written as a block only where the points fill it,
        else point by point: HDF5 does not reuse the space of an overwritten string."""
        extra = sum(np.asarray(value).nbytes for _, outcome in points for value in outcome.data.values())
        low = np.min([index for index, _ in points], axis=0)
        high = np.max([index for index, _ in points], axis=0)
        box = tuple(slice(int(a), int(b) + 1) for a, b in zip(low, high))
        dense = int(np.prod(high - low + 1)) == len({index for index, _ in points})
        datasets: dict[str, Any] = {}
        layouts: dict[str, tuple[tuple[int, ...], str]] = {}   # h5py builds .shape and .dtype anew at each call
        dtypes: dict[str, np.dtype] = {}
        blocks: dict[str, np.ndarray] = {}
        strings: dict[str, list[tuple[tuple[int, ...], str]]] = {}

        def put(key: str, index: tuple[int, ...], value: Any, created: np.ndarray | None = None) -> None:
            if key not in datasets:
                dataset = datasets[key] = self._dataset(key, created)
                dtypes[key] = dataset.dtype
                layouts.update(dataset_layout({key: dataset}))
            text = dtypes[key].kind == "O"
            if text and not dense:
                strings.setdefault(key, []).append((index, value))
                return
            if key not in blocks:
                blocks[key] = (np.empty(tuple(b.stop - b.start for b in box), dtype=object) if text
                               else datasets[key][box])
            blocks[key][tuple(i - a for i, a in zip(index, low))] = value

        with self._writing(extra):
            if self._point_digests is None:   # a group of format 3 (an older one is resumed without)
                self._point_digests = POINT_DIGEST in self.group
            for index, outcome in points:
                stored = {}
                for key, value in outcome.data.items():
                    put(key, index, value, np.asarray(value))
                    stored[key] = np.asarray(value, dtype=dtypes[key])
                for key, value in (("status", outcome.status), ("message", outcome.message),
                                   ("point_run_time", outcome.run_time)):
                    put(key, index, value)
                if self._point_digests:
                    touched = {key: layouts[key] for key in (*outcome.data, "status", "message", "point_run_time")}
                    put(POINT_DIGEST, index, point_digest(outcome.status, outcome.message,
                                                          float(outcome.run_time), stored, touched))
                put("done", index, True)
            for key, block in blocks.items():
                datasets[key][box] = block
            for key, values in strings.items():
                for index, value in values:
                    datasets[key][index] = value

    def _dataset(self, key: str, value: np.ndarray | None = None) -> Any:
        """The dataset ``key`` of the group, created for an output at its first ``value`` (grid shape
        + value shape, NaN-filled, with its unit)."""
        handle = self._owner.handle if self._owner is not None else self._group
        if self._datasets_of is not handle:
            self._datasets, self._datasets_of = {}, handle
        dataset = self._datasets.get(key)
        if dataset is None:
            group = self.group
            if key in group:
                dataset = group[key]
            else:
                shape = self.shape + value.shape
                if np.iscomplexobj(value):  # HDF5 has no complex fill value: fill explicitly
                    dataset = group.create_dataset(key, data=np.full(shape, complex(np.nan, np.nan)))
                else:
                    dataset = group.create_dataset(key, shape=shape, dtype=float, fillvalue=np.nan)
                dataset.attrs["units"] = self.unit(key)
                dataset.attrs[POINT_MARK] = True
            self._datasets[key] = dataset
        return dataset

    def unit(self, key: str) -> str:
        if self.is_output(key):
            return self.units[key] if key in self.units else self.units[key.split("/")[0]]
        raise KeyError(f"no unit declared for grid output {key!r}")

    def is_output(self, key: str) -> bool:
        """Whether ``key`` is a point output: a declared name, or under a declared group name
        (``linear_range/<link>.<measure>``)."""
        return key in self.units or key.split("/")[0] in self.units

    def read(self, index: tuple[int, ...]) -> PointOutcome:
        self.flush()
        group = self.group
        data = {key: group[key][index] for key in _dataset_names(group) if self.is_output(key)}
        return PointOutcome(data, _text(group["status"][index]), _text(group["message"][index]),
                            float(group["point_run_time"][index]))


def grid_identity(settings: Mapping[str, Any], units: Mapping[str, str]) -> dict[str, Any]:
    """What makes two runs of a grid study the same: its settings with the scene text replaced by the
    numbers of the scene (``studies._identity.scene_numbers``), and its output names."""
    plain = dict(settings)
    if isinstance(plain.get("scene"), str):
        plain["scene"] = scene_numbers(plain["scene"])
    return {"settings": plain, "outputs": sorted(units)}


def _differing_settings(group: Any, settings: Mapping[str, Any]) -> list[str]:
    try:
        old = json.loads(group.attrs.get("settings", "{}"))
    except (json.JSONDecodeError, TypeError):
        return ["(unreadable)"]
    old = grid_identity(old, {})["settings"] if isinstance(old, dict) else old
    return differing_paths(old, grid_identity(settings, {})["settings"]) or ["outputs"]


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
    not recomputed. Each finished point goes to ``store`` (in this process: ``GridStore.write``), all
    of them written by the return, an interrupt's included.
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
            with deferred_interrupts():  # a pool forks its workers here: no interrupt in fork hooks
                futures = [executor.submit(evaluate_batch, point, problem, batch, options)
                           for batch in batches]
            try:
                for future in as_completed(futures):
                    for index, outcome in future.result():
                        finish(index, outcome)
            finally:
                for future in futures:
                    future.cancel()
    finally:
        bar.close()
        if store is not None:
            store.flush()   # what the study writes next (verdicts judged again, its fields) reads them
    return outcomes


def _progress(total: int, initial: int, description: str, enabled: bool):
    from ._progress import progress_bar

    return progress_bar(total=total, initial=initial, desc=description, unit="point", enabled=enabled,
                        leave=False)


# ---------------------------------------------------------------------------------------------------
# worker processes that die with their parent
# ---------------------------------------------------------------------------------------------------
#: prctl option: the signal the kernel sends this process when its parent dies (linux/prctl.h).
_PR_SET_PDEATHSIG = 1
#: How often (s) a worker's watchdog checks that its parent is alive (where prctl is missing).
WATCHDOG_PERIOD = 1.0


def die_with_parent(parent_pid: int) -> None:
    """Initializer of a pool's worker processes: the worker dies when the run that started it does
    (killed or not), and leaves Ctrl-C to its parent (which saves and stops the pool).

    On Linux the kernel kills the worker when its parent ends (``PR_SET_PDEATHSIG``); a watchdog
    thread checking ``os.getppid()`` covers other systems and a parent gone before the call.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):  # no libc prctl: the watchdog alone
            pass
    if os.getppid() != parent_pid:
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent_pid,), daemon=True,
                     name="flexvib-parent-watchdog").start()


def _watch_parent(parent_pid: int) -> None:
    while True:
        time.sleep(WATCHDOG_PERIOD)
        if os.getppid() != parent_pid:
            os._exit(1)


def single_threaded_libraries() -> None:
    """Cap the thread pools of the BLAS and OpenMP libraries of this process at one thread: those
    already loaded through ``threadpoolctl``, those loaded later through ``THREAD_VARIABLES``.

    For a pool's worker processes, which parallelise already: with each worker's BLAS running one
    thread per core, N workers on a loaded 2-core machine oversubscribed it (a dense solve of a grid
    point measured 0.4 s instead of 17 ms).
    """
    from threadpoolctl import threadpool_limits

    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    threadpool_limits(limits=1)  # a call, not a context: the limits stay for the process's life


def start_worker(parent_pid: int) -> None:
    """Initializer of :func:`process_pool`'s workers: :func:`die_with_parent`, and
    :func:`single_threaded_libraries` (the processes are the parallelism)."""
    die_with_parent(parent_pid)
    single_threaded_libraries()


def process_pool(workers: int) -> Executor:
    """A ``ProcessPoolExecutor`` of ``workers`` processes that die with this one and run their BLAS
    and OpenMP libraries on one thread each (the in-process path, ``executor=None``, leaves this
    process's threads as they are)."""
    from concurrent.futures import ProcessPoolExecutor

    return ProcessPoolExecutor(workers, initializer=start_worker, initargs=(os.getpid(),))


def stop_executor(executor: Executor, *, interrupted: bool) -> None:
    """Shut ``executor`` down: wait for it after a normal end; after an interrupt, cancel what is
    queued and end the pool's workers now (their points are recomputed by the next run)."""
    if not interrupted:
        executor.shutdown()
        return
    executor.shutdown(wait=False, cancel_futures=True)
    # ProcessPoolExecutor has no public way to end busy workers before Python 3.14
    # (terminate_workers); without it the interpreter's exit would wait for their batches.
    for process in list((getattr(executor, "_processes", None) or {}).values()):
        process.kill()
