"""Timing helpers the benchmark scripts share (run as scripts, they import this module from their
own folder)."""

from __future__ import annotations

import statistics
import time


def median_time(func, repeats):
    """The median wall time (s) of ``repeats`` calls of ``func()`` and the last call's value."""
    times, value = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        value = func()
        times.append(time.perf_counter() - start)
    return statistics.median(times), value


def clear_study_caches():
    """Empty the studies' per-process caches (speed families, assembled mechanisms), so that a timed
    run includes the linearisation it needs; pool workers are fresh processes anyway."""
    from studies import _mechanism

    _mechanism._families.clear()
    _mechanism._mechanisms.clear()
