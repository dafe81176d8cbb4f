"""The ``[studies]`` table of a scene (documented key by key in docs/studies.md) and running it.

A scene declares the studies to run; ``plan(table, nominal_speed)`` checks every key and fills the
defaults, ``run_plan`` runs the declared studies (and nothing else) into one HDF5 file, skipping
studies already complete in it with the same request and resuming interrupted grids.
"""

from __future__ import annotations

import difflib
import logging
import math
from typing import Any, Mapping

import numpy as np

from ._problem import SPEED
from ._store import encode, open_file, read_group

logger = logging.getLogger(__name__)

KINDS = ("steady_state", "sweep", "campbell", "stability_chart", "nonlinear_check", "error_cost")
_COMMON = ("n_steps", "observables")
_AXIS = ("parameter", "start", "stop", "count", "values", "spacing")
_KEYS = {
    "steady_state": ("speed", "n_steps"),
    "sweep": _AXIS + ("max_harmonic", "n_steps"),
    "campbell": ("start", "stop", "count", "values", "spacing", "frozen_samples", "max_harmonic", "n_steps"),
    "stability_chart": ("x", "y", "n_steps"),
    "nonlinear_check": ("speed", "n_periods", "from_rest", "max_periods_from_rest", "steady_tol", "n_steps"),
    "error_cost": ("speed", "n_steps", "reference_steps", "resolution"),
}


class StudiesError(ValueError):
    """A ``[studies]`` table that cannot be run: unknown keys, wrong types, bad ranges."""


def default_table(nominal_speed: float) -> dict[str, Any]:
    """The studies run for a scene without a ``[studies]`` table: steady state, a 100-point speed
    sweep and a 40-speed Campbell diagram from 0.2 to 4 times the scene's speed (``2 pi / period``,
    rad/s), a 3-period nonlinear check."""
    low, high = 0.2 * abs(nominal_speed), 4.0 * abs(nominal_speed)
    return {"steady_state": {}, "sweep": {"parameter": SPEED, "start": low, "stop": high, "count": 100},
            "campbell": {"start": low, "stop": high, "count": 40}, "nonlinear_check": {"n_periods": 3}}


def _unknown(where: str, keys, allowed) -> None:
    for key in keys:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), list(allowed), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise StudiesError(f"[{where}]: unknown key {key!r}{hint} (keys: {', '.join(allowed)})")


