"""What a study kind declares (:class:`StudyKind`) and the checks of its ``[studies.<kind>]`` table.

Each kind lives in one module of ``studies._kinds`` and the registry there lists them; ``_plan`` (the
``[studies]`` table) and ``cli`` (summaries, figures) only iterate that registry.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from ._errors import StudiesError
from ._plots import headline
from ._problem import SPEED
from ._summary import Summary

#: Keys of an axis table: a parameter and its values (``values = [...]`` or ``start, stop, count``).
AXIS_KEYS = ("parameter", "start", "stop", "count", "values", "spacing")

# Upper bounds of the size-like keys of the [studies] tables (docs/studies.md, "Limits"), each with
# the reason given when a value is refused. They stop absurd values when the table is read; what a
# study costs in all (points x steps x coordinates) is estimated by the resource guard (_guard.py).
#: Steps per period: 65536 resolve a mode of 10^4 times the crank frequency to 0.01 %.
MAX_STEPS = 65536
STEPS_WHY = "65536 steps per period resolve modes up to 10^4 times the crank frequency"
#: Values on one axis (``count`` or the length of ``values``).
MAX_AXIS_POINTS = 100_000
AXIS_WHY = "points of one axis"
#: Highest harmonic k of the resonance marks and lines k * speed.
MAX_HARMONIC = 100
HARMONIC_WHY = "harmonics of the crank speed marked in a figure"
#: Periods of a nonlinear run.
MAX_PERIODS = 10_000
PERIODS_WHY = "periods of one nonlinear run, each n_steps steps"


def _no_parameters(options: Mapping[str, Any]) -> tuple[str, ...]:
    return ()


def _no_default(nominal_speed: float) -> None:
    return None


def _one_run(options: Mapping[str, Any]) -> dict[str, Mapping[str, Any]]:
    return {"": options}


def _one_figure(result: Any) -> dict[str, Callable]:
    return {"": result.plot}


def _no_headlines(result: Any) -> Summary:
    """A kind that names no headline numbers: its status and run time alone."""
    status = getattr(result, "status", "")
    run_time = getattr(result, "run_time", float("nan"))
    return Summary(status=headline(status) if isinstance(status, str) else "",
                   run_time=float(run_time) if np.ndim(run_time) == 0 else float(np.nansum(run_time)))


@dataclass(frozen=True)
class StudyKind:
    """One kind of study, as a scene declares it (``[studies.<name>]``) and as the CLI shows it.

    ``name``: the table's name, the HDF5 group of a run and the key of the registry.
    ``result``: the result class (``plot(*, axes=None) -> Plot``, ``to_hdf5``).
    ``keys``: the keys its table accepts (anything else is rejected, with the nearest key suggested).
    ``check(where, table, n_steps) -> options``: the table's values checked, defaults filled in
    (``n_steps`` is the ``[studies]`` default); ``where`` names the table in messages.
    ``run(problem, options, *, out, executor, progress) -> result``: the study from checked options
    (``out`` the open HDF5 file a grid study writes its points into as they finish).
    ``summary(result) -> str``: the one line ``flexvib run`` prints.
    ``headlines(result) -> studies._summary.Summary``: its rows of the summary table ``flexvib run``
    prints and ``flexvib report`` writes: headline numbers with units and errors, status in words,
    run time.
    ``grid``: a resumable grid study (writes itself into ``out``; otherwise the plan writes the result).
    ``point``: the top-level point function of a grid study (picklable, run in workers).
    ``varies(options) -> (path, ...)``: the scene parameters (besides ``speed``) it changes.
    ``default(nominal_speed) -> table | None``: its table in the studies run for a scene without a
    ``[studies]`` table (None: not run by default).
    ``figures(result) -> {suffix: draw}``: the figures ``flexvib plot`` writes, ``draw() -> Plot``,
    each saved as ``<group name><suffix>.png/.svg``.
    ``runs(options) -> {suffix: options}``: a table that declares several runs of a single (not grid)
    study, e.g. a nonlinear check at several ``speeds``, each written as group ``<name><suffix>``.
    """

    name: str
    result: type
    keys: tuple[str, ...]
    check: Callable[[str, Mapping[str, Any], int], dict[str, Any]]
    run: Callable[..., Any]
    summary: Callable[[Any], str]
    grid: bool = False
    point: Callable | None = None
    varies: Callable[[Mapping[str, Any]], tuple[str, ...]] = _no_parameters
    default: Callable[[float], Mapping[str, Any] | None] = _no_default
    figures: Callable[[Any], dict[str, Callable]] = _one_figure
    runs: Callable[[Mapping[str, Any]], dict[str, Mapping[str, Any]]] = _one_run
    headlines: Callable[[Any], Summary] = _no_headlines


# ---------------------------------------------------------------------------------------------------
# checks of scene-table values: each names the table and key, what was expected and what was given
# ---------------------------------------------------------------------------------------------------
def reject_unknown(where: str, keys, allowed) -> None:
    for key in keys:
        if key not in allowed:
            close = difflib.get_close_matches(str(key), list(allowed), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise StudiesError(f"[{where}]: unknown key {key!r}{hint} (keys: {', '.join(allowed)})")


def number(where: str, key: str, value: Any, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise StudiesError(f"[{where}] {key}: expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise StudiesError(f"[{where}] {key}: expected a positive number, got {value!r}")
    return float(value)


def integer(where: str, key: str, value: Any, minimum: int, *, even: bool = False,
            maximum: int | None = None, why: str = "") -> int:
    """An integer of at least ``minimum`` (even if asked); above ``maximum`` refused, saying ``why``
    there is a limit."""
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum or (even and value % 2):
        kind = "an even integer" if even else "an integer"
        raise StudiesError(f"[{where}] {key}: expected {kind} >= {minimum}, got {value!r}")
    if maximum is not None and value > maximum:
        raise StudiesError(f"[{where}] {key}: at most {maximum} ({why}), got {value!r}")
    return value


def fraction(where: str, key: str, value: Any) -> float:
    """A fraction in [0, 1) (a tolerance relative to a peak-to-peak)."""
    value = number(where, key, value)
    if not 0.0 <= value < 1.0:
        raise StudiesError(f"[{where}] {key}: expected a fraction in [0, 1), got {value!r}")
    return value


def boolean(where: str, key: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise StudiesError(f"[{where}] {key}: expected true or false, got {value!r}")
    return value


def steps(where: str, table: Mapping[str, Any], default: int, *, minimum: int = 16, multiple: int = 4) -> int:
    """The table's ``n_steps`` (``default`` when absent): a multiple of ``multiple`` and at least the
    study's ``minimum`` (docs/studies.md)."""
    from ._studies import check_n_steps

    value = table.get("n_steps", default)
    try:
        value = check_n_steps(value, minimum=minimum, multiple=multiple, study=f"a {where.split('.')[-1]} study")
    except StudiesError as error:
        raise StudiesError(f"[{where}] {error}") from None
    # the default comes from the [studies] table: name that one
    return integer(where if "n_steps" in table else "studies", "n_steps", value, minimum,
                   maximum=MAX_STEPS, why=STEPS_WHY)


