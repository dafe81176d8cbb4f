"""The ``[studies]`` table of a scene (documented key by key in docs/studies.md) and running it.

A scene declares the studies to run; ``plan(table)`` checks every key and fills the defaults,
``run_plan`` runs the declared studies (and nothing else) into one HDF5 file, skipping studies
already complete in it with the same request and resuming interrupted grids. The kinds of study
and their tables are those of the registry ``studies.kinds()``.
"""

from __future__ import annotations

import json
import logging
from typing import Any, Mapping

import numpy as np

from . import _jit
from ._errors import StudiesError, is_numerical_failure
from ._identity import canonical, differing_paths, digest, scene_numbers
from ._kind import COMMON_KEYS, integer, kind_named, kinds, reject_unknown
from ._problem import SPEED
from ._resultfile import ResultFile
from ._store import StorageError, read_group, write_attrs

__all__ = ["RunInterrupted", "StudiesError", "default_table", "parameters_needed", "plan", "run_plan",
           "scene_identity"]

logger = logging.getLogger(__name__)

def default_table(nominal_speed: float) -> dict[str, Any]:
    """The studies run for a scene without a ``[studies]`` table, each kind's default (steady state,
    a 100-point speed sweep and a 40-speed Campbell diagram from 0.2 to 4 times the scene's speed
    ``2 pi / period`` (rad/s), a 3-period nonlinear check)."""
    tables = {name: kind.default(nominal_speed) for name, kind in kinds().items()}
    return {name: table for name, table in tables.items() if table is not None}


def plan(table: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Check a ``[studies]`` table; returns ``(common, {kind: options})`` with the defaults filled in
    (options are what each kind's ``run`` takes: the keyword arguments of its study function)."""
    if not isinstance(table, Mapping):
        raise StudiesError(f"[studies]: expected a table, got {table!r}")
    reject_unknown("studies", table, COMMON_KEYS + tuple(kinds()))
    n_steps = integer("studies", "n_steps", table.get("n_steps", 256), 4, even=True)
    observables = table.get("observables")
    if observables is not None and (not isinstance(observables, list)
                                    or not all(isinstance(s, str) for s in observables)):
        raise StudiesError(f"[studies] observables: expected a list of specs such as "
                           f"'coupler.deflection@0.5', got {observables!r}")
    common = {"n_steps": n_steps, "observables": None if observables is None else tuple(observables)}
    studies: dict[str, dict[str, Any]] = {}
    for name, kind in kinds().items():
        if name not in table:
            continue
        where = f"studies.{name}"
        options = table[name]
        if not isinstance(options, Mapping):
            raise StudiesError(f"[{where}]: expected a table, got {options!r}")
        reject_unknown(where, options, kind.keys)
        studies[name] = kind.check(where, options, n_steps)
    if not studies:
        raise StudiesError(f"[studies] declares no study; add at least one of the tables "
                           f"{', '.join(f'[studies.{k}]' for k in kinds())}")
    return common, studies


def parameters_needed(studies: Mapping[str, Mapping[str, Any]]) -> tuple[str, ...]:
    """The scene parameters (dotted paths, not ``speed``) the declared studies vary."""
    names = [path for name, options in studies.items() for path in kind_named(name).varies(options)]
    return tuple(dict.fromkeys(n for n in names if n != SPEED))


def scene_identity(problem: Any) -> dict[str, Any]:
    """What identifies the scene of a run (its sha256 is the result file's ``scene_hash``): the
    numbers of the scene (its tables without name, description and studies,
    ``studies._identity.scene_numbers``) and the observables; for a ``PeriodicProblem`` also its name,
    parameters and observable rows (its text is an equation, not a scene)."""
    identity: dict[str, Any] = {"scene": scene_numbers(getattr(problem, "text", ""))}
    if hasattr(problem, "observable_specs"):
        identity["observables"] = problem.observable_specs
    if hasattr(problem, "parameter_values"):
        identity.update(problem=problem.name, parameters=dict(problem.parameter_values),
                        observables=problem.observable_rows, labels=problem.labels)
    return identity


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
    study starts its clock (``studies._jit.warm_up``), and record the compile time of the run as the
    file attribute ``compile_time`` (s; 0 when every kernel came from the disk cache).
    """
    runs = [(name + suffix, kind_named(name), each) for name, options in studies.items()
            for suffix, each in kind_named(name).runs(options).items()]
    try:
        with ResultFile(path, scene=scene_identity(problem), overwrite=overwrite) as file:
            _refuse_other_grid_options(file, runs)
            clock = _jit.warm_up(problem, studies) if warm_up else None
            try:
                outcome = _run_studies(problem, runs, file, executor=executor, progress=progress)
            finally:
                compile_time = clock.stop() if clock is not None else None  # no listener left behind
            if compile_time is not None:
                with file.writing():
                    file.handle.attrs["compile_time"] = compile_time
            return outcome
    except KeyboardInterrupt:
        raise RunInterrupted(*_points_saved(path, runs), str(path)) from None


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


def _run_studies(problem: Any, runs: list, file: ResultFile, *, executor: Any, progress: bool
                 ) -> tuple[dict[str, Any], dict[str, str]]:
    from ._console import progress_bar

    results, failures = {}, {}
    for name, _kind, options in runs:  # a grid group made by this run gets these attributes
        file.study_attrs[name] = {"request": canonical(options), "request_hash": digest(options)}
    with progress_bar(runs, desc="studies", unit="study", enabled=progress and len(runs) > 1) as bar:
        # An overall bar, since a study without grid points (steady state, nonlinear check,
        # error against cost) has no bar of its own; grid studies nest theirs below it.
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
