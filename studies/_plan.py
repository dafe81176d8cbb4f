"""The ``[studies]`` table of a scene (documented key by key in docs/studies.md) and running it.

A scene declares the studies to run; ``plan(table)`` checks every key and fills the defaults,
``run_plan`` runs the declared studies (and nothing else) into one HDF5 file, skipping studies
already complete in it with the same request and resuming interrupted grids. The kinds of study
and their tables are those of the registry ``studies._kinds.KINDS``.
"""

from __future__ import annotations

import logging
from typing import Any, Mapping

from ._errors import StudiesError, is_numerical_failure
from ._kind import integer, reject_unknown
from ._kinds import KINDS
from ._problem import SPEED
from ._store import encode, open_file, read_group

__all__ = ["StudiesError", "default_table", "parameters_needed", "plan", "run_plan"]

logger = logging.getLogger(__name__)

_COMMON = ("n_steps", "observables")


def default_table(nominal_speed: float) -> dict[str, Any]:
    """The studies run for a scene without a ``[studies]`` table, each kind's default (steady state,
    a 100-point speed sweep and a 40-speed Campbell diagram from 0.2 to 4 times the scene's speed
    ``2 pi / period`` (rad/s), a 3-period nonlinear check)."""
    tables = {name: kind.default(nominal_speed) for name, kind in KINDS.items()}
    return {name: table for name, table in tables.items() if table is not None}


def plan(table: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Check a ``[studies]`` table; returns ``(common, {kind: options})`` with the defaults filled in
    (options are what each kind's ``run`` takes: the keyword arguments of its study function)."""
    if not isinstance(table, Mapping):
        raise StudiesError(f"[studies]: expected a table, got {table!r}")
    reject_unknown("studies", table, _COMMON + tuple(KINDS))
    n_steps = integer("studies", "n_steps", table.get("n_steps", 256), 4, even=True)
    observables = table.get("observables")
    if observables is not None and (not isinstance(observables, list)
                                    or not all(isinstance(s, str) for s in observables)):
        raise StudiesError(f"[studies] observables: expected a list of specs such as "
                           f"'coupler.deflection@0.5', got {observables!r}")
    common = {"n_steps": n_steps, "observables": None if observables is None else tuple(observables)}
    studies: dict[str, dict[str, Any]] = {}
    for name, kind in KINDS.items():
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
                           f"{', '.join(f'[studies.{k}]' for k in KINDS)}")
    return common, studies


def parameters_needed(studies: Mapping[str, Mapping[str, Any]]) -> tuple[str, ...]:
    """The scene parameters (dotted paths, not ``speed``) the declared studies vary."""
    names = [path for name, options in studies.items() for path in KINDS[name].varies(options)]
    return tuple(dict.fromkeys(n for n in names if n != SPEED))


def run_plan(problem: Any, studies: Mapping[str, Mapping[str, Any]], path: str, *, executor: Any = None,
             progress: bool = False) -> tuple[dict[str, Any], dict[str, str]]:
    """Run the declared ``studies`` on ``problem`` into the HDF5 file ``path``; returns
    ``(results, failures)``: ``{kind: result}`` and ``{kind: message}`` of studies that failed
    numerically (see ``studies._errors``).

    Grid studies resume an interrupted run; the other studies are skipped when the file already holds
    a complete result for the same request, and recomputed otherwise.
    """
    from ._console import progress_bar

    results, failures = {}, {}
    runs = [(name + suffix, KINDS[name], each) for name, options in studies.items()
            for suffix, each in KINDS[name].runs(options).items()]
    with open_file(path) as handle, progress_bar(runs, desc="studies", unit="study",
                                                 enabled=progress and len(runs) > 1) as bar:
        # An overall bar, since a study without grid points (steady state, nonlinear check,
        # error against cost) has no bar of its own; grid studies nest theirs below it.
        for name, kind, options in bar:
            bar.set_postfix_str(name)
            request = encode({"options": options, "scene": problem.text})
            group = handle.get(name)
            if group is not None and not kind.grid:
                if group.attrs.get("request") == request and group.attrs.get("complete"):
                    logger.info("%s: already complete in %s, skipped", name, path)
                    results[name] = read_group(group)
                    continue
                del handle[name]
            logger.info("running %s", name)
            try:
                result = kind.run(problem, options, out=handle, executor=executor, progress=progress)
            except Exception as error:
                if not is_numerical_failure(error):
                    raise  # bad input stops the run (exit code 2), a bug too
                # a study that cannot be computed is reported and the others go on; grid points
                # fail one by one inside the grid, a nonlinear run that fails gives its check the
                # verdict "failed".
                logger.error("%s failed: %s: %s", name, type(error).__name__, error)
                failures[name] = f"{type(error).__name__}: {error}"
                continue
            if not kind.grid:
                result.to_hdf5(handle.create_group(name))
            handle[name].attrs["request"] = request
            results[name] = result
    return results, failures
