"""Checksums of a result file (result format 3), and what a check finds.

What is checksummed, and when:

* the file's own attributes (versions, scene identity, compile time): the root attribute ``digest``,
  written at every commit of a run (``studies._resultfile.ResultFile``) and when a file is stamped;
* a study group: its attribute ``digest`` covers every attribute of the group and the content of
  every dataset in it (names, types, shapes, values), written when the study is written
  (``Result.to_hdf5``, a run's request attributes after it) and when a grid study's group is made;
* a grid study's points: the point datasets (``done``, ``status``, ``message``,
  ``point_run_time`` and the outputs the group lists in its attribute ``point_outputs``) are left
  out of the group's digest (but for their shapes and types once the study is complete), and each
  point has its own digest in the dataset ``point_digest`` (grid shape, uint64; 0 for a point not
  written), written with the point, so a point-by-point run never re-hashes a whole study and a
  damaged point can be told from the intact ones.

A check (:func:`check_group`, :func:`check_root`) reads everything it covers and recomputes the
digests: a study is ``intact``, ``damaged`` (with the damaged points of a grid, or the whole study),
or ``not verifiable`` (written before format 3, without checksums). The digests are BLAKE2b over a
canonical byte form of each value (independent of the numpy version's ``repr``).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any, Iterable, Mapping

import numpy as np

__all__ = ["BOOKKEEPING_ATTRS", "BOOKKEEPING_DATASETS", "DIGEST", "POINT_DIGEST", "POINT_MARK", "POINT_OUTPUTS",
           "Check", "check_group", "check_root", "dataset_layout", "forget_points", "open_study", "point_digest",
           "points_resumable", "seal", "seal_points", "seal_root"]

#: The attribute of a group (and of the file) holding its digest.
DIGEST = "digest"
#: The dataset of a grid study's per-point digests, and the attribute naming its point outputs.
POINT_DIGEST = "point_digest"
POINT_OUTPUTS = "point_outputs"
#: A study group's integrity bookkeeping, not results: the attributes and datasets that ``flexvib
#: info`` and anything listing a study's fields from its group leave out (tables and ``flexvib
#: export`` are made from the result's fields, which never include them).
BOOKKEEPING_ATTRS = (DIGEST, POINT_OUTPUTS)
BOOKKEEPING_DATASETS = (POINT_DIGEST,)
#: The datasets every grid study writes point by point (``studies._grid.GridStore``).
POINT_FIXED = ("done", "status", "message", "point_run_time", POINT_DIGEST)
#: The attribute marking an output dataset made point by point (``studies._grid.GridStore``); a
#: finished study's result may write a field of the same name over it in another layout.
POINT_MARK = "grid_points"
#: The first result format whose files carry checksums.
CHECKSUMMED_FORMAT = 3

INTACT, DAMAGED, NOT_VERIFIABLE = "intact", "damaged", "not verifiable"


@dataclass(frozen=True)
class Check:
    """What a check of a study group (or of the file's attributes) found: ``state`` one of "intact",
    "damaged", "not verifiable"; ``cause`` in words; ``points`` (grid shape, bool) the damaged points of
    a grid study whose damage is confined to points (None: the whole study, or nothing)."""

    state: str
    cause: str = ""
    points: np.ndarray | None = None

    @property
    def damaged(self) -> bool:
        return self.state == DAMAGED

    def describe(self) -> str:
        """"damaged (3 of 40 points: ...)" or "damaged (cause)"; "" when intact."""
        if self.state == INTACT:
            return ""
        if self.points is not None:
            return f"{self.state} ({int(self.points.sum())} of {self.points.size} points: {self.cause})"
        return f"{self.state} ({self.cause})" if self.cause else self.state


# ---------------------------------------------------------------------------------------------------
# canonical bytes
# ---------------------------------------------------------------------------------------------------
def _value_bytes(value: Any) -> bytes:
    """A canonical byte form of an attribute value or array (type, shape and content)."""
    if isinstance(value, bytes):
        return b"b" + value
    if isinstance(value, str):
        return b"s" + value.encode("utf-8", "surrogatepass")
    array = np.asarray(value)
    if array.dtype.kind in "OUS":
        texts = [item.decode("utf-8", "replace") if isinstance(item, bytes) else str(item)
                 for item in array.ravel()]
        return b"t" + repr(array.shape).encode() + "\x1f".join(texts).encode("utf-8", "surrogatepass")
    array = np.ascontiguousarray(array)
    return array.dtype.str.encode() + repr(array.shape).encode() + array.tobytes()


def _hasher() -> Any:
    return hashlib.blake2b(digest_size=16)


def _attrs_into(hasher: Any, attrs: Any) -> None:
    for key in sorted(k for k in attrs.keys() if k != DIGEST):
        hasher.update(key.encode() + b"\0")
        hasher.update(_value_bytes(attrs[key]) + b"\0")


def _dataset_value(dataset: Any) -> Any:
    if dataset.dtype.kind == "O":
        return dataset.asstr()[()]
    return dataset[()]


def point_outputs(group: Any) -> tuple[str, ...] | None:
    """The output names a grid study's group lists (None: not a grid study of format 3)."""
    raw = group.attrs.get(POINT_OUTPUTS)
    if raw is None:
        return None
    return tuple(json.loads(raw))


def _is_point_dataset(name: str, outputs: Iterable[str]) -> bool:
    outputs = tuple(outputs)
    return name in POINT_FIXED or name in outputs or name.split("/")[0] in outputs


def _datasets(group: Any) -> list[str]:
    names: list[str] = []
    group.visititems(lambda name, item: names.append(name) if hasattr(item, "shape") else None)
    return sorted(names)


def group_digest(group: Any) -> str:
    """The digest of a study group: its attributes and every dataset but a grid study's point
    datasets (those have their own digests)."""
    outputs = point_outputs(group)
    complete = bool(group.attrs.get("complete", False))
    hasher = _hasher()
    _attrs_into(hasher, group.attrs)
    for name in _datasets(group):
        if outputs is not None and _is_point_dataset(name, outputs):
            if complete:   # a finished grid's point datasets are all made: their shapes and types too
                dataset = group[name]
                hasher.update(f"{name}:{tuple(dataset.shape)}:{dataset.dtype.str}".encode() + b"\0")
            continue
        dataset = group[name]
        hasher.update(name.encode() + b"\0")
        _attrs_into(hasher, dataset.attrs)
        hasher.update(_value_bytes(_dataset_value(dataset)) + b"\0")
    return hasher.hexdigest()


def seal(group: Any) -> None:
    """Write the study group's digest (after its attributes and datasets are written)."""
    group.attrs[DIGEST] = group_digest(group)


def seal_root(handle: Any) -> None:
    """Write the digest of the file's own attributes."""
    hasher = _hasher()
    _attrs_into(hasher, handle.attrs)
    handle.attrs[DIGEST] = hasher.hexdigest()


# ---------------------------------------------------------------------------------------------------
# per-point digests
# ---------------------------------------------------------------------------------------------------
def point_digest(status: str, message: str, run_time: float, values: Mapping[str, np.ndarray],
                 layout: Mapping[str, tuple[tuple[int, ...], str]]) -> int:
    """The digest (a nonzero uint64) of one grid point as stored: its status, message, run time and
    its output values (``values``: name -> the value cast to its dataset's type), with the shape and
    type of each dataset they are in (``layout``: name -> (shape, dtype.str), the point datasets
    ``status``, ``message``, ``point_run_time`` and the outputs), so that a dataset whose header is
    damaged fails every point. An output entirely NaN (not computed at this point: the datasets are
    NaN-filled) is left out, so that the digest reads the same from the outcome written and from the
    datasets."""
    hasher = hashlib.blake2b(digest_size=8)
    hasher.update(_value_bytes(str(status)) + b"\0" + _value_bytes(str(message)) + b"\0")
    hasher.update(np.float64(run_time).tobytes())
    names = ["status", "message", "point_run_time"]
    for name in sorted(values):
        value = np.asarray(values[name])
        if value.dtype.kind in "fc" and np.all(np.isnan(value)):
            continue
        names.append(name)
        hasher.update(name.encode() + b"\0" + _value_bytes(value) + b"\0")
    for name in names:
        shape, dtype = layout[name]
        hasher.update(f"{name}:{tuple(int(n) for n in shape)}:{dtype}".encode() + b"\0")
    return int.from_bytes(hasher.digest(), "little") or 1


def dataset_layout(datasets: Mapping[str, Any]) -> dict[str, tuple[tuple[int, ...], str]]:
    """``{name: (shape, dtype.str)}`` of h5py datasets (what :func:`point_digest` covers of them)."""
    return {name: (tuple(dataset.shape), dataset.dtype.str) for name, dataset in datasets.items()}


def _text(value: Any) -> str:
    return value.decode("utf-8", "replace") if isinstance(value, bytes) else str(value)


def _read_points(dataset: Any, shape: tuple[int, ...], broken: np.ndarray) -> np.ndarray | None:
    """The dataset's values (strings decoded), or None when it cannot be read as a whole: then each
    point is read alone and those that fail are marked in ``broken``."""
    try:
        return _dataset_value(dataset)
    except Exception:  # any read failure is damage, whatever h5py raises
        pass
    values = np.empty(dataset.shape, dtype=object)
    for index in np.ndindex(*shape):
        try:
            values[index] = dataset.asstr()[index] if dataset.dtype.kind == "O" else dataset[index]
        except Exception:
            broken[index] = True
            values[index] = None
    return values


def _stored_digests(group: Any, outputs: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(done, digests, broken)`` of a grid study as stored: its ``done`` mask, each written point's
    digest recomputed from the datasets (0 elsewhere), and the points that could not be read."""
    done = np.asarray(group["done"][()], dtype=bool)
    shape = done.shape
    broken = np.zeros(shape, dtype=bool)
    stored = np.asarray(group[POINT_DIGEST][()], dtype=np.uint64)
    status = _read_points(group["status"], shape, broken)
    message = _read_points(group["message"], shape, broken)
    run_time = _read_points(group["point_run_time"], shape, broken)
    names = [name for name in _datasets(group) if name not in POINT_FIXED and _is_point_dataset(name, outputs)]
    values = {name: _read_points(group[name], shape, broken) for name in names}
    layout = dataset_layout({name: group[name] for name in ["status", "message", "point_run_time", *names]})
    digests = np.zeros(shape, dtype=np.uint64)
    for index in zip(*np.nonzero((done | (stored != 0)) & ~broken)):
        try:
            digests[index] = point_digest(_text(status[index]), _text(message[index]), float(run_time[index]),
                                          {name: np.asarray(value[index]) for name, value in values.items()},
                                          layout)
        except Exception:  # a value that cannot be read back is damage
            broken[index] = True
    return done, digests, broken


def _check_points(group: Any, outputs: tuple[str, ...]) -> tuple[np.ndarray | None, str]:
    """The damaged points of a grid study (bool, grid shape; None: the whole study) and what was
    found."""
    if POINT_DIGEST not in group:
        return None, f"no {POINT_DIGEST} dataset"
    stored = np.asarray(group[POINT_DIGEST][()], dtype=np.uint64)
    done, digests, broken = _stored_digests(group, outputs)
    written = done | (stored != 0)
    damaged = written & (broken | ~done | (digests != stored))
    if damaged.any() and damaged.sum() == written.sum():
        # every point: the layout itself (a dataset's header) is damaged, not points one by one
        return None, "every point fails its checksum"
    return damaged, "their data do not match their checksums"


def seal_points(group: Any) -> None:
    """Write every point's digest from the grid study's datasets as they now are: when the finished
    study is written over its points (``Result.to_hdf5``; its fields may store an output in another
    type, a flag as bool), from the outcomes just computed or verified."""
    outputs = point_outputs(group)
    if outputs is None or POINT_DIGEST not in group:
        return
    done, digests, _ = _stored_digests(group, outputs)
    group[POINT_DIGEST][...] = np.where(done, digests, np.uint64(0))


def check_group(group: Any, format_version: int) -> Check:
    """Check a study group: every attribute and dataset it covers is read and its digest recomputed
    (see the module docstring); a group of a format before 3 is "not verifiable"."""
    try:
        if DIGEST not in group.attrs:
            if format_version < CHECKSUMMED_FORMAT:
                return Check(NOT_VERIFIABLE, f"result format {format_version}: written without checksums")
            return Check(DAMAGED, "its checksum is missing")
        if _text(group.attrs[DIGEST]) != group_digest(group):
            return Check(DAMAGED, "its attributes or data do not match its checksum")
        _read_every_attribute(group)
        outputs = point_outputs(group)
        if outputs is None:
            return Check(INTACT)
        points, cause = _check_points(group, outputs)
    except Exception as error:  # whatever h5py raises on damaged bytes is the finding
        return Check(DAMAGED, f"unreadable: {type(error).__name__}: {str(error)[:200]}")
    if points is None:
        return Check(DAMAGED, cause)
    if points.any():
        return Check(DAMAGED, cause, points)
    return Check(INTACT)


def _read_every_attribute(group: Any) -> None:
    """Read every attribute of every object below ``group`` (raising whatever h5py raises on damaged
    bytes): the digest leaves out the attributes of a grid's point datasets, whose object headers a
    resume reads (``points_resumable``), so damage there must be found by reading them."""
    def read(_name: str, item: Any) -> None:
        for key in item.attrs:
            item.attrs[key]

    group.visititems(read)


def check_root(handle: Any, format_version: int) -> Check:
    """Check the file's own attributes against their digest."""
    try:
        if DIGEST not in handle.attrs:
            if format_version < CHECKSUMMED_FORMAT:
                return Check(NOT_VERIFIABLE, f"result format {format_version}: written without checksums")
            return Check(DAMAGED, "the file's attributes have no checksum")
        hasher = _hasher()
        _attrs_into(hasher, handle.attrs)
        if _text(handle.attrs[DIGEST]) != hasher.hexdigest():
            return Check(DAMAGED, "the file's own attributes do not match their checksum")
    except Exception as error:
        return Check(DAMAGED, f"the file's attributes are unreadable: {type(error).__name__}: {error}")
    return Check(INTACT)


def points_resumable(group: Any) -> bool:
    """Whether a grid study's points can be recomputed one by one into its datasets: every output
    dataset is still the one made point by point (a finished result may have written one of its
    fields over an output of the same name, e.g. a Campbell diagram's crank angle)."""
    outputs = point_outputs(group) or ()
    return all(group[name].attrs.get(POINT_MARK, False) for name in _datasets(group)
               if name not in POINT_FIXED and _is_point_dataset(name, outputs))


def open_study(handle: Any, name: str) -> tuple[Any, Check | None]:
    """``(group, None)`` for the study ``name`` of an open file, ``(None, None)`` when there is none,
    ``(None, damaged Check)`` when its link is there but the object does not open (h5py's ``get``
    would call that absent)."""
    try:
        return handle[name], None
    except (KeyError, OSError, RuntimeError, ValueError) as error:
        try:
            present = name in handle
        except (KeyError, OSError, RuntimeError, ValueError):
            present = True
        if not present:
            return None, None
        return None, Check(DAMAGED, f"unreadable: {type(error).__name__}: {str(error)[:200]}")


def forget_points(group: Any, points: np.ndarray) -> None:
    """Mark the damaged ``points`` (bool, grid shape) of a grid study as not done, their data NaN and
    their texts empty, so that a resume recomputes them; the study is no longer complete, and its
    group is sealed again (what remains was verified)."""
    outputs = point_outputs(group) or ()
    outputs_here = [group[name] for name in _datasets(group)
                    if name not in POINT_FIXED and _is_point_dataset(name, outputs)]
    for index in map(tuple, np.argwhere(points)):   # h5py takes one point at a time (no fancy indices)
        group["done"][index] = False
        group[POINT_DIGEST][index] = 0
        group["status"][index] = ""
        group["message"][index] = ""
        group["point_run_time"][index] = np.nan
        for dataset in outputs_here:
            dataset[index] = complex(np.nan, np.nan) if dataset.dtype.kind == "c" else np.nan
    group.attrs["complete"] = False
    seal(group)
