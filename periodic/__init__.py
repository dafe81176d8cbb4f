"""Periodic steady state and Floquet stability of ``M(t) x'' + C(t) x' + K(t) x = f(t)`` with period T.

Newmark shooting on a uniform grid of N steps (numba kernels).  Knows nothing of mechanisms.
"""

from ._demo import demo_system as demo_system
from ._floquet import FloquetResult as FloquetResult
from ._floquet import NearResonanceWarning as NearResonanceWarning
from ._floquet import floquet as floquet
from ._scheme import SCHEMES as SCHEMES
from ._scheme import Newmark as Newmark
from ._scheme import Scheme as Scheme
from ._shooting import SteadyState as SteadyState
from ._shooting import steady_state as steady_state
from ._system import PeriodicError as PeriodicError
from ._system import PeriodicSystem as PeriodicSystem
from ._system import ShootingError as ShootingError
from ._verdict import STABILITY_TOL as STABILITY_TOL
from ._verdict import STATUSES as STATUSES
from ._verdict import ErrorCheck as ErrorCheck
from ._verdict import Stability as Stability
from ._verdict import error_verdict as error_verdict
from ._verdict import stability_verdict as stability_verdict
from ._verdict import worst_status as worst_status

__all__ = [
    "SCHEMES",
    "STABILITY_TOL",
    "STATUSES",
    "ErrorCheck",
    "FloquetResult",
    "NearResonanceWarning",
    "Newmark",
    "Scheme",
    "PeriodicError",
    "PeriodicSystem",
    "ShootingError",
    "Stability",
    "SteadyState",
    "demo_system",
    "error_verdict",
    "floquet",
    "stability_verdict",
    "steady_state",
    "worst_status",
]
