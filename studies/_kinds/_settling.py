"""The settling of a start-up vibration (``[studies.control_comparison]``'s measure): when a sampled
quantity stays inside a band above its steady peak, and whether it settled or grows."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._toolkit import StudiesError

#: Default ``band``: the start-up has settled once the envelope of a quantity stays within 5 % above
#: its steady peak (docs/studies.md).
BAND = 0.05


@dataclass(frozen=True)
class Settling:
    """The settling of one sampled quantity: ``time`` (s, from t[0]; NaN when it does not settle),
    ``steady_peak`` (max |y| over the last period), ``periodicity_defect`` (max |y(t) - y(t - T)|
    over the last period), ``settled`` and ``growing`` (the envelope grows: see :func:`settling_time`)."""

    time: float
    steady_peak: float
    periodicity_defect: float
    settled: bool
    growing: bool = False


def settling_time(t: np.ndarray, y: np.ndarray, steps_per_period: int, band: float = BAND) -> Settling:
    """When the start-up vibration of ``y`` (n_t,) sampled at ``t`` (n_t,) s, ``steps_per_period``
    samples per period, has settled.

    Definitions: the steady peak ``P`` is ``max |y|`` over the last period; the envelope is
    ``e(t) = max over tau >= t of |y(tau)|`` (the smallest non-increasing function above ``|y|``);
    the settling time is the first sample time with ``e(t) <= (1 + band) P``, i.e. the time after
    which ``|y|`` never again exceeds the band above its steady peak. The quantity has *settled* when
    the last period repeats the one before to the band, ``max |y(t) - y(t - T)| <= band * P`` over the
    last period: a growing, still decaying or irregular ``y`` has not settled, and its time is NaN.
    Settled implies a settling time at most ``t_end - 2 T`` (plus the band's worth). ``y`` is
    *growing* when each of the last two periods' peaks exceeds the one before by more than the band
    (needs three periods; one rise alone may be the beat of a decaying start-up)."""
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    n = int(steps_per_period)
    if y.shape != t.shape or t.ndim != 1 or t.size < 2 * n + 1:
        raise StudiesError(f"settling_time: expected t and y of the same length of at least two periods "
                           f"({2 * n + 1} samples), got shapes {t.shape} and {y.shape}")
    magnitude = np.abs(y)
    peak = float(magnitude[-(n + 1):].max())
    defect = float(np.abs(y[-(n + 1):] - y[-(2 * n + 1):-n]).max())
    envelope = np.maximum.accumulate(magnitude[::-1])[::-1]
    first = int(np.argmax(envelope <= (1.0 + band) * peak))   # the last sample always qualifies
    settled = defect <= band * peak
    growing = False
    if t.size >= 3 * n + 1:
        before, earlier = (float(magnitude[-(k + 1) * n - 1:-k * n].max()) for k in (1, 2))
        growing = peak > (1.0 + band) * before and before > (1.0 + band) * earlier
    return Settling(time=float(t[first] - t[0]) if settled else float("nan"), steady_peak=peak,
                    periodicity_defect=defect, settled=bool(settled), growing=bool(growing))
