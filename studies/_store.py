"""HDF5 layout shared by every study result, and ``studies.load``.

One file per run. File attributes: ``flexvib_version``, ``versions`` (JSON: package -> version),
``created`` (UTC ISO time). One group per study, with attributes ``kind`` (the result class),
``settings`` (JSON), ``scene`` (the scene text) and the result's scalar fields (error estimates, run
times, statuses; JSON-encoded), and datasets for its array fields, each with a ``units`` attribute.
A field holding a dict of arrays (one per observable) is a subgroup with one dataset per key.
Grid studies write the same names point by point (see ``studies._grid``), so ``load`` reads a
complete and an interrupted run alike.

``flexvib run`` writes through a :class:`ResultFile`, which makes every write survive any kill: the
run works on a sibling copy ``FILE.work`` and each *commit* (after each study, and every few seconds
of a grid) closes it, copies it to ``FILE.commit``, fsyncs that and renames it over ``FILE``
(``os.replace`` is atomic), so ``FILE`` is always a complete HDF5 file: the previous commit or the
new one. A lock file ``FILE.lock`` (pid and host, a POSIX record lock that dies with its process)
keeps a second run out. The file stores its scene's identity (``scene_hash``, ``scene``) and each
study the identity of its options (``options_hash``, ``options``), so that a different scene is
refused before anything is written.
"""

from __future__ import annotations

import contextlib
import dataclasses
import datetime
import errno
import hashlib
import json
import logging
import os
import shutil
import signal
import socket
import threading
import time
from importlib import metadata
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

from ._errors import StudiesError

logger = logging.getLogger(__name__)

#: The result format this flexvib writes: the file attribute and each study group's attribute
#: ``format_version``. Format 1 (files without the attribute, flexvib before it was recorded): a
#: group's ``kind`` is the name of its result class. Format 2: ``kind`` is the registered name of the
#: study kind (``studies.register_kind``), a stable string, so that moving or renaming a result class
#: breaks no file. A file or group of a higher format is refused (:func:`check_format`).
FORMAT_VERSION = 2

#: Result classes by the name a file stores them under (the kind's name and its aliases).
_RESULTS: dict[str, type] = {}
_NAMES: dict[type, str] = {}


