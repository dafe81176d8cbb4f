"""The time-stepping scheme of the shooting: Newmark's family, and a registry of named members.

Newmark's scheme with parameters ``beta`` and ``gamma`` (the kernel in ``periodic._newmark`` cites its
equations) is of order 2 for ``gamma = 1/2`` and of order 1 otherwise (Hughes, The Finite Element
Method, sec. 9.1).  With ``gamma = 1/2`` it is time-symmetric (swapping k and k+1 with h -> -h gives
the same equations), so its global error expands in even powers of h and one Richardson step on N
and N/2 steps is of order 4.  It is unconditionally stable (A-stable) for ``2 beta >= gamma >= 1/2``.

A new member of the family is one line in :data:`SCHEMES`; ``tests/test_periodic_numerics.py``
checks the observed order of every registered scheme against its declared :attr:`Newmark.order`.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from types import MappingProxyType
from typing import Protocol, runtime_checkable

from ._newmark import march
from ._system import PeriodicError, check_real


@dataclass(frozen=True)
class Newmark:
    """Newmark's scheme with parameters ``beta`` and ``gamma`` (dimensionless).

    Construction validates: real (TypeError otherwise), finite and non-negative (PeriodicError); a
    ``RuntimeWarning`` when the scheme is only conditionally stable (not ``2 beta >= gamma >= 1/2``):
    the multipliers of modes above its stability limit are then spurious.

    Attributes
    ----------
    beta, gamma : float
    order : int
        Order of convergence of the solution and the multipliers: 2 for ``gamma = 1/2``, else 1.
    error_factor : float
        ``1 / (2**order - 1)``: ``error_factor * |x_N - x_{N/2}|`` estimates the error of ``x_N`` to
        leading order (1/3 at order 2, 1 at order 1).
    symmetric : bool
        Time-symmetric (``gamma = 1/2``): Richardson extrapolation of N and N/2 steps is allowed and
        gains two orders.
    unconditionally_stable : bool
        ``2 beta >= gamma >= 1/2`` (A-stability).
    """

    beta: float = 0.25
    gamma: float = 0.5

    def __post_init__(self):
        beta = check_real("beta", self.beta)
        gamma = check_real("gamma", self.gamma)
        if beta < 0.0 or gamma < 0.0:
            raise PeriodicError(f"beta, gamma: expected non-negative values, got beta={beta}, gamma={gamma}")
        object.__setattr__(self, "beta", beta)
        object.__setattr__(self, "gamma", gamma)
        if not self.unconditionally_stable:
            warnings.warn(
                f"beta={beta}, gamma={gamma}: Newmark's scheme is unconditionally stable only for "
                "2 beta >= gamma >= 1/2; multipliers of modes above its stability limit are spurious",
                RuntimeWarning,
                stacklevel=3,  # the caller of Newmark(...)
            )

    @property
    def order(self) -> int:
        return 2 if self.symmetric else 1

    @property
    def error_factor(self) -> float:
        return 1.0 / (2.0**self.order - 1.0)

    @property
    def symmetric(self) -> bool:
        return self.gamma == 0.5

    @property
    def unconditionally_stable(self) -> bool:
        return 2.0 * self.beta >= self.gamma >= 0.5

    def march(self, system, forced, x, v, a, x_hist, v_hist, a_hist) -> int:
        """Integrate the columns of ``x, v`` (n, m) over one period of ``system`` in place (``a``
        (n, m) receives the end accelerations); column j carries the force ``forced[j] * f(t)``.
        ``x_hist, v_hist, a_hist`` (N+1, n, m) receive every sample, or have length 0. Returns the
        kernel's status: -1, or the sample whose matrix was singular (see ``raise_on_singular``). The shooting and
        ``floquet``
        call only this, so a scheme of another family is a class with its own ``march``."""
        if system.n_first_order and 2.0 * self.beta != self.gamma:
            raise PeriodicError(
                f"scheme: first-order coordinates {system.first_order.tolist()} need a Newmark scheme with "
                f"2 beta = gamma (the trapezoidal rule on them, e.g. 'trapezoidal'), got beta={self.beta}, "
                f"gamma={self.gamma}")
        # the kernel by size: hand-written LU for small n, LAPACK for large (periodic._newmark.choose_solver)
        return march(system.M, system.C, system.K, system.f, system.step, self.beta, self.gamma,
                     forced, x, v, a, x_hist, v_hist, a_hist, first_order=system.first_order_mask)


#: Named schemes, all unconditionally stable (the shooting integrates every mode of the system, stiff
#: ones included, over a whole period).  Pass a name or a :class:`Newmark` as ``scheme=``.
SCHEMES = MappingProxyType(
    {
        # average acceleration = the trapezoidal rule on the first-order form: order 2, no numerical damping
        "trapezoidal": Newmark(beta=0.25, gamma=0.5),
        # gamma = 1/2 + 0.1 and beta = (gamma + 1/2)^2 / 4 (strongest high-frequency damping for this
        # gamma): order 1
        "damped": Newmark(beta=0.3025, gamma=0.6),
    }
)
#: The default of ``steady_state`` and ``floquet``.
DEFAULT_SCHEME = SCHEMES["trapezoidal"]


@runtime_checkable
class Scheme(Protocol):
    """What the shooting and ``floquet`` need of a time-stepping scheme (:class:`Newmark` is one; a
    scheme of another family is any object with these members): its ``order`` of convergence, the
    ``error_factor`` ``1 / (2**order - 1)`` of the N/2 error estimate, whether it is ``symmetric``
    (Richardson extrapolation allowed) and ``march``, which integrates the columns of a state over
    one period (see :meth:`Newmark.march` for the arguments)."""

    order: int
    error_factor: float
    symmetric: bool

    def march(self, system, forced, x, v, a, x_hist, v_hist, a_hist) -> int: ...


def as_scheme(scheme) -> Scheme:
    """A :class:`Scheme` given as itself or by its name in :data:`SCHEMES`."""
    if isinstance(scheme, Scheme):
        return scheme
    if isinstance(scheme, str):
        try:
            return SCHEMES[scheme]
        except KeyError:
            raise PeriodicError(
                f"scheme: expected one of {', '.join(map(repr, SCHEMES))} or a periodic.Newmark, got {scheme!r}"
            ) from None
    raise TypeError(f"scheme: expected a periodic.Newmark (or another object with order, error_factor, symmetric "
                    f"and march) or a name in periodic.SCHEMES, got {type(scheme).__name__}")
