"""What every study result offers, whatever its kind: :class:`StudyResult`.

Each study kind's result (``studies._kinds``) is a frozen dataclass deriving from :class:`StudyResult`
(through ``GridResult`` for the grid kinds) and answers the same questions the same way:

``status``
    str, the study's verdict, one of ``periodic.STATUSES`` (``ok``, ``unstable``, ``marginal``,
    ``near_resonance``, ``outside_linear_range``, ``inaccurate``, ``unresolved_stiff_mode``,
    ``failed``); a grid study's is the worst of its points' and of its reduction check's.
``message``
    str, the cause and the fix in words ("" when there is nothing to say).
``run_time``
    float, s: the wall time of the whole study (a grid's total).
``peak``, ``peak_to_peak``, ``peak_error``, ``peak_to_peak_error``
    {spec: value}: each reported observable's largest magnitude and peak-to-peak over the steady
    period (``studies._numerics.peak_summary``: the extremes refined through their neighbours) and
    their estimated errors, in the observable's unit (``units[spec]``). ``value`` is a float for a
    study of one point, and an array of the grid's shape for a study over a grid (a sweep's
    parameter values, an error-cost study's resolutions x step counts, an optimisation's speeds, a
    nonlinear branch's orbits); NaN where a point failed or was not reached. ``{}`` for a study that
    reports no observable response (a Campbell diagram, a stability chart).
``point_status``, ``point_message``, ``point_run_time``
    arrays of the grid's shape, each point's verdict and wall time (s), where a study has grid points
    with verdicts of their own.
``plot(*, axes=None)``
    the result's figure, a ``studies.Plot``.
``to_hdf5(group)``
    writes the result (``studies._store.Result``); ``studies.load`` reads it back with the same fields.
``to_dataframe(rows=None)``, ``to_xarray(rows=None)``
    the result as a pandas DataFrame (one row per grid point or time sample, columns named after the
    fields, units in ``attrs``) or an xarray Dataset (coordinates the swept parameters), generic over
    the fields (``studies._tables``; ``pip install 'flexvib[tables]'``). The rows are the fields named
    in ``_axes`` (default the time samples ``t``).

Derived fields are properties (never written), so a file written before a field existed still
loads; a field stored under another name (or under an older name in older files) is declared in
``_stored_as``, and what an older file lacks is filled on reading by ``_filled``.
"""

from __future__ import annotations

import dataclasses
from typing import Any, ClassVar, Mapping

import numpy as np

from ._numerics import peak_summary
from ._store import Result

#: The names of the observable summaries every result has (see the module's docstring).
PEAK_FIELDS = ("peak", "peak_error", "peak_to_peak", "peak_to_peak_error")


class StudyResult(Result):
    """Base of every study result: the fields a user reads are the same in every kind (see
    ``studies._result``); a subclass declares them as dataclass fields or properties."""

    #: Whether the result is a grid of points with their own verdicts (``point_status``, ...): the
    #: command reports those per point, not as the study's failure.
    is_grid: ClassVar[bool] = False
    #: field name -> the names it is stored under in a result file, the current one first and
    #: older ones after it (read from the first the file holds).
    _stored_as: ClassVar[Mapping[str, tuple[str, ...]]] = {}
    #: The fields that are the rows of its tables, in axis order -> the axis's name (``"@attr"``: read
    #: from the result, e.g. a sweep's ``"@parameter"``): a grid's swept values; by default the time
    #: samples (``studies._tables``).
    _axes: ClassVar[Mapping[str, str]] = {"t": "t"}
    #: The fields every result has, which a kind may give as properties: its tables include them.
    _shared_fields: ClassVar[tuple[str, ...]] = (*PEAK_FIELDS, "point_status", "point_message", "point_run_time",
                                                 "status", "message", "run_time")

    def to_dataframe(self, rows: str | None = None) -> Any:
        """A pandas DataFrame: one row per grid point (or time sample), one column per field (an
        observable's entry as ``peak_to_peak[<spec>]``, a grid's point verdicts as ``status``,
        ``message``, ``run_time``), ``attrs["units"]`` {column: unit}, the scalar fields (the study's
        ``status``, ``message``, ``run_time``, ...) in ``attrs``. ``rows``: a field to table against
        instead (e.g. ``"t_linear"`` of a nonlinear check). Needs pandas (``flexvib[tables]``)."""
        from ._tables import to_dataframe

        return to_dataframe(self, rows)

    def to_xarray(self, rows: str | None = None) -> Any:
        """An xarray Dataset of the same data: the grid's swept parameters (or ``t``) as dimensions
        and coordinates with their units, one variable per field. Needs xarray (``flexvib[tables]``)."""
        from ._tables import to_xarray

        return to_xarray(self, rows)

    def _write(self, group: Any) -> None:
        super()._write(_Stored(group, self._stored_as, reading=False))

    @classmethod
    def from_hdf5(cls, group: Any) -> "StudyResult":
        result = super().from_hdf5(_Stored(group, cls._stored_as, reading=True))
        changes = result._filled(group)
        return dataclasses.replace(result, **changes) if changes else result

    def _filled(self, group: Any) -> dict[str, Any]:
        """The fields a file written before they existed lacks, as replacements (``group`` the study's
        HDF5 group, to see what it holds); none by default."""
        return {}


