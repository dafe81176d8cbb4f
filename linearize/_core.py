"""Linearisation of constrained equations of motion about a periodic nominal motion.

The model (any ``mechanisms.ConstrainedModel``) obeys

    R(s, s', s'', lam, t) = M(s) s'' - Q(s, s', t) + Phi_s(s, t)^T lam = 0,     Phi(s, t) = 0.

About a nominal motion ``s0(t), lam0(t)`` (rigid: elastic coordinates zero, constraints satisfied), we
write ``s = s0 + x``, ``lam = lam0 + mu`` and keep first-order terms (thesis chapter 4):

    M0 x'' + D x' + K x + Phi_s0^T mu = -R0,          Phi_s0 x = 0,

    D = -dQ/ds',   K = d(M s0'')/ds - dQ/ds + d(Phi_s^T lam0)/ds  (+ geometric stiffness),
    R0 = M0 s0'' - Q0 + Phi_s0^T lam0  (zero on the rigid rows: it is the load of the rigid motion on
    the elastic coordinates).

The constraint is eliminated by coordinate partitioning: the independent coordinates ``z`` (the
elastic coordinates, plus any rigid coordinate that is a degree of freedom of its own) and
``x = V(t) z`` with ``V_dependent = -Phi_d^-1 Phi_i``, ``V_independent = I``. With
``x' = V z' + V' z`` and ``x'' = V z'' + 2 V' z' + V'' z``, projecting on ``V^T`` (which removes
``Phi_s0^T mu`` since ``Phi_s0 V = 0``):

    (V^T M0 V) z'' + V^T (2 M0 V' + D V) z' + V^T (M0 V'' + D V' + K V) z = -V^T R0.

``V`` is a smooth periodic function of time (a function of the configuration), so ``V'`` and ``V''``
are computed by Fourier (spectral) differentiation over the period; the size of the highest
harmonics that the grid holds is reported as the error estimate of that step.

The multipliers' change ``mu`` along a solution follows from the rows of the dependent coordinates,
where ``Phi_s0^T`` is the invertible block ``Phi_d^T``:

    mu = A_x z + A_v z' + A_a z'',      A_a = -Phi_d^-T (M0 V)_d,
    A_v = -Phi_d^-T (2 M0 V' + D V)_d,  A_x = -Phi_d^-T (M0 V'' + D V' + K V)_d

(the rigid rows of ``R0`` are round-off, ``rigid_residual``, and left out), so joint forces and
drive torques, which are sums of multipliers, are linear in ``z, z', z''``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

import mechanisms

from ._lag import lag_count, with_lag_states

__all__ = ["LinearizationError", "LinearCoefficients", "linear_coefficients",
           "spectral_derivatives", "choose_independent"]

# A dependent-coordinate block whose condition number exceeds this is treated as a toggle position:
# beyond it the elimination amplifies round-off by more than ~1e-16 * 1e10 = 1e-6 relative.
TOGGLE_CONDITION = 1.0e10
# Above this the result is still computed, but a warning names the worst time.
WARN_CONDITION = 1.0e6


class LinearizationError(ValueError):
    """The mechanism or the request cannot be linearised as asked: a toggle (dead-centre) position
    along the prescribed motion, an over-constrained linkage, a drive that ``speed_family`` cannot
    scale, a joint whose load on a stiffened link is not a point force, or an argument of the wrong
    shape or value (the message names it). Bad input, hence a ``ValueError``; numerical failures on a valid mechanism
    raise ``mechanisms.ConvergenceError``
    (a ``RuntimeError``)."""


@dataclass(frozen=True)
class LinearCoefficients:
    """The linearised equations in independent coordinates on the nominal grid.

    ``M, C, K`` (N+1, m, m) and ``f`` (N+1, m) for ``M z'' + C z' + K z = f``; ``V``, ``Vdot``,
    ``Vddot`` (N+1, n, m) map ``z`` to the full coordinate deviation ``x = V z``;
    ``independent`` (m - L,) are the indices of ``z`` in ``s`` (the last L entries of ``z`` are
    the states of the model's L lagged controllers, ``linearize._lag``: first-order coordinates,
    zero columns of ``V``); ``dependent_condition`` (N+1,) the
    condition number of the dependent block of the constraint Jacobian; ``spectral_error`` an
    estimate of the relative error of ``Vdot``, ``Vddot`` (size of the highest harmonics kept);
    ``rigid_residual`` the largest rigid-row residual of the nominal motion (should be round-off);
    ``stride``: the model was evaluated at every ``stride``-th sample and the coefficients
    interpolated spectrally to the others (1: evaluated everywhere), with ``interpolation_error``
    the relative size of the highest harmonics the coarse samples resolve (``spectral_tail``);
    ``multiplier_maps``: ``(A_x, A_v, A_a)`` each (N+1, r, m), the change of the multipliers
    ``mu = A_x z + A_v z' + A_a z''`` (module docstring).
    """

    t: np.ndarray
    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    f: np.ndarray
    V: np.ndarray
    Vdot: np.ndarray
    Vddot: np.ndarray
    independent: np.ndarray
    dependent_condition: np.ndarray
    spectral_error: float
    rigid_residual: float
    stride: int = 1
    interpolation_error: float = 0.0
    multiplier_maps: tuple = ()


def spectral_derivatives(values: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray, float]:
    """First and second time derivatives of a smooth periodic sampled function.

    ``values`` (N+1, ...) sampled at ``t_k = k T / N`` with ``values[N] == values[0]``. Returns
    ``(d1, d2, tail)`` shaped like ``values`` and the relative size of the harmonics in the top
    eighth of the resolved band: a spectrally converged function has ``tail`` near round-off.
    """
    n_steps = values.shape[0] - 1
    samples = values[:n_steps]
    coefficients = np.fft.rfft(samples, axis=0)               # harmonics 0 .. N/2 (real input)
    harmonics = np.arange(coefficients.shape[0])
    omega = 2.0 * math.pi / period
    shape = (coefficients.shape[0],) + (1,) * (values.ndim - 1)
    ik = (1j * omega * harmonics).reshape(shape)
    first = coefficients * ik
    if n_steps % 2 == 0:
        # The Nyquist harmonic has no defined odd derivative on the grid: drop it.
        first[n_steps // 2] = 0.0
    second = coefficients * ik**2
    d1 = np.fft.irfft(first, n=n_steps, axis=0)
    d2 = np.fft.irfft(second, n=n_steps, axis=0)
    d1 = np.concatenate([d1, d1[:1]], axis=0)
    d2 = np.concatenate([d2, d2[:1]], axis=0)
    return d1, d2, _tail(coefficients, n_steps)


def _tail(coefficients: np.ndarray, n_steps: int) -> float:
    """Largest |coefficient| in the top eighth of the band of a real FFT (``rfft`` of N samples),
    relative to the largest of all (0 for a zero function)."""
    magnitude = np.abs(coefficients).reshape(coefficients.shape[0], -1).max(axis=1)
    scale = magnitude.max()
    if scale == 0.0:
        return 0.0
    top = np.arange(magnitude.shape[0]) >= (n_steps // 2) * 7 // 8
    return float(magnitude[top].max() / scale)


def spectral_tail(values: np.ndarray) -> float:
    """Relative size of the harmonics in the top eighth of the band that the samples ``values``
    (N+1, ...) of a periodic function resolve (``values[N] == values[0]``): near round-off for a
    spectrally converged function, and a bound on the error of interpolating it from these samples.
    """
    n_steps = values.shape[0] - 1
    return _tail(np.fft.rfft(values[:n_steps], axis=0), n_steps)


def interpolate_periodic(values: np.ndarray, n_steps: int) -> np.ndarray:
    """Trigonometric interpolation of periodic samples ``values`` (Nc+1, ...) on ``t_k = k T / Nc``
    to (n_steps+1, ...) on ``k T / n_steps``; the Nyquist harmonic of the coarse grid is dropped
    (it is negligible wherever ``spectral_tail`` says the samples resolve the function)."""
    coarse = values.shape[0] - 1
    if coarse == n_steps:
        return values.copy()
    spectrum = np.fft.rfft(values[:coarse], axis=0)
    if coarse % 2 == 0:
        spectrum[coarse // 2] = 0.0
    padded = np.zeros((n_steps // 2 + 1,) + spectrum.shape[1:], dtype=complex)
    padded[:spectrum.shape[0]] = spectrum
    fine = np.fft.irfft(padded, n=n_steps, axis=0) * (n_steps / coarse)
    return np.concatenate([fine, fine[:1]], axis=0)


def choose_independent(jacobian: np.ndarray, preferred: np.ndarray) -> np.ndarray:
    """Indices of independent coordinates: ``preferred`` first (the elastic coordinates and any
    degree of freedom named by the caller), then as many further columns as the constraint
    Jacobian (r, n) leaves free, picked by QR with column pivoting so that the remaining dependent
    block is as well conditioned as possible."""
    import scipy.linalg

    n = jacobian.shape[1]
    preferred = np.asarray(preferred, dtype=np.int64)
    others = np.setdiff1d(np.arange(n), preferred)
    n_free = n - jacobian.shape[0] - preferred.size
    if n_free < 0:
        raise LinearizationError(
            f"the constraints ({jacobian.shape[0]}) leave fewer free coordinates than the "
            f"{preferred.size} requested independent ones; the mechanism is over-constrained")
    if n_free == 0:
        return np.sort(preferred)
    _, _, pivots = scipy.linalg.qr(jacobian[:, others], pivoting=True, mode="economic")
    extra = others[pivots[jacobian.shape[0]:]][:n_free]
    return np.sort(np.concatenate([preferred, extra]))


def linear_coefficients(model, t: np.ndarray, s0: np.ndarray, sdot0: np.ndarray,
                        sddot0: np.ndarray, lam0: np.ndarray, *, period: float,
                        independent: np.ndarray, extra_stiffness: np.ndarray | None = None,
                        time_label=None, multipliers: bool = False) -> LinearCoefficients:
    """Linearise ``model`` about the nominal motion given on the uniform grid ``t`` (N+1,).

    ``s0, sdot0, sddot0`` (N+1, n), ``lam0`` (N+1, r); ``independent`` (m,) coordinate indices;
    ``extra_stiffness`` (N+1, n, n) is added to ``K`` (the geometric stiffness of axially loaded
    links). ``time_label(k)`` describes sample k in error messages (e.g. the crank angle).
    ``multipliers``: also the maps of the multipliers' change (``multiplier_maps``, else ``()``),
    which joint forces and drive torques need.
    """
    n_samples, n = s0.shape
    independent = np.asarray(independent, dtype=np.int64)
    dependent = np.setdiff1d(np.arange(n), independent)
    m = independent.size
    label = time_label or (lambda k: f"t = {t[k]:.6g} s")

    terms = mechanisms.linear_terms_along(model, t, s0, sdot0, sddot0, lam0)
    mass, damping, stiffness, residual, jacobian = (
        terms.mass, terms.damping, terms.stiffness, terms.residual, terms.jacobian)
    if extra_stiffness is not None:
        stiffness = stiffness + extra_stiffness
    n_lags = lag_count(model)
    if n_lags:
        # lagged controllers: their states are extra (first-order, independent) coordinates
        mass, damping, stiffness, residual, jacobian = with_lag_states(
            model, t, s0, sdot0, mass, damping, stiffness, residual, jacobian)
        independent = np.concatenate((independent, n + np.arange(n_lags)))
        m = independent.size
    Phi_d = jacobian[:, :, dependent]
    singular_values = np.linalg.svd(Phi_d, compute_uv=False)
    with np.errstate(divide="ignore"):
        condition = singular_values[:, 0] / singular_values[:, -1]
    bad = np.flatnonzero(~(condition < TOGGLE_CONDITION))
    if bad.size:
        k = int(bad[0])
        raise LinearizationError(
            f"the constraint Jacobian is singular at {label(k)} (condition number "
            f"{condition[k]:.3g} of the dependent block): a toggle (dead-centre) position, "
            f"where {_worst_constraints(Phi_d[k], model)} lose their rank. Change the link lengths "
            f"or the crank range so the mechanism does not pass through it.")
    V = np.zeros((n_samples, n + n_lags, m))
    V[:, independent, np.arange(m)] = 1.0
    V[:, dependent, :] = -np.linalg.solve(Phi_d, jacobian[:, :, independent])
    rigid_rows = np.asarray(model.rigid_index, dtype=np.int64)

    Vdot, Vddot, tail = spectral_derivatives(V, period)
    # Projection on V^T (module docstring).
    Vt = np.swapaxes(V, 1, 2)
    M_z = Vt @ mass @ V
    C_z = Vt @ (2.0 * mass @ Vdot + damping @ V)
    K_z = Vt @ (mass @ Vddot + damping @ Vdot + stiffness @ V)
    f_z = -np.einsum("kni,kn->ki", V, residual)
    rigid_residual = float(np.abs(residual[:, rigid_rows]).max()) if rigid_rows.size else 0.0
    multiplier_maps = ()
    if multipliers:
        # mu = -Phi_d^-T [M x'' + D x' + K x]_d (module docstring), one solve for the three maps
        blocks = np.concatenate([(mass @ Vddot + damping @ Vdot + stiffness @ V)[:, dependent],
                                 (2.0 * mass @ Vdot + damping @ V)[:, dependent],
                                 (mass @ V)[:, dependent]], axis=2)
        maps = -np.linalg.solve(np.swapaxes(Phi_d, 1, 2), blocks)
        multiplier_maps = (maps[:, :, :m], maps[:, :, m:2 * m], maps[:, :, 2 * m:])
    # the maps to the mechanism's coordinates: x = V z has no component along the lag states
    V, Vdot, Vddot = V[:, :n], Vdot[:, :n], Vddot[:, :n]
    return LinearCoefficients(t=t, M=M_z, C=C_z, K=K_z, f=f_z, V=V, Vdot=Vdot, Vddot=Vddot,
                              independent=independent[:m - n_lags], dependent_condition=condition,
                              spectral_error=tail, rigid_residual=rigid_residual,
                              multiplier_maps=multiplier_maps)


def _worst_constraints(Phi_d: np.ndarray, model) -> str:
    """Names of the constraint rows that dominate the null direction of a singular block."""
    u, _, _ = np.linalg.svd(Phi_d)
    weights = np.abs(u[:, -1])
    labels = list(getattr(model, "constraint_labels", [f"row {i}" for i in range(len(weights))]))
    rows = np.argsort(weights)[::-1][:3]
    return "the constraints " + ", ".join(labels[i] for i in rows if weights[i] > 1e-3)
