"""The resource guard: before any study runs, its memory (bytes) and run time (s) are estimated by
its kind's cost model (``StudyKind.cost``, written with the helpers of ``studies._cost``), and a
study above the limits is refused unless forced (docs/studies.md, "Limits").
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ._cost import Estimate, estimate, format_bytes, format_seconds
from ._errors import StudiesError
from ._kind import kind_named

__all__ = ["Estimate", "ResourceError", "estimate", "guard", "memory_limit", "TIME_LIMIT"]

logger = logging.getLogger(__name__)

GIB = 2.0**30
#: The memory limit is the smaller of this and ``MEMORY_FRACTION`` of the machine's RAM (bytes).
MEMORY_LIMIT = 4.0 * GIB
MEMORY_FRACTION = 0.5
#: The longest a single study, or all the studies of a run together, may be estimated to take (s).
TIME_LIMIT = 2.0 * 3600.0


class ResourceError(StudiesError):
    """A study whose estimated memory or run time exceeds the guard's limits (exit code 2)."""


def memory_limit() -> float:
    """The memory limit in bytes: ``MEMORY_LIMIT`` or ``MEMORY_FRACTION`` of the RAM if smaller."""
    try:
        ram = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # not POSIX: the fixed limit alone
        return MEMORY_LIMIT
    return min(MEMORY_LIMIT, MEMORY_FRACTION * ram)


@dataclass(frozen=True)
class _Saved:
    """What a result file already holds of the declared runs: the names of those ``complete`` (with
    the same options) and, for a grid study partly saved, its ``done`` mask (bool, grid shape)."""

    complete: frozenset[str] = frozenset()
    done: Mapping[str, np.ndarray] = field(default_factory=dict)


def _saved(path: str | os.PathLike | None, problem: Any, runs: Sequence[tuple[str, Any, Any]]) -> _Saved:
    """What the result file ``path`` holds of ``runs`` (``(name, kind, options)``), judged as
    ``studies.cli._run.run_plan`` judges it: the file's scene identity must be this problem's (else the
    run refuses the file), and a study's ``request_hash`` the digest of its options; nothing for a
    missing or unreadable file (the run reports those)."""
    if path is None or not os.path.isfile(path):
        return _Saved()
    import h5py

    from ._identity import digest, scene_identity
    from ._integrity import check_group
    from ._store import format_of

    complete, done = set(), {}
    try:
        with h5py.File(path, "r", locking=False) as handle:  # the last commit; a run may be writing
            if handle.attrs.get("scene_hash") != digest(scene_identity(problem)):
                return _Saved()
            for name, kind, options in runs:
                group = handle.get(name)
                if group is None or group.attrs.get("request_hash") != digest(options):
                    continue
                if group.attrs.get("complete") and not check_group(group, format_of(group)).damaged:
                    complete.add(name)   # a damaged study is recomputed by the run: estimated
                elif kind.grid and "done" in group:
                    done[name] = np.asarray(group["done"][()], dtype=bool)
    except (KeyError, OSError, RuntimeError, ValueError):  # not HDF5, unreadable, a group's structure
        return _Saved()                                      # damaged: the result file's own checks say so
    return _Saved(frozenset(complete), done)


def guard(problem: Any, studies: Mapping[str, Mapping[str, Any]], *, force: bool = False,
          workers: int = 1, result_file: str | os.PathLike | None = None) -> list[Estimate]:
    """Estimate every declared study (``{kind: options}`` as ``plan`` returns them, each of the runs
    it declares) and raise :class:`ResourceError` for the first above the memory or time limit, or
    when all together exceed the time limit; ``force=True`` logs the estimates and raises nothing.
    First each kind's ``validate(problem, options)`` (``StudyKind.validate``) is run for every
    declared study, so that an option the problem cannot take is refused before anything is written.
    Also builds the scene at the ends of every axis, so that a value it cannot take is refused (a
    ``MechanismError``) before anything is written. Returns the estimates.

    ``result_file``: the file the run will resume (None for a new file or one started afresh). A
    study it holds complete with the same options is skipped by the run, so it is neither estimated
    nor refused (a run started with ``--force`` resumes without it); a grid study partly saved is
    estimated for its missing points only."""
    limit_memory, limit_time = memory_limit(), TIME_LIMIT
    limits = f"limits {format_bytes(limit_memory)}, {format_seconds(limit_time)}"
    advice = "pass --force (force=True from Python) to run anyway"
    runs = [(kind + suffix, kind_named(kind), each) for kind, options in studies.items()
            for suffix, each in kind_named(kind).runs(options).items()]
    # every declared study's options against the problem, before any study is estimated or written
    for _name, study_kind, each in runs:
        if study_kind.validate is not None:
            study_kind.validate(problem, each)
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
