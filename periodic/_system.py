"""The time-periodic linear system ``M(t) x'' + C(t) x' + K(t) x = f(t)`` sampled on a uniform grid."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ._newmark import mass_pivot_ratios

# A sample of M whose LU pivots span more than this ratio is treated as singular: rounding
# alone makes the smallest pivot of an exactly singular matrix about n * eps times its norm.
_SINGULAR_PIVOT_RATIO = 1e3 * np.finfo(float).eps
# Periodicity of the samples: t_N = T must repeat t_0.  Rounding in the caller's sampling
# (e.g. evaluating cos(2 pi k / N)) differs at the 1e-15 level; a mismatch above 1e-10 is
# suspicious (warned) and one above 1e-6 means the coefficients are not T-periodic (error).
_PERIODICITY_WARN = 1e-10
_PERIODICITY_ERROR = 1e-6


class PeriodicError(ValueError):
    """Invalid input to ``periodic``: the message names the argument, what was expected and what was given.

    Wrong types and unknown options raise ``TypeError`` instead.
    """


class ShootingError(RuntimeError):
    """The computation failed on valid input: a matrix of the Newmark steps or ``I - Phi`` is exactly
    singular (e.g. a free rigid-body mode, a multiplier at +1 to rounding)."""


@dataclass(frozen=True, eq=False)
class PeriodicSystem:
    """``M(t) x'' + C(t) x' + K(t) x = f(t)`` with period ``T``, sampled at ``t_k = k T / N``.

    Attributes
    ----------
    period : float
        ``T`` in s.
    M, C, K : ndarray, shape (N+1, n, n)
        Mass, damping and stiffness samples at ``t_0 .. t_N`` (``t_N = T`` repeats ``t_0``).
    f : ndarray, shape (N+1, n)
        Force samples (zeros when the system is unforced).

    First-order coordinates: a coordinate whose row and column of M are zero at every sample (a
    massless coordinate such as a sensor or actuator lag, ``tau y' + y = u``) is integrated as a
    first-order equation (its row of C, with an invertible block ``C[first_order][:, first_order]``,
    gives its rate): the state is then ``z = [x; v[massive]]`` of size ``n_state = 2 n - n_first_order``
    (``first_order`` and ``massive`` index the coordinates), with no spurious multiplier.  Their rates
    are not states; the scheme must satisfy ``2 beta = gamma`` (the trapezoidal rule on them).

    The arrays are private read-only float64 copies.  Construct with ``PeriodicSystem(period, M, C,
    K, f=None)`` or :meth:`from_functions`.
    """

    period: float
    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    f: np.ndarray

    def __init__(self, period, M, C, K, f=None):
        _validate_and_set(self, _check_period(period), M, C, K, f)

    @classmethod
    def from_functions(
        cls,
        period: float,
        mass: Callable[[float], np.ndarray],
        damping: Callable[[float], np.ndarray],
        stiffness: Callable[[float], np.ndarray],
        force: Callable[[float], np.ndarray] | None = None,
        *,
        n_steps: int,
    ) -> "PeriodicSystem":
        """Sample callables of scalar ``t`` (s) at ``t_k = k T / n_steps``, k = 0..n_steps.

        ``mass``, ``damping``, ``stiffness`` return (n, n) arrays, ``force`` an (n,) array.
        """
        period = _check_period(period)
        n_steps = _check_n_steps(n_steps)
        times = np.arange(n_steps + 1) * (period / n_steps)
        sampled = []
        for name, func in (("mass", mass), ("damping", damping), ("stiffness", stiffness), ("force", force)):
            if func is None and name == "force":
                sampled.append(None)
                continue
            if not callable(func):
                raise TypeError(f"{name}: expected a callable of scalar t, got {type(func).__name__}")
            sampled.append(_sample(name, func, times))
        system = object.__new__(cls)
        _validate_and_set(system, period, *sampled)  # period already checked
        return system

    def __repr__(self) -> str:
        return f"PeriodicSystem(period={self.period!r}, n_steps={self.n_steps}, n_dof={self.n_dof})"

    @property
    def n_steps(self) -> int:
        """Number of Newmark steps ``N`` per period."""
        return self.M.shape[0] - 1

    @property
    def n_dof(self) -> int:
        """Number of coordinates ``n``."""
        return self.M.shape[1]

    @property
    def first_order(self) -> np.ndarray:
        """Indices of the first-order coordinates (rows and columns of M zero), shape (n_first_order,)."""
        return np.flatnonzero(self.first_order_mask)

    @property
    def massive(self) -> np.ndarray:
        """Indices of the second-order coordinates, shape (n - n_first_order,)."""
        return np.flatnonzero(self.first_order_mask == 0)

    @property
    def n_first_order(self) -> int:
        """Number of first-order coordinates."""
        return int(np.count_nonzero(self.first_order_mask))

    @property
    def n_state(self) -> int:
        """Size of the state ``[x; v[massive]]`` and of the monodromy: ``2 n - n_first_order``."""
        return 2 * self.n_dof - self.n_first_order

    @property
    def step(self) -> float:
        """Step ``h = T / N`` in s."""
        return self.period / self.n_steps

    @property
    def t(self) -> np.ndarray:
        """Sample times ``t_k = k T / N``, shape (N+1,), s."""
        return np.arange(self.n_steps + 1) * self.step

    def coarsened(self) -> "PeriodicSystem":
        """The same system on the grid of ``N/2`` steps (every other sample); ``N`` must be even, >= 4."""
        check_coarsenable(self.n_steps, "sample the system with an even n_steps (or skip the error estimate)")
        return every_other_sample(self)


def check_coarsenable(n_steps: int, fix: str) -> None:
    """Refuse an ``n_steps`` that has no N/2 grid of at least 2 steps; ``fix`` ends the message."""
    if n_steps % 2 or n_steps < 4:
        raise PeriodicError(f"n_steps: comparing with N/2 steps needs an even n_steps >= 4, got {n_steps}; {fix}")


def check_quarterable(n_steps: int, fix: str) -> None:
    """Refuse an ``n_steps`` that has no N/4 grid of at least 2 steps; ``fix`` ends the message."""
    if n_steps % 4 or n_steps < 8:
        raise PeriodicError(
            f"n_steps: the error check compares N, N/2 and N/4 steps and needs a multiple of 4 >= 8, "
            f"got {n_steps}; {fix}"
        )


def every_other_sample(system: PeriodicSystem) -> PeriodicSystem:
    """``system`` on N/2 steps, unchecked: the caller has called :func:`check_coarsenable`."""
    coarse = object.__new__(PeriodicSystem)
    # Every other sample of validated arrays is valid: no re-validation needed.
    arrays = [np.ascontiguousarray(a[::2]) for a in (system.M, system.C, system.K, system.f)]
    for arr in arrays:
        # read-only as every system's arrays: the numba kernels then compile for one signature
        arr.flags.writeable = False
    _set(coarse, system.period, *arrays)
    return coarse


def _validate_and_set(system: PeriodicSystem, period: float, M, C, K, f) -> None:
    """Check the samples (``period`` is checked by the caller) and store read-only copies in ``system``."""
    mass = _as_samples("mass", M, ndim=3)
    n_samples, n_dof = mass.shape[0], mass.shape[1]
    if mass.shape[2] != n_dof:
        raise PeriodicError(f"mass: expected shape (N+1, n, n), got {mass.shape} (matrices not square)")
    if n_samples < 3:
        raise PeriodicError(f"mass: expected N+1 >= 3 samples (n_steps >= 2), got {n_samples} sample(s)")
    damping = _as_samples("damping", C, ndim=3, shape=mass.shape)
    stiffness = _as_samples("stiffness", K, ndim=3, shape=mass.shape)
    if f is None:
        force = np.zeros((n_samples, n_dof))
    else:
        force = _as_samples("force", f, ndim=2, shape=(n_samples, n_dof))
    for name, samples in (("mass", mass), ("damping", damping), ("stiffness", stiffness), ("force", force)):
        _check_periodic(name, samples)
    first = first_order_mask(mass).astype(bool)
    massive = ~first
    if massive.any():
        _refuse_singular("mass", mass[:, massive][:, :, massive], period, (
            "The Newmark start needs M(0) invertible and the problem must be an ODE in x: eliminate massless "
            "coordinates (static condensation) or give them mass; a coordinate whose row and column of M are "
            "both zero at every sample is treated as first-order (e.g. a lag, tau y' + y = u)"))
    if first.any():
        _refuse_singular("damping", damping[:, first][:, :, first], period, (
            f"coordinates {np.flatnonzero(first).tolist()} have no mass (their rows and columns of M are zero) "
            "and are integrated as first-order equations, which needs their block of C invertible: give "
            "them mass, or damping that sets their rates (e.g. tau for a lag tau y' + y = u)"))
    for arr in (mass, damping, stiffness, force):
        arr.flags.writeable = False
    _set(system, period, mass, damping, stiffness, force)


def _refuse_singular(name: str, blocks: np.ndarray, period: float, fix: str) -> None:
    """PeriodicError naming the first sample of ``blocks`` (N+1, k, k) whose LU pivots span more than
    ``_SINGULAR_PIVOT_RATIO``; ``fix`` ends the message."""
    n_samples = blocks.shape[0]
    ratios = mass_pivot_ratios(np.ascontiguousarray(blocks))
    singular = np.flatnonzero(ratios <= _SINGULAR_PIVOT_RATIO)
    if not singular.size:
        return
    k = int(singular[0])
    t_k = k * period / (n_samples - 1)
    what = "mass matrix" if name == "mass" else "block of the first-order coordinates"
    raise PeriodicError(
        f"{name}: the {what} is singular at sample {k} (t = {t_k:.6g} s; smallest/largest "
        f"LU pivot {ratios[k]:.3g}); {singular.size} of {n_samples} samples are singular. {fix}."
    )


def first_order_mask(M: np.ndarray) -> np.ndarray:
    """(n,) int8: 1 for a coordinate whose row and column of M (N+1, n, n) are zero at every sample."""
    nonzero = M != 0.0
    return (~(nonzero.any(axis=(0, 2)) | nonzero.any(axis=(0, 1)))).astype(np.int8)


def state_trace(system: PeriodicSystem) -> np.ndarray:
    """``tr A(t_k)`` (N+1,) of the first-order form ``z' = A z + ...`` of the state ``z = [x; v[massive]]``:
    ``-tr(M_mm^-1 (C_mm - C_m1 C_11^-1 C_1m)) - tr(C_11^-1 K_11)`` (m massive, 1 first-order
    coordinates; ``-tr(M^-1 C)`` without first-order ones), the integrand of Liouville's formula."""
    if not system.n_first_order:
        return -np.trace(np.linalg.solve(system.M, system.C), axis1=1, axis2=2)
    m, one = system.massive, system.first_order
    C, K = system.C, system.K
    c11_inv_c1m = np.linalg.solve(C[:, one][:, :, one], C[:, one][:, :, m])
    effective_damping = C[:, m][:, :, m] - C[:, m][:, :, one] @ c11_inv_c1m
    massive_part = 0.0
    if m.size:
        massive_part = np.trace(np.linalg.solve(system.M[:, m][:, :, m], effective_damping), axis1=1, axis2=2)
    lag_part = np.trace(np.linalg.solve(C[:, one][:, :, one], K[:, one][:, :, one]), axis1=1, axis2=2)
    return -massive_part - lag_part


def start_rates(system: PeriodicSystem) -> np.ndarray:
    """(n_first_order, n_state): the rates of the first-order coordinates at t = 0 from a homogeneous state
    ``z = [x; v[massive]]``: ``-C_11^-1 [K_1: , C_1m]`` (their rows of ``M x'' + C x' + K x = 0``)."""
    one, m = system.first_order, system.massive
    rows = np.hstack((system.K[0][one], system.C[0][one][:, m]))
    return -np.linalg.solve(system.C[0][one][:, one], rows)


def _set(obj, period, mass, damping, stiffness, force):
    object.__setattr__(obj, "period", period)
    object.__setattr__(obj, "M", mass)
    object.__setattr__(obj, "C", damping)
    object.__setattr__(obj, "K", stiffness)
    object.__setattr__(obj, "f", force)
    # not a field: follows from M (every other sample keeps it); the kernels' int8 flags
    mask = first_order_mask(mass)
    mask.flags.writeable = False
    object.__setattr__(obj, "first_order_mask", mask)


def _check_period(period) -> float:
    if isinstance(period, bool) or not isinstance(period, (int, float, np.integer, np.floating)):
        raise TypeError(f"period: expected a positive real number (s), got {type(period).__name__}")
    value = float(period)
    if not math.isfinite(value) or value <= 0.0:
        raise PeriodicError(f"period: expected a finite positive number (s), got {value!r}")
    return value


def check_system(system) -> None:
    """Refuse anything but a :class:`PeriodicSystem` (a TypeError naming ``system``)."""
    if not isinstance(system, PeriodicSystem):
        raise TypeError(f"system: expected a periodic.PeriodicSystem, got {type(system).__name__}")


def check_real(name: str, value) -> float:
    """A finite real number as float (TypeError for other types, PeriodicError if not finite)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a real number, got {type(value).__name__}")
    value = float(value)
    if not math.isfinite(value):
        raise PeriodicError(f"{name}: expected a finite number, got {value}")
    return value


def check_tol(name: str, value, upper: float = np.inf) -> float:
    """A tolerance in [0, upper] as float."""
    value = check_real(name, value)
    if not 0.0 <= value <= upper:
        raise PeriodicError(f"{name}: expected a tolerance in [0, {upper:g}], got {value}")
    return value


def _check_n_steps(n_steps) -> int:
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)):
        raise TypeError(f"n_steps: expected an integer >= 2, got {type(n_steps).__name__}")
    if n_steps < 2:
        raise PeriodicError(f"n_steps: expected an integer >= 2, got {n_steps}")
    return int(n_steps)


def _as_samples(name: str, values, *, ndim: int, shape=None) -> np.ndarray:
    if np.iscomplexobj(values):
        raise TypeError(f"{name}: expected real values, got a complex array (its imaginary part would be lost)")
    try:
        arr = np.array(values, dtype=np.float64, order="C", copy=True)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name}: expected a real array, got {type(values).__name__} ({exc})") from None
    expected = "(N+1, n, n)" if ndim == 3 else "(N+1, n)"
    if arr.ndim != ndim or (shape is not None and arr.shape != tuple(shape)):
        want = expected if shape is None else f"{expected} = {tuple(shape)}"
        raise PeriodicError(f"{name}: expected shape {want}, got {arr.shape}")
    if not np.isfinite(arr).all():
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise PeriodicError(
            f"{name}: expected finite values, got {arr[tuple(bad)]} at index {tuple(int(i) for i in bad)}"
        )
    return arr


def _check_periodic(name: str, samples: np.ndarray) -> None:
    scale = float(np.abs(samples).max())
    if scale == 0.0:
        return
    mismatch = float(np.abs(samples[-1] - samples[0]).max()) / scale
    if mismatch > _PERIODICITY_ERROR:
        raise PeriodicError(
            f"{name}: the last sample (t = T) must repeat the first (t = 0) for a T-periodic system; "
            f"they differ by {mismatch:.3g} relative to the largest entry. Check the period and that "
            "the grid includes both ends (N+1 samples)."
        )
    if mismatch > _PERIODICITY_WARN:
        warnings.warn(
            f"{name}: samples at t = 0 and t = T differ by {mismatch:.3g} (relative); the system is "
            "treated as T-periodic anyway",
            RuntimeWarning,
            stacklevel=4,
        )


def _sample(name: str, func, times: np.ndarray) -> np.ndarray:
    out = None
    with warnings.catch_warnings():
        # Storing a complex value into the float array would drop its imaginary part with a warning.
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        for k, t in enumerate(times.tolist()):
            try:
                value = func(t)
            except Exception as exc:  # any failure of user code is reported with its argument and time
                raise PeriodicError(
                    f"{name}: the callable raised {type(exc).__name__} at t = {t:.6g} s: {exc}"
                ) from exc
            shape = np.shape(value)
            if out is None:
                out = np.empty((times.size,) + shape)
            elif shape != out.shape[1:]:  # checked: assignment alone would broadcast a scalar
                raise PeriodicError(
                    f"{name}: the callable returned shape {shape} at t = {t:.6g} s but {out.shape[1:]} at t = 0"
                )
            try:
                out[k] = value
            except (TypeError, ValueError, np.exceptions.ComplexWarning) as exc:
                raise TypeError(f"{name}: the callable returned a non-real value at t = {t:.6g} s ({exc})") from None
    return out
