"""HDF5 layout shared by every study result, and ``studies.load``.

One file per run. File attributes: ``flexvib_version``, ``versions`` (JSON: package -> version),
``created`` (UTC ISO time). One group per study, with attributes ``kind`` (the result class),
``settings`` (JSON), ``scene`` (the scene text) and the result's scalar fields (error estimates, run
times, statuses; JSON-encoded), and datasets for its array fields, each with a ``units`` attribute.
A field holding a dict of arrays (one per observable) is a subgroup with one dataset per key.
Grid studies write the same names point by point (see ``studies._grid``), so ``load`` reads a
complete and an interrupted run alike.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
from importlib import metadata
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from ._errors import StudiesError

_REGISTRY: dict[str, type] = {}


def register(cls: type) -> type:
    """Class decorator: make ``cls`` loadable by its ``kind`` (the class name)."""
    _REGISTRY[cls.__name__] = cls
    return cls


def versions() -> dict[str, str]:
    """Versions of flexvib and of the packages whose numbers enter the results."""
    found = {}
    for package in ("flexvib", "numpy", "scipy", "numba", "h5py", "matplotlib"):
        try:
            found[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            found[package] = "not installed"
    return found


def open_file(path: str | Path, mode: str = "a"):
    """Open (create) a result file and stamp it with versions and creation time."""
    import h5py

    try:
        if mode != "r":
            Path(path).parent.mkdir(parents=True, exist_ok=True)  # as a user expects of --out a/b.h5
        handle = h5py.File(path, mode)
    except OSError as error:  # a folder, no permission, not HDF5, locked by another run
        raise StudiesError(f"result file {str(path)!r}: cannot open it {'to read' if mode == 'r' else 'to write'} "
                           f"({error}); expected the path of a new file or of an HDF5 file written "
                           f"by flexvib") from None
    if "flexvib_version" not in handle.attrs and mode != "r":
        stamp = versions()
        handle.attrs["flexvib_version"] = stamp["flexvib"]
        handle.attrs["versions"] = json.dumps(stamp, sort_keys=True)
        handle.attrs["created"] = datetime.datetime.now(datetime.timezone.utc).isoformat(
            timespec="seconds")
    return handle


class Result:
    """Base of the study results: frozen dataclasses whose array fields have units.

    Subclasses declare ``_units``: field name -> unit string, or ``"@observables"`` (dict field, unit of
    each key from ``self.units``) or ``"@parameter"`` (the unit of the swept parameter, from
    ``self.parameter_unit``).
    """

    _units: Mapping[str, str] = {}

    def _unit(self, name: str, key: str | None = None) -> str:
        unit = self._units.get(name, "1")
        if unit == "@observables":
            return dict(self.units)[key]
        if unit.startswith("@"):
            return getattr(self, unit[1:])
        return unit

    def to_hdf5(self, group: Any) -> Any:
        """Write into ``group`` (an h5py Group or File); returns the group."""
        group.attrs["kind"] = type(self).__name__
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, np.ndarray):
                _write_array(group, field.name, value, self._unit(field.name))
            elif isinstance(value, Mapping) and value and all(isinstance(v, np.ndarray)
                                                              for v in value.values()):
                sub = group.require_group(field.name)
                for key, array in value.items():
                    _write_array(sub, key, array, self._unit(field.name, key))
            else:
                write_attrs(group, {field.name: value})
        group.attrs["complete"] = True
        return group

    def save(self, path: str | Path, name: str | None = None) -> None:
        """Write to the file ``path`` as group ``name`` (default: the class kind), replacing it."""
        name = name or type(self).__name__
        with open_file(path) as handle:
            if name in handle:
                del handle[name]
            self.to_hdf5(handle.create_group(name))

    @classmethod
    def from_hdf5(cls, group: Any) -> "Result":
        values = {}
        for field in dataclasses.fields(cls):
            if field.name in group:
                item = group[field.name]
                if hasattr(item, "keys"):
                    values[field.name] = {key: _read_array(item[key]) for key in item.keys()}
                else:
                    values[field.name] = _read_array(item)
            elif field.name in group.attrs and field.type == "str":
                values[field.name] = str(group.attrs[field.name])
            elif field.name in group.attrs:
                value = json.loads(group.attrs[field.name])
                if isinstance(field.type, str) and field.type.startswith("tuple"):
                    value = _tuples(value)
                values[field.name] = value
            elif field.default is not dataclasses.MISSING:
                values[field.name] = field.default
            elif field.default_factory is not dataclasses.MISSING:
                values[field.name] = field.default_factory()
            else:
                raise StudiesError(f"{group.file.filename}: group {group.name!r} has no {field.name!r}; "
                                   f"the file is not a complete {cls.__name__} result")
        return cls(**values)


def write_attrs(group: Any, values: Mapping[str, Any]) -> None:
    """Scalar fields as attributes: text as is (scene, status, message stay readable), the rest as
    JSON."""
    for name, value in values.items():
        group.attrs[name] = value if isinstance(value, str) else encode(value)


def _write_array(group: Any, name: str, array: np.ndarray, unit: str) -> None:
    import h5py

    if name in group:
        del group[name]
    if array.dtype.kind in "USO":
        dataset = group.create_dataset(name, data=np.asarray(array, dtype=object),
                                       dtype=h5py.string_dtype())
    else:
        dataset = group.create_dataset(name, data=array)
    dataset.attrs["units"] = unit


def _read_array(dataset: Any) -> np.ndarray:
    if dataset.dtype.kind == "O":
        return np.array(dataset.asstr()[()], dtype=str)
    return dataset[()]


def encode(value: Any) -> str:
    """JSON text of ``value`` (tuples as lists, numpy scalars and arrays as Python numbers/lists)."""
    return json.dumps(_plain(value), sort_keys=True)


def _plain(value: Any) -> Any:
    """JSON-ready copy: tuples to lists, numpy scalars to Python, non-finite floats kept as strings."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if dataclasses.is_dataclass(value):
        return _plain(dataclasses.asdict(value))
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def _tuples(value: Any) -> Any:
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    return value


def load(path: str | Path) -> dict[str, Result]:
    """Every study result in a run file: ``{group name: result}`` (grid studies interrupted before
    the end come back with NaN and ``done = False`` at the missing points)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"result file {str(path)!r} does not exist")
    import h5py

    try:
        handle = h5py.File(path, "r")
    except OSError as error:
        raise StudiesError(f"{str(path)!r} is not an HDF5 result file: {error}") from None
    with handle:
        return {name: read_group(group) for name, group in handle.items()}


def read_group(group: Any) -> Result:
    """The result stored in one study group (its class from the ``kind`` attribute)."""
    kind = group.attrs.get("kind")
    if kind not in _REGISTRY:
        raise StudiesError(f"{group.file.filename}: group {group.name!r} has unknown kind {kind!r} "
                           f"(known: {sorted(_REGISTRY)})")
    return _REGISTRY[kind].from_hdf5(group)


def study_attrs(group: Any) -> dict[str, Any]:
    """The JSON-decoded attributes of a study group (for ``flexvib info``)."""
    out = {}
    for key, value in group.attrs.items():
        try:
            out[key] = json.loads(value) if isinstance(value, str) else _plain(value)
        except json.JSONDecodeError:
            out[key] = value
    return out
