"""Verdicts in words: the status vocabulary, stability with its own error bar, and the asymptotic-range
check of the N/2 error estimate.

Stability.  A multiplier ``mu`` whose modulus has the error estimate ``e`` (from the N/2 run: the
phase error of a lightly damped mode is far larger and does not move it across the unit circle) has
the error bar
``E = ERROR_BAR_FACTOR * e``; it is decided unstable only where ``|mu| - 1 > E + stability_tol``; where
``||mu| - 1| <= E + stability_tol`` the verdict is ``marginal`` (an undamped system, whose multipliers
lie on the unit circle up to the scheme's error).  The factor 2: where the exact multiplier is on the
circle and the scheme's moves it out by ``c h^2``, the N/2 estimate is ``c h^2 (1 + O(h^2))``, as
large as the excess itself; a bar of one estimate would decide such a case by the sign of the O(h^2)
remainder (``near_resonance`` uses the same factor).
The critical multiplier is the largest one among the resolved modes (``step_rate <= 1``, see
``periodic._floquet``).  An unresolved mode's discrete multiplier does not approximate the exact
one: with constant coefficients the A-stable scheme keeps a decaying mode inside the unit circle
whatever its (wrong) value, but with time-varying coefficients an undamped stiff mode can leave the
circle by a discretisation artefact (the undamped four-bar's axial modes: |mu| - 1 = 1.2e-3 at
N = 256 while every resolved multiplier is within 1e-7 of the circle), and a real instability of
such a mode cannot be resolved either.  So an unresolved mode outside the circle beyond its error
bar, while the resolved ones are stable or marginal, gives ``inaccurate`` ("refine n_steps"), not
``unstable``; a real divergence fast enough to be unresolved at a usable step (growth by more than
e per step) is rare, and refining shows it.  The kind of the critical multiplier: real near +1 a
fold or divergence, real near -1 period doubling, a complex pair a secondary Hopf
(Neimark-Sacker) bifurcation.  A resolved multiplier outside the circle whose modulus does not
converge like the scheme over N, N/2, N/4 is ``inaccurate``; ``is_stable`` is still False there
where the three moduli converge geometrically at their own rate to a value above 1 beyond the rest
of that series (the radius has converged above 1, ``MIN_CONVERGENCE_RATIO``): whatever status word
a point ends with, ``is_stable`` says what the converged radius says.

Error estimate.  ``|x_N - x_{N/2}| / (2^p - 1)`` estimates the error of ``x_N`` only in the asymptotic
range, where the error is ``C h^p``.  A third level N/4 tests it: the ratio of successive differences
``r = |x_{N/2} - x_{N/4}| / |x_N - x_{N/2}|`` tends to ``2^p``.  If the errors shrank geometrically
by ``r`` per halving of h, the estimate would be ``(r - 1) / (2^p - 1)`` times the true error: the
accepted band ``-ORDER_TOLERANCE <= log2 r - p <= CONSERVATIVE_ORDERS`` (r in [2.83, 16] at order 2)
keeps that factor in [0.61, 5]: an estimate too small is refused, a conservative one kept.  A ratio near 2^p can also
be a coincidence of a grid far too coarse (measured: the
four-bar at N = 8 has r = 3.06 and an estimate 22x too small): an N/4 grid of 2 steps puts the
fundamental harmonic at its Nyquist frequency and resolves nothing, so the N/4 grid must have at
least ``MIN_QUARTER_STEPS`` = 4 steps (N >= 16).  Finally an estimate may be trustworthy and still
too large: above ``MAX_RELATIVE_ERROR`` of the solution's size the result is ``inaccurate`` too.
The measurements behind these numbers are in docs/methods.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._system import PeriodicError

#: The status vocabulary of every result of the project, most severe first.
STATUSES = (
    "failed",
    "unstable",
    "outside_linear_range",
    "inaccurate",
    "near_resonance",
    "marginal",
    "unresolved_stiff_mode",
    "ok",
)
_SEVERITY = {status: rank for rank, status in enumerate(STATUSES)}

#: Default tolerance of the stability verdict: unstable only where spectral radius - 1 exceeds its
#: error estimate plus STABILITY_TOL.  The multipliers of an undamped (conservative) system lie on the
#: unit circle; numerically their moduli differ from 1 by rounding, about eps * cond(eigenvectors) ~
#: 1e-14..1e-12, and by up to sqrt(eps) ~ 1.5e-8 times a modest factor where two multipliers collide
#: (a Jordan block, e.g. on a transition curve of Mathieu's equation).  1e-6 stays above both, and far
#: below growth rates of practical interest (|lam| > 1e-6 / T).
STABILITY_TOL = 1e-6
#: The error bar of a multiplier is this many times its N/2 error estimate (see the module notes).
ERROR_BAR_FACTOR = 2.0
#: A multiplier whose mode changes by more than a factor e per step (``step_rate > 1``) is unresolved.
RESOLVED_STEP_RATE = 1.0
#: The estimate is trusted where the observed order log2(ratio) is at least the scheme's order less
#: this (a smaller ratio: the errors shrink more slowly than assumed and the estimate is too small) ...
ORDER_TOLERANCE = 0.5
#: ... and at most the order plus this: a larger ratio means the errors shrink faster than assumed, so
#: the estimate is conservative, by (r - 1) / (2^p - 1) for geometric decay (at most 5x at order 2,
#: inside the 0.5x-20x the tests demand; the slider-crank at its own 150 rad/s had r = 9.3 and an
#: estimate 1.16x the true error).
CONSERVATIVE_ORDERS = 2.0
#: ... and where the N/4 grid has at least this many steps per period (2 steps sample the fundamental
#: harmonic at its Nyquist frequency).
MIN_QUARTER_STEPS = 4
#: An unresolved mode outside the unit circle counts as unstable only if its modulus converges over
#: N, N/2, N/4 and it at least doubles per period.  Matching a stiff mode's multiplier across the
#: three grids is unreliable (at N = 1024 the undamped four-bar's axial artefact, |mu| - 1 = 4e-4 and
#: shrinking as h^2, passed the convergence test by a mismatch), and the artefacts of neutral modes
#: are small (1e-4..1e-3 there), while a real divergence fast enough to be unresolved grows by orders
#: of magnitude (six_bar at 260 rad/s: |mu| = 13 at N = 128, 13.1 converged).  Below, ``inaccurate``.
UNRESOLVED_GROWTH = 2.0
#: A modulus whose successive differences over N, N/2, N/4 shrink by at least this ratio converges
#: geometrically, if not at the scheme's rate: where it is above 1 by far more than the rest of that
#: series, the radius has converged above 1 and ``is_stable`` is False (status ``inaccurate``).
#: Measured: four_bar_fem4 at 185 rad/s, N = 64, ratio 72 (1.116; 1.114 converged); undamped,
#: N = 256, ratio 2.3 (1.362); six_bar at 190 rad/s, N = 16 and 32, ratios 1.03 and 1.16 (2.33 and
#: 1.44 where the converged value is 0.81): not converged.
MIN_CONVERGENCE_RATIO = 1.5
#: Where no mode is resolved and even the slowest changes by more than exp(this) per step, the
#: largest multiplier is the scheme's alone and a stable verdict is ``unresolved_stiff_mode``, not
#: ``ok`` (a 1000x stiffer coupler of four_bar_fem4 at 100 rad/s, N = 256: smallest step rate 2.3,
#: |mu|max 0.98 against a resolved radius below 1e-4). Just past 1 the slowest mode's multiplier is
#: still about right (four_bar_fem4 at 25 rad/s, N = 64: 1.16), and the radius stands as it is.
NO_RESOLVED_RATE = 2.0
#: An estimated error above this fraction of the solution's size is too large, however trustworthy.
MAX_RELATIVE_ERROR = 0.1
#: Differences below this fraction of the solution's size are round-off: nothing left to estimate.
ROUNDOFF_LIMIT = 1e-10
# A multiplier within this relative distance of the real axis (plus its error) counts as real: two
# real multipliers that collide split into a complex pair of imaginary part ~ sqrt(eps).
_REAL_AXIS_TOL = 1e-7

_KIND_WORDS = {
    "fold": "a real multiplier past +1 (fold or divergence)",
    "period_doubling": "a real multiplier past -1 (period doubling)",
    "secondary_hopf": "a complex pair off the unit circle (secondary Hopf, quasi-periodic growth)",
}


def worst_status(*statuses: str) -> str:
    """The most severe of ``statuses`` in the order of :data:`STATUSES` (``"ok"`` if none given)."""
    worst = len(STATUSES) - 1
    for status in statuses:
        try:
            worst = min(worst, _SEVERITY[status])
        except (KeyError, TypeError):
            raise PeriodicError(f"status: expected one of {', '.join(STATUSES)}, got {status!r}") from None
    return STATUSES[worst]


@dataclass(frozen=True)
class Stability:
    """Stability verdict of a set of Floquet multipliers with their error estimates.

    Attributes
    ----------
    status : str
        ``"ok"`` (stable), ``"unstable"``, ``"marginal"`` (spectral radius within its error bar of 1) or
        ``"inaccurate"`` (an unresolved mode outside the circle: refine n_steps).
    message : str
        The verdict in words, with the critical multiplier, its error and the tolerance.
    is_stable : bool
        False for ``"unstable"``, and for ``"inaccurate"`` where the modulus converges over N, N/2,
        N/4 at an observed rate other than the scheme's to a value above 1 beyond that rate's error
        (the radius has converged above 1; ``MIN_CONVERGENCE_RATIO``).
    spectral_radius : float
        ``|critical_multiplier|``: the radius over the resolved modes (over the growing unresolved
        one for ``"inaccurate"``).
    spectral_radius_error : float
        Error bar of ``critical_multiplier``: ``ERROR_BAR_FACTOR`` times its error estimate (0 when no
        errors were given).  Unstable only where ``spectral_radius - 1`` exceeds it plus the tolerance.
    critical_multiplier : complex
        The multiplier that decides the verdict (NaN when there is none).
    kind : str
        For ``"unstable"`` and ``"marginal"``: ``"fold"`` (real, near +1), ``"period_doubling"`` (real,
        near -1), ``"secondary_hopf"`` (complex pair); ``""`` when stable.
    """

    status: str
    message: str
    is_stable: bool
    spectral_radius: float
    spectral_radius_error: float
    critical_multiplier: complex
    kind: str


def stability_verdict(multipliers, multiplier_errors, step_rates, *, stability_tol: float = STABILITY_TOL,
                      coarse=None, quarter=None, order: int = 2, n_steps: int | None = None) -> Stability:
    """Stability of multipliers (2n,) complex with error estimates (2n,) (or None: no error bar) and
    the step rates (2n,) of their modes; see the module notes for the rules. ``coarse`` and ``quarter``
    (2n,): the multipliers on N/2 and N/4 steps, with the scheme's ``order`` and ``n_steps`` (N): the
    modulus of a critical multiplier outside the circle must then converge like the scheme
    (``error_verdict`` on its successive differences) for ``unstable``, else the verdict is
    ``inaccurate`` (refine n_steps); an unresolved mode outside the circle is ``unstable`` only so."""
    # A plain loop: for the 2n <= 100 multipliers of practical systems it costs less than the numpy
    # calls it replaces, and the verdict runs with every steady state.
    values = [complex(value) for value in np.asarray(multipliers).tolist()]
    rates = np.asarray(step_rates).tolist()
    if multiplier_errors is None:
        errors = [0.0] * len(values)
    else:
        errors = (ERROR_BAR_FACTOR * np.asarray(multiplier_errors, dtype=float)).tolist()
    if not values:
        return Stability("ok", "stable: no multipliers (no coordinates)", True, 0.0, 0.0, complex("nan"), "")
    critical = largest = growing = None  # the largest resolved, the largest, the largest growing unresolved
    for i, (value, rate, error) in enumerate(zip(values, rates, errors)):
        modulus = abs(value)
        if largest is None or modulus > abs(values[largest]):
            largest = i
        if rate <= RESOLVED_STEP_RATE:
            if critical is None or modulus > abs(values[critical]):
                critical = i
        elif modulus - 1.0 > error + stability_tol and (growing is None or modulus > abs(values[growing])):
            growing = i
    none_resolved = critical is None
    if none_resolved:  # only unresolved modes: the largest stands in
        critical = largest
    # an unresolved growing mode decides only where the resolved modes do not already say unstable
    resolved_unstable = abs(values[critical]) - 1.0 > errors[critical] + stability_tol
    unresolved = (growing is not None and abs(values[growing]) > abs(values[critical])
                  and not resolved_unstable)
    if unresolved:
        critical = growing
    mu, error = values[critical], errors[critical]
    radius = abs(mu)
    excess = radius - 1.0
    bar = error + stability_tol
    if abs(mu.imag) <= error + _REAL_AXIS_TOL * radius:
        kind = "fold" if mu.real > 0.0 else "period_doubling"
    else:
        kind = "secondary_hopf"
    where = (f"Floquet multiplier {mu:.6g}, |mu| - 1 = {excess:.3g}, its error bar {error:.2g} + "
             f"tolerance {stability_tol:.2g}")
    converged = None if coarse is None or quarter is None else _modulus_convergence(
        mu, np.asarray(coarse), np.asarray(quarter), order, n_steps)
    if unresolved and not (converged is not None and converged.trusted and radius >= UNRESOLVED_GROWTH):
        # An unresolved mode's discrete multiplier does not approximate the exact one: with
        # time-varying coefficients an undamped stiff mode can leave the unit circle by a
        # discretisation artefact (the undamped four-bar's axial modes at N = 128..1024). Only a
        # growth whose modulus converges like the scheme (N, N/2, N/4) is taken as real.
        message = (f"inaccurate: refine n_steps: a mode the step does not resolve (step rate "
                   f"{rates[critical]:.3g} > {RESOLVED_STEP_RATE:g}) has the multiplier {mu:.6g}, |mu| - 1 = "
                   f"{excess:.3g}, and its modulus has not converged, so its growth cannot be told from "
                   f"the discretisation error at this step")
        return Stability("inaccurate", message, True, radius, error, mu, kind)
    if excess > bar and converged is not None and not converged.trusted:
        # a growth that does not converge like the scheme: a coarse step's artefact as often as not
        # (measured: six_bar at 190 rad/s, N = 16, |mu| = 2.33 where the converged value is 0.81).
        # But where the three levels converge at their own observed rate to a modulus above 1 by
        # far more than the error that rate implies, the radius has converged above 1: unstable
        # whatever the status word (four_bar_fem4 at 185 rad/s, N = 64: 1.116, 1.114 converged).
        above, bound = _converged_above_one(mu, np.asarray(coarse), np.asarray(quarter), order, stability_tol)
        if above:
            message = (f"inaccurate: refine n_steps: the multiplier is unstable ({where}) and its modulus "
                       f"is above 1 beyond the error {bound:.2g} of its observed convergence over N, "
                       f"N/2, N/4, but that convergence is not the scheme's ({converged.message}): "
                       f"not stable, its value not accurate")
            return Stability("inaccurate", message, False, radius, error, mu, kind)
        message = (f"inaccurate: refine n_steps: at this step the multiplier would be unstable ({where}), "
                   f"but its modulus has not converged ({converged.message})")
        return Stability("inaccurate", message, True, radius, error, mu, kind)
    apart = _unresolved_apart(values, rates, radius)
    if excess < -bar:
        error_text = "no error estimate" if multiplier_errors is None else f"error bar {error:.2g}"
        if none_resolved and min(rates) > NO_RESOLVED_RATE:
            # the number is the scheme's, not the system's (a 1000x stiffer coupler at N = 256:
            # 0.98 where the resolved modes' converged radius is below 1e-4)
            message = (f"unresolved stiff modes: no Floquet mode is resolved at this step (every step "
                       f"rate > {RESOLVED_STEP_RATE:g}, the smallest {min(rates):.3g}): the largest "
                       f"multiplier, |mu| = {radius:.6g}, is the scheme's, not the system's; stable (the "
                       f"scheme is A-stable), but refine n_steps about {math.ceil(min(rates)):d}x to see "
                       f"the spectral radius")
            return Stability("unresolved_stiff_mode", message, True, radius, error, mu, "")
        return Stability("ok", f"stable: spectral radius {radius:.6g} of the resolved modes ({error_text})"
                         f"{apart}", True, radius, error, mu, "")
    if excess > bar:
        message = (f"unstable: {_KIND_WORDS[kind]}; {where}: the periodic solution is not reached by the "
                   f"system{apart}")
        return Stability("unstable", message, False, radius, error, mu, kind)
    message = (
        f"marginal: the spectral radius is 1 within its error bar ({where}): neutrally stable to this "
        f"accuracy, as an undamped mode is; refine n_steps to shrink the error bar{apart}"
    )
    return Stability("marginal", message, True, radius, error, mu, kind)


def _unresolved_apart(values: list, rates: list, radius: float) -> str:
    """``"; k multipliers of unresolved modes ... not counted"`` where modes the step does not
    resolve have multipliers larger than the reported ``radius``, else ``""``."""
    larger = [abs(value) for value, rate in zip(values, rates)
              if rate > RESOLVED_STEP_RATE and abs(value) > radius]
    if not larger:
        return ""
    return (f"; {len(larger)} multipliers of modes the step does not resolve (step rate > "
            f"{RESOLVED_STEP_RATE:g}; largest |mu| = {max(larger):.3g}, the scheme's value, not the "
            f"system's) are not counted in the radius")


def resolved_radius(multipliers, step_rates, stability: Stability, modulus_errors=None) -> tuple[float, float]:
    """``(spectral_radius, spectral_radius_error)`` a result reports: the largest modulus of the
    resolved modes (``step_rate <= RESOLVED_STEP_RATE``) and its error bar (``ERROR_BAR_FACTOR``
    times ``modulus_errors`` there, NaN without them); the critical multiplier's where the verdict
    is ``unstable`` (an unresolved divergence converged like the scheme) or no mode is resolved
    (the largest stands in, ``unresolved_stiff_mode``). The unresolved modes' multipliers are
    named apart (``unresolved_multipliers``)."""
    multipliers = np.asarray(multipliers)
    resolved = np.asarray(step_rates) <= RESOLVED_STEP_RATE
    if stability.status == "unstable" or not resolved.any():
        return abs(stability.critical_multiplier), stability.spectral_radius_error
    moduli = np.where(resolved, np.abs(multipliers), -1.0)
    i = int(np.argmax(moduli))
    error = float("nan") if modulus_errors is None else ERROR_BAR_FACTOR * float(modulus_errors[i])
    return float(moduli[i]), error


def unresolved_multipliers(multipliers, step_rates) -> np.ndarray:
    """The multipliers (k,) of the modes the step does not resolve (``step_rate >
    RESOLVED_STEP_RATE``), decreasing modulus: reported apart from the spectral radius."""
    multipliers = np.asarray(multipliers)
    return multipliers[np.asarray(step_rates) > RESOLVED_STEP_RATE]


def _converged_above_one(mu: complex, coarse: np.ndarray, quarter: np.ndarray, order: int,
                         stability_tol: float) -> tuple[bool, float]:
    """``(above, bound)``: whether the moduli of ``mu`` and of its nearest multipliers on N/2 and
    N/4 steps converge geometrically (ratio of successive differences ``r >=
    MIN_CONVERGENCE_RATIO``) to a value above 1, the N and N/2 moduli both more than
    ``ERROR_BAR_FACTOR`` times the error bound ``d (max(1 / (2^p - 1), 1 / (r - 1)))`` (the rest of a
    geometric series of differences at the observed or the scheme's rate, whichever is slower) plus
    ``stability_tol`` above 1."""
    half = coarse[np.argmin(np.abs(coarse - mu))]
    fourth = quarter[np.argmin(np.abs(quarter - half))]
    fine_difference = abs(abs(mu) - abs(half))
    coarse_difference = abs(abs(half) - abs(fourth))
    if fine_difference == 0.0:
        bound = 0.0
    elif coarse_difference < MIN_CONVERGENCE_RATIO * fine_difference:
        return False, math.inf
    else:
        ratio = coarse_difference / fine_difference
        bound = fine_difference * max(1.0 / (2.0**order - 1.0), 1.0 / (ratio - 1.0))
    margin = ERROR_BAR_FACTOR * bound + stability_tol
    return bool(min(abs(mu), abs(half)) - 1.0 > margin), float(bound)


def _modulus_convergence(mu: complex, coarse: np.ndarray, quarter: np.ndarray, order: int, n_steps):
    """``error_verdict`` on the modulus of ``mu`` through its nearest multipliers on N/2 and N/4
    steps: ``||mu| - |mu_{N/2}||`` against ``||mu_{N/2}| - |mu_{N/4}||``, relative to ``max(1, |mu|)``."""
    half = coarse[np.argmin(np.abs(coarse - mu))]
    fourth = quarter[np.argmin(np.abs(quarter - half))]
    return error_verdict(abs(abs(mu) - abs(half)), abs(abs(half) - abs(fourth)), order,
                         scale=max(1.0, abs(mu)), n_steps=n_steps, quantity="|mu|")


@dataclass(frozen=True)
class ErrorCheck:
    """Whether the N/2 error estimate is in its asymptotic range.

    Attributes
    ----------
    trusted : bool
    ratio : float
        ``|x_{N/2} - x_{N/4}| / |x_N - x_{N/2}|`` (max norms); ``2**order`` in the asymptotic range.
    status : str
        ``"ok"`` or ``"inaccurate"``.
    message : str
        Why; for ``"inaccurate"`` it starts with ``"refine n_steps: "``.
    """

    trusted: bool
    ratio: float
    status: str
    message: str


def error_verdict(
    difference_fine: float,
    difference_coarse: float,
    order: int,
    *,
    scale: float,
    n_steps: int | None = None,
    order_tolerance: float = ORDER_TOLERANCE,
    max_relative_error: float = MAX_RELATIVE_ERROR,
    roundoff: float = ROUNDOFF_LIMIT,
    quantity: str = "x",
) -> ErrorCheck:
    """Trust of the N/2 estimate ``difference_fine / (2**order - 1)`` from ``difference_fine =
    max|x_N - x_{N/2}|`` and ``difference_coarse = max|x_{N/2} - x_{N/4}|`` (units of x) for a scheme of
    ``order``; ``scale`` is the size of the solution (e.g. ``max|x_N|``, units of x); ``n_steps`` (N,
    optional) checks that the N/4 grid has at least ``MIN_QUARTER_STEPS``; ``quantity`` names what
    the differences are of in the message.  See the module notes."""
    fine, coarse, scale = float(difference_fine), float(difference_coarse), float(scale)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = float(np.float64(coarse) / np.float64(fine))
    ideal = 2.0**order
    if max(fine, coarse) <= roundoff * scale or max(fine, coarse) == 0.0:
        return ErrorCheck(True, ratio, "ok", (
            f"error estimate trusted: the N, N/2 and N/4 solutions agree to round-off ({roundoff:g} of the "
            "solution's size)"))
    if n_steps is not None and n_steps // 4 < MIN_QUARTER_STEPS:
        return ErrorCheck(False, ratio, "inaccurate", (
            f"refine n_steps: the N/4 grid of the error check has {n_steps // 4} steps per period, too few to "
            f"resolve even the fundamental harmonic, so the N/2 error estimate is not trusted; use n_steps "
            f">= {4 * MIN_QUARTER_STEPS}"))
    observed_order = math.log2(ratio) if 0.0 < ratio < math.inf else math.nan
    if not -order_tolerance <= observed_order - order <= CONSERVATIVE_ORDERS:  # also refuses NaN
        low, high = 2.0 ** (order - order_tolerance), 2.0 ** (order + CONSERVATIVE_ORDERS)
        q = quantity
        return ErrorCheck(False, ratio, "inaccurate", (
            f"refine n_steps: the ratio of successive differences |{q}_N/2 - {q}_N/4| / |{q}_N - {q}_N/2| is "
            f"{ratio:.3g}, expected about {ideal:g} (between {low:.3g} and {high:.3g}) in the asymptotic "
            f"range of this order-{order} scheme: the N/2 error estimate is not trusted"))
    relative_error = fine / (ideal - 1.0) / scale
    if relative_error > max_relative_error:
        return ErrorCheck(True, ratio, "inaccurate", (
            f"refine n_steps: the estimated error is {relative_error:.3g} of the solution's size "
            f"(> {max_relative_error:g}; ratio of successive differences {ratio:.3g})"))
    return ErrorCheck(True, ratio, "ok", (
        f"error estimate trusted: ratio of successive differences {ratio:.3g} (asymptotic value {ideal:g})"))