class ResultFileError(StudiesError):
    """A result file that cannot be used as asked (a folder, an unwritable path, not a flexvib file,
    another scene, written by another live run, a newer result format): exit code 2, the file
    untouched."""


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
        _stamp(handle)
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
        owner = owner_of(group)
        with owner.writing(self.nbytes()) if owner is not None else contextlib.nullcontext():
            self._write(group)
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
                _write_array(group, field.name, value, self._unit(field.name))
            elif isinstance(value, Mapping) and value and all(isinstance(v, np.ndarray)
                                                              for v in value.values()):
                sub = group.require_group(field.name)
                for key, array in value.items():
                    _write_array(sub, key, array, self._unit(field.name, key))
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
        # no HDF5 lock: a run replaces the file atomically and never holds it open
        handle = h5py.File(path, "r", locking=False)
    except OSError as error:
        raise StudiesError(f"{str(path)!r} is not an HDF5 result file: {error}") from None
    with handle:
        check_format(handle)
        return {name: read_group(group) for name, group in handle.items()}


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
            out[key] = json.loads(value) if isinstance(value, str) else _plain(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


# ---------------------------------------------------------------------------------------------------
# identities: what makes two runs the same scene, and the same study
# ---------------------------------------------------------------------------------------------------
def canonical(value: Any) -> str:
    """Canonical JSON of ``value``: sorted keys, no spaces, tuples and arrays as lists."""
    return json.dumps(_plain(value), sort_keys=True, separators=(",", ":"))


def digest(value: Any) -> str:
    """sha256 (hex) of the canonical JSON of ``value``."""
    return hashlib.sha256(canonical(value).encode()).hexdigest()


#: Top-level scene keys that change no number: the scene's name and description, and the studies
#: (each study's options are identified on their own, the observables by the plan).
NOT_NUMBERS = ("name", "description", "studies")


def scene_numbers(text: str) -> dict[str, Any]:
    """What of a scene's text changes numbers: the TOML tables without :data:`NOT_NUMBERS` (comments
    and layout are gone once parsed); ``{"text": text}`` for a text that is not TOML (the equation of
    a ``PeriodicProblem``)."""
    import tomllib

    try:
        tables = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return {"text": text}
    return {key: value for key, value in tables.items() if key not in NOT_NUMBERS}


def differing_paths(old: Any, new: Any, *, limit: int = 5) -> list[str]:
    """Dotted key paths where two JSON-like values differ (at most ``limit``; "..." ends a longer list).
    A key present in one only counts; lists compare as a whole."""
    found: list[str] = []

    def walk(a: Any, b: Any, path: str) -> None:
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            for key in sorted(set(a) | set(b)):
                walk(a.get(key, _ABSENT), b.get(key, _ABSENT), f"{path}.{key}" if path else str(key))
        elif a != b:
            found.append(path or "(the whole value)")

    walk(_plain(old), _plain(new), "")
    return found[:limit] + (["..."] if len(found) > limit else [])


_ABSENT = object()


# ---------------------------------------------------------------------------------------------------
# interrupts (Ctrl-C, SIGTERM) wait for the end of a write, so a commit never sees half a write
# ---------------------------------------------------------------------------------------------------
_DEFERRAL = threading.local()


def _deferral() -> Any:
    if not hasattr(_DEFERRAL, "depth"):
        _DEFERRAL.depth, _DEFERRAL.pending = 0, False
    return _DEFERRAL


def interrupt_handler(signum: int, frame: Any) -> None:
    """Signal handler for SIGINT and SIGTERM: ``KeyboardInterrupt`` now, or at the end of the write
    in progress (see :func:`deferred_interrupts`). The request stays pending until a write's end
    raises it, in case the first ``KeyboardInterrupt`` landed where Python swallows exceptions (a
    fork hook, a finaliser)."""
    state = _deferral()
    state.pending = True
    if not state.depth:
        raise KeyboardInterrupt(signal.Signals(signum).name)


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """A block that SIGINT/SIGTERM (through :func:`interrupt_handler`) do not cut in two: an interrupt
    arriving inside, or before it and lost, is raised when the block ends."""
    state = _deferral()
    state.depth += 1
    try:
        yield
    finally:
        state.depth -= 1
        if not state.depth and state.pending:
            import sys

            if sys.exc_info()[0] is None:  # an error already on its way keeps precedence
                raise KeyboardInterrupt("deferred")


@contextlib.contextmanager
def interrupts_handled() -> Iterator[None]:
    """Install :func:`interrupt_handler` for SIGINT and SIGTERM (main thread only) for the block."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    import sys

    previous = {sig: signal.signal(sig, interrupt_handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    hook = sys.unraisablehook
    sys.unraisablehook = _quiet_about_interrupts(hook)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        sys.unraisablehook = hook
        _deferral().pending = False  # the interrupt has been delivered: a new run starts clean


def _quiet_about_interrupts(hook: Any) -> Any:
    """``sys.unraisablehook`` that says nothing of a ``KeyboardInterrupt`` Python swallowed (raised
    in a finaliser or fork hook): it stays pending and is raised at the end of the next write."""
    def quiet(unraisable: Any) -> None:
        if not issubclass(unraisable.exc_type, KeyboardInterrupt):
            hook(unraisable)

    return quiet


# ---------------------------------------------------------------------------------------------------
# the crash-safe result file of a run
# ---------------------------------------------------------------------------------------------------
#: Free space kept beyond what a write or commit needs (HDF5 metadata, other writers on the disk).
SPACE_RESERVE = 1 << 20
#: A grid commits at most this often (s), and spends at most about 5 % of its time committing.
COMMIT_INTERVAL = 2.0
_COMMIT_SHARE = 0.05

_OPEN_FILES: dict[str, "ResultFile"] = {}


def owner_of(item: Any) -> "ResultFile | None":
    """The :class:`ResultFile` whose working copy ``item`` (an h5py object) belongs to, if any."""
    try:
        return _OPEN_FILES.get(os.path.realpath(item.file.filename))
    except (AttributeError, ValueError, RuntimeError):  # closed or not an h5py object
        return None


def _describe_os_error(error: OSError) -> str:
    return error.strerror or str(error)


class ResultFile:
    """The result file ``path`` of one run, written so that any kill leaves it readable.

    ``handle`` is the open h5py File of the working copy ``PATH.work``; :meth:`commit` (or
    :meth:`maybe_commit`, time-batched) makes its state the content of ``path`` atomically;
    :meth:`writing` wraps a write (interrupts wait for its end, free space checked first). Use as a
    context manager: on leaving, the work is committed (also after Ctrl-C or SIGTERM), the working
    copy removed and the lock released; a write that failed half-way (an ``OSError``, a full disk)
    is not committed. ``scene``: the identity of the scene (JSON-like dict); an existing file of
    another scene is refused, naming the differing keys, unless ``overwrite`` (start afresh).
    """

    def __init__(self, path: str | Path, *, scene: Mapping[str, Any] | None = None,
                 overwrite: bool = False, commit_interval: float = COMMIT_INTERVAL) -> None:
        self.path = Path(path)
        self.work = self.path.with_name(self.path.name + ".work")
        self.staging = self.path.with_name(self.path.name + ".commit")
        self.lock_path = self.path.with_name(self.path.name + ".lock")
        self.scene = None if scene is None else json.loads(canonical(scene))
        self.overwrite = overwrite
        self.commit_interval = commit_interval
        self._handle: Any = None
        self._lock_fd: int | None = None
        self._last_commit = time.monotonic()
        self._interval = commit_interval
        self._broken = False
        self._dirty = False  # written since the last commit (a run that wrote nothing commits nothing)
        self._signals = contextlib.ExitStack()
        #: attributes a study group gets when it is created (``studies._plan``: what was asked of it)
        self.study_attrs: dict[str, dict[str, Any]] = {}

    # -- opening -------------------------------------------------------------------------------
    def __enter__(self) -> "ResultFile":
        self._signals.enter_context(interrupts_handled())
        try:
            with deferred_interrupts():
                self._open()
        except BaseException:
            self._release()
            self._signals.close()
            raise
        return self

    def _open(self) -> None:
        import h5py

        self._check_path()
        self._lock()
        existed = self.path.exists()
        if existed:
            self._check_existing()
        self._check_space(2 * (self.path.stat().st_size if existed else 0), at_start=True)
        for stale in (self.work, self.staging):
            stale.unlink(missing_ok=True)  # left by a killed run: scratch, the lock is ours
        try:
            if existed and not self.overwrite:
                shutil.copyfile(self.path, self.work)
            # PATH.lock guards the run; HDF5's own lock (flock) would be inherited by forked pool
            # workers and block the reopening after each commit
            self._handle = h5py.File(self.work, "a", locking=False)
        except OSError as error:
            raise ResultFileError(f"result file {str(self.path)!r}: cannot write its working copy "
                                  f"{str(self.work)!r} ({_describe_os_error(error)})") from None
        _OPEN_FILES[os.path.realpath(self.work)] = self
        if "flexvib_version" not in self._handle.attrs:
            _stamp(self._handle)
        if self.scene is not None:
            self._handle.attrs["scene_hash"] = digest(self.scene)
            self._handle.attrs["scene"] = canonical(self.scene)

    def refusal(self, cause: str, fix: str = "") -> ResultFileError:
        """The error refusing this file: ``result file 'PATH': cause; fix``."""
        return ResultFileError(f"result file {str(self.path)!r}: {cause}" + (f"; {fix}" if fix else ""))

    def _check_path(self) -> None:
        if self.path.is_dir():
            raise self.refusal("is a folder",
                               f"expected the path of a file, e.g. {str(self.path / 'run.h5')!r}")
        ancestor = self.path.parent
        while not ancestor.exists() and ancestor != ancestor.parent:
            ancestor = ancestor.parent
        if not ancestor.is_dir():
            raise self.refusal(f"{str(ancestor)!r} is a file, not a folder", "choose another --out")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)  # as a user expects of --out a/b.h5
        except OSError as error:
            raise self.refusal(f"cannot create its folder ({_describe_os_error(error)})") from None
        if self.path.exists() and not self.path.is_file():
            raise self.refusal("is not a regular file", "choose another --out")
        if self.path.exists() and not os.access(self.path, os.R_OK | os.W_OK):
            raise self.refusal("is read-only (no permission to replace it)", "choose another --out")
        if not os.access(self.path.parent, os.W_OK | os.X_OK):
            raise self.refusal(f"no permission to write in the folder {str(self.path.parent)!r}",
                             "choose another --out")

    def _lock(self) -> None:
        """Take ``PATH.lock`` (a POSIX record lock: released by the kernel when its process dies,
        and not inherited by worker processes); report a lock a dead run left behind."""
        import fcntl

        while True:
            try:
                fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as error:
                raise self.refusal(f"cannot create the lock file {str(self.lock_path)!r} "
                                 f"({_describe_os_error(error)})", "choose another --out") from None
            try:
                fcntl.lockf(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:
                holder = os.pread(fd, 200, 0).decode(errors="replace").strip() or "unknown process"
                os.close(fd)
                raise self.refusal(f"is being written by another flexvib run ({holder})",
                                 "wait for it to end, or write to another file with --out") from None
            try:
                same = os.stat(self.lock_path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)  # the file was removed by a run that just ended: lock the new one
        left = os.pread(fd, 200, 0).decode(errors="replace").strip()
        if left:
            logger.warning("%s: released the lock left by a run that ended without finishing (%s)",
                           self.path, left)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"pid {os.getpid()} on {socket.gethostname()}".encode(), 0)
        self._lock_fd = fd

    def _check_existing(self) -> None:
        """Refuse a file that is not flexvib's or holds another scene (before writing anything)."""
        import h5py

        if not h5py.is_hdf5(self.path):
            raise self.refusal("exists and is not an HDF5 file", "remove it or choose another --out")
        try:
            with h5py.File(self.path, "r", locking=False) as handle:
                attrs, names = dict(handle.attrs), list(handle)
        except OSError as error:
            raise self.refusal(f"cannot be read ({_describe_os_error(error)})",
                             "remove it or choose another --out") from None
        if "flexvib_version" not in attrs:
            raise self.refusal("is an HDF5 file not written by flexvib; refusing to change it",
                             "choose another --out")
        if self.overwrite:
            return
        written = int(attrs.get("format_version", 1))
        if written != FORMAT_VERSION and names:
            raise self.refusal(
                f"was written by flexvib {attrs.get('flexvib_version', '?')} in result format {written}; "
                f"this flexvib writes format {FORMAT_VERSION} and "
                + ("cannot read it" if written > FORMAT_VERSION else "does not add to an older file"),
                "run with --overwrite to start it afresh, or choose another --out"
                + (" (studies.load still reads it)" if written < FORMAT_VERSION else ""))
        if self.scene is None:
            return
        if "scene_hash" not in attrs:
            if names:
                raise self.refusal(
                    f"was written by flexvib {attrs.get('flexvib_version', '?')}, which did not record "
                    f"its scene's identity, so resuming could mix two scenes",
                    "run with --overwrite to start it afresh, or choose another --out")
            return
        if attrs["scene_hash"] != digest(self.scene):
            try:
                paths = differing_paths(json.loads(attrs.get("scene", "{}")), self.scene)
            except json.JSONDecodeError:
                paths = ["(unknown)"]
            raise self.refusal(f"holds the results of another scene (differing: {', '.join(paths)})",
                             "write to another file with --out, or run with --overwrite to start it afresh")

    # -- writing -------------------------------------------------------------------------------
    @property
    def handle(self) -> Any:
        """The open h5py File of the working copy (a new object after each commit)."""
        return self._handle

    def _free(self) -> int:
        stats = os.statvfs(self.path.parent)
        return stats.f_bavail * stats.f_frsize

    def _check_space(self, needed: int, *, at_start: bool = False) -> None:
        free = self._free()
        if free >= needed + SPACE_RESERVE:
            return
        cause = (f"not enough free space on its disk: {free / 2**20:.1f} MiB free, about "
                 f"{(needed + SPACE_RESERVE) / 2**20:.1f} MiB needed")
        if at_start:
            raise self.refusal(cause, "free some space or choose another --out")
        raise StorageError(f"result file {str(self.path)!r}: {cause}; it holds what was saved before "
                           f"(free some space and run the same command to resume)")

    def _work_size(self) -> int:
        try:
            return self.work.stat().st_size
        except FileNotFoundError:
            return 0

    @contextlib.contextmanager
    def writing(self, extra: int = 0) -> Iterator[None]:
        """A write of about ``extra`` bytes into the working copy: free space checked first (for the
        write and the next commit's copy), interrupts wait for its end, a failure marks the copy as
        not to be committed."""
        self._check_space(self._work_size() + 2 * extra)
        with deferred_interrupts():
            self._dirty = True
            try:
                yield
            except BaseException:
                self._broken = True
                raise

    def commit(self) -> None:
        """Make the working copy's state the content of ``path``, atomically (nothing to do when
        nothing was written since the last commit)."""
        import h5py

        if not self._dirty:
            return
        if self._broken:
            raise StorageError(f"result file {str(self.path)!r}: a write failed half-way; it holds "
                               f"what was saved before")
        start = time.monotonic()
        with deferred_interrupts():
            self._check_space(self._work_size())
            self._handle.close()
            try:
                shutil.copyfile(self.work, self.staging)
                with open(self.staging, "rb") as staged:
                    os.fsync(staged.fileno())
                os.replace(self.staging, self.path)
                _fsync_folder(self.path.parent)
            except OSError as error:
                self.staging.unlink(missing_ok=True)
                cause = ("the disk is full" if error.errno in (errno.ENOSPC, errno.EDQUOT)
                         else _describe_os_error(error))
                raise StorageError(f"result file {str(self.path)!r}: cannot save ({cause}); it holds "
                                   f"what was saved before") from None
            finally:
                self._handle = h5py.File(self.work, "a", locking=False)
        self._dirty = False
        spent = time.monotonic() - start
        self._last_commit = time.monotonic()
        self._interval = max(self.commit_interval, spent / _COMMIT_SHARE)

    def maybe_commit(self) -> None:
        """Commit when the last commit is older than the commit interval (grids batch their points)."""
        if time.monotonic() - self._last_commit >= self._interval:
            self.commit()

    # -- closing -------------------------------------------------------------------------------
    def __exit__(self, kind: type | None, error: BaseException | None, traceback: Any) -> None:
        try:
            with deferred_interrupts():
                if self._handle is not None and not self._broken and (
                        error is None or not isinstance(error, (OSError, StorageError))):
                    try:
                        self.commit()
                    except StorageError as failure:
                        if error is None:
                            raise
                        logger.error("%s", failure)
        finally:
            self._release()
            self._signals.close()

    def _release(self) -> None:
        if self._handle is not None:
            _OPEN_FILES.pop(os.path.realpath(self.work), None)
            try:
                self._handle.close()
            except Exception:  # a handle whose write failed: the copy is scratch anyway
                pass
            self._handle = None
        if self._lock_fd is not None:  # the scratch files are ours only under the lock
            for scratch in (self.work, self.staging):
                scratch.unlink(missing_ok=True)
            self.lock_path.unlink(missing_ok=True)  # while still holding it (see _lock)
            os.close(self._lock_fd)
            self._lock_fd = None


def _fsync_folder(folder: Path) -> None:
    """Make a rename in ``folder`` durable (a no-op where folders cannot be opened)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _stamp(handle: Any) -> None:
    """Versions and creation time of a new result file."""
    stamp = versions()
    handle.attrs["flexvib_version"] = stamp["flexvib"]
    handle.attrs["format_version"] = FORMAT_VERSION
    handle.attrs["versions"] = json.dumps(stamp, sort_keys=True)
    handle.attrs["created"] = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
