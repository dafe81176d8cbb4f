"""The demo system: a damped two-degree-of-freedom Mathieu-type system with harmonic forcing,

    M x'' + C x' + (K0 + K1 cos(Omega t)) x = F cos(Omega t),   T = 2 pi / Omega = 1 s,

whose stiffness pulsates at the forcing frequency (as a link's stiffness does over a crank turn).
Used by ``python -m periodic``, the benchmarks and the tests; ``studies`` writes it to files.
"""

from __future__ import annotations

import numpy as np

from ._system import PeriodicSystem

OMEGA = 2.0 * np.pi  # rad/s, forcing and pulsation frequency: T = 1 s
MASS = np.array([[2.0, 0.5], [0.5, 1.0]])  # kg
STIFFNESS_MEAN = np.array([[900.0, -300.0], [-300.0, 500.0]])  # N/m
STIFFNESS_PULSE = np.array([[180.0, 0.0], [0.0, -100.0]])  # N/m, amplitude of the cos(Omega t) part
DAMPING = 1e-3 * STIFFNESS_MEAN + 0.2 * MASS  # N s/m, Rayleigh damping
FORCE = np.array([10.0, 0.0])  # N, amplitude of the cos(Omega t) force


def stiffness(t: float) -> np.ndarray:
    """``K0 + K1 cos(Omega t)`` (2, 2), N/m."""
    return STIFFNESS_MEAN + STIFFNESS_PULSE * np.cos(OMEGA * t)


def force(t: float) -> np.ndarray:
    """``F cos(Omega t)`` (2,), N."""
    return FORCE * np.cos(OMEGA * t)


def demo_system(n_steps: int) -> PeriodicSystem:
    """The demo system (see ``periodic._demo``): a damped 2-DOF Mathieu-type system with harmonic
    forcing, T = 1 s, sampled on ``n_steps`` steps per period."""
    return PeriodicSystem.from_functions(
        2.0 * np.pi / OMEGA, lambda t: MASS, lambda t: DAMPING, stiffness, force, n_steps=n_steps
    )
