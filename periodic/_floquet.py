"""Monodromy matrix and Floquet multipliers by Newmark integration of the 2n unit initial states.

The state is ``z = [x; v]`` (2n,).  Column ``j`` of the monodromy ``Phi`` (2n, 2n) is the state at
``t = T`` of the homogeneous solution that starts from the unit state ``e_j``.

Resolution of a multiplier.  For constant coefficients the eigenvector ``[x; v]`` of the discrete
monodromy is an eigenvector of the one-step map, and for the trapezoidal rule its two halves obey
``v = lam_h x`` with ``lam_h = (2/h)(R - 1)/(R + 1)``: the continuous-time rate that the scheme
resolves with per-step amplification ``R``.  ``step_rate = h |v| / |x|`` therefore estimates
``|lam h|`` of each Floquet mode.  A mode with ``step_rate > 1`` changes by more than a factor e (or
turns by more than a radian) within one step: its multiplier is a property of the scheme, not of
the system.  The typical case is a stiff or overdamped mode (``lam h -> -inf``): the trapezoidal
``R`` tends to -1, so over an even number of steps its multiplier can approach +1 although the exact
multiplier ``exp(lam T)`` is nearly 0.  Such modes are labelled unresolved and never reported as a
near-resonance.  They do not spoil the stability verdict: the scheme is A-stable (for
``2 beta >= gamma >= 1/2``), so a decaying mode keeps ``|R| <= 1`` (exactly so for constant
coefficients), but they can dominate ``spectral_radius`` at small N.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ._scheme import DEFAULT_SCHEME, Scheme, get_scheme
from ._system import (
    PeriodicSystem,
    ShootingError,
    check_quarterable,
    check_system,
    check_tol,
    every_other_sample,
    start_rates,
    state_trace,
)
from ._verdict import (
    RESOLVED_STEP_RATE,
    STABILITY_TOL,
    resolved_radius,
    stability_verdict,
    unresolved_multipliers,
)

#: Default of ``resonance_tol``: a resolved multiplier within this distance of +1 amplifies the
#: periodic response by more than 1/resonance_tol = 100 relative to the forcing's quasi-static level.
RESONANCE_TOL = 1e-2


class NearResonanceWarning(RuntimeWarning):
    """A resolved Floquet multiplier is close to +1: the periodic response is strongly amplified."""


@dataclass(frozen=True)
class FloquetResult:
    """Floquet analysis of a :class:`PeriodicSystem`.

    Attributes
    ----------
    monodromy : ndarray (s, s)
        ``Phi``, maps the state ``[x; v]`` at t = 0 to t = T (Newmark, N steps); s = 2n, or
        ``system.n_state`` with first-order coordinates, whose rates are not states (``[x; v[massive]]``).
    multipliers : ndarray (s,) complex
        Eigenvalues of ``Phi``, sorted by decreasing modulus.
    spectral_radius : float
        The largest ``|multiplier|`` of the resolved modes (``resolved``; the others are
        ``unresolved_multipliers``), or the critical multiplier's where the verdict is ``unstable``
        or no mode is resolved (``periodic._verdict.resolved_radius``).
    is_stable : bool
        False only where ``status`` is ``"unstable"``.
    stability_tol : float
        Tolerance of the stability verdict: at most ``STABILITY_TOL`` = 1e-6 (larger values are
        refused, they would hide growth), smaller values are allowed.
    multiplier_errors : ndarray (2n,) or None
        ``scheme.error_factor * |mu_N - mu_{N/2}|`` (nearest N/2 multiplier) with ``estimate_error``,
        else None.
    multipliers_coarse : ndarray (2n,) complex or None
        The N/2-step multipliers (decreasing modulus) with ``estimate_error``, else None: callers
        estimate the errors of quantities derived from the multipliers (characteristic frequencies)
        from them without another run.
    spectral_radius_error : float
        Error bar of ``|critical_multiplier|``, twice the N/2 error estimate of its modulus (NaN without
        ``estimate_error``: the verdict then
        has no error bar, only ``stability_tol``).
    critical_multiplier : complex
        The multiplier that decides stability (see :func:`periodic.stability_verdict`).
    instability_kind : str
        ``"fold"``, ``"period_doubling"``, ``"secondary_hopf"`` where unstable or marginal, else ``""``.
    status : str
        ``"ok"``, ``"unstable"`` or ``"marginal"``.
    message : str
    exponents : ndarray (2n,) complex
        Characteristic exponents ``log(multipliers) / T`` (1/s, principal branch; the imaginary part
        is defined modulo 2 pi / T; ``-inf`` real part for a zero multiplier).
    step_rates : ndarray (2n,)
        Estimated ``|lam h|`` of each multiplier's mode (see the module notes); ``resolved`` is
        ``step_rates <= 1``.
    resolved : ndarray (2n,) bool
    liouville_log_det : float
        ``log|det Phi|`` of the computed monodromy.
    liouville_log_det_exact : float
        ``-int_0^T tr(M^-1 C) dt`` (trapezoidal quadrature on the samples; with first-order
        coordinates the trace of their first-order form, ``periodic._system.state_trace``): Liouville's
        formula for the exact monodromy.  The two agree to O(h^2) when all modes are resolved; an unresolved damped
        mode makes them differ (its numerical multiplier is not exp(lam T)).
    n_steps : int
    scheme : Scheme
        The scheme used; ``scheme.error_factor * |mu_N - mu_{N/2}|`` estimates a multiplier's error
        (with a second call on ``system.coarsened()``).
    run_time : float
        Wall time in s.
    unresolved_multipliers : ndarray (k,) complex
        The multipliers of the modes the step does not resolve, decreasing modulus (the scheme's
        values, not the system's), reported apart from ``spectral_radius``.
    eigenvectors : ndarray (s, s) complex or None
        The Floquet modes at t = 0: column ``j`` the eigenvector of ``Phi`` of ``multipliers[j]``
        (unit 2-norm, the state ``[x; v[massive]]``); what tells which natural mode a multiplier belongs
        to (a characteristic frequency is known from its multiplier only modulo ``2 pi / T``).
    """

    monodromy: np.ndarray
    multipliers: np.ndarray
    spectral_radius: float
    is_stable: bool
    stability_tol: float
    multiplier_errors: np.ndarray | None
    multipliers_coarse: np.ndarray | None
    spectral_radius_error: float
    critical_multiplier: complex
    instability_kind: str
    status: str
    message: str
    exponents: np.ndarray
    step_rates: np.ndarray
    resolved: np.ndarray
    liouville_log_det: float
    liouville_log_det_exact: float
    n_steps: int
    scheme: Scheme
    run_time: float
    unresolved_multipliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=complex))
    eigenvectors: np.ndarray | None = None


def floquet(
    system: PeriodicSystem,
    *,
    scheme: Scheme | str = DEFAULT_SCHEME,
    stability_tol: float = STABILITY_TOL,
    estimate_error: bool = False,
) -> FloquetResult:
    """Monodromy, multipliers and stability of ``system`` by ``scheme`` (a :class:`Scheme`, e.g. a
    :class:`Newmark`, or a name in ``SCHEMES``) with N steps.  ``estimate_error=True`` also runs N/2 steps
    (N even >= 4) for the multipliers' errors, the error bar of the stability verdict.  Raises
    :class:`ShootingError` if a step's matrix is singular."""
    start = time.perf_counter()
    check_system(system)
    scheme = get_scheme(scheme)
    stability_tol = check_tol("stability_tol", stability_tol, STABILITY_TOL)
    if estimate_error:
        check_quarterable(system.n_steps, "use such an n_steps or estimate_error=False")
    phi, _ = monodromy(system, scheme, particular=False)
    multipliers, vectors = sorted_eigen(phi)
    step_rates = step_rates_of(vectors, system)
    errors = coarse = quarter = None
    if estimate_error:
        coarse_system = every_other_sample(system)
        coarse = sorted_eigenvalues(monodromy(coarse_system, scheme, particular=False)[0])
        quarter = sorted_eigenvalues(monodromy(every_other_sample(coarse_system), scheme, particular=False)[0])
        errors = multiplier_errors(multipliers, coarse, scheme.error_factor)
    moduli_errors = None if coarse is None else modulus_errors(multipliers, coarse, scheme.error_factor)
    stability = stability_verdict(
        multipliers, moduli_errors,
        step_rates, stability_tol=stability_tol, coarse=coarse, quarter=quarter, order=scheme.order,
        n_steps=system.n_steps)
    with np.errstate(divide="ignore"):
        exponents = np.log(multipliers.astype(complex)) / system.period
    trace = state_trace(system)
    exact = float(np.sum(trace[1:] + trace[:-1]) * 0.5 * system.step)
    radius, radius_error = resolved_radius(multipliers, step_rates, stability, moduli_errors)
    return FloquetResult(
        monodromy=phi,
        multipliers=multipliers,
        spectral_radius=radius,
        is_stable=stability.is_stable,
        stability_tol=stability_tol,
        multiplier_errors=errors,
        multipliers_coarse=coarse,
        spectral_radius_error=radius_error if estimate_error else float("nan"),
        critical_multiplier=stability.critical_multiplier,
        instability_kind=stability.kind,
        status=stability.status,
        message=stability.message,
        exponents=exponents,
        step_rates=step_rates,
        resolved=step_rates <= RESOLVED_STEP_RATE,
        liouville_log_det=float(np.linalg.slogdet(phi)[1]),
        liouville_log_det_exact=exact,
        n_steps=system.n_steps,
        scheme=scheme,
        run_time=time.perf_counter() - start,
        unresolved_multipliers=unresolved_multipliers(multipliers, step_rates),
        eigenvectors=vectors,
    )


def monodromy(system: PeriodicSystem, scheme: Scheme, *, particular: bool):
    """``Phi`` (s, s) of the state ``z = [x; v[massive]]`` (s = ``system.n_state``, 2n without
    first-order coordinates) and, if ``particular``, the end state ``b`` (s,) of the forced solution
    from rest.  The rates of first-order coordinates are not states: the kernel sets them consistently."""
    n, n_state, massive = system.n_dof, system.n_state, system.massive
    m = n_state + 1 if particular else n_state
    x = np.zeros((n, m))
    v = np.zeros((n, m))
    x[:, :n] = np.eye(n)
    v[massive, n + np.arange(massive.size)] = 1.0
    forced = np.zeros(m)
    if particular:
        forced[-1] = 1.0
    a = np.empty((n, m))
    empty = np.empty((0, n, m))
    status = scheme.march(system, forced, x, v, a, empty, empty, empty)
    raise_on_singular(system, status)
    phi = np.vstack((x[:, :n_state], v[massive, :n_state]))
    end = np.concatenate((x[:, -1], v[massive, -1])) if particular else None
    return phi, end


def sorted_eigenvalues(phi: np.ndarray) -> np.ndarray:
    """Eigenvalues of ``phi`` in decreasing modulus, complex (numpy returns a real array when they
    all are real)."""
    values = np.linalg.eigvals(phi).astype(complex)
    return values[np.argsort(-np.abs(values), kind="stable")]


def multiplier_errors(multipliers: np.ndarray, coarse: np.ndarray, factor: float) -> np.ndarray:
    """``factor * |mu - nearest N/2 multiplier|`` (2n,): the error estimate of each multiplier."""
    return factor * np.abs(multipliers[:, None] - coarse[None, :]).min(axis=1)


def modulus_errors(multipliers: np.ndarray, coarse: np.ndarray, factor: float) -> np.ndarray:
    """``factor * ||mu| - |nearest N/2 multiplier||`` (2n,): the error estimate of each multiplier's
    modulus, the error bar of the stability verdict. The phase error of a lightly damped mode (its
    frequency error over a period) is usually far larger and does not move the multiplier across
    the unit circle, so it must not widen the bar."""
    nearest = np.abs(multipliers[:, None] - coarse[None, :]).argmin(axis=1)
    return factor * np.abs(np.abs(multipliers) - np.abs(coarse[nearest]))


def raise_on_singular(system: PeriodicSystem, status: int) -> None:
    """Turn a kernel status (sample index of a singular matrix, or -1) into a ShootingError."""
    if status < 0:
        return
    t_k = status * system.step
    what = "mass matrix M" if status == 0 else "step's effective matrix (M + gamma h C + beta h^2 K for Newmark)"
    raise ShootingError(
        f"system: the {what} is singular at sample {status} (t = {t_k:.6g} s); "
        "check the mass, damping and stiffness there"
    )


def analyse_multipliers(phi: np.ndarray, system: PeriodicSystem):
    """Multipliers sorted by decreasing modulus, and the step rate ``h |v| / |x|`` of each eigenvector
    (``v`` with the rates of first-order coordinates, from their row equations at t = 0)."""
    values, vectors = sorted_eigen(phi)
    return values, step_rates_of(vectors, system)


def sorted_eigen(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues (s,) of ``phi`` in decreasing modulus (complex; real-valued when all are real) and
    their eigenvectors (s, s), columns in the same order."""
    values, vectors = np.linalg.eig(phi)
    order = np.argsort(-np.abs(values), kind="stable")
    values, vectors = values[order], vectors[:, order]
    if np.all(values.imag == 0.0):
        values = values.real.astype(complex)
    return values, vectors


def step_rates_of(vectors: np.ndarray, system: PeriodicSystem) -> np.ndarray:
    """The step rate ``h |v| / |x|`` (s,) of each eigenvector column of ``vectors`` (s, s) of the
    monodromy of ``system`` (``v`` with the rates of first-order coordinates, from their row equations
    at t = 0); inf where ``x`` vanishes."""
    n = system.n_dof
    norm_x = np.linalg.norm(vectors[:n], axis=0)
    velocities = vectors[n:]
    if system.n_first_order:
        velocities = np.vstack((velocities, start_rates(system) @ vectors))
    norm_v = np.linalg.norm(velocities, axis=0)
    with np.errstate(divide="ignore"):
        return np.where(norm_x > 0.0, system.step * norm_v / np.where(norm_x > 0.0, norm_x, 1.0), np.inf)


def near_resonance(multipliers, step_rates, tol, multiplier_errors=None):
    """Indices of resolved multipliers within ``max(tol, 2 * error)`` of +1, and of unresolved ones within ``tol``."""
    distance = np.abs(1.0 - multipliers)
    resolved = step_rates <= RESOLVED_STEP_RATE
    limit = np.full(distance.shape, tol)
    if multiplier_errors is not None:
        # A multiplier whose discretisation error is comparable to its distance from +1 may sit on it.
        limit = np.maximum(limit, 2.0 * multiplier_errors)
    physical = np.flatnonzero(resolved & (distance <= limit))
    spurious = np.flatnonzero(~resolved & (distance <= tol))
    return physical, spurious
