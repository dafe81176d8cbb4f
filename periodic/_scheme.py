"""The time-stepping scheme of the shooting: Newmark's family, and a registry of named members.

Newmark's scheme with parameters ``beta`` and ``gamma`` (the kernel in ``periodic._newmark`` cites its
equations) is of order 2 for ``gamma = 1/2`` and of order 1 otherwise (Hughes, The Finite Element
Method, sec. 9.1).  With ``gamma = 1/2`` it is time-symmetric (swapping k and k+1 with h -> -h gives
the same equations), so its global error expands in even powers of h and one Richardson step on N
and N/2 steps is of order 4.  It is unconditionally stable (A-stable) for ``2 beta >= gamma >= 1/2``.

A scheme is any object that satisfies :class:`Scheme` (its order, error factor, symmetry and ``march``, which a
user can write in numpy: ``tests/test_extend_scheme.py`` does).  :func:`register_scheme` names one in
:data:`SCHEMES` (a read-only view of the registry), :func:`get_scheme` turns a name or a scheme into a scheme;
``tests/test_periodic_numerics.py`` checks the observed order of every registered scheme against its declared
``order``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from types import MappingProxyType
from typing import Protocol, runtime_checkable

import numpy as np

from ._forcings import newmark_march_forcings
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
        """:class:`Scheme`'s ``march`` (the arguments and the return value are documented there): integrate the
        columns of ``x, v`` (n, m) over one period of ``system`` in place by the numba kernel
        (``periodic._newmark``).  The shooting and ``floquet`` call only this, so a scheme of another family
        is an object with its own ``march``."""
        if system.n_first_order and 2.0 * self.beta != self.gamma:
            raise PeriodicError(
                f"scheme: first-order coordinates {system.first_order.tolist()} need a Newmark scheme with "
                f"2 beta = gamma (the trapezoidal rule on them, e.g. 'trapezoidal'), got beta={self.beta}, "
                f"gamma={self.gamma}")
        # the kernel by size: hand-written LU for small n, LAPACK for large (periodic._newmark.choose_solver)
        return march(system.M, system.C, system.K, system.f, system.step, self.beta, self.gamma,
                     forced, x, v, a, x_hist, v_hist, a_hist, first_order=system.first_order_mask)

    def march_forcings(self, system, forcings, x, v, a, x_hist, v_hist, a_hist) -> int:
        """``march`` with column j driven by ``forcings[:, :, j]`` (N+1, n, m) instead of ``forced[j] * f``,
        all columns with one factorisation per step (the kernel of ``periodic._forcings``; the parameter
        derivatives of ``periodic._sensitivity``)."""
        if system.n_first_order and 2.0 * self.beta != self.gamma:
            self.march(system, np.zeros(x.shape[1]), x, v, a, x_hist, v_hist, a_hist)  # raises, naming them
        return newmark_march_forcings(system.M, system.C, system.K, forcings, system.first_order_mask,
                                      system.step, self.beta, self.gamma, x, v, a, x_hist, v_hist, a_hist)


@runtime_checkable
class Scheme(Protocol):
    """What the shooting (``steady_state``) and ``floquet`` need of a time-stepping scheme; :class:`Newmark` is
    one, and a scheme of another family is any object with these four members (plain Python and numpy will
    do: no kernel of this package is needed).

    ``order`` : int >= 1
        Order of convergence of the solution and the multipliers in the step h.
    ``error_factor`` : float
        ``1 / (2**order - 1)``: ``error_factor * |x_N - x_{N/2}|`` estimates the error of ``x_N``.
    ``symmetric`` : bool
        True only when the global error expands in even powers of h (time-symmetric schemes): then Richardson
        extrapolation of N and N/2 steps (``extrapolate=True``) gains two orders.
    ``march(system, forced, x, v, a, x_hist, v_hist, a_hist) -> int``
        Integrate m independent solutions of ``system`` (a :class:`PeriodicSystem`: ``M, C, K`` (N+1, n, n)
        and ``f`` (N+1, n) sampled at ``t_k = k h``, ``h = system.step``, ``N = system.n_steps``) over one
        period, in place.  ``x, v`` (n, m): the columns' values at t_0 on entry, at t_N on return; column j
        is driven by ``forced[j] * f`` (``forced`` (m,): 1 for the forced solution, 0 for the unit states of
        the monodromy).  ``a`` (n, m) receives the accelerations at t_N.  ``x_hist, v_hist, a_hist`` are
        (N+1, n, m) arrays to fill with every sample, or have length 0 (nothing to store).  Returns -1, or
        the sample k whose step (or start) matrix is singular, which the caller reports as a
        ``ShootingError`` at t_k.  First-order coordinates (``system.n_first_order > 0``: rows and columns of M
        zero; their rows of ``v`` on entry are not data) need consistent rates at the start, as
        :meth:`Newmark.march` sets them; a scheme that does not handle them raises :class:`PeriodicError`
        naming them.

    Use it by name after :func:`register_scheme`, or pass the object as ``scheme=``.
    """

    order: int
    error_factor: float
    symmetric: bool

    def march(self, system, forced, x, v, a, x_hist, v_hist, a_hist) -> int: ...


# The registry behind SCHEMES, filled here with Newmark's members and by register_scheme.
_REGISTRY: dict[str, Scheme] = {
    # average acceleration = the trapezoidal rule on the first-order form: order 2, no numerical damping
    "trapezoidal": Newmark(beta=0.25, gamma=0.5),
    # gamma = 1/2 + 0.1 and beta = (gamma + 1/2)^2 / 4 (strongest high-frequency damping for this
    # gamma): order 1
    "damped": Newmark(beta=0.3025, gamma=0.6),
}
#: Named schemes, all unconditionally stable (the shooting integrates every mode of the system, stiff
#: ones included, over a whole period): a read-only view of the registry, which :func:`register_scheme`
#: extends.  Pass a name or a :class:`Scheme` as ``scheme=``.
SCHEMES = MappingProxyType(_REGISTRY)
#: The default of ``steady_state`` and ``floquet``.
DEFAULT_SCHEME = SCHEMES["trapezoidal"]
_MEMBERS = ("order", "error_factor", "symmetric", "march")


def check_scheme(scheme, what: str = "scheme") -> Scheme:
    """``scheme`` itself if it satisfies :class:`Scheme`: a TypeError naming the members it lacks (or a
    ``march`` that is not callable), a :class:`PeriodicError` for an ``order`` that is not an integer >= 1, an
    ``error_factor`` other than ``1 / (2**order - 1)`` or a ``symmetric`` that is not a bool."""
    missing = [member for member in _MEMBERS if not hasattr(scheme, member)]
    if missing:
        raise TypeError(f"{what}: {type(scheme).__name__} does not satisfy periodic.Scheme: it lacks "
                        f"{', '.join(missing)} (a scheme has order, error_factor, symmetric and march)")
    if not callable(scheme.march):
        raise TypeError(f"{what}: {type(scheme).__name__}.march must be callable "
                        "(march(system, forced, x, v, a, x_hist, v_hist, a_hist) -> int)")
    order = scheme.order
    if isinstance(order, bool) or not isinstance(order, int) or order < 1:
        raise PeriodicError(f"{what}: order: expected an integer >= 1, got {order!r}")
    expected = 1.0 / (2.0**order - 1.0)
    if not isinstance(scheme.error_factor, (int, float)) or abs(scheme.error_factor - expected) > 1e-12 * expected:
        raise PeriodicError(f"{what}: error_factor: expected 1 / (2**order - 1) = {expected:.6g} for order {order}, "
                            f"got {scheme.error_factor!r}")
    if not isinstance(scheme.symmetric, bool):
        raise PeriodicError(f"{what}: symmetric: expected True or False, got {scheme.symmetric!r}")
    return scheme


def register_scheme(name: str, scheme: Scheme) -> Scheme:
    """Register ``scheme`` under ``name`` in :data:`SCHEMES`, so that ``scheme=name`` selects it (in
    ``steady_state``, ``floquet`` and the studies' ``scheme`` option) and the convergence test covers it.
    Returns the scheme.  Refuses a name that is not a non-empty string (TypeError, PeriodicError), a name
    already registered to another scheme (PeriodicError: registrations are never replaced; the same scheme again is
    accepted) and an object that does not satisfy
    :class:`Scheme` (see :func:`check_scheme`).  Register at import of the module that defines the scheme, so
    that every process (a study's worker pool too) sees it."""
    if not isinstance(name, str):
        raise TypeError(f"name: expected a string, got {type(name).__name__}")
    if not name.strip():
        raise PeriodicError(f"name: expected a non-empty name, got {name!r}")
    if name in _REGISTRY and _REGISTRY[name] is scheme:   # its module imported again: nothing to do
        return scheme
    if name in _REGISTRY:
        raise PeriodicError(f"name: {name!r} is already registered in periodic.SCHEMES ({_REGISTRY[name]!r}); "
                            "choose another name")
    _REGISTRY[name] = check_scheme(scheme, f"scheme {name!r}")
    return scheme


def get_scheme(scheme) -> Scheme:
    """The :class:`Scheme` given as itself (checked by :func:`check_scheme`) or by its name in :data:`SCHEMES`.
    Unknown names raise :class:`PeriodicError`, other types TypeError."""
    if isinstance(scheme, str):
        try:
            return SCHEMES[scheme]
        except KeyError:
            raise PeriodicError(
                f"scheme: expected a name in periodic.SCHEMES ({', '.join(map(repr, SCHEMES))}) or a periodic.Scheme, "
                f"got {scheme!r}"
            ) from None
    if isinstance(scheme, Scheme):
        return check_scheme(scheme)
    raise TypeError(f"scheme: expected a periodic.Scheme (a periodic.Newmark, or another object with order, "
                    f"error_factor, symmetric and march) or a name in periodic.SCHEMES, got {type(scheme).__name__}")
