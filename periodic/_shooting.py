"""Periodic steady state by shooting: ``(I - Phi) z0 = b``, then one forced run from ``z0``.

One kernel call integrates the 2n unit states and the particular solution from rest (2n+1 columns,
one factorisation per step) and gives ``Phi`` and ``b``; a second call with one column integrates the
periodic solution from ``z0 = [x0; v0]`` and stores it at every sample.  The error estimate repeats
the computation on N/2 steps: for a scheme of order p, ``|x_N - x_{N/2}| / (2^p - 1)`` estimates the
error of ``x_N`` (``Newmark.error_factor``).  A time-symmetric scheme (``gamma = 1/2``) has a global
error in even powers of h, so one Richardson step, ``x_N + (x_N - x_{N/2}) / 3``, is of order 4.
The N/2 solution comes back in the result (``x_coarse``, ``error_factor``) so that callers estimate
the error of anything linear in x (observables) without a second run.

The estimate is trusted only in its asymptotic range: a third run on N/4 steps (a quarter of the cost
of the N-step run) gives the ratio of successive differences, checked by
:func:`periodic.error_verdict`; stability is decided with the multipliers' own error bars by
:func:`periodic.stability_verdict`.  ``status`` is the worst of the two and of the resonance check.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from ._floquet import (
    RESONANCE_TOL,
    NearResonanceWarning,
    analyse_multipliers,
    modulus_errors,
    monodromy,
    near_resonance,
    raise_on_singular,
    sorted_eigenvalues,
)
from ._floquet import (
    multiplier_errors as estimate_multiplier_errors,
)
from ._scheme import DEFAULT_SCHEME, Scheme, get_scheme
from ._system import (
    PeriodicError,
    PeriodicSystem,
    ShootingError,
    check_coarsenable,
    check_quarterable,
    check_system,
    check_tol,
    every_other_sample,
)
from ._verdict import (
    STABILITY_TOL,
    STATUSES,
    error_verdict,
    resolved_radius,
    stability_verdict,
    unresolved_multipliers,
    worst_status,
)

logger = logging.getLogger(__name__)

#: Values of ``SteadyState.status``.
STATUS_OK = "ok"
STATUS_NEAR_RESONANCE = "near_resonance"
STATUS_UNRESOLVED = "unresolved_stiff_mode"
STATUS_INACCURATE = "inaccurate"


@dataclass(frozen=True)
class SteadyState:
    """Periodic solution of ``M x'' + C x' + K x = f`` over one period.

    Attributes
    ----------
    t : ndarray (N+1,)
        Sample times, s.
    x, v, a : ndarray (N+1, n)
        Displacement, velocity, acceleration of the periodic solution (units of x, x/s, x/s^2).
    monodromy : ndarray (s, s)
        ``Phi`` of the state ``[x; v]`` (Richardson-extrapolated when ``extrapolated``); s = 2n, or
        ``system.n_state`` with first-order coordinates (state ``[x; v[massive]]``).
    multipliers : ndarray (s,) complex
        Floquet multipliers (eigenvalues of ``monodromy``), decreasing modulus.
    step_rates : ndarray (2n,)
        ``|lam h|`` estimate of each multiplier's mode; > 1 means unresolved (see ``periodic._floquet``).
    spectral_radius : float
        The largest ``|multiplier|`` of the resolved modes (``step_rates <= 1``; the unresolved
        ones are ``unresolved_multipliers``), or of the critical multiplier where the verdict is
        ``unstable`` or no mode is resolved (``periodic._verdict.resolved_radius``).
    spectral_radius_error : float
        Error bar of ``|critical_multiplier|`` (twice the N/2 error estimate of its modulus, see
        :func:`periodic.stability_verdict`; NaN when
        ``multiplier_errors`` is None).
    critical_multiplier : complex
        The multiplier that decides stability: the largest among the resolved modes and the
        unresolved ones growing beyond their error bar (:func:`periodic.stability_verdict`).
    instability_kind : str
        ``"fold"``, ``"period_doubling"`` or ``"secondary_hopf"`` where unstable or marginal, else ``""``.
    is_stable : bool
        False only where the stability verdict is ``"unstable"``: ``|critical_multiplier| - 1`` above its
        error plus ``stability_tol``.
    condition_number : float
        2-norm condition number of ``I - Phi`` (N-step monodromy) solved for the initial state: it
        bounds the rounding error of the periodic initial state (relative error <~ cond * eps).  It
        mixes the units of x and v, so it is large for stiff systems even far from resonance, and it
        can be 1 at resonance (``I - Phi`` a small multiple of a rotation); use ``status``.
    inverse_norm : float
        ``||(I - Phi)^-1||_2``: the amplification of the state mismatch of the particular solution
        into the periodic initial state, about ``1 / min |1 - mu|`` (large near resonance).
    error_estimate : float
        Estimated max abs error of ``x`` (units of x), from the N/2-step solution; NaN when skipped
        (``estimate_error=False``).  With ``extrapolated`` it is the estimate for the N-step result,
        a conservative bound for the extrapolated one.  Always
        ``error_factor * max|x[::2] - x_coarse|``.
    x_coarse : ndarray (N/2+1, n) or None
        Displacement of the N/2-step periodic solution at ``t[::2]`` (None when skipped).  The error of
        any quantity ``o`` linear in x (an observable) is estimated, like ``error_estimate``, by
        ``error_factor * |o(x[::2]) - o(x_coarse)|``, with no second run.
    x_quarter : ndarray (N/4+1, n) or None
        Displacement of the N/4-step periodic solution at ``t[::4]`` (None without ``estimate_error``).
    error_trusted : bool
        The estimate is in its asymptotic range (:func:`periodic.error_verdict` on
        ``max|x_N - x_{N/2}|`` and ``max|x_{N/2} - x_{N/4}|`` of the N-step, not extrapolated, runs);
        False when not checked (``estimate_error=False``).
    error_ratio : float
        ``max|x_{N/2} - x_{N/4}| / max|x_N - x_{N/2}|``, ``2**order`` in the asymptotic range (NaN when
        not checked).
    error_factor : float
        The factor of that estimate (NaN when skipped): ``scheme.error_factor = 1 / (2^p - 1)`` for a
        scheme of order p; with ``extrapolated``, ``1 / 2^p``, since then
        ``x[::2] - x_coarse = 2^p / (2^p - 1) (x_N - x_{N/2})`` and the estimate stays the N-step one.
    multiplier_errors : ndarray (2n,) or None
        Estimated error of each multiplier from the N/2 run (None when skipped); with
        ``extrapolated`` the N-step estimate, a conservative bound.
    periodicity_residual : float
        ``max |x(T) - x(0)|`` of the final forced run (rounding times conditioning).
    status : str
        The most severe (:data:`periodic.STATUSES`) of: the stability verdict (``"unstable"``,
        ``"marginal"``), the error check (``"inaccurate"``), ``"near_resonance"`` (a resolved multiplier
        near +1; also warned with :class:`NearResonanceWarning`; an untrusted error estimate there is
        reported in the message but stays ``"near_resonance"``: refining would not help) and
        ``"unresolved_stiff_mode"`` (a multiplier near +1 belongs to a mode the step does not
        resolve; the exact multiplier is not near +1); else ``"ok"``.
    message : str
        Every non-ok part in words, most severe first (for ``"ok"``: the radius and the error check).
    n_steps : int
    extrapolated : bool
    scheme : Scheme
        The scheme used.
    run_time : float
        Wall time in s, including the N/2 and N/4 runs.
    unresolved_multipliers : ndarray (k,) complex
        The multipliers of the modes the step does not resolve (step rate > 1), decreasing
        modulus: the scheme's values, not the system's, reported apart from ``spectral_radius``.

    coarse_monodromy : ndarray (s, s) or None
        ``Phi`` of the N/2-step run (None when skipped), and ``v_coarse``, ``a_coarse`` (N/2+1, n) its
        periodic rates and accelerations: what ``periodic.response_derivative`` differentiates for
        its error estimate without a second shooting.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    monodromy: np.ndarray
    multipliers: np.ndarray
    step_rates: np.ndarray
    spectral_radius: float
    spectral_radius_error: float
    critical_multiplier: complex
    instability_kind: str
    is_stable: bool
    condition_number: float
    inverse_norm: float
    error_estimate: float
    x_coarse: np.ndarray | None
    error_factor: float
    x_quarter: np.ndarray | None
    error_trusted: bool
    error_ratio: float
    multiplier_errors: np.ndarray | None
    periodicity_residual: float
    status: str
    message: str
    n_steps: int
    extrapolated: bool
    scheme: Scheme
    run_time: float
    unresolved_multipliers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=complex))

    coarse_monodromy: np.ndarray | None = None
    v_coarse: np.ndarray | None = None
    a_coarse: np.ndarray | None = None


