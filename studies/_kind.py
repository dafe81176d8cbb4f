"""What a study kind declares (:class:`StudyKind`), the one registry of kinds
(:func:`register_kind`, :func:`kinds`, :func:`kind_of`) and the checks of a ``[studies.<kind>]`` table.

Each kind is an object declared where it is defined (a module of ``studies._kinds``, or a user's
module) and registered there with :func:`register_kind`; the ``[studies]`` table, the resource
guard, the warm-up, the summary table, the figures and ``studies.load`` only ask the registry.
"""

from __future__ import annotations

import difflib
import math
import types
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from ._errors import StudiesError
from ._plots import headline
from ._problem import SPEED
from ._store import Result, register_result
from ._studies import check_n_steps
from ._summary import Summary

#: Keys of an axis table: a parameter and its values (``values = [...]`` or ``start, stop, count``).
AXIS_KEYS = ("parameter", "start", "stop", "count", "values", "spacing")

# Upper bounds of the size-like keys of the [studies] tables (docs/studies.md, "Limits"), each with
# the reason given when a value is refused. They stop absurd values when the table is read; what a
# study costs in all (points x steps x coordinates) is estimated by its kind's cost model (StudyKind.cost)
# for the resource guard.
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


#: Steps per period of the warm-up runs (``studies.cli``'s JIT warm-up, ``StudyKind.warm_up``): the
#: smallest every study kind accepts (the numba types, not the sizes, decide what is compiled).
WARM_UP_STEPS = 32


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
    ``cost(name, problem, options, workers[, done]) -> studies.Estimate``: the kind's cost model for
    the resource guard, memory (bytes) and time (s) of one run from checked options (``done``, grid
    kinds only: the points already saved). Required: a kind without one is refused at registration,
    so that nothing is ever sized as something cheaper. ``studies._cost`` has the sizing helpers.
    ``demo``: its table in the built-in ``mathieu`` scene of ``flexvib run`` (None: not in it).
    ``warm_up(problem) -> None``: runs the kind's own code path on a tiny grid before the run's
    clocks start, so that numba compiles its kernels (``WARM_UP_STEPS`` steps); None: a grid kind
    runs one ``point``, another needs nothing beyond the steady state every run warms up.
    ``schemes``: the kind integrates with a periodic scheme, named by the ``[studies]`` table's
    ``scheme`` key: the plan adds it to the options (``options["scheme"]``, part of the request and
    its hash) and ``run`` passes it to the study function.
    ``aliases``: other names files store this kind under (result format 1 wrote the result class's
    name), read by ``studies.load``.
    ``validate(problem, options) -> None``: the checks of options against the problem (a control
    comparison needs a drive with feedback; an optimisation's bounds must be continuous parameters
    of it), raising a ``ValueError`` subclass; the resource guard runs it for every declared study
    before the first is written (None: ``check`` says all).
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
    cost: Callable[..., Any] | None = None
    demo: Mapping[str, Any] | None = None
    warm_up: Callable[[Any], None] | None = None
    schemes: bool = False
    aliases: tuple[str, ...] = ()
    validate: Callable[[Any, Mapping[str, Any]], None] | None = None


# ---------------------------------------------------------------------------------------------------
# the registry of study kinds
# ---------------------------------------------------------------------------------------------------
#: Keys of the ``[studies]`` table that are not kinds (a kind may not take their names).
COMMON_KEYS = ("n_steps", "observables", "scheme", "error_tolerance")

#: What every study result offers a user and the command (``studies.StudyResult``): a result class
#: without one of them is refused at registration, not when the command reads it after the run.
RESULT_FIELDS = ("status", "message", "run_time", "peak", "peak_error", "peak_to_peak", "peak_to_peak_error",
                 "plot", "to_hdf5")


def _has_field(cls: type, name: str) -> bool:
    """Whether instances of ``cls`` have ``name``: a dataclass field, or a class attribute (a property,
    a method, a class-level default)."""
    return name in getattr(cls, "__dataclass_fields__", {}) or hasattr(cls, name)


_KINDS: dict[str, StudyKind] = {}
_BY_RESULT: dict[type, StudyKind] = {}