def _number(where: str, key: str, value: Any, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise StudiesError(f"[{where}] {key}: expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise StudiesError(f"[{where}] {key}: expected a positive number, got {value!r}")
    return float(value)


def _integer(where: str, key: str, value: Any, minimum: int, *, even: bool = False) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum or (even and value % 2):
        kind = "an even integer" if even else "an integer"
        raise StudiesError(f"[{where}] {key}: expected {kind} >= {minimum}, got {value!r}")
    return value


def _axis(where: str, table: Mapping[str, Any], *, parameter: bool = True) -> tuple[str, np.ndarray]:
    """``(parameter, values)`` of an axis table: ``values = [...]`` or ``start, stop, count`` with
    ``spacing`` "linear" (default) or "log"; the parameter defaults to the crank speed."""
    name = table.get("parameter", SPEED) if parameter else SPEED
    if not isinstance(name, str):
        raise StudiesError(f"[{where}] parameter: expected a parameter name ('speed' or a dotted scene "
                           f"path), got {name!r}")
    if "values" in table:
        if any(k in table for k in ("start", "stop", "count")):
            raise StudiesError(f"[{where}]: give either values or start, stop, count, not both")
        values = table["values"]
        if not isinstance(values, list) or not values:
            raise StudiesError(f"[{where}] values: expected a non-empty list of numbers, got {values!r}")
        return name, np.array([_number(where, "values", v) for v in values])
    missing = [k for k in ("start", "stop", "count") if k not in table]
    if missing:
        raise StudiesError(f"[{where}]: missing {', '.join(missing)} (or give values = [...])")
    start, stop = _number(where, "start", table["start"]), _number(where, "stop", table["stop"])
    count = _integer(where, "count", table["count"], 1)
    spacing = table.get("spacing", "linear")
    if spacing == "linear":
        return name, np.linspace(start, stop, count)
    if spacing == "log":
        if start <= 0 or stop <= 0:
            raise StudiesError(f"[{where}] spacing = 'log' needs positive start and stop")
        return name, np.geomspace(start, stop, count)
    raise StudiesError(f"[{where}] spacing: expected 'linear' or 'log', got {spacing!r}")


def plan(table: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, dict[str, Any]]]:
    """Check a ``[studies]`` table; returns ``(common, {kind: options})`` with the defaults filled in
    (options are the keyword arguments of the study functions, plus ``values`` for the point)."""
    if not isinstance(table, Mapping):
        raise StudiesError(f"[studies]: expected a table, got {table!r}")
    _unknown("studies", table, _COMMON + KINDS)
    n_steps = _integer("studies", "n_steps", table.get("n_steps", 256), 4, even=True)
    observables = table.get("observables")
    if observables is not None and (not isinstance(observables, list)
                                    or not all(isinstance(s, str) for s in observables)):
        raise StudiesError(f"[studies] observables: expected a list of specs such as "
                           f"'coupler.deflection@0.5', got {observables!r}")
    common = {"n_steps": n_steps, "observables": None if observables is None else tuple(observables)}
    studies: dict[str, dict[str, Any]] = {}
    for kind in KINDS:
        if kind not in table:
            continue
        where = f"studies.{kind}"
        options = table[kind]
        if not isinstance(options, Mapping):
            raise StudiesError(f"[{where}]: expected a table, got {options!r}")
        if kind != "error_cost":  # there n_steps is the list of step counts compared
            steps = _integer(where, "n_steps", options.get("n_steps", n_steps), 4, even=True)
        _unknown(where, options, _KEYS[kind])
        if kind in ("steady_state", "nonlinear_check", "error_cost"):
            values = {SPEED: _number(where, "speed", options["speed"], positive=True)} if "speed" in options else {}
        if kind == "steady_state":
            studies[kind] = {"values": values, "n_steps": steps}
        elif kind == "sweep":
            parameter, grid = _axis(where, options)
            harmonic = _integer(where, "max_harmonic", options.get("max_harmonic", 4), 1)
            studies[kind] = {"parameter": parameter, "values": grid, "max_harmonic": harmonic, "n_steps": steps}
        elif kind == "campbell":
            _, grid = _axis(where, options, parameter=False)
            studies[kind] = {"speeds": grid, "n_steps": steps,
                             "frozen_samples": _integer(where, "frozen_samples",
                                                        options.get("frozen_samples", 64), 2),
                             "max_harmonic": _integer(where, "max_harmonic", options.get("max_harmonic", 6), 1)}
        elif kind == "stability_chart":
            axes = []
            for key in ("x", "y"):
                if not isinstance(options.get(key), Mapping):
                    raise StudiesError(f"[{where}] {key}: expected a table {{parameter = ..., start = ..., "
                                       f"stop = ..., count = ...}}, got {options.get(key)!r}")
                _unknown(f"{where}.{key}", options[key], _AXIS)
                axes.append(_axis(f"{where}.{key}", options[key]))
            studies[kind] = {"first": axes[0], "second": axes[1],
                             "n_steps": _integer(where, "n_steps", options.get("n_steps", 128), 4, even=True)}
        elif kind == "nonlinear_check":
            studies[kind] = {"values": values, "n_steps": steps,
                             "n_periods": _integer(where, "n_periods", options.get("n_periods", 5), 2),
                             "from_rest": _boolean(where, "from_rest", options.get("from_rest", False)),
                             "max_periods_from_rest": _integer(where, "max_periods_from_rest",
                                                               options.get("max_periods_from_rest", 200), 2),
                             "steady_tol": _number(where, "steady_tol", options.get("steady_tol", 0.01),
                                                   positive=True)}
        elif kind == "error_cost":
            step_list = options.get("n_steps", [32, 64, 128, 256])
            if not isinstance(step_list, list) or not step_list:
                raise StudiesError(f"[{where}] n_steps: expected a list of even step counts, got {step_list!r}")
            resolution = None
            if "resolution" in options:
                if not isinstance(options["resolution"], Mapping):
                    raise StudiesError(f"[{where}] resolution: expected a table {{parameter = ..., "
                                       f"values = [...]}}, got {options['resolution']!r}")
                _unknown(f"{where}.resolution", options["resolution"], _AXIS)
                resolution = _axis(f"{where}.resolution", options["resolution"])
            reference = options.get("reference_steps")
            studies[kind] = {"values": values,
                             "n_steps": tuple(_integer(where, "n_steps", n, 4, even=True) for n in step_list),
                             "resolution": resolution,
                             "reference_steps": None if reference is None else
                             _integer(where, "reference_steps", reference, 4, even=True)}
    if not studies:
        raise StudiesError(f"[studies] declares no study; add at least one of the tables "
                           f"{', '.join(f'[studies.{k}]' for k in KINDS)}")
    return common, studies


def _boolean(where: str, key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise StudiesError(f"[{where}] {key}: expected true or false, got {value!r}")
    return value


def parameters_needed(studies: Mapping[str, Mapping[str, Any]]) -> tuple[str, ...]:
    """The scene parameters (dotted paths, not ``speed``) the declared studies vary."""
    names = []
    for kind, options in studies.items():
        if kind == "sweep":
            names.append(options["parameter"])
        elif kind == "stability_chart":
            names += [options["first"][0], options["second"][0]]
        elif kind == "error_cost" and options["resolution"] is not None:
            names.append(options["resolution"][0])
    return tuple(dict.fromkeys(n for n in names if n != SPEED))


def run_plan(problem: Any, studies: Mapping[str, Mapping[str, Any]], path: str, *, executor: Any = None,
             progress: bool = False) -> tuple[dict[str, Any], dict[str, str]]:
    """Run the declared ``studies`` on ``problem`` into the HDF5 file ``path``; returns
    ``(results, failures)``: ``{kind: result}`` and ``{kind: message}`` of studies that raised.

    Grid studies resume an interrupted run; the other studies are skipped when the file already holds
    a complete result for the same request, and recomputed otherwise.
    """
    from tqdm.auto import tqdm

    results, failures = {}, {}
    with open_file(path) as handle, tqdm(studies.items(), desc="studies", unit="study",
                                         disable=not progress or len(studies) < 2) as bar:
        # An overall bar, since a study without grid points (steady state, nonlinear check,
        # error against cost) has no bar of its own; grid studies nest theirs below it.
        for kind, options in bar:
            bar.set_postfix_str(kind)
            request = encode({"options": options, "scene": problem.text})
            group = handle.get(kind)
            grid = kind in ("sweep", "campbell", "stability_chart")
            if group is not None and not grid:
                if group.attrs.get("request") == request and group.attrs.get("complete"):
                    logger.info("%s: already complete in %s, skipped", kind, path)
                    results[kind] = read_group(group)
                    continue
                del handle[kind]
            logger.info("running %s", kind)
            try:
                result = _run_study(problem, kind, options, handle, executor, progress)
            except (ArithmeticError, RuntimeError, np.linalg.LinAlgError) as error:
                # a study that cannot be computed (a nonlinear run whose Newton iteration fails) is
                # reported and the others go on; grid points fail one by one inside the grid. Bad
                # input (ValueError) still stops the run with exit code 2.
                logger.error("%s failed: %s: %s", kind, type(error).__name__, error)
                failures[kind] = f"{type(error).__name__}: {error}"
                continue
            if not grid:
                result.to_hdf5(handle.create_group(kind))
            handle[kind].attrs["request"] = request
            results[kind] = result
    return results, failures


def _run_study(problem: Any, kind: str, options: Mapping[str, Any], handle: Any, executor: Any,
               progress: bool) -> Any:
    from . import _studies

    if kind == "steady_state":
        return _studies.steady_state(problem, options["values"], n_steps=options["n_steps"])
    if kind == "sweep":
        return _studies.sweep(problem, options["parameter"], options["values"], n_steps=options["n_steps"],
                              max_harmonic=options["max_harmonic"], executor=executor, out=handle,
                              name=kind, progress=progress)
    if kind == "campbell":
        return _studies.campbell(problem, options["speeds"], n_steps=options["n_steps"],
                                 frozen_samples=options["frozen_samples"],
                                 max_harmonic=options["max_harmonic"], executor=executor, out=handle,
                                 name=kind, progress=progress)
    if kind == "stability_chart":
        return _studies.stability_chart(problem, options["first"], options["second"],
                                        n_steps=options["n_steps"], executor=executor, out=handle,
                                        name=kind, progress=progress)
    if kind == "nonlinear_check":
        return _studies.nonlinear_check(
            problem, options["values"], n_steps=options["n_steps"], n_periods=options["n_periods"],
            from_rest=options["from_rest"], max_periods_from_rest=options["max_periods_from_rest"],
            steady_tol=options["steady_tol"])
    return _studies.error_cost(problem, options["values"], n_steps=options["n_steps"],
                               resolution=options["resolution"], reference_steps=options["reference_steps"])