@dataclass(frozen=True)
class _Shot:
    phi: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    condition_number: float
    inverse_norm: float
    periodicity_residual: float


def steady_state(
    system: PeriodicSystem,
    *,
    extrapolate: bool = False,
    estimate_error: bool = True,
    scheme: Scheme | str = DEFAULT_SCHEME,
    resonance_tol: float = RESONANCE_TOL,
    stability_tol: float = STABILITY_TOL,
) -> SteadyState:
    """Periodic steady state of ``system`` by shooting with ``scheme`` (a :class:`Scheme`, e.g. a
    :class:`Newmark`, or a name in ``SCHEMES``) on its N steps.

    ``extrapolate=True`` returns the Richardson extrapolation of the N and N/2 results (order 4;
    needs a symmetric scheme, ``gamma = 1/2``, and an even N >= 4).  ``estimate_error=True`` runs N/2
    and N/4 steps (N a multiple of 4, >= 8) for the error estimate and its asymptotic-range check
    (together about 3/4 of the cost of the N-step run); ``estimate_error=False`` skips both when not
    extrapolating (the stability verdict then has no error bar).  Raises :class:`ShootingError` if
    ``I - Phi`` is exactly singular (a multiplier at +1 to rounding) or a step's matrix is.
    """
    start = time.perf_counter()
    check_system(system)
    scheme = get_scheme(scheme)
    resonance_tol = check_tol("resonance_tol", resonance_tol)
    stability_tol = check_tol("stability_tol", stability_tol, STABILITY_TOL)
    if extrapolate and not scheme.symmetric:
        raise PeriodicError(
            f"extrapolate: Richardson extrapolation gains two orders only for a symmetric scheme (Newmark's with "
            f"gamma = 1/2), got {scheme!r}; use a symmetric scheme (e.g. scheme='trapezoidal') or extrapolate=False"
        )
    if estimate_error:
        check_quarterable(system.n_steps, "use such an n_steps or estimate_error=False")
    elif extrapolate:
        check_coarsenable(system.n_steps, "use an even n_steps or extrapolate=False")
    fine = _shoot(system, scheme)
    phi, x, v, a = fine.phi, fine.x, fine.v, fine.a
    error_estimate = error_factor = error_ratio = float("nan")
    x_coarse = x_quarter = multiplier_errors = radius_errors = check = None
    coarse = None
    coarse_multipliers = quarter_multipliers = None
    multipliers, step_rates = analyse_multipliers(phi, system)
    if estimate_error or extrapolate:
        coarse_system = every_other_sample(system)
        coarse = _shoot(coarse_system, scheme, conditioning=False)  # its conditioning is not reported
        x_coarse = coarse.x
        factor = error_factor = scheme.error_factor
        difference = float(np.abs(x[::2] - coarse.x).max())
        error_estimate = difference * factor
        coarse_multipliers = sorted_eigenvalues(coarse.phi)
        multiplier_errors = estimate_multiplier_errors(multipliers, coarse_multipliers, factor)
        radius_errors = modulus_errors(multipliers, coarse_multipliers, factor)
        if estimate_error:
            quarter = _shoot(every_other_sample(coarse_system), scheme, conditioning=False)
            x_quarter, quarter_multipliers = quarter.x, sorted_eigenvalues(quarter.phi)
            coarse_difference = float(np.abs(coarse.x[::2] - x_quarter).max())
            check = error_verdict(difference, coarse_difference, scheme.order, scale=float(np.abs(x).max()),
                                  n_steps=system.n_steps)
            error_ratio = check.ratio
        if extrapolate:
            phi = phi + factor * (phi - coarse.phi)
            x = _richardson(x, coarse.x, factor)
            v = _richardson(v, coarse.v, factor)
            a = _richardson(a, coarse.a, factor)
            # x[::2] - x_coarse is now (1 + factor) times the N-step difference.
            error_factor = factor / (1.0 + factor)
            fine_multipliers = multipliers
            multipliers, step_rates = analyse_multipliers(phi, system)
            # The Richardson correction estimates the error of the N-step values: a conservative
            # bound for the extrapolated ones, as for error_estimate.
            multiplier_errors = estimate_multiplier_errors(multipliers, fine_multipliers, 1.0)
            radius_errors = modulus_errors(multipliers, fine_multipliers, 1.0)
    stability = stability_verdict(multipliers, radius_errors, step_rates, stability_tol=stability_tol,
                                  coarse=coarse_multipliers if estimate_error and not extrapolate else None,
                                  quarter=quarter_multipliers, order=scheme.order, n_steps=system.n_steps)
    physical, spurious = near_resonance(multipliers, step_rates, resonance_tol, multiplier_errors)
    resonance = _resonance_verdict(multipliers, step_rates, physical, spurious, fine, error_estimate)
    if physical.size and np.all(np.abs(1.0 - multipliers[physical]) > resonance_tol):
        # near +1 only within twice the multipliers' error estimate, not within resonance_tol: at this
        # step a resonance can neither be shown nor excluded, and refining n_steps settles it
        resonance = (STATUS_INACCURATE, f"refine n_steps: possibly {resonance[1]} (the multiplier is "
                     f"farther than resonance_tol = {resonance_tol:g} from +1, but within twice its error)")
    status, message = _combine(stability, resonance, check)
    radius, radius_error = resolved_radius(multipliers, step_rates, stability, radius_errors)
    if resonance[0] == STATUS_NEAR_RESONANCE:
        warnings.warn(resonance[1], NearResonanceWarning, stacklevel=2)
    elif resonance[0] == STATUS_UNRESOLVED:
        logger.debug(resonance[1])
    return SteadyState(
        t=system.t,
        x=x,
        v=v,
        a=a,
        monodromy=phi,
        multipliers=multipliers,
        step_rates=step_rates,
        spectral_radius=radius,
        spectral_radius_error=float("nan") if multiplier_errors is None else radius_error,
        critical_multiplier=stability.critical_multiplier,
        instability_kind=stability.kind,
        is_stable=stability.is_stable,
        condition_number=fine.condition_number,
        inverse_norm=fine.inverse_norm,
        error_estimate=error_estimate,
        x_coarse=x_coarse,
        error_factor=error_factor,
        x_quarter=x_quarter,
        error_trusted=check is not None and check.trusted,
        error_ratio=error_ratio,
        multiplier_errors=multiplier_errors,
        periodicity_residual=fine.periodicity_residual,
        status=status,
        message=message,
        n_steps=system.n_steps,
        extrapolated=bool(extrapolate),
        scheme=scheme,
        run_time=time.perf_counter() - start,
        unresolved_multipliers=unresolved_multipliers(multipliers, step_rates),

        coarse_monodromy=None if coarse is None else coarse.phi,
        v_coarse=None if coarse is None else coarse.v,
        a_coarse=None if coarse is None else coarse.a,
    )


