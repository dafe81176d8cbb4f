"""The status of a study point in words: the verdicts of ``periodic`` (stability with its error bar,
error trust, near resonance, unresolved modes) and ``linearize`` (the linear range) combined with
``worst_status``, plus ``failed``.

The vocabulary, most severe first (``periodic.STATUSES``): ``failed``, ``unstable``, ``outside_linear_range``,
``inaccurate``, ``near_resonance``, ``marginal``, ``unresolved_stiff_mode``, ``ok``. A point's
``status`` is the worst of its verdicts and its ``message`` joins theirs (most severe first);
``is_stable`` is the stability verdict's (``periodic.stability_verdict``): False where the point is
``unstable`` and wherever the spectral radius has converged above 1, whatever status word wins
(an ``inaccurate`` multiplier converging at another rate than the scheme's, a point also outside the
linear range).
"""

from __future__ import annotations

from typing import Any, Iterable

import numpy as np

import periodic

_SEVERITY = {status: rank for rank, status in enumerate(periodic.STATUSES)}


# ---------------------------------------------------------------------------------------------------
def combine(parts: Iterable[tuple[str, str]]) -> tuple[str, str]:
    """``(status, message)`` of a point from its verdicts' ``(status, message)``: the worst status, and
    the messages of the verdicts that are not ``ok``, most severe first."""
    parts = [(status, message) for status, message in parts if status and status != "ok"]
    parts.sort(key=lambda part: severity(part[0]))
    status = periodic.worst_status(*(status for status, _ in parts))
    return status, "; ".join(dict.fromkeys(message for _, message in parts if message))


def severity(status: str) -> int:
    """Rank of a status, 0 the most severe (unknown statuses, e.g. "missing", rank last)."""
    return _SEVERITY.get(status, len(_SEVERITY))


#: The linear-range measures reported per elastic link (names of ``linearize``'s per-link records).
RANGE_MEASURES = ("peak_deflection_over_length", "peak_deflection_over_height", "peak_slope",
                  "peak_compression_over_euler", "peak_stress_over_yield")


#: The saturation measures reported per torque drive with a limit or a motor, as fractions of the
#: limit (``linearize.DriveRange``: peak demanded torque / ``torque_limit``, peak motor command /
#: ``G stall_torque``; 0 for the one a drive lacks, none for a drive with neither): above 1 the
#: drive saturates.
DRIVE_MEASURES = {"peak_torque_over_limit": ("peak_demanded_torque", "torque_limit"),
                  "peak_command_over_limit": ("peak_command", "command_limit")}


def linear_range(linear: Any, z: np.ndarray) -> tuple[dict[str, float], str, str]:
    """The linear-range measures of the solution ``z`` (N+1, m) of ``linear`` (a study ``Linear``):
    ``({"<link>.<measure>": value, "drive.<joint>.<measure>": value}, status, message)``, all
    dimensionless (``RANGE_MEASURES``, ``DRIVE_MEASURES``); empty and ``ok`` for a problem without
    them."""
    measure = getattr(linear, "linear_range", None)
    if measure is None:
        return {}, "ok", ""
    found = measure(z)
    values = {f"{link.link}.{name}": float(getattr(link, name)) for link in found.links
              for name in RANGE_MEASURES}
    for drive in getattr(found, "drives", ()):
        for name, (peak, limit) in DRIVE_MEASURES.items():
            values[f"drive.{drive.joint}.{name}"] = float(getattr(drive, peak) / getattr(drive, limit))
    return values, found.status, found.message
