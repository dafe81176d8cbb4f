"""The HDF5 layout of study results, and ``studies.load``.

One file per run. File attributes: ``flexvib_version``, ``versions`` (JSON: package -> version),
``created`` (UTC ISO time), ``format_version`` (:data:`FORMAT_VERSION`). One group per study, with
attributes ``kind`` (the registered name of its study kind), ``format_version``, ``settings`` (JSON),
``scene`` (the scene text) and the result's scalar fields (error estimates, run times, statuses;
JSON-encoded), and datasets for its array fields, each with a ``units`` attribute. A field holding a
dict of arrays (one per observable) is a subgroup with one dataset per key. Grid studies write the
same names point by point (see ``studies._grid``), so ``load`` reads a complete and an interrupted
run alike. ``flexvib run`` writes through ``studies._resultfile.ResultFile`` (crash-safe commits).
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
from ._identity import plain
from ._integrity import POINT_MARK, check_group, check_root, open_study, seal, seal_points, seal_root
from ._writes import writing_to

#: The result format this flexvib writes: the file attribute and each study group's attribute
#: ``format_version``. Format 1 (files without the attribute, flexvib before it was recorded): a
#: group's ``kind`` is the name of its result class. Format 2: ``kind`` is the registered name of the
#: study kind (``studies.register_kind``), a stable string, so that moving or renaming a result class
#: breaks no file. Format 3: ``spectral_radius`` (and its error) is that of the resolved modes, the
#: steady state's unresolved ones stored apart (``unresolved_multipliers``); in older files it is over
#: all modes, and they are read with that meaning. Format 3 results also carry their error budget
#: (``studies._budget``: time step, mesh, linearisation, reduction) and their errors
#: (``peak_to_peak_error``, ...) are its totals; in files of formats 1 and 2 the errors were the time
#: step's alone, and they read so (a budget of the time step with the other terms unknown). And
#: format 3 carries checksums (``studies._integrity``): the file's attributes, each study group and
#: each grid point carry a digest, verified by ``load``, ``flexvib info`` and the resume; a format-2
#: file has none and reads as "not verifiable". A file or group of a higher format is refused
#: (:func:`check_format`).
FORMAT_VERSION = 3

#: Result classes by the name a file stores them under (the kind's name and its aliases).
_RESULTS: dict[str, type] = {}
_NAMES: dict[type, str] = {}


class ResultFileError(StudiesError):
    """A result file that cannot be used as asked (a folder, an unwritable path, not a flexvib file,
    another scene, written by another live run, a newer result format): exit code 2, the file
    untouched."""


class DamagedResultError(ResultFileError):
    """A result file, or studies in it, whose bytes no longer match their checksums (``load``,
    ``flexvib plot`` and ``report`` refuse it naming the studies; ``flexvib run`` recomputes them)."""


class StorageError(RuntimeError):
    """The disk filled (or failed) while a run was writing: exit code 1; the last commit stands."""


def register_result(name: str, cls: type, *, aliases: tuple[str, ...] = ()) -> None:
    """Make ``cls`` loadable from groups whose ``kind`` is ``name`` (format 2) or one of ``aliases``
    (the names older files wrote); ``studies.register_kind`` calls it for each kind."""
    for stored in (name, *aliases):
        if _RESULTS.get(stored, cls) is not cls:
            raise StudiesError(f"result kind {stored!r} is already stored by {_RESULTS[stored].__name__}")
    for stored in (name, *aliases):
        _RESULTS[stored] = cls
    _NAMES[cls] = name


def stored_name(cls: type) -> str:
    """The ``kind`` attribute a result of class ``cls`` is written with: its kind's registered name."""
    try:
        return _NAMES[cls]
    except KeyError:
        raise StudiesError(f"{cls.__name__} is not the result of a registered study kind; register its "
                           f"kind with studies.register_kind before writing it") from None