def _shoot(system: PeriodicSystem, scheme: Scheme, *, conditioning: bool = True) -> _Shot:
    """The periodic solution on ``system``'s grid; ``conditioning=False`` skips the SVD of ``I - Phi``
    (condition number and inverse norm NaN), for the N/2 and N/4 runs, whose conditioning is not reported."""
    n = system.n_dof
    phi, end = monodromy(system, scheme, particular=True)
    system_matrix = np.eye(system.n_state) - phi
    try:
        z0 = np.linalg.solve(system_matrix, end)
    except np.linalg.LinAlgError:
        distance = np.abs(1.0 - np.linalg.eigvals(phi)).min()
        raise ShootingError(
            f"system: I - Phi is singular (a Floquet multiplier is within {distance:.3g} of +1): the "
            "system is at resonance and has no unique periodic solution"
        ) from None
    condition_number = inverse_norm = float("nan")
    if conditioning:
        singular_values = np.linalg.svd(system_matrix, compute_uv=False)
        condition_number = float(singular_values[0] / singular_values[-1])
        inverse_norm = float(1.0 / singular_values[-1])
    x = np.ascontiguousarray(z0[:n, None])
    v = np.zeros((n, 1))
    v[system.massive, 0] = z0[n:]  # the rates of first-order coordinates are set by the kernel's start
    a = np.empty((n, 1))
    n_samples = system.n_steps + 1
    xs, vs, as_ = np.empty((n_samples, n, 1)), np.empty((n_samples, n, 1)), np.empty((n_samples, n, 1))
    status = scheme.march(system, np.ones(1), x, v, a, xs, vs, as_)
    raise_on_singular(system, status)
    xs, vs, as_ = xs[:, :, 0], vs[:, :, 0], as_[:, :, 0]
    residual = float(np.abs(xs[-1] - xs[0]).max())
    return _Shot(phi, xs, vs, as_, condition_number, inverse_norm, residual)


