"""Compiling the periodic engine's numba kernels ahead of use, and whether numba's disk cache
already holds them (``flexvib run`` compiles them in a helper process on a cold start)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ._newmark import mass_pivot_ratios, newmark_march

#: The kernels every steady state and Floquet analysis calls from Python.
KERNELS = (newmark_march, mass_pivot_ratios)


def warm_up_kernels() -> None:
    """Compile (or load from numba's disk cache) the kernels of ``steady_state`` and ``floquet``,
    with the numba types of any ``PeriodicSystem``, on a 2-DOF system of 32 steps."""
    from ._floquet import floquet
    from ._shooting import steady_state
    from ._system import PeriodicSystem

    system = PeriodicSystem.from_functions(
        2.0 * math.pi, lambda t: np.eye(2), lambda t: 0.1 * np.eye(2),
        lambda t: np.diag([2.0 + 0.5 * math.cos(t), 5.0]), lambda t: np.array([math.sin(t), 0.0]),
        n_steps=32)
    steady_state(system)
    floquet(system, estimate_error=True)


def kernels_cached() -> bool:
    """Whether numba's disk cache holds the kernels (their index files exist; a stale entry is still
    recompiled on use)."""
    return all(any(Path(kernel.stats.cache_path).glob(f"*.{kernel.py_func.__name__}-*.nbi"))
               for kernel in KERNELS)
