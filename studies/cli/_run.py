"""Running a plan (``studies.cli._scene.ScenePlan``): ``run_plan`` runs the declared studies (and
nothing else) into one HDF5 file, skipping studies already complete in it with the same request and
resuming interrupted grids; ``scene_identity`` is what a resumed file must share with the run.
"""

from __future__ import annotations

import json
import logging
from typing import Any, Mapping

import numpy as np

from .._errors import interruption, is_numerical_failure
from .._identity import canonical, differing_paths, digest, scene_identity
from .._integrity import check_group, forget_points, open_study, points_resumable, seal
from .._kind import kind_named
from .._resultfile import ResultFile
from .._store import StorageError, format_of, read_group, write_attrs
from . import _jit

__all__ = ["RunInterrupted", "interrupted_run", "run_plan", "scene_identity"]

#: Seconds before the run's bar over its studies appears (no bar for a run that takes less).
PROGRESS_DELAY = 1.0

logger = logging.getLogger(__name__)


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM stopped a run; ``line`` says what was saved (``flexvib`` prints it)."""

    def __init__(self, saved: int, total: int, path: str) -> None:
        self.saved, self.total, self.path = saved, total, path
        self.line = (f"interrupted: {saved} of {total} points saved in {path}; run the same command "
                     f"to resume")
        super().__init__(self.line)


def run_plan(problem: Any, studies: Mapping[str, Mapping[str, Any]], path: str, *, executor: Any = None,
             progress: bool = False, overwrite: bool = False, warm_up: bool = False
             ) -> tuple[dict[str, Any], dict[str, str]]:
    """Run the declared ``studies`` on ``problem`` into the HDF5 file ``path``; returns
    ``(results, failures)``: ``{kind: result}`` and ``{kind: message}`` of studies that failed
    numerically (see ``studies._errors``).

    The file is written through ``studies._resultfile.ResultFile`` (any kill leaves it readable). A file
    of another scene, or holding a grid study asked with other options, is refused before anything
    is written (``overwrite``: start the file afresh). Grid studies resume an interrupted run; the
    other studies are skipped when the file already holds a complete result for the same options,
    and recomputed otherwise. Ctrl-C or SIGTERM: :class:`RunInterrupted` after saving.

    ``warm_up``: once the file is accepted, compile the numba kernels the studies need before any
    study starts its clock (``studies.cli._jit.warm_up``), and record the compile time of the run as the
    file attribute ``compile_time`` (s; 0 when every kernel came from the disk cache), added to what the
    file's earlier runs recorded when it resumes one.
    """
    runs = _runs(studies)
    try:
        with ResultFile(path, scene=scene_identity(problem), overwrite=overwrite) as file:
            _set_damage_aside(file, runs)   # first: what follows reads the studies' attributes
            _refuse_other_grid_options(file, runs)
            clock = _jit.warm_up(problem, studies) if warm_up else None
            try:
                outcome = _run_studies(problem, runs, file, executor=executor, progress=progress)
            finally:
                compile_time = clock.stop() if clock is not None else None  # no listener left behind
            if compile_time is not None:
                with file.writing():
                    # a resumed file keeps what its earlier runs compiled: the attribute is their sum
                    # (a warm resume adds 0 instead of replacing the first run's compile time)
                    earlier = float(file.handle.attrs.get("compile_time", 0.0))
                    file.handle.attrs["compile_time"] = earlier + compile_time
            return outcome
    except KeyboardInterrupt:
        raise RunInterrupted(*_points_saved(path, runs), str(path)) from None
    except Exception as error:
        if interruption(error) is None:   # a lazy import cut by the signal raises ImportError from it
            raise
        raise RunInterrupted(*_points_saved(path, runs), str(path)) from None


def interrupted_run(studies: Mapping[str, Mapping[str, Any]], path: str) -> RunInterrupted:
    """What an interrupt outside ``run_plan`` (before it opened the file, or after it returned, while
    the summary is printed) says: the points of ``studies`` that the file at ``path`` holds, which
    the same command resumes from (or, all saved, only reports)."""
    runs = _runs(studies)
    return RunInterrupted(*_points_saved(path, runs), str(path))


def _runs(studies: Mapping[str, Mapping[str, Any]]) -> list:
    """``[(name in the file, kind, options)]`` of the declared studies (a kind may run several)."""
    return [(name + suffix, kind_named(name), each) for name, options in studies.items()
            for suffix, each in kind_named(name).runs(options).items()]


def _refuse_other_grid_options(file: ResultFile, runs: list) -> None:
    """A grid study the file holds with other options cannot be resumed: say so before writing."""
    changed = []
    for name, kind, options in runs:
        group = file.handle.get(name)
        asked = digest(options)
        if kind.grid and group is not None and group.attrs.get("request_hash", asked) != asked:
            old = json.loads(group.attrs.get("request", "{}"))
            changed.append(f"{name} ({', '.join(differing_paths(old, json.loads(canonical(options))))})")
    if changed:
        raise file.refusal(f"holds {'; '.join(changed)} with other options, which cannot be resumed",
                           "write to another file with --out, or run with --overwrite to start it afresh")


def _set_damage_aside(file: ResultFile, runs: list) -> None:
    """Check the declared studies the file holds against their checksums (``studies._integrity``):
    a damaged study is left out of the working copy (rebuilt from the intact ones), so that it is
    computed again; a grid study whose damage is confined to some points keeps the intact ones and
    recomputes those (one line each says what was found)."""
    whole, points = [], {}
    for name, _kind, _options in runs:
        group, check = open_study(file.handle, name)
        if group is None and check is None:
            continue
        check = check or check_group(group, format_of(group))
        if not check.damaged:
            continue
        if check.points is not None and points_resumable(group):
            logger.warning("%s in %s: %s; recomputing those points", name, file.path, check.describe())
            points[name] = check.points
        else:
            logger.warning("%s in %s: %s; recomputing it", name, file.path, check.describe())
            whole.append(name)
    if not whole and not points:
        return
    with file.writing():
        file.rebuild_without(whole)
        for name, damaged in points.items():
            if name in file.handle:   # else its copy did not read back: it is recomputed whole
                forget_points(file.handle[name], damaged)


def _run_studies(problem: Any, runs: list, file: ResultFile, *, executor: Any, progress: bool
                 ) -> tuple[dict[str, Any], dict[str, str]]:
    from .._progress import progress_bar

    results, failures = {}, {}
    for name, _kind, options in runs:  # a grid group made by this run gets these attributes
        file.study_attrs[name] = {"request": canonical(options), "request_hash": digest(options)}
    # An overall bar, since a study without grid points (steady state, nonlinear check, error
    # against cost) has no bar of its own; grid studies nest theirs below it (a lone grid study
    # needs none). It ticks, so its clock runs through a long study, and shows after a second.
    overall = progress and (len(runs) > 1 or not any(kind.grid for _, kind, _ in runs))
    with progress_bar(runs, desc="studies", unit="study", enabled=overall, ticking=True,
                      delay=PROGRESS_DELAY) as bar:
        for name, kind, options in bar:
            bar.set_postfix_str(name)
            asked = file.study_attrs[name]
            group = file.handle.get(name)
            if group is not None and not kind.grid:
                if group.attrs.get("request_hash") == asked["request_hash"] and group.attrs.get("complete"):
                    logger.info("%s: already complete in %s, skipped", name, file.path)
                    results[name] = read_group(group)
                    continue
                with file.writing():
                    del file.handle[name]
            logger.info("running %s", name)
            try:
                result = kind.run(problem, options, out=file.handle, executor=executor, progress=progress)
            except Exception as error:
                if isinstance(error, StorageError) or not is_numerical_failure(error):
                    raise  # bad input stops the run (exit code 2), a full disk or a bug too (1)
                # a study that cannot be computed is reported and the others go on; grid points
                # fail one by one inside the grid, a nonlinear run that fails gives its check the
                # verdict "failed".
                logger.error("%s failed: %s: %s", name, type(error).__name__, error)
                failures[name] = f"{type(error).__name__}: {error}"
                continue
            with file.writing(result.nbytes()):
                if not kind.grid:
                    result.to_hdf5(file.handle.create_group(name))
                write_attrs(file.handle[name], asked)
                seal(file.handle[name])   # its checksum covers what was asked of it too
            file.commit()
            results[name] = result
    return results, failures


def _points(kind: Any, options: Mapping[str, Any]) -> int:
    """Points of one run: 1 for a single study; for a grid, the product of the sizes of the arrays
    among its options (its axes: a sweep's values, a Campbell diagram's speeds, a chart's two axes)."""
    if not kind.grid:
        return 1
    sizes = [value.size for value in _arrays(options)]
    return int(np.prod(sizes)) if sizes else 1


def _arrays(value: Any) -> list[np.ndarray]:
    if isinstance(value, np.ndarray):
        return [value]
    if isinstance(value, Mapping):
        value = list(value.values())
    if isinstance(value, (list, tuple)):
        return [array for item in value for array in _arrays(item)]
    return []


def _points_saved(path: str, runs: list) -> tuple[int, int]:
    """``(saved, total)`` points of ``runs`` in the file at ``path`` (as committed)."""
    import h5py

    total = sum(_points(kind, options) for _, kind, options in runs)
    saved = 0
    try:
        with h5py.File(path, "r", locking=False) as handle:
            for name, _kind, options in runs:
                group = handle.get(name)
                if group is None or group.attrs.get("request_hash") != digest(options):
                    continue
                if "done" in group:
                    saved += int(np.count_nonzero(group["done"][()]))
                elif group.attrs.get("complete"):
                    saved += 1
    except (OSError, KeyError):  # no file yet
        pass
    return saved, total