class DerivedPeaks:
    """The observable summaries of a result that derives them from what it stores (nothing more is
    written, so older files have them too): ``_peaks()`` returns {name: {spec: value}} for each of
    :data:`PEAK_FIELDS`."""

    def _peaks(self) -> dict[str, dict[str, Any]]:
        raise NotImplementedError

    @property
    def peak(self) -> dict[str, Any]:
        return self._peaks()["peak"]

    @property
    def peak_error(self) -> dict[str, Any]:
        return self._peaks()["peak_error"]

    @property
    def peak_to_peak(self) -> dict[str, Any]:
        return self._peaks()["peak_to_peak"]

    @property
    def peak_to_peak_error(self) -> dict[str, Any]:
        return self._peaks()["peak_to_peak_error"]


class NoObservables(DerivedPeaks):
    """The observable summaries of a study that reports no observable response: empty."""

    def _peaks(self) -> dict[str, dict[str, Any]]:
        return {name: {} for name in PEAK_FIELDS}


def peaks_of(response: Mapping[str, np.ndarray], error: Mapping[str, float]) -> dict[str, dict[str, float]]:
    """``{name: {spec: float}}`` for each of :data:`PEAK_FIELDS`, of a periodic ``response`` {spec:
    (N+1,)} (t_N repeats t_0) whose samples are within ``error[spec]`` of the truth (NaN: unknown);
    NaN for a response that is not finite (a failed run)."""
    out: dict[str, dict[str, float]] = {name: {} for name in PEAK_FIELDS}
    for spec, samples in response.items():
        samples = np.asarray(samples, dtype=float)
        if samples.size < 3 or not np.isfinite(samples).all():
            for name in PEAK_FIELDS:
                out[name][spec] = float("nan")
            continue
        found = peak_summary(samples[:, None], np.array([float(error.get(spec, float("nan")))]))
        for name in PEAK_FIELDS:
            out[name][spec] = float(found[name][0])
    return out


def unknown_peaks(specs: Any, shape: tuple[int, ...]) -> dict[str, dict[str, np.ndarray]]:
    """NaN observable summaries {name: {spec: array of ``shape``}}: what a file written before a study
    recorded them reads as."""
    return {name: {spec: np.full(shape, np.nan) for spec in specs} for name in PEAK_FIELDS}


class _Stored:
    """An h5py group seen through a result's field names: field ``name`` is written under
    ``aliases[name][0]`` and read from the first of ``aliases[name]`` the group holds (datasets
    and attributes alike); other names pass through."""

    def __init__(self, group: Any, aliases: Mapping[str, tuple[str, ...]], *, reading: bool,
                 attrs: bool = False) -> None:
        self._group, self._aliases, self._reading, self._attrs = group, aliases, reading, attrs

    def _name(self, name: str) -> str:
        names = self._aliases.get(name)
        if not names:
            return name
        if self._reading:
            return next((stored for stored in names if stored in self._group), names[0])
        return names[0]

    @property
    def attrs(self) -> "_Stored":
        return _Stored(self._group.attrs, self._aliases, reading=self._reading, attrs=True)

    @property
    def file(self) -> Any:
        return self._group.file

    @property
    def name(self) -> str:
        return self._group.name

    def __contains__(self, name: str) -> bool:
        return self._name(name) in self._group

    def __getitem__(self, name: str) -> Any:
        return self._group[self._name(name)]

    def __setitem__(self, name: str, value: Any) -> None:
        self._group[self._name(name)] = value

    def __delitem__(self, name: str) -> None:
        del self._group[self._name(name)]

    def create_dataset(self, name: str, *args: Any, **kwargs: Any) -> Any:
        return self._group.create_dataset(self._name(name), *args, **kwargs)

    def require_group(self, name: str) -> Any:
        return self._group.require_group(self._name(name))