def register_kind(kind: StudyKind) -> StudyKind:
    """Add ``kind`` to the registry (in the order a run performs the kinds); returns it, so that a
    module declares ``KIND = register_kind(StudyKind(...))``. Refused (:class:`StudiesError`): a name
    that is not an identifier, is taken or is a ``[studies]`` key; a kind without a cost model, or
    without the hooks it needs; a result class that is not a ``studies.Result`` or is another kind's."""
    if not isinstance(kind, StudyKind):
        raise TypeError(f"register_kind: expected a studies.StudyKind, got {type(kind).__name__}")
    name = kind.name
    where = f"study kind {name!r}"
    if not isinstance(name, str) or not name.isidentifier() or name.startswith("_"):
        raise StudiesError(f"register_kind: a kind's name must be an identifier not starting with '_' "
                           f"(it names a [studies.<name>] table and an HDF5 group), got {name!r}")
    if name in COMMON_KEYS:
        raise StudiesError(f"register_kind: {name!r} is a key of the [studies] table "
                           f"({', '.join(COMMON_KEYS)}); choose another name")
    if name in _KINDS:
        if _KINDS[name] is kind:
            return kind
        raise StudiesError(f"register_kind: a study kind {name!r} is already registered "
                           f"(kinds: {', '.join(_KINDS)})")
    if not callable(kind.cost):
        raise StudiesError(f"register_kind: {where} declares no cost model (StudyKind(cost=...): memory "
                           f"and time of a run for the resource guard, see studies._cost); got "
                           f"{kind.cost!r}")
    for hook in ("check", "run", "summary", "varies", "default", "figures", "runs", "headlines"):
        if not callable(getattr(kind, hook)):
            raise StudiesError(f"register_kind: {where}: {hook} must be callable, got "
                               f"{getattr(kind, hook)!r}")
    if kind.demo is not None and not isinstance(kind.demo, Mapping):
        raise StudiesError(f"register_kind: {where}: demo must be a table (a mapping) or None, got "
                           f"{kind.demo!r}")
    if not all(isinstance(key, str) for key in kind.keys):
        raise StudiesError(f"register_kind: {where}: keys must be strings, got {kind.keys!r}")
    if kind.grid and not callable(kind.point):
        raise StudiesError(f"register_kind: {where} is a grid study without a point function")
    if not (isinstance(kind.result, type) and issubclass(kind.result, Result)):
        raise StudiesError(f"register_kind: {where}: result must be a subclass of studies.Result, got "
                           f"{kind.result!r}")
    missing = [name for name in RESULT_FIELDS if not _has_field(kind.result, name)]
    if missing:
        raise StudiesError(f"register_kind: {where}: result class {kind.result.__name__} lacks "
                           f"{', '.join(missing)}: every result has {', '.join(RESULT_FIELDS)} (derive it "
                           f"from studies.StudyResult, whose docstring says their shapes)")
    if kind.result in _BY_RESULT:
        raise StudiesError(f"register_kind: {where}: result class {kind.result.__name__} is already the "
                           f"result of kind {_BY_RESULT[kind.result].name!r}")
    register_result(name, kind.result, aliases=kind.aliases)
    _KINDS[name] = kind
    _BY_RESULT[kind.result] = kind
    return kind


def kinds() -> Mapping[str, StudyKind]:
    """The registered study kinds by name (read-only), in the order a run performs them."""
    return types.MappingProxyType(_KINDS)


def kind_named(name: str) -> StudyKind:
    """The registered kind ``name`` (a :class:`StudiesError` listing the kinds otherwise)."""
    try:
        return _KINDS[name]
    except KeyError:
        close = difflib.get_close_matches(str(name), list(_KINDS), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise StudiesError(f"unknown study kind {name!r}{hint} (kinds: {', '.join(_KINDS)})") from None


def kind_of(result: Any) -> StudyKind:
    """The kind whose result ``result`` is (e.g. one read back by ``studies.load``)."""
    try:
        return _BY_RESULT[type(result)]
    except KeyError:
        raise StudiesError(f"{type(result).__name__} is not the result of a registered study kind") from None


def in_run_order(results: Mapping[str, Any]) -> dict[str, Any]:
    """Results in the order a run performs their kinds (steady state, sweep, ...), not the file's
    alphabetical order."""
    order = list(_KINDS)
    return dict(sorted(results.items(), key=lambda item: order.index(kind_of(item[1]).name)))


def summaries(results: Mapping[str, Any]) -> dict[str, Summary]:
    """``{study name: Summary}`` of results in run order, each from its kind's ``headlines`` hook."""
    return {name: kind_of(result).headlines(result) for name, result in in_run_order(results).items()}


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
