"""A model evaluated along a whole sampled motion (the nominal motion and ``linearize`` need it at
every sample of a period).

Public face: ``linear_terms_along``, ``inertia_residual_along`` and ``constraint_terms_along`` take
any ``ConstrainedModel`` and samples ``t`` (N,), ``s, sdot, sddot`` (N, n), ``lam`` (N, r). A model
that offers the method of the same name (``mechanisms.Model`` does: one call per quantity of the
kernels in ``_kernels``, which take all samples at once, and numpy for the sums) is evaluated by it;
any other model through its per-sample protocol methods. Both give the same numbers up to
summation order (tests/test_batch.py).

The kernels here (the nominal motion's position continuation and its helpers) take the assembled
model's tables (``_model._Tables``, layouts in ``_kernels``; the constraint terms ``ct_int`` have six
columns, the last the frame of a term in a moving link's frame) as arrays and fill their outputs;
only ``Model`` calls them. Numba's cache of a kernel here is keyed by this file, not by the
``_kernels`` functions it calls: a change of a kernel's layout there must touch this file too (as
this note did: the model kernels now take samples along a leading axis), or stale compiled code is
reused.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from periodic.lapack import solve_in_place

from . import _kernels


@dataclass(frozen=True)
class LinearTerms:
    """The terms of the linearised equations at N samples (``linearize._core``):

    ``mass`` M (N, n, n); ``damping`` D = -dQ/ds' (N, n, n); ``stiffness``
    K = d(M s'')/ds - dQ/ds + d(Phi_s^T lam)/ds (N, n, n); ``residual`` R = M s'' - Q + Phi_s^T lam
    (N, n); ``jacobian`` Phi_s (N, r, n). Units: those of the coordinates' equations (N, N m).
    """

    mass: np.ndarray
    damping: np.ndarray
    stiffness: np.ndarray
    residual: np.ndarray
    jacobian: np.ndarray


@dataclass(frozen=True)
class ConstraintTerms:
    """The constraint terms at N samples: ``jacobian`` Phi_s (N, r, n), ``rate`` Phi_t (N, r),
    ``gamma`` (N, r) with ``Phi_s s'' = gamma`` (``None`` when no rates were given) and ``values``
    Phi (N, r) (``None`` unless asked for)."""

    jacobian: np.ndarray
    rate: np.ndarray
    gamma: np.ndarray | None
    values: np.ndarray | None


# ---------------------------------------------------------------------------------------------------
# Any model
# ---------------------------------------------------------------------------------------------------
def linear_terms_along(model, t, s, sdot, sddot, lam) -> LinearTerms:
    """``LinearTerms`` of ``model`` along the samples ``t`` (N,), ``s, sdot, sddot`` (N, n),
    ``lam`` (N, r)."""
    method = getattr(model, "linear_terms_along", None)
    if method is not None:
        return method(t, s, sdot, sddot, lam)
    n_samples, n = np.shape(s)
    mass = np.empty((n_samples, n, n))
    damping = np.empty((n_samples, n, n))
    stiffness = np.empty((n_samples, n, n))
    residual = np.empty((n_samples, n))
    jacobian = np.empty((n_samples, model.n_constraints, n))
    for k in range(n_samples):
        sk, sdk, sddk, lamk, tk = s[k], sdot[k], sddot[k], lam[k], t[k]
        mass[k] = model.mass_matrix(sk)
        jacobian[k] = model.constraint_jacobian(sk, tk)
        dQ_ds, dQ_dsdot = model.force_jacobians(sk, sdk, tk)
        damping[k] = -dQ_dsdot
        stiffness[k] = (model.mass_matrix_jacobian(sk, sddk) - dQ_ds
                        + model.constraint_force_jacobian(sk, lamk, tk))
        residual[k] = mass[k] @ sddk - model.forces(sk, sdk, tk) + jacobian[k].T @ lamk
    return LinearTerms(mass, damping, stiffness, residual, jacobian)


def inertia_residual_along(model, t, s, sdot, sddot) -> np.ndarray:
    """``M(s) s'' - Q(s, s', t)`` (N, n) of ``model`` along the samples ``t`` (N,),
    ``s, sdot, sddot`` (N, n): minus the constraint forces of the inverse dynamics."""
    method = getattr(model, "inertia_residual_along", None)
    if method is not None:
        return method(t, s, sdot, sddot)
    return np.stack([model.mass_matrix(s[k]) @ sddot[k] - model.forces(s[k], sdot[k], t[k])
                     for k in range(len(t))])


def constraint_terms_along(model, t, s, sdot=None, *, values: bool = False) -> ConstraintTerms:
    """``ConstraintTerms`` of ``model`` along the samples ``t`` (N,), ``s`` (N, n) and, for
    ``gamma``, ``sdot`` (N, n); ``values=True`` also evaluates Phi."""
    method = getattr(model, "constraint_terms_along", None)
    if method is not None:
        return method(t, s, sdot, values=values)
    samples = range(len(t))
    return ConstraintTerms(
        jacobian=np.stack([model.constraint_jacobian(s[k], t[k]) for k in samples]),
        rate=np.stack([model.constraint_rate(s[k], t[k]) for k in samples]),
        gamma=None if sdot is None else np.stack([model.constraint_gamma(s[k], sdot[k], t[k])
                                                  for k in samples]),
        values=np.stack([model.constraints(s[k], t[k]) for k in samples]) if values else None)


# ---------------------------------------------------------------------------------------------------
# The assembled model's tables along a motion (``Model``'s methods of the same names)
# ---------------------------------------------------------------------------------------------------
#: The (n, n) terms that are only summed into others (the mass matrices of the inertia residual,
#: dQ/ds of the stiffness) are formed this many entries (2 MB) at a time, not for every sample.
CHUNK_ENTRIES = 2 ** 18


def _chunks(n_samples: int, n: int):
    """(start, stop) of consecutive sample ranges of at most ``CHUNK_ENTRIES`` (n, n) entries."""
    size = max(1, min(n_samples, CHUNK_ENTRIES // max(n * n, 1)))
    return [(start, min(start + size, n_samples)) for start in range(0, n_samples, size)], size


def tables_linear_terms(tb, gx, gy, s, sdot, sddot, lam):
    """M, D, K (N, n, n), R (N, n), J (N, r, n) of ``LinearTerms`` from the model's tables ``tb``
    (``_model._Tables``) and gravity ``gx, gy`` (m/s^2) at the samples ``s, sdot, sddot`` (N, n),
    ``lam`` (N, r), contiguous; torque drives left out. One kernel call per quantity; numpy sums."""
    n_samples, n = s.shape
    M, D, K = (np.zeros((n_samples, n, n)) for _ in range(3))
    Q = np.zeros((n_samples, n))
    J = np.empty((n_samples, lam.shape[1], n))
    J[:] = tb.h_lin
    _kernels.mass_matrix(s, tb.mp_int, tb.mp_real, tb.shp, tb.idx, M)
    _kernels.forces(s, sdot, gx, gy, tb.mp_int, tb.mp_real, tb.sp_int, tb.sp_real, tb.shp, tb.idx, tb.k0,
                    tb.c0, Q)
    _kernels.mass_matrix_jacobian(s, sddot, tb.mp_int, tb.mp_real, tb.shp, tb.idx, K)
    _kernels.constraint_force_jacobian(s, lam, tb.ct_int, tb.ct_real, tb.shp, tb.idx, K)
    _kernels.constraint_jacobian(s, tb.ct_int, tb.ct_real, tb.shp, tb.idx, J)
    ranges, size = _chunks(n_samples, n)
    dQ_ds = np.empty((size, n, n))
    for start, stop in ranges:
        block = dQ_ds[:stop - start]
        block[:] = 0.0
        _kernels.force_jacobians(s[start:stop], sdot[start:stop], gx, gy, tb.mp_int, tb.mp_real, tb.sp_int,
                                 tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, block, D[start:stop])
        K[start:stop] -= block      # d(M s'')/ds - dQ/ds + d(Phi_s^T lam)/ds
    np.negative(D, out=D)           # D = -dQ/ds'
    R = np.einsum("kab,kb->ka", M, sddot) - Q + np.einsum("kra,kr->ka", J, lam)
    return M, D, K, R, J


def tables_inertia_residual(tb, gx, gy, s, sdot, sddot):
    """``M(s) s'' - Q(s, s')`` (N, n) from the model's tables at the samples ``s, sdot, sddot``
    (N, n), contiguous; torque drives left out."""
    n_samples, n = s.shape
    Q = np.zeros((n_samples, n))
    _kernels.forces(s, sdot, gx, gy, tb.mp_int, tb.mp_real, tb.sp_int, tb.sp_real, tb.shp, tb.idx, tb.k0,
                    tb.c0, Q)
    out = np.empty((n_samples, n))
    # the mass matrices a chunk of samples at a time: M s'' needs no (N, n, n) array of them
    ranges, size = _chunks(n_samples, n)
    M = np.empty((size, n, n))
    for start, stop in ranges:
        block = M[:stop - start]
        block[:] = 0.0
        _kernels.mass_matrix(s[start:stop], tb.mp_int, tb.mp_real, tb.shp, tb.idx, block)
        np.einsum("kab,kb->ka", block, sddot[start:stop], out=out[start:stop])
    out -= Q
    return out


def tables_constraint_terms(tb, s, sdot, J, gamma, phi) -> None:
    """Fill ``J`` (N, r, n) with Phi_s at the samples ``s`` (N, n); with ``sdot`` (N, n) add the
    point constraints' part of gamma to ``gamma`` (N, r); with ``phi`` (N, r) add ``h_lin s`` and
    the point constraints' part of Phi to it. ``gamma`` and ``phi`` hold the constant and drive
    parts on entry."""
    J[:] = tb.h_lin
    _kernels.constraint_jacobian(s, tb.ct_int, tb.ct_real, tb.shp, tb.idx, J)
    if sdot is not None:
        _kernels.constraint_gamma(s, sdot, tb.ct_int, tb.ct_real, tb.shp, tb.idx, gamma)
    if phi is not None:
        phi += s @ tb.h_lin.T
        _kernels.constraints(s, tb.ct_int, tb.ct_real, tb.shp, tb.idx, phi)


# ---------------------------------------------------------------------------------------------------
# Kernels of the assembled model
# ---------------------------------------------------------------------------------------------------
# no_cfunc_wrapper: no kernel is passed as a first-class function (its C wrapper is first-run
# compilation for nothing; see _kernels).
# forceinline on the helpers of a few lines: LLVM inlines them into every caller (its alwaysinline),
# so the machine code is what numba's inline="always" gave, while numba types and lowers each once, as
# a kernel of its own, instead of once per call site (inline="always" cost about 7 % more of the first
# run's compilation: docs/benchmarks.md, session 9).
@numba.njit(cache=True, forceinline=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _copy_matrix(source, target):
    """target[:, :] = source, as a loop: an array assigned to a slice would compile numba's
    shape-mismatch message (string formatting, seconds of the first run's compilation)."""
    for i in range(source.shape[0]):
        for j in range(source.shape[1]):
            target[i, j] = source[i, j]


@numba.njit(cache=True, forceinline=True, no_cfunc_wrapper=True)
def _max_abs(values):
    """max |values| of a 1-D array (0 when empty, NaN when one is NaN: never a converged NaN), as
    a loop: ``np.abs(values).max()`` compiles a temporary array's ufunc and numba's reduction, a
    second of the first run's compilation."""
    worst = 0.0
    for value in values:
        size = abs(value)
        if size > worst or size != size:  # a NaN stays: no comparison passes it
            worst = size
    return worst


@numba.njit(cache=True, no_cfunc_wrapper=True)
def scaled_correction(corrected, predicted, rigid, column_scale):
    """How far Newton moved the rigid coordinates from the predictor:
    ``max_j |corrected - predicted|[rigid[j]] / column_scale[j]`` (rad, or units of the link scale).
    The one measure of both continuation paths of the nominal motion (``_kinematics``)."""
    worst = 0.0
    for j in range(rigid.shape[0]):
        worst = max(worst, abs(corrected[rigid[j]] - predicted[rigid[j]]) / column_scale[j])
    return worst


@numba.njit(cache=True, no_cfunc_wrapper=True)
def continue_positions_kernel(s, start, drive_rows, drive_angles, rigid, phi0, h_lin, ct_int,
                              ct_real, shp, idx, newton_stop, max_correction, column_scale,
                              max_iterations):
    """Positions s[k] (in place) for k = start.. by continuation: predictor the quadratic
    extrapolation of s[k-3..k-1], then Newton on the rigid coordinates. Returns the first k whose
    Newton did not converge or moved further than ``max_correction`` from the predictor
    (``scaled_correction``), or len(s)."""
    n_samples, n = s.shape
    r = phi0.shape[0]
    n_rigid = rigid.shape[0]
    phi = np.empty(r)
    jac = np.empty((r, n))
    jac_r = np.empty((r, n_rigid))
    predicted = np.empty(n)
    q = np.empty(n)
    # one-sample views for the model kernels, which take samples along a leading axis
    q_row = q.reshape((1, n))
    phi_row = phi.reshape((1, r))
    jac_row = jac.reshape((1, r, n))
    for k in range(start, n_samples):
        for j in range(n):  # loops, not array expressions: less to compile on the first run
            predicted[j] = 3.0 * s[k - 1, j] - 3.0 * s[k - 2, j] + s[k - 3, j]
            q[j] = predicted[j]
        converged = False
        for _ in range(max_iterations):
            # Phi = phi0 + h_lin s - drive angle (drive rows) + point-constraint terms.
            for i in range(r):
                acc = phi0[i]
                for j in range(n):
                    acc += h_lin[i, j] * q[j]
                phi[i] = acc
            for d in range(drive_rows.shape[0]):
                phi[drive_rows[d]] -= drive_angles[k, d]
            _kernels.constraints(q_row, ct_int, ct_real, shp, idx, phi_row)
            if _max_abs(phi) < newton_stop:
                converged = True
                break
            _copy_matrix(h_lin, jac)
            _kernels.constraint_jacobian(q_row, ct_int, ct_real, shp, idx, jac_row)
            for i in range(r):
                for j in range(n_rigid):
                    jac_r[i, j] = jac[i, rigid[j]]
            if not solve_in_place(jac_r, phi):  # singular (a toggle): the careful Python path names it
                return k
            for j in range(n_rigid):
                q[rigid[j]] -= phi[j]
        if not converged or scaled_correction(q, predicted, rigid,
                                              column_scale) >= max_correction:
            return k
        for j in range(n):
            s[k, j] = q[j]
    return n_samples
