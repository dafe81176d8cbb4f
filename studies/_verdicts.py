"""The status of a study point in words: the verdicts of ``periodic`` (stability with its error bar,
error trust, near resonance, unresolved modes) and ``linearize`` (the linear range) combined with
``worst_status``, plus ``failed``.

The vocabulary, most severe first (``STATUSES``): ``failed``, ``unstable``, ``outside_linear_range``,
``inaccurate``, ``near_resonance``, ``marginal``, ``unresolved_stiff_mode``, ``ok``. A point's
``status`` is the worst of its verdicts and its ``message`` joins theirs (most severe first);
``is_stable`` is False only where the point is ``unstable``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

import numpy as np

import periodic

# ---------------------------------------------------------------------------------------------------
# Stand-ins for the contract's periodic.STATUSES / worst_status / stability_verdict / error_verdict
# (branch verdict-periodic); removed when that lands.
# ---------------------------------------------------------------------------------------------------
STATUSES = ("failed", "unstable", "outside_linear_range", "inaccurate", "near_resonance", "marginal",
            "unresolved_stiff_mode", "ok")
_SEVERITY = {status: rank for rank, status in enumerate(STATUSES)}


def _worst_status(*statuses: str) -> str:
    """The most severe of ``statuses`` (``"ok"`` if none)."""
    return min(statuses, key=severity, default="ok")


@dataclass(frozen=True)
class _Stability:
    status: str
    message: str
    is_stable: bool
    spectral_radius: float
    spectral_radius_error: float
    critical_multiplier: complex
    kind: str


_KIND_WORDS = {"fold": "fold (divergence), multiplier near +1", "period_doubling":
               "period doubling, multiplier near -1", "secondary_hopf": "secondary Hopf, complex pair"}


def _stability_verdict(multipliers: np.ndarray, multiplier_errors: np.ndarray, step_rates: np.ndarray, *,
                       stability_tol: float = periodic.STABILITY_TOL) -> _Stability:
    resolved = step_rates <= 1.0
    pool = np.flatnonzero(resolved) if resolved.any() else np.arange(multipliers.size)
    i = pool[np.argmax(np.abs(multipliers[pool]))]
    mu, radius = complex(multipliers[i]), float(abs(multipliers[i]))
    error = float(multiplier_errors[i]) if np.isfinite(multiplier_errors[i]) else 0.0
    angle = abs(math.atan2(mu.imag, mu.real))
    kind = ("fold" if angle < 1e-6 else "period_doubling" if math.pi - angle < 1e-6 else "secondary_hopf")
    excess = radius - 1.0
    if excess > error + stability_tol:
        return _Stability("unstable", f"unstable: spectral radius {radius:.6g} +- {error:.2g} "
                          f"({_KIND_WORDS[kind]}: mu = {mu:.4g})", False, radius, error, mu, kind)
    if abs(excess) <= error + stability_tol:
        return _Stability("marginal", f"marginal: spectral radius {radius:.6g} is within its error "
                          f"{error:.2g} of 1 (undamped or on a stability boundary)", True, radius, error,
                          mu, kind)
    return _Stability("ok", "", True, radius, error, mu, "")


def _error_verdict(difference_fine: float, difference_coarse: float, order: int, *,
                   scale: float) -> tuple[str, str]:
    """Trusted when the ratio of successive N/2 differences is near ``2**order`` (asymptotic range),
    or when both are at round-off relative to ``scale``."""
    tiny = 1e-11 * max(scale, np.finfo(float).tiny)
    if difference_coarse <= tiny and difference_fine <= tiny:
        return "ok", ""
    ratio = difference_coarse / difference_fine if difference_fine > 0 else math.inf
    ideal = 2.0 ** order
    if 0.5 * ideal <= ratio <= 2.0 * ideal:
        return "ok", ""
    return "inaccurate", (f"refine n_steps: the error estimate is outside its asymptotic range (ratio of "
                          f"successive differences {ratio:.3g}, expected about {ideal:g})")


# ---------------------------------------------------------------------------------------------------
def combine(parts: Iterable[tuple[str, str]]) -> tuple[str, str]:
    """``(status, message)`` of a point from its verdicts' ``(status, message)``: the worst status, and
    the messages of the verdicts that are not ``ok``, most severe first."""
    parts = [(status, message) for status, message in parts if status and status != "ok"]
    parts.sort(key=lambda part: severity(part[0]))
    status = _worst_status(*(status for status, _ in parts))
    return status, "; ".join(dict.fromkeys(message for _, message in parts if message))


def multiplier_errors(fine: np.ndarray, coarse: np.ndarray, factor: float) -> np.ndarray:
    """Estimated error of the modulus of each N-step multiplier (2m,): ``factor`` times the change of
    the modulus from the nearest N/2-step multiplier (the phase error of a multiplier does not move
    it across the unit circle)."""
    nearest = np.abs(fine[:, None] - coarse[None, :]).argmin(axis=1)
    return np.abs(np.abs(fine) - np.abs(coarse[nearest])) * factor


def stability(multipliers: np.ndarray, errors: np.ndarray, step_rates: np.ndarray) -> Any:
    """The stability verdict of multipliers with their error estimates (``periodic`` decides)."""
    return _stability_verdict(multipliers, errors, step_rates)


def error_trust(fine: np.ndarray, coarse: np.ndarray, quarter: np.ndarray, order: int) -> tuple[str, str]:
    """Whether the N/2 error estimate of a solution is in its asymptotic range: ``fine`` (N+1, n),
    ``coarse`` (N/2+1, n), ``quarter`` (N/4+1, n) on their own grids."""
    d_fine = float(np.abs(fine[::2] - coarse).max())
    d_coarse = float(np.abs(coarse[::2] - quarter).max())
    return _error_verdict(d_fine, d_coarse, order, scale=float(np.abs(fine).max()))


def worst(statuses: Sequence[str]) -> str:
    return _worst_status(*statuses)


def severity(status: str) -> int:
    """Rank of a status, 0 the most severe (unknown statuses, e.g. "missing", rank last)."""
    return _SEVERITY.get(status, len(STATUSES))


#: The linear-range measures reported per elastic link (names of ``linearize``'s per-link records).
RANGE_MEASURES = ("peak_deflection_over_length", "peak_deflection_over_height", "peak_slope",
                  "peak_compression_over_euler", "peak_stress_over_yield")


def linear_range(linear: Any, z: np.ndarray) -> tuple[dict[str, float], str, str]:
    """The linear-range measures of the solution ``z`` (N+1, m) of ``linear`` (a study ``Linear``):
    ``({"<link>.<measure>": value}, status, message)``; empty and ``ok`` for a problem without them."""
    measure = getattr(linear, "linear_range", None)
    if measure is None:
        return {}, "ok", ""
    found = measure(z)
    values = {f"{link.link}.{name}": float(getattr(link, name)) for link in found.links
              for name in RANGE_MEASURES}
    return values, found.status, found.message