def _richardson(fine: np.ndarray, coarse: np.ndarray, factor: float) -> np.ndarray:
    """``fine + factor (fine - coarse)`` at the common samples; the O(h^2) correction is linearly
    interpolated at the odd samples, an O(h^2) * O(h^2) error that keeps order 4."""
    correction = factor * (fine[::2] - coarse)
    out = fine.copy()
    out[::2] += correction
    out[1::2] += 0.5 * (correction[:-1] + correction[1:])
    return out


def _combine(stability, resonance, check):
    """``(status, message)``: the worst of the stability verdict, the resonance verdict ``(status,
    message)`` and the error check (None when not run), with every non-ok message, most severe first."""
    parts = [(stability.status, stability.message), resonance]
    if check is not None:
        if resonance[0] == STATUS_NEAR_RESONANCE and not check.trusted:
            # Near resonance the response hangs on the multipliers' discretisation error, so the levels
            # disagree at any N: the resonance, not the step, is the cause (refining would not help).
            parts.append((STATUS_NEAR_RESONANCE, f"error estimate not trusted near resonance ({check.message})"))
        else:
            parts.append((check.status, check.message))
    status = worst_status(*(part[0] for part in parts))
    if status == STATUS_OK:
        checked = "" if check is None else f"; {check.message}"
        return status, f"ok: {stability.message}{checked}"
    ranked = sorted((part for part in parts if part[0] != STATUS_OK), key=lambda part: STATUSES.index(part[0]))
    return status, "; ".join(part[1] for part in ranked)


