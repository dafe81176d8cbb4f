"""Numerical pieces shared by the studies: steady state with per-observable error estimates, frozen-time
modes, MAC tracking, resonance crossings, unfolding of Floquet characteristic frequencies."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

import periodic

from . import _verdicts as verdicts
from ._errors import StudiesError
from ._problem import Linear

#: The integration scheme of a study unless its ``scheme`` says otherwise (the ``[studies]`` table's
#: ``scheme``, a study function's keyword). A scheme's ``error_factor`` (``1 / (2**order - 1)``) turns
#: the difference between an N-step and an N/2-step value into the error estimate of the N-step value.
DEFAULT_SCHEME = "trapezoidal"


def study_scheme(name: str = DEFAULT_SCHEME) -> periodic.Scheme:
    """The periodic scheme registered under ``name`` (``periodic.SCHEMES``, to which
    ``periodic.register_scheme`` adds): the one place the studies resolve a scheme's name. An
    unknown name raises :class:`StudiesError` listing the registered ones."""
    schemes = periodic.SCHEMES
    if not isinstance(name, str) or name not in schemes:
        raise StudiesError(f"scheme: expected the name of a registered periodic scheme "
                           f"({', '.join(sorted(schemes))}), got {name!r}")
    return schemes[name]


#: The default scheme itself.
STUDY_SCHEME = study_scheme()


@dataclass(frozen=True, eq=False)
class Steady:
    """Steady state of a :class:`Linear` with error estimates and its verdict.

    ``state`` the N-step ``periodic.SteadyState``; ``response`` (N+1, n_obs) observables;
    ``response_error`` (n_obs,) estimated max abs error of each observable, ``|o_N - o_{N/2}|`` times the
    scheme's ``error_factor`` (1/3 for the order-2 trapezoidal rule); ``error_estimate`` the same for
    the coordinates ``z``; ``spectral_radius_error`` the estimated error of the spectral radius;
    ``instability_kind`` ("fold", "period_doubling", "secondary_hopf", or "" when neither unstable nor
    marginal); ``linear_range`` {"<link>.<measure>": value} (empty without a mechanism); ``status``,
    ``message``, ``is_stable`` the point's verdict (see ``studies._verdicts``); ``run_time`` s.
    """

    state: periodic.SteadyState
    response: np.ndarray
    response_error: np.ndarray
    error_estimate: float
    spectral_radius_error: float
    instability_kind: str
    linear_range: dict
    status: str
    message: str
    is_stable: bool
    run_time: float


def solve_steady(linear: Linear, scheme: str = DEFAULT_SCHEME) -> Steady:
    """The steady state on N steps with the periodic scheme named ``scheme``, its error estimate from
    N/2 (trusted only when N/4 shows the asymptotic range: N a multiple of 4) and its verdict:
    stability with its error bar, error trust, near resonance or unresolved modes, linear range."""
    # N, N/2 and N/4 with verdicts
    state = periodic.steady_state(linear.system, scheme=study_scheme(scheme))
    response = linear.observe(state.x)
    # the error of each observable from the N/2 solution the shooting returns (it is linear in x)
    response_error = state.error_factor * np.abs(
        response[::2] - linear.observe(state.x_coarse, stride=2)).max(axis=0)
    ranges, range_status, range_message = verdicts.linear_range(linear, state.x)
    status, message = verdicts.combine([(state.status, state.message), (range_status, range_message)])
    return Steady(state=state, response=response, response_error=response_error,
                  error_estimate=state.error_estimate, spectral_radius_error=state.spectral_radius_error,
                  instability_kind=state.instability_kind, linear_range=ranges, status=status,
                  message=message, is_stable=state.is_stable, run_time=state.run_time)


def extremes(samples: np.ndarray) -> tuple[float, float, float, float]:
    """Largest and smallest value of a periodic signal sampled at ``t_0 .. t_N`` (``t_N`` repeats
    ``t_0``), (N+1,), each refined by the parabola through it and its two neighbours: the sampled
    extremes miss the true ones by up to ``A (k dphi)^2 / 8`` for a harmonic k of amplitude A
    sampled every ``dphi`` rad (the refinement's error is of higher order). Returns ``(high, low,
    high_change, low_change)``, the changes the refinement made bounding the sampling error of the
    unrefined extremes."""
    values = samples[:-1]
    n = values.size
    refined = []
    for sign in (1.0, -1.0):
        i = int(np.argmax(sign * values))
        left, centre, right = values[(i - 1) % n], values[i], values[(i + 1) % n]
        curvature = left - 2.0 * centre + right
        offset = 0.0 if curvature == 0.0 else 0.5 * (left - right) / curvature
        refined.append((centre - 0.25 * (left - right) * offset, centre))
    (high, high_sampled), (low, low_sampled) = refined
    return float(high), float(low), float(abs(high - high_sampled)), float(abs(low - low_sampled))


def peak_to_peak(samples: np.ndarray) -> tuple[float, float]:
    """Peak-to-peak of a periodic signal sampled at ``t_0 .. t_N`` (``t_N`` repeats ``t_0``), (N+1,),
    from its refined ``extremes``. Returns ``(value, correction)`` where ``correction`` (the change
    made by the refinement) bounds the sampling error of the unrefined value and is reported as
    part of the error estimate.
    """
    values = samples[:-1]
    high, low, _, _ = extremes(samples)
    sampled = float(values.max() - values.min())
    return float(high - low), float(abs((high - low) - sampled))


def peak(samples: np.ndarray) -> tuple[float, float]:
    """The largest magnitude of a periodic signal (N+1,), ``max(|high|, |low|)`` of its refined
    ``extremes`` (N): ``(value, correction)``, the correction bounding the sampling error."""
    high, low, high_change, low_change = extremes(samples)
    return (float(abs(high)), high_change) if abs(high) >= abs(low) else (float(abs(low)), low_change)


def peak_summary(response: np.ndarray, response_error: np.ndarray) -> dict[str, np.ndarray]:
    """Peak and peak-to-peak of each observable of a steady ``response`` (N+1, n_obs) with their
    errors from the per-observable ``response_error`` (n_obs,): a peak is within the response's
    error ``e`` of the truth, a peak-to-peak within ``2 e`` (the extremes of two functions each
    within ``e`` differ by at most ``2 e``); the sampling correction of the extremes is added as a
    bound on what the refinement leaves. Returns ``{"peak", "peak_error", "peak_to_peak",
    "peak_to_peak_error"}``, each (n_obs,), in the observables' units."""
    out = {name: np.empty(response.shape[1]) for name in
           ("peak", "peak_error", "peak_to_peak", "peak_to_peak_error")}
    for k in range(response.shape[1]):
        error = float(response_error[k])
        out["peak"][k], sampling = peak(response[:, k])
        out["peak_error"][k] = error + sampling
        out["peak_to_peak"][k], sampling = peak_to_peak(response[:, k])
        out["peak_to_peak_error"][k] = 2.0 * error + sampling
    return out