def speed_values(where: str, table: Mapping[str, Any]) -> dict[str, float]:
    """``{"speed": value}`` of a table's optional ``speed`` key (empty: the scene's speed)."""
    return {SPEED: number(where, "speed", table["speed"], positive=True)} if "speed" in table else {}


def sub_table(where: str, table: Mapping[str, Any], key: str, expected: str) -> Mapping[str, Any]:
    """The sub-table ``key`` of an axis (``x = {parameter = ..., ...}``), its keys checked."""
    value = table.get(key)
    if not isinstance(value, Mapping):
        raise StudiesError(f"[{where}] {key}: expected a table {expected}, got {value!r}")
    reject_unknown(f"{where}.{key}", value, AXIS_KEYS)
    return value


def axis(where: str, table: Mapping[str, Any], *, parameter: bool = True) -> tuple[str, np.ndarray]:
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
        if len(values) > MAX_AXIS_POINTS:
            raise StudiesError(f"[{where}] values: at most {MAX_AXIS_POINTS} ({AXIS_WHY}), got a list of "
                               f"{len(values)}")
        return name, np.array([number(where, "values", v) for v in values])
    missing = [k for k in ("start", "stop", "count") if k not in table]
    if missing:
        raise StudiesError(f"[{where}]: missing {', '.join(missing)} (or give values = [...])")
    start, stop = number(where, "start", table["start"]), number(where, "stop", table["stop"])
    count = integer(where, "count", table["count"], 1, maximum=MAX_AXIS_POINTS, why=AXIS_WHY)
    spacing = table.get("spacing", "linear")
    if spacing == "linear":
        return name, np.linspace(start, stop, count)
    if spacing == "log":
        if start <= 0 or stop <= 0:
            raise StudiesError(f"[{where}] spacing = 'log' needs positive start and stop")
        return name, np.geomspace(start, stop, count)
    raise StudiesError(f"[{where}] spacing: expected 'linear' or 'log', got {spacing!r}")