def _resonance_verdict(multipliers, step_rates, physical, spurious, shot: _Shot, error_estimate):
    """Status and message from the indices of near-+1 multipliers with resolved / unresolved modes."""
    if not (physical.size or spurious.size):
        return STATUS_OK, "ok"
    candidates = physical if physical.size else spurious
    i = candidates[np.argmin(np.abs(1.0 - multipliers[candidates]))]
    closeness = f"Floquet multiplier {multipliers[i]:.8g} is {abs(1.0 - multipliers[i]):.3g} from +1"
    conditioning = f"cond(I - Phi) = {shot.condition_number:.3g}, ||(I - Phi)^-1|| = {shot.inverse_norm:.3g}"
    if physical.size:
        return STATUS_NEAR_RESONANCE, (
            f"near resonance: {closeness} (its mode is resolved, step rate {step_rates[i]:.3g}); "
            f"{conditioning}. The periodic response is amplified about 1/|1 - mu| times and is sensitive "
            "to the parameters"
            + ("; this multiplier is on the unit circle (an undamped mode): at exact resonance such a "
               "system has no periodic solution (its response grows without bound), whatever the step."
               if abs(abs(multipliers[i]) - 1.0) <= 1e-6 else ".")
        )
    return STATUS_UNRESOLVED, (
        f"{closeness}, but its mode changes by exp({step_rates[i]:.3g}) per step: a stiff mode the step "
        f"does not resolve, whose exact multiplier is not near +1 (not a resonance). {conditioning}; "
        f"error estimate of x = {error_estimate:.3g}."
    )
