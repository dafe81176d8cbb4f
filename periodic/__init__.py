"""Periodic steady state and Floquet stability of ``M(t) x'' + C(t) x' + K(t) x = f(t)`` with period T.

Newmark shooting on a uniform grid of N steps (numba kernels).  Knows nothing of mechanisms.
Nonlinear systems: periodic orbits of any period map by Newton shooting (``find_orbit``) and their
continuation over a parameter with bifurcation detection (``continue_orbits``).  Schemes of other families are
objects satisfying ``Scheme``, named by ``register_scheme`` and looked up by ``get_scheme``.  ``periodic.lapack``
(a public module, the packages' one home of the numba LU routines) binds LAPACK for the kernels.
"""

from ._continuation import OrbitBranch as OrbitBranch
from ._continuation import continue_orbits as continue_orbits
from ._demo import demo_system as demo_system
from ._duffing import Duffing as Duffing
from ._duffing import DuffingPeriodMap as DuffingPeriodMap
from ._duffing import duffing_period_map as duffing_period_map
from ._floquet import FloquetResult as FloquetResult
from ._floquet import NearResonanceWarning as NearResonanceWarning
from ._floquet import floquet as floquet
from ._harmonic import HarmonicBalance as HarmonicBalance
from ._harmonic import harmonic_balance as harmonic_balance
from ._orbit import BIFURCATIONS as BIFURCATIONS
from ._orbit import SETTLE_SLACK as SETTLE_SLACK
from ._orbit import PeriodicOrbit as PeriodicOrbit
from ._orbit import PeriodMap as PeriodMap
from ._orbit import find_orbit as find_orbit
from ._scheme import SCHEMES as SCHEMES
from ._scheme import Newmark as Newmark
from ._scheme import Scheme as Scheme
from ._scheme import get_scheme as get_scheme
from ._scheme import register_scheme as register_scheme
from ._sensitivity import ResponseDerivative as ResponseDerivative
from ._sensitivity import SystemDerivative as SystemDerivative
from ._sensitivity import response_derivative as response_derivative
from ._shooting import SteadyState as SteadyState
from ._shooting import steady_state as steady_state
from ._system import PeriodicError as PeriodicError
from ._system import PeriodicSystem as PeriodicSystem
from ._system import ShootingError as ShootingError
from ._verdict import MAX_RELATIVE_ERROR as MAX_RELATIVE_ERROR
from ._verdict import ORDER_TOLERANCE as ORDER_TOLERANCE
from ._verdict import STABILITY_TOL as STABILITY_TOL
from ._verdict import STATUSES as STATUSES
from ._verdict import ErrorCheck as ErrorCheck
from ._verdict import Stability as Stability
from ._verdict import error_verdict as error_verdict
from ._verdict import stability_verdict as stability_verdict
from ._verdict import worst_status as worst_status

__all__ = [
    "BIFURCATIONS",
    "SCHEMES",
    "MAX_RELATIVE_ERROR", "ORDER_TOLERANCE", "STABILITY_TOL",
    "STATUSES",
    "Duffing",
    "DuffingPeriodMap",
    "ErrorCheck",
    "FloquetResult",
    "HarmonicBalance",
    "NearResonanceWarning",
    "OrbitBranch",
    "Newmark",
    "Scheme",
    "PeriodicError",
    "PeriodicOrbit",
    "SETTLE_SLACK",
    "PeriodicSystem",
    "PeriodMap",
    "ResponseDerivative",
    "ShootingError",
    "Stability",
    "SteadyState",
    "SystemDerivative",
    "continue_orbits",
    "demo_system",
    "duffing_period_map",
    "error_verdict",
    "find_orbit",
    "floquet",
    "harmonic_balance",
    "get_scheme",
    "register_scheme",
    "response_derivative",
    "stability_verdict",
    "steady_state",
    "worst_status",
]