def frozen_modes(system: periodic.PeriodicSystem, n_samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frozen-time natural frequencies of ``(K(t), M(t))`` at ``n_samples`` equally spaced samples of
    one period (the first at t = 0).

    Returns ``(index, frequencies, shapes)``: ``index`` (n_samples,) sample indices;
    ``frequencies`` (n_samples, m) rad/s, ascending, ``sign(lam) sqrt(|lam|)`` of the generalised
    eigenvalues ``lam`` (real parts; a negative frequency flags a statically unstable frozen system);
    ``shapes`` (m, m) the real mode shapes at t = 0, columns in the order of the frequencies, unit
    norm.
    """
    n_steps = system.n_steps
    n_samples = max(2, min(int(n_samples), n_steps))
    index = np.unique(np.round(np.linspace(0, n_steps, n_samples, endpoint=False)).astype(int))
    # eigenvalues of M^-1 K at all samples in one batched call (M is well conditioned: PeriodicSystem
    # rejects singular mass samples); the shapes only at t = 0, from the generalised problem.
    values = np.sort(np.linalg.eigvals(np.linalg.solve(system.M[index], system.K[index])).real, axis=1)
    frequencies = np.sign(values) * np.sqrt(np.abs(values))
    first, vectors = scipy.linalg.eig(system.K[0], system.M[0])
    shapes = vectors[:, np.argsort(first.real)].real
    shapes /= np.linalg.norm(shapes, axis=0)
    return index, frequencies, shapes


def mac(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Modal assurance criterion of the columns of ``a`` (m, p) against those of ``b`` (m, q):
    ``|a_i . b_j|^2 / ((a_i . a_i)(b_j . b_j))``, shape (p, q), in [0, 1]."""
    cross = np.abs(a.T @ b) ** 2
    return cross / np.outer(np.sum(a * a, axis=0), np.sum(b * b, axis=0))


def track_modes(shapes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Follow modes across consecutive grid points by MAC.

    ``shapes`` (n, m, m): mode shapes (columns, ascending frequency) at each point. Returns
    ``order`` (n, m) int: tracked mode j is column ``order[i, j]`` at point i (identity at the first
    point), and ``confidence`` (n, m): the MAC of each assignment with the previous point (1 at the
    first point). The assignment maximises the total MAC (Hungarian algorithm).
    """
    n, m = shapes.shape[0], shapes.shape[2]
    order = np.empty((n, m), dtype=int)
    confidence = np.ones((n, m))
    order[0] = np.arange(m)
    for i in range(1, n):
        previous = shapes[i - 1][:, order[i - 1]]
        if not (np.isfinite(previous).all() and np.isfinite(shapes[i]).all()):
            order[i] = np.arange(m)
            confidence[i] = np.nan
            continue
        score = mac(previous, shapes[i])
        from scipy.optimize import linear_sum_assignment  # here: scipy.optimize costs ~0.5 s to import

        rows, cols = linear_sum_assignment(-score)
        order[i, rows] = cols
        confidence[i, rows] = score[rows, cols]
    return order, confidence


def crossings(parameter: np.ndarray, difference: np.ndarray) -> list[tuple[int, float]]:
    """Where ``difference`` (n,) changes sign between consecutive finite points: ``(i, value)`` with
    ``value`` the parameter at the zero by linear interpolation between points i and i + 1."""
    found = []
    for i in range(parameter.size - 1):
        a, b = difference[i], difference[i + 1]
        if not (np.isfinite(a) and np.isfinite(b)):
            continue
        if a == 0.0:
            found.append((i, float(parameter[i])))
        elif a * b < 0.0:
            found.append((i, float(parameter[i] + (parameter[i + 1] - parameter[i]) * a / (a - b))))
    return found


def unstable_intervals(parameter: np.ndarray, radius: np.ndarray, *, tol: float) -> list[tuple[float, float]]:
    """Parameter intervals where ``radius > 1 + tol``, ends interpolated linearly in ``radius - 1``;
    an interval touching the end of the grid ends there."""
    excess = radius - (1.0 + tol)
    unstable = np.isfinite(excess) & (excess > 0.0)
    intervals = []
    i = 0
    while i < parameter.size:
        if not unstable[i]:
            i += 1
            continue
        j = i
        while j + 1 < parameter.size and unstable[j + 1]:
            j += 1
        start = float(parameter[i])
        if i > 0 and np.isfinite(excess[i - 1]):
            a, b = excess[i - 1], excess[i]
            start = float(parameter[i - 1] + (parameter[i] - parameter[i - 1]) * a / (a - b))
        end = float(parameter[j])
        if j + 1 < parameter.size and np.isfinite(excess[j + 1]):
            a, b = excess[j], excess[j + 1]
            end = float(parameter[j] + (parameter[j + 1] - parameter[j]) * a / (a - b))
        intervals.append((start, end))
        i = j + 1
    return intervals


def characteristic_frequencies(multipliers: np.ndarray, period: float, targets: np.ndarray) -> np.ndarray:
    """Floquet characteristic frequencies, unfolded, each to its own target.

    A multiplier ``mu = exp(lam T)`` fixes ``Im lam`` only modulo ``Omega = 2 pi / T``: the candidates
    are ``|arg mu| / T + k Omega`` and ``-|arg mu| / T + k Omega`` (k integer, kept >= 0). Multiplier
    ``i`` takes the candidate nearest ``targets[i]`` (rad/s: the mean frozen natural frequency of the
    mode it belongs to, :func:`multiplier_modes`); shape (s,), rad/s, NaN where the target is not
    finite. (Unfolding each multiplier to the nearest of a pool of targets picks the wrong mode as soon
    as ``Omega`` is small against the modes' spacing: every multiplier has a candidate within
    ``Omega / 2`` of every target.)
    """
    omega = 2.0 * math.pi / period
    base = np.abs(np.angle(multipliers)) / period
    targets = np.broadcast_to(np.asarray(targets, dtype=float), np.shape(multipliers))
    out = np.full(np.shape(multipliers), np.nan)
    for i, (b, target) in enumerate(zip(base, targets)):
        if not math.isfinite(target):
            continue
        best, best_distance = np.nan, np.inf
        for sign in (1.0, -1.0):
            candidate = sign * b + np.round((target - sign * b) / omega) * omega
            if candidate < 0.0:
                candidate += omega * np.ceil(-candidate / omega)
            if abs(candidate - target) < best_distance:
                best, best_distance = candidate, abs(candidate - target)
        out[i] = best
    return out


def multiplier_modes(eigenvectors: np.ndarray, shapes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which frozen natural mode each Floquet multiplier belongs to.

    ``eigenvectors`` (s, s) complex: the Floquet modes at t = 0 (``periodic.FloquetResult.eigenvectors``,
    state ``[x; v]``, positions first); ``shapes`` (n, m): the frozen mode shapes at t = 0
    (:func:`frozen_modes`), n the first rows of the state. Each Floquet mode's positions are split into
    the frozen modes (``x = shapes q``) and each frozen mode given the two multipliers (a conjugate
    pair) with the largest shares ``|q_j|^2 / sum |q|^2`` in one optimal assignment. Returns ``(modes,
    shares)``: (s,) int, the column of ``shapes`` of each multiplier (-1 where unassigned), and (s,)
    the share of that mode in the multiplier's Floquet mode (1: a pure frozen mode; below 1/2 the
    Floquet mode mixes several frozen ones and the mode it is given is the largest of them).
    """
    n, m = shapes.shape
    count = eigenvectors.shape[1]
    modes, shares = np.full(count, -1, dtype=int), np.zeros(count)
    try:
        q = np.linalg.solve(shapes, eigenvectors[:n]) if n == m else np.linalg.lstsq(shapes, eigenvectors[:n],
                                                                                        rcond=None)[0]
    except np.linalg.LinAlgError:
        return modes, shares
    weight = np.abs(q) ** 2
    total = weight.sum(axis=0)
    share = np.divide(weight, total, out=np.zeros_like(weight), where=total > 0.0)   # (m, s)
    if not np.all(np.isfinite(share)):
        return modes, shares
    from scipy.optimize import linear_sum_assignment  # here: scipy.optimize costs ~0.5 s to import

    rows, columns = linear_sum_assignment(-np.repeat(share, 2, axis=0).T)   # each mode twice
    modes[rows] = columns // 2
    shares[rows] = share[columns // 2, rows]
    return modes, shares


def pooled_frequencies(multipliers: np.ndarray, period: float, pool: np.ndarray) -> np.ndarray:
    """Characteristic frequencies (s,) rad/s, each multiplier unfolded to whichever of the targets
    ``pool`` (k,) rad/s its candidate comes nearest (:func:`characteristic_frequencies`): the unfolding
    of results saved before :func:`multiplier_modes`, ambiguous where ``2 pi / period`` is small against
    the targets' spacing; NaN without a finite target."""
    pool = np.asarray(pool, dtype=float)
    pool = pool[np.isfinite(pool)]
    if pool.size == 0:
        return np.full(np.shape(multipliers), np.nan)
    each = np.array([characteristic_frequencies(multipliers, period, target) for target in pool])   # (k, s)
    return each[np.abs(each - pool[:, None]).argmin(axis=0), np.arange(each.shape[1])]


def mode_targets(modes: np.ndarray, means: np.ndarray) -> np.ndarray:
    """The frequency (s,) rad/s each multiplier is unfolded to: ``means`` (m,) rad/s (the mean frozen
    frequency of each frozen mode column) at its mode ``modes`` (s,) int (:func:`multiplier_modes`),
    NaN where unassigned (-1)."""
    modes = np.asarray(modes).astype(int)
    return np.where(modes >= 0, means[np.clip(modes, 0, means.size - 1)], np.nan)
