"""Periodic steady state and Floquet stability of ``M(t) x'' + C(t) x' + K(t) x = f(t)`` with period T.

Newmark shooting on a uniform grid of N steps (numba kernels).  Knows nothing of mechanisms.
"""

from ._demo import demo_system as demo_system
from ._floquet import STABILITY_TOL as STABILITY_TOL
from ._floquet import FloquetResult as FloquetResult
from ._floquet import NearResonanceWarning as NearResonanceWarning
from ._floquet import floquet as floquet
from ._scheme import SCHEMES as SCHEMES
from ._scheme import Newmark as Newmark
from ._shooting import SteadyState as SteadyState
from ._shooting import steady_state as steady_state
from ._system import PeriodicError as PeriodicError
from ._system import PeriodicSystem as PeriodicSystem
from ._system import ShootingError as ShootingError

__all__ = [
    "SCHEMES",
    "STABILITY_TOL",
    "FloquetResult",
    "NearResonanceWarning",
    "Newmark",
    "PeriodicError",
    "PeriodicSystem",
    "ShootingError",
    "SteadyState",
    "demo_system",
    "floquet",
    "steady_state",
]