def format_of(item: Any) -> int:
    """The result format of an h5py group or file: its own ``format_version``, else its file's, else
    1 (written before the format was recorded)."""
    for attrs in (item.attrs, item.file.attrs):
        if "format_version" in attrs:
            try:
                return int(attrs["format_version"])
            except (TypeError, ValueError):
                raise ResultFileError(f"{item.file.filename}: unreadable format_version "
                                      f"{attrs['format_version']!r}") from None
    return 1


def check_format(item: Any) -> int:
    """``format_of(item)``, refused when this flexvib cannot read it (a newer format): the message names
    the flexvib version and format that wrote it, and what to do."""
    version = format_of(item)
    if version > FORMAT_VERSION:
        writer = item.file.attrs.get("flexvib_version", "?")
        raise ResultFileError(
            f"result file {str(item.file.filename)!r}: written by flexvib {writer} in result format "
            f"{version}; this flexvib ({versions()['flexvib']}) reads formats 1 to {FORMAT_VERSION}. "
            f"Upgrade flexvib (pip install -U flexvib) to read it, or run the scene again with this "
            f"version")
    return version


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
    """Open (create) a result file and stamp it with versions and creation time (an h5py File; for
    scripts: ``flexvib run`` writes through the crash-safe :class:`ResultFile`). An existing HDF5
    file that flexvib did not write is refused, so that none of its datasets is ever replaced."""
    import h5py

    try:
        if mode != "r":
            Path(path).parent.mkdir(parents=True, exist_ok=True)  # as a user expects of --out a/b.h5
            if Path(path).is_file() and h5py.is_hdf5(path):
                with h5py.File(path, "r", locking=False) as existing:
                    foreign = "flexvib_version" not in existing.attrs and len(existing) > 0
                    if not foreign:  # never add to a file of a newer format
                        for item in (existing, *(g for g in existing.values() if hasattr(g, "attrs"))):
                            check_format(item)
                if foreign:
                    raise StudiesError(f"result file {str(path)!r}: an HDF5 file not written by flexvib; "
                                       f"refusing to change it (choose another path)")
        handle = h5py.File(path, mode)
    except OSError as error:  # a folder, no permission, not HDF5, locked by another run
        raise StudiesError(f"result file {str(path)!r}: cannot open it {'to read' if mode == 'r' else 'to write'} "
                           f"({error}); expected the path of a new file or of an HDF5 file written "
                           f"by flexvib") from None
    if "flexvib_version" not in handle.attrs and mode != "r":
        stamp(handle)
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
        """Write into ``group`` (an h5py Group or File); returns the group. In a :class:`ResultFile`
        the write is one piece: an interrupt waits for its end, the free space is checked first."""
        with writing_to(group, self.nbytes()):
            self._write(group)
            seal_points(group)   # a grid study written over its points (none elsewhere)
            seal(group)
        return group

    def nbytes(self) -> int:
        """The bytes of the result's arrays (what ``to_hdf5`` writes, about)."""
        total = 0
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            arrays = value.values() if isinstance(value, Mapping) else [value]
            total += sum(a.nbytes for a in arrays if isinstance(a, np.ndarray) and a.dtype.kind != "O")
        return total

    def _write(self, group: Any) -> None:
        group.attrs["kind"] = stored_name(type(self))
        group.attrs["format_version"] = FORMAT_VERSION
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, np.ndarray):
                write_array(group, field.name, value, self._unit(field.name))
            elif isinstance(value, Mapping) and value and all(isinstance(v, np.ndarray)
                                                              for v in value.values()):
                sub = group.require_group(field.name)
                for key, array in value.items():
                    write_array(sub, key, array, self._unit(field.name, key))
            else:
                write_attrs(group, {field.name: value})
        group.attrs["complete"] = True

    def save(self, path: str | Path, name: str | None = None) -> None:
        """Write to the file ``path`` as group ``name`` (default: its kind's name), replacing it."""
        name = name or stored_name(type(self))
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


