"""Every result as a table: ``StudyResult.to_dataframe()`` (pandas) and ``.to_xarray()`` (xarray).

One generic conversion, driven by the result's fields and their units (``Result._units``), never by
its kind. A result names the fields that are its rows (``StudyResult._axes``: a grid study's swept
values, by default the time samples ``t``); every field whose leading dimensions have the rows'
shape becomes columns:

- an array of the rows' shape: one column named after the field (``speed``, ``spectral_radius``);
- a dict of such arrays (one per observable): one column per key, ``peak_to_peak[coupler.deflection@0.5]``;
- one trailing dimension: one column per index, ``multipliers[0]``, ``joints[B][1]`` (per coordinate
  where the field's unit says its entries are the coordinates: ``x[coupler.b1]``);
- more trailing dimensions (a Campbell diagram's frozen frequencies over the crank angle): left out of
  the data frame (``attrs["left_out"]`` names them), kept in the xarray Dataset with dimensions of
  their own.

A grid's per-point verdicts are the columns ``status``, ``message``, ``run_time`` (the dataset names
of the result file); the study's own ``status``, ``message``, ``run_time`` and every scalar field are
in ``attrs``, with ``attrs["units"]`` {column: unit} and ``attrs["kind"]``. pandas and xarray are
optional (``pip install 'flexvib[tables]'``).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

from ._errors import StudiesError

#: What to install for the tables (the optional extra of pyproject.toml).
TABLES_EXTRA = "pip install 'flexvib[tables]'"
#: Per-point verdict fields of a grid and their column names (the names of the result file's datasets).
POINT_COLUMNS = {"point_status": "status", "point_message": "message", "point_run_time": "run_time"}


class MissingTablesError(StudiesError):
    """pandas or xarray is not installed: the message says what to install (exit code 2 at the
    command line)."""


def require(module: str) -> Any:
    """Import ``module`` (``"pandas"`` or ``"xarray"``), or say what to install."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingTablesError(f"tables of results need the optional package {module!r}: "
                                 f"{TABLES_EXTRA} (or pip install {module})") from None


def _field_names(result: Any) -> list[str]:
    """The dataclass fields of ``result`` and the shared properties (``result._shared_fields``: the
    peaks, a grid's verdicts, its status, message and run time, where they are properties)."""
    names = [f.name for f in dataclasses.fields(result)]
    return names + [name for name in result._shared_fields if name not in names and hasattr(type(result), name)]


def _unit(result: Any, name: str, key: str | None = None) -> str:
    """The unit of field ``name`` (of its entry ``key``), "" when the result does not say."""
    units = getattr(result, "units", None)
    if key is not None and isinstance(units, Mapping) and key in units \
            and result._units.get(name, "@observables") == "@observables":
        return str(units[key])
    try:
        return str(result._unit(name, key))
    except (KeyError, AttributeError, TypeError):
        return ""


def _axis_name(result: Any, field: str, name: str) -> str:
    """An axis's name: ``name`` itself, or ``"@attr"`` / ``"@attr[i]"`` read from the result (a
    sweep's ``parameter``, a chart's ``parameters[0]``)."""
    if not name.startswith("@"):
        return name
    attribute, _, index = name[1:].partition("[")
    value = getattr(result, attribute)
    value = str(value[int(index.rstrip("]"))] if index else value)
    return value or field   # an unnamed axis (an error-cost study over the steps alone)


def axes_of(result: Any, rows: str | None = None) -> list[tuple[str, str, np.ndarray, str]]:
    """``[(field, name, values, unit), ...]``: the axes of the table's rows, in order (``rows`` a
    field of ``result`` to table against instead: its first dimension)."""
    if rows is not None:
        if rows not in _field_names(result):
            raise StudiesError(f"rows: expected a field of {type(result).__name__} "
                               f"({', '.join(_field_names(result))}), got {rows!r}")
        declared = {rows: rows}
    else:
        declared = {field: name for field, name in result._axes.items()
                    if isinstance(getattr(result, field, None), np.ndarray)}
    if not declared and isinstance(getattr(result, "point_status", None), np.ndarray):
        # a grid that declares no axes (a kind written outside the package): its points by index
        shape = result.point_status.shape
        return [(f"point_{k}", f"point_{k}" if len(shape) > 1 else "point", np.arange(n), "1")
                for k, n in enumerate(shape)]
    if not declared:
        arrays = [name for name in _field_names(result) if isinstance(getattr(result, name), np.ndarray)]
        raise StudiesError(f"{type(result).__name__}: no rows to table (it declares none of "
                           f"{list(result._axes)}); pass rows= one of its array fields ({', '.join(arrays)})")
    axes = []
    for field, name in declared.items():
        values = getattr(result, field, None)
        if not isinstance(values, np.ndarray) or values.ndim < 1:
            raise StudiesError(f"{type(result).__name__}: its rows {field!r} hold no array "
                               f"(got {type(values).__name__}); choose rows= among its array fields")
        axes.append((field, _axis_name(result, field, name), values if values.ndim == 1 else
                     np.arange(values.shape[0]), _unit(result, field)))
    return axes