def write_array(group: Any, name: str, array: np.ndarray, unit: str) -> None:
    import h5py

    if name in group:
        existing = group[name]
        same_strings = array.dtype.kind in "USO" and getattr(existing, "dtype", None) is not None \
            and existing.dtype.kind == "O"
        if getattr(existing, "shape", None) == array.shape and (
                same_strings or getattr(existing, "dtype", None) == array.dtype):
            # the same layout (a grid study's points, written over by its result): in place, keeping
            # the dataset's attributes (studies._integrity.POINT_MARK)
            existing[...] = np.asarray(array, dtype=object) if same_strings else array
            existing.attrs["units"] = unit
            return
        # another type in the same shape (a grid's 0/1 flag as bool) still holds one entry per point
        keep = {POINT_MARK: True} if (getattr(existing, "shape", None) == array.shape
                                      and existing.attrs.get(POINT_MARK, False)) else {}
        del group[name]
    else:
        keep = {}
    if array.dtype.kind in "USO":
        dataset = group.create_dataset(name, data=np.asarray(array, dtype=object),
                                       dtype=h5py.string_dtype())
    else:
        dataset = group.create_dataset(name, data=array)
    dataset.attrs["units"] = unit
    for key, value in keep.items():
        dataset.attrs[key] = value


def _read_array(dataset: Any) -> np.ndarray:
    if dataset.dtype.kind == "O":
        return np.array(dataset.asstr()[()], dtype=str)
    return dataset[()]


def encode(value: Any) -> str:
    """JSON text of ``value`` (tuples as lists, numpy scalars and arrays as Python numbers/lists)."""
    return json.dumps(plain(value), sort_keys=True)


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
        # no HDF5 lock: a run replaces the file atomically and never holds it open
        handle = h5py.File(path, "r", locking=False)
    except OSError as error:
        raise StudiesError(f"{str(path)!r} is not an HDF5 result file: {error}") from None
    with handle:
        check_format(handle)
        for group in handle.values():   # a newer format is refused as such before any checksum
            if hasattr(group, "keys"):
                check_format(group)
        damaged = damage_report(handle)
        if damaged:
            raise DamagedResultError(f"result file {str(path)!r} is damaged: {damaged}; run the same "
                                     f"`flexvib run` command to recompute what is damaged (or with "
                                     f"--overwrite to move an unreadable file aside)")
        return {name: read_group(group) for name, group in handle.items()}


def damage_report(handle: Any) -> str:
    """The damage the checksums find in an open result file, in words ("" when none: intact, or a
    file written before format 3, which is not verifiable)."""
    version = format_of(handle)
    found = []
    root = check_root(handle, version)
    if root.damaged:
        found.append(root.cause)
    for name in handle:
        group, check = open_study(handle, name)
        if check is None and hasattr(group, "keys"):
            check = check_group(group, format_of(group))
        if check is not None and check.damaged:
            found.append(f"study {name!r} {check.describe()}")
    return "; ".join(found)


def read_group(group: Any) -> Result:
    """The result stored in one study group (its class from the ``kind`` attribute: the registered
    kind's name, or in format 1 the result class's name, which each kind lists as an alias)."""
    check_format(group)
    kind = group.attrs.get("kind")
    if kind not in _RESULTS:
        raise StudiesError(f"{group.file.filename}: group {group.name!r} has unknown kind {kind!r} "
                           f"(known: {', '.join(sorted(_NAMES.values()))}); register the study kind "
                           f"that wrote it (studies.register_kind) before loading")
    return _RESULTS[kind].from_hdf5(group)


def study_attrs(group: Any) -> dict[str, Any]:
    """The JSON-decoded attributes of a study group (for ``flexvib info``)."""
    out = {}
    for key, value in group.attrs.items():
        try:
            out[key] = json.loads(value) if isinstance(value, str) else plain(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def stamp(handle: Any) -> None:
    """Versions and creation time of a new result file."""
    stamp = versions()
    handle.attrs["flexvib_version"] = stamp["flexvib"]
    handle.attrs["format_version"] = FORMAT_VERSION
    handle.attrs["versions"] = json.dumps(stamp, sort_keys=True)
    handle.attrs["created"] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    seal_root(handle)