def _blocks(result: Any, shape: tuple[int, ...], axis_fields: set[str]):
    """``(column, field, array of shape + trailing, unit)`` for every field that has the rows' shape,
    and ``(scalars, left_out)``: {name: value} of the fields that are not, and the names of arrays
    with more than one trailing dimension or another shape."""
    blocks, scalars, left_out = [], {}, []
    for name in _field_names(result):
        value = getattr(result, name)
        if name in axis_fields and isinstance(value, np.ndarray) and value.ndim == 1:
            continue
        column = POINT_COLUMNS.get(name, name) if isinstance(value, np.ndarray) else name
        if isinstance(value, np.ndarray):
            entries = [(column, None, value)]
        elif isinstance(value, Mapping) and value and all(isinstance(v, np.ndarray) for v in value.values()):
            entries = [(f"{column}[{key}]", key, array) for key, array in value.items()]
        else:
            scalars[name] = value
            continue
        for label, key, array in entries:
            if array.shape[:len(shape)] == shape and array.ndim >= len(shape):
                blocks.append((label, name, array, _unit(result, name, key)))
            else:
                left_out.append(label)
    return blocks, scalars, left_out


def _shape(axes: list) -> tuple[int, ...]:
    return tuple(len(values) for _, _, values, _ in axes)


def to_dataframe(result: Any, rows: str | None = None) -> Any:
    """The result as a pandas DataFrame (see the module's docstring)."""
    pandas = require("pandas")
    axes = axes_of(result, rows)
    shape = _shape(axes)
    grid = np.meshgrid(*[values for _, _, values, _ in axes], indexing="ij")
    columns: dict[str, np.ndarray] = {name: g.reshape(-1) for (_, name, _, _), g in zip(axes, grid)}
    units = {name: unit for _, name, _, unit in axes}
    blocks, scalars, left_out = _blocks(result, shape, {field for field, *_ in axes})
    for label, _name, array, unit in blocks:
        if label in columns:   # a field that repeats an axis (a speed sweep's "speed")
            if _same(columns[label], array.reshape(-1)):
                continue
            label = f"{label} (field)"
        flat = array.reshape((int(np.prod(shape)),) + array.shape[len(shape):])
        if flat.ndim == 1:
            columns[label], units[label] = flat, unit
        elif flat.ndim == 2:
            for j, entry in enumerate(_entries(result, unit, flat.shape[1])):
                columns[f"{label}[{entry}]"], units[f"{label}[{entry}]"] = flat[:, j], unit
        else:
            left_out.append(label)
    frame = pandas.DataFrame(columns)
    frame.attrs.update(_attrs(result, scalars, units, left_out))
    return frame


def to_xarray(result: Any, rows: str | None = None) -> Any:
    """The result as an xarray Dataset: dimensions and coordinates the rows' axes (a grid's swept
    parameters, with their units), one variable per column block of :func:`to_dataframe`, trailing
    dimensions named ``<column>_<k>``."""
    xarray = require("xarray")
    axes = axes_of(result, rows)
    shape = _shape(axes)
    dims = [name for _, name, _, _ in axes]
    coords = {name: (name, values, {"units": unit}) for _, name, values, unit in axes}
    blocks, scalars, left_out = _blocks(result, shape, {field for field, *_ in axes})
    variables = {}
    for label, _name, array, unit in blocks:
        if label in coords:
            if _same(coords[label][1], array.reshape(-1)):
                continue
            label = f"{label} (field)"
        trailing = [f"{label}_{k}" for k in range(array.ndim - len(shape))]
        if len(trailing) == 1 and not isinstance(_entries(result, unit, array.shape[-1])[0], int):
            # the coordinates, by their labels: one dimension shared by the fields that hold them
            trailing = ["coordinate"]
            coords.setdefault("coordinate", ("coordinate", list(_entries(result, unit, array.shape[-1]))))
        variables[label] = (dims + trailing, array, {"units": unit})
    dataset = xarray.Dataset(variables, coords=coords)
    dataset.attrs.update({key: value for key, value in
                          _attrs(result, scalars, {}, left_out).items() if key != "units"})
    return dataset


def _entries(result: Any, unit: str, count: int) -> list:
    """The names of a trailing dimension's entries: the coordinates' labels where the field's unit
    says its entries are the coordinates (``"SI (see labels)"``: ``x[coupler.b1]``), else 0, 1, ..."""
    labels = tuple(getattr(result, "labels", ()) or ())
    if unit.startswith("SI (see labels") and len(labels) == count:
        return list(labels)
    return list(range(count))


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    try:
        return a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-12, atol=0.0, equal_nan=True))
    except TypeError:
        return False


def _attrs(result: Any, scalars: Mapping[str, Any], units: Mapping[str, str], left_out: list) -> dict:
    """The table's ``attrs``: the kind, the study's verdict and scalars, the units, what was left out
    (the scene text is left out: it is the result's ``scene``)."""
    from ._store import stored_name

    try:
        kind = stored_name(type(result))
    except StudiesError:
        kind = type(result).__name__
    attrs = {"kind": kind}
    attrs.update({name: value for name, value in scalars.items() if name != "scene"})
    attrs["units"] = dict(units)
    if left_out:
        attrs["left_out"] = list(left_out)
    return attrs
