"""Numba kernels of the assembled equations of motion (see ``_assemble`` for the formulation).

Every material quantity is a sum over *points* of a link. A point sits at local position
``p = c + S q`` in the link frame (``c`` = (cx, cy) in m, ``S`` the 2 x ne shape matrix, zero for a
rigid link) and at ``r = R + A(theta) p`` in the plane. With ``s_link = (x, y, theta, q)``:

    L = dr/ds_link = [I, A' p, A S],            A' = J A,  J = [[0, -1], [1, 0]]     (1)
    r'' = L s_link'' + c,  c = Ldot s' = -theta'^2 A p + 2 theta' J A S q'           (2)
    D(v) = d(L^T v)/ds_link (v fixed): D_tt = -(A p).v, D_tq_k = D_q_k t = (J A S_k).v  (3)

Point tables (rows of int64 and float64 arrays, built once by ``_assemble``). Shape rows are stored
sparsely: a point of a Hermite element touches at most 6 of its link's elastic coordinates, so each
point keeps only its ``nnz`` active ones, ``idx[iptr : iptr + nnz]`` (indices among the link's
elastic coordinates), with their values in ``shp`` (``nnz`` per row):

* mass points ``mp_int = (offset, nnz, ptr, iptr)``, ``mp_real = (m, J, cx, cy)``: mass m (kg),
  rotary inertia J (kg m^2) with angular velocity ``theta' + g.q'``;
  ``shp[ptr : ptr + 3 nnz] = (S_axial, S_transverse, g)``.
* strain points ``sp_int = (offset, nnz, ptr, iptr, size, pptr)``, ``sp_real = (w EA, w EI, beta)``
  (quadrature weight times rigidity, and the link's Kelvin-Voigt coefficient beta in s);
  ``shp[ptr : ptr + 3 nnz] = (u', w', w'')``. Strain points come
  in consecutive *groups* (an element of a Hermite link, a whole Ritz link) that share ``offset``,
  ``nnz`` and ``iptr``; the first row of a group holds its ``size`` G and ``shp[pptr : pptr + G^2]``
  the row-major projection ``P`` (G x G) onto the link's axial strain functions (``_assemble``).
  Projected membrane strain (geometric stiffening; links without it use the constant ``K0``):

      s_j = w'_j q,   eps_g = u'_g q + sum_j P_gj s_j^2 / 2,   kappa_g = w''_g q           (4)
      Pi = sum_g 1/2 (w EA eps_g^2 + w EI kappa_g^2),   c_j = sum_g w_g EA eps_g P_gj
      dPi/dq = sum_g w EA eps_g u'_g + c_g s_g w'_g + w EI kappa_g w''_g                     (5)
      d2Pi/dq2 = sum_g w EA G_g G_g^T + c_g w'_g w'_g^T + w EI w''_g w''_g^T,
      G_g = d eps_g / dq = u'_g + sum_j P_gj s_j w'_j                                         (6)

  Kelvin-Voigt damping acts on the rates of the same strains (damping stress beta E eps'), i.e.
  the Rayleigh dissipation function D = beta/2 sum_g (w EA eps'_g^2 + w EI kappa'_g^2) with

      s'_j = w'_j q',   eps'_g = G_g q' = u'_g q' + sum_j P_gj s_j s'_j,   kappa'_g = w''_g q'  (7)
      -dD/dq' = -beta sum_g w EA eps'_g G_g + w EI kappa'_g w''_g
              = -sum_g beta w EA eps'_g u'_g + d_g s_g w'_g + beta w EI kappa'_g w''_g,
      d_j = beta sum_g w EA eps'_g P_gj                                                     (8)
      d2D/dq'2 = beta sum_g w EA G_g G_g^T + w EI w''_g w''_g^T
      d2D/dq'dq = sum_g d_g w'_g w'_g^T + beta w EA G_g r_g^T,  r_g = d eps'_g/dq
                = sum_j P_gj s'_j w'_j                                                     (9)

  At q = 0 this is the constant ``beta K_ee``; unlike it, it does not resist the chord shortening
  of a bent link (eps' = 0 there while u' moves), which the linear form would damp as an axial
  strain rate ("damping locking").
* constraint terms ``ct_int = (row, offset, nnz, ptr, iptr, frame)``, ``ct_real = (dx, dy, cx, cy)``:
  ``Phi[row] += d . r`` with ``frame = -1`` (``d`` fixed in the plane: pins, sliders), else
  ``Phi[row] += e . (r - R_f)``, ``e = A(theta_f) d``, with ``R_f, theta_f`` the frame of the link
  whose coordinates start at ``frame`` (a point on a line of a moving link: a pin in a slot);
  ``shp[ptr : ptr + 2 nnz] = (S_axial, S_transverse)``. With ``delta = r - R_f`` and
  ``Je = (-e_y, e_x)`` (``de/dtheta_f``), a frame term adds to the point term's derivatives

      Phi_s: -e on R_f, (Je) . delta on theta_f                                            (10)
      gamma: -2 theta_f' (Je) . delta' + theta_f'^2 e . delta,   delta' = L s' - R_f'       (11)
      d(Phi_s^T lam)/ds: lam [L^T Je on (point, theta_f) and its transpose, -Je on
                         (R_f, theta_f) and its transpose, -e . delta on (theta_f, theta_f)] (12)

  and the point term itself is taken with ``e`` for ``d``.

Inside a kernel, ``cols[a]`` maps the point's local column ``a`` (0, 1, 2 = x, y, theta, then the
active elastic coordinates) to its index in ``s``.

All kernels fill preallocated outputs (zeroed by the caller where they accumulate). The kernels of
the model's quantities (``mass_matrix`` to ``constraint_force_jacobian``) take N samples at once, a
leading axis on their coordinates and outputs (N = 1 for one state: a ``reshape`` view), so that a
model evaluated along a motion is one call per quantity with nothing compiled around it: a kernel
that called them at each sample had LLVM optimise and emit their code again inside it (the batch
kernels ``linear_terms_kernel`` and ``constraint_terms_kernel`` were 2.5 s of a first run's 17 s of
compilation for a steady state: docs/benchmarks.md, session 15).
"""

from __future__ import annotations

import math

import numba
import numpy as np


# no_cfunc_wrapper on every kernel: none is passed as a first-class function, and the C wrapper numba
# builds for that costs about 35 ms of the first run's compilation per kernel; no_cpython_wrapper on
# the helpers that only kernels call (the Python wrapper unboxing their arrays costs as much again).
# forceinline on the helpers of a few lines: LLVM inlines them into every caller (its alwaysinline),
# so the machine code is what numba's inline="always" gave, while numba types and lowers each once, as
# a kernel of its own, instead of once per call site (inline="always" cost about 7 % more of the first
# run's compilation: docs/benchmarks.md, session 9). Not on the three that allocate the scratch arrays
# (inline="always"): returned from a function of their own, the arrays' reference counting made the
# constraint terms along a motion 12 % slower (four_bar_fem4, session 9).
@numba.njit(cache=True, inline="always", no_cfunc_wrapper=True)
def _max_local(table_nnz):
    n = 0
    for i in range(table_nnz.shape[0]):
        if table_nnz[i] > n:
            n = table_nnz[i]
    return n + 3


@numba.njit(cache=True, inline="always", no_cfunc_wrapper=True)
def _scratch(table_nnz):
    """Columns of L (x and y components) and their indices in s, for the largest point."""
    nmax = _max_local(table_nnz)
    return np.empty(nmax), np.empty(nmax), np.empty(nmax, dtype=np.int64)


@numba.njit(cache=True, inline="always", no_cfunc_wrapper=True)
def _group_scratch(sp_int):
    """Per-point arrays (slope, eps, kappa, c) for the largest strain-point group."""
    n = 1
    for i in range(sp_int.shape[0]):
        if sp_int[i, 4] > n:
            n = sp_int[i, 4]
    return np.empty(n), np.empty(n), np.empty(n), np.empty(n)


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _strain_rows(v, i0, sp_int, shp, idx, axial, slope, curvature):
    """u'_g v, w'_g v and w''_g v (the first ``size`` entries) at the strain points of the group
    starting at row i0, for a vector v of coordinates (q, eq. 4) or of their rates (q', eq. 7)."""
    off, nnz, iptr = sp_int[i0, 0], sp_int[i0, 1], sp_int[i0, 3]
    for g in range(sp_int[i0, 4]):
        ptr = sp_int[i0 + g, 2]
        du = 0.0
        dw = 0.0
        kap = 0.0
        for k in range(nnz):
            vk = v[off + 3 + idx[iptr + k]]
            du += shp[ptr + k] * vk
            dw += shp[ptr + nnz + k] * vk
            kap += shp[ptr + 2 * nnz + k] * vk
        axial[g] = du
        slope[g] = dw
        curvature[g] = kap


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _project(i0, sp_int, sp_real, shp, factor, a, b, scale, strain, coef):
    """strain_g += factor sum_j P_gj a_j b_j, then coef_j = scale sum_g w EA strain_g P_gj, over the
    group starting at row i0 (eq. 4-5 with a = b = s, factor 1/2, scale 1; eq. 7-8 with a = s,
    b = s', factor 1, scale beta)."""
    size, pptr = sp_int[i0, 4], sp_int[i0, 5]
    for g in range(size):
        acc = 0.0
        for j in range(size):
            acc += shp[pptr + g * size + j] * a[j] * b[j]
        strain[g] += factor * acc
    for j in range(size):
        acc = 0.0
        for g in range(size):
            acc += sp_real[i0 + g, 0] * strain[g] * shp[pptr + g * size + j]
        coef[j] = scale * acc


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _membrane_group(s, i0, sp_int, sp_real, shp, idx, slope, eps, kappa, coef):
    """Eq. (4)-(5) for the strain-point group starting at row i0: fill slope s_j, projected strain
    eps_g, curvature kappa_g and c_j (first ``size`` entries); return the group's size."""
    _strain_rows(s, i0, sp_int, shp, idx, eps, slope, kappa)
    _project(i0, sp_int, sp_real, shp, 0.5, slope, slope, 1.0, eps, coef)
    return sp_int[i0, 4]


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _membrane_rate_group(sdot, i0, sp_int, sp_real, shp, idx, slope, slope_rate, eps_rate,
                         kappa_rate, coef_rate):
    """Eq. (7)-(8) for the group starting at row i0, after ``_membrane_group`` filled ``slope``:
    fill s'_j, eps'_g, kappa'_g and d_j (first ``size`` entries)."""
    _strain_rows(sdot, i0, sp_int, shp, idx, eps_rate, slope_rate, kappa_rate)
    _project(i0, sp_int, sp_real, shp, 1.0, slope, slope_rate, sp_real[i0, 2], eps_rate,
             coef_rate)


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _subtract_strain_force(out, i0, sp_int, sp_real, shp, idx, scale, strain, curvature, slope,
                           coef):
    """out -= sum_g scale (w EA strain_g u'_g + w EI curvature_g w''_g) + coef_g slope_g w'_g over
    the group starting at row i0: dPi/dq of eq. (5) (scale 1) or dD/dq' of eq. (8) (scale beta,
    with the rates of eq. 7 and d_j)."""
    off, nnz, iptr = sp_int[i0, 0], sp_int[i0, 1], sp_int[i0, 3]
    for g in range(sp_int[i0, 4]):
        ptr = sp_int[i0 + g, 2]
        ea, ei = sp_real[i0 + g, 0], sp_real[i0 + g, 1]
        for k in range(nnz):
            out[off + 3 + idx[iptr + k]] -= (scale * (ea * strain[g] * shp[ptr + k]
                                                      + ei * curvature[g] * shp[ptr + 2 * nnz + k])
                                             + coef[g] * slope[g] * shp[ptr + nnz + k])


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _fill_l(s, off, nnz, cx, cy, ptr, iptr, shp, idx, lx, ly, cols):
    """Fill the active columns of L (eq. 1) into lx, ly and their indices in s into cols (length
    3 + nnz); return A p."""
    th = s[off + 2]
    c = math.cos(th)
    sn = math.sin(th)
    px = cx
    py = cy
    cols[0] = off
    cols[1] = off + 1
    cols[2] = off + 2
    for k in range(nnz):
        col = off + 3 + idx[iptr + k]
        cols[3 + k] = col
        px += shp[ptr + k] * s[col]
        py += shp[ptr + nnz + k] * s[col]
    apx = c * px - sn * py
    apy = sn * px + c * py
    lx[0] = 1.0
    ly[0] = 0.0
    lx[1] = 0.0
    ly[1] = 1.0
    lx[2] = -apy
    ly[2] = apx
    for k in range(nnz):
        sa = shp[ptr + k]
        st = shp[ptr + nnz + k]
        lx[3 + k] = c * sa - sn * st
        ly[3 + k] = sn * sa + c * st
    return apx, apy


@numba.njit(cache=True, forceinline=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _elastic_velocity(sdot, nnz, lx, ly, cols):
    """A S q' (m/s)."""
    vx = 0.0
    vy = 0.0
    for k in range(nnz):
        vx += lx[3 + k] * sdot[cols[3 + k]]
        vy += ly[3 + k] * sdot[cols[3 + k]]
    return vx, vy


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _point_motion(s, sdot, gx, gy, i, mp_int, mp_real, shp, idx, lx, ly, cols):
    """For mass point ``i``: fill L (eq. 1) and return A p, theta', A S q' and v = g - c (eq. 2),
    the acceleration that gravity minus the velocity terms give the point:
    c = -theta'^2 A p + 2 theta' J A S q'."""
    off, nnz, ptr, iptr = mp_int[i, 0], mp_int[i, 1], mp_int[i, 2], mp_int[i, 3]
    apx, apy = _fill_l(s, off, nnz, mp_real[i, 2], mp_real[i, 3], ptr, iptr, shp, idx, lx, ly,
                       cols)
    wt = sdot[off + 2]
    asv_x, asv_y = _elastic_velocity(sdot, nnz, lx, ly, cols)
    vx = gx + wt * wt * apx + 2.0 * wt * asv_y
    vy = gy + wt * wt * apy - 2.0 * wt * asv_x
    return apx, apy, wt, asv_x, asv_y, vx, vy


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _add_d(out, scale, nnz, apx, apy, lx, ly, cols, vx, vy):
    """out += scale * D(v), eq. (3)."""
    t = cols[2]
    out[t, t] += -scale * (apx * vx + apy * vy)
    for k in range(nnz):
        # J A S_k = (-ly, lx)
        value = scale * (-ly[3 + k] * vx + lx[3 + k] * vy)
        out[t, cols[3 + k]] += value
        out[cols[3 + k], t] += value


@numba.njit(cache=True, no_cfunc_wrapper=True)
def mass_matrix(S, mp_int, mp_real, shp, idx, outs):
    """M = sum m L^T L + J h h^T, h = (0, 0, 1, g) (seed eq. 2.12 by d'Alembert) at each sample of
    S (N, n) into outs (N, n, n), zeroed."""
    lx, ly, cols = _scratch(mp_int[:, 1])
    for sample in range(S.shape[0]):
        s, out = S[sample], outs[sample]
        for i in range(mp_int.shape[0]):
            off, nnz, ptr, iptr = mp_int[i, 0], mp_int[i, 1], mp_int[i, 2], mp_int[i, 3]
            m, inertia, cx, cy = mp_real[i, 0], mp_real[i, 1], mp_real[i, 2], mp_real[i, 3]
            _fill_l(s, off, nnz, cx, cy, ptr, iptr, shp, idx, lx, ly, cols)
            nl = 3 + nnz
            for a in range(nl):
                for b in range(nl):
                    out[cols[a], cols[b]] += m * (lx[a] * lx[b] + ly[a] * ly[b])
            if inertia != 0.0:
                g0 = ptr + 2 * nnz
                t = off + 2
                out[t, t] += inertia
                for k in range(nnz):
                    out[t, cols[3 + k]] += inertia * shp[g0 + k]
                    out[cols[3 + k], t] += inertia * shp[g0 + k]
                    for j in range(nnz):
                        out[cols[3 + k], cols[3 + j]] += inertia * shp[g0 + k] * shp[g0 + j]


@numba.njit(cache=True, no_cfunc_wrapper=True)
def mass_matrix_jacobian(S, Acc, mp_int, mp_real, shp, idx, outs):
    """d(M(s) a)/ds, a fixed: sum m [L^T d(L a)/ds + D(L a)] (eq. 1, 3); h is constant so the
    rotary inertia adds nothing. At each sample of S, Acc (N, n) into outs (N, n, n), zeroed."""
    lx, ly, cols = _scratch(mp_int[:, 1])
    jx = np.empty(len(lx))
    jy = np.empty(len(lx))
    for sample in range(S.shape[0]):
        s, acc, out = S[sample], Acc[sample], outs[sample]
        for i in range(mp_int.shape[0]):
            off, nnz, ptr, iptr = mp_int[i, 0], mp_int[i, 1], mp_int[i, 2], mp_int[i, 3]
            m, cx, cy = mp_real[i, 0], mp_real[i, 2], mp_real[i, 3]
            if m == 0.0:
                continue
            apx, apy = _fill_l(s, off, nnz, cx, cy, ptr, iptr, shp, idx, lx, ly, cols)
            nl = 3 + nnz
            la_x = 0.0
            la_y = 0.0
            for a in range(nl):
                la_x += lx[a] * acc[cols[a]]
                la_y += ly[a] * acc[cols[a]]
            asa_x, asa_y = _elastic_velocity(acc, nnz, lx, ly, cols)  # A S a_q
            at = acc[off + 2]
            # d(L a)/ds: theta column -A p a_t + J A S a_q; q_k columns J A S_k a_t
            jx[2] = -apx * at - asa_y
            jy[2] = -apy * at + asa_x
            for k in range(nnz):
                jx[3 + k] = -ly[3 + k] * at
                jy[3 + k] = lx[3 + k] * at
            for a in range(nl):
                for b in range(2, nl):
                    out[cols[a], cols[b]] += m * (lx[a] * jx[b] + ly[a] * jy[b])
            _add_d(out, m, nnz, apx, apy, lx, ly, cols, la_x, la_y)


@numba.njit(cache=True, no_cfunc_wrapper=True)
def forces(S, Sd, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0, c0, outs):
    """Q = sum m L^T (g - c) - dPi/ds - dD/ds' - K0 s - C0 s' (eq. 2, 5, 8; seed eq. 2.10, 2.13) at
    each sample of S, Sd (N, n) into outs (N, n), zeroed."""
    lx, ly, cols = _scratch(mp_int[:, 1])
    slope, eps, kappa, coef = _group_scratch(sp_int)
    slope_rate, eps_rate, kappa_rate, coef_rate = _group_scratch(sp_int)
    for sample in range(S.shape[0]):
        s, sdot, out = S[sample], Sd[sample], outs[sample]
        for i in range(mp_int.shape[0]):
            m = mp_real[i, 0]
            if m == 0.0:
                continue
            apx, apy, wt, asv_x, asv_y, vx, vy = _point_motion(s, sdot, gx, gy, i, mp_int, mp_real,
                                                               shp, idx, lx, ly, cols)
            for a in range(3 + mp_int[i, 1]):
                out[cols[a]] += m * (lx[a] * vx + ly[a] * vy)
        i0 = np.int64(0)  # not the literal 0: callees would compile a second, Literal[int] signature
        while i0 < sp_int.shape[0]:
            # -dPi/dq, eq. (5)
            size = _membrane_group(s, i0, sp_int, sp_real, shp, idx, slope, eps, kappa, coef)
            _subtract_strain_force(out, i0, sp_int, sp_real, shp, idx, 1.0, eps, kappa, slope, coef)
            beta = sp_real[i0, 2]
            if beta != 0.0:
                # -dD/dq', eq. (8)
                _membrane_rate_group(sdot, i0, sp_int, sp_real, shp, idx, slope, slope_rate,
                                     eps_rate, kappa_rate, coef_rate)
                _subtract_strain_force(out, i0, sp_int, sp_real, shp, idx, beta, eps_rate,
                                       kappa_rate, slope, coef_rate)
            i0 += size
        n = s.shape[0]
        if k0.shape[0] == n:
            for a in range(n):
                acc = 0.0
                for b in range(n):
                    acc += k0[a, b] * s[b] + c0[a, b] * sdot[b]
                out[a] -= acc


@numba.njit(cache=True, no_cfunc_wrapper=True)
def force_jacobians(S, Sd, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0, c0, outs_s,
                    outs_v):
    """dQ/ds and dQ/ds' of ``forces`` (derivatives of eq. 2 and of the strain forces) at each sample
    of S, Sd (N, n) into outs_s, outs_v (N, n, n), zeroed."""
    lx, ly, cols = _scratch(mp_int[:, 1])
    slope, eps, kappa, coef = _group_scratch(sp_int)
    slope_rate, eps_rate, kappa_rate, coef_rate = _group_scratch(sp_int)
    grad = np.empty(max(_max_local(sp_int[:, 1]) - 3, 1))
    grad_rate = np.empty(grad.shape[0])
    for sample in range(S.shape[0]):
        s, sdot, out_s, out_v = S[sample], Sd[sample], outs_s[sample], outs_v[sample]
        for i in range(mp_int.shape[0]):
            m = mp_real[i, 0]
            if m == 0.0:
                continue
            apx, apy, wt, asv_x, asv_y, vx, vy = _point_motion(s, sdot, gx, gy, i, mp_int, mp_real,
                                                               shp, idx, lx, ly, cols)
            nnz = mp_int[i, 1]
            nl = 3 + nnz
            t = mp_int[i, 0] + 2
            # d(g - c)/dtheta = w^2 J A p + 2 w A S q', with J A p = (-apy, apx)
            dtx = -wt * wt * apy + 2.0 * wt * asv_x
            dty = wt * wt * apx + 2.0 * wt * asv_y
            # d(g - c)/dtheta' = 2 w A p - 2 J A S q'
            dvx = 2.0 * wt * apx + 2.0 * asv_y
            dvy = 2.0 * wt * apy - 2.0 * asv_x
            for a in range(nl):
                ca = cols[a]
                out_s[ca, t] += m * (lx[a] * dtx + ly[a] * dty)
                out_v[ca, t] += m * (lx[a] * dvx + ly[a] * dvy)
                for k in range(nnz):
                    ck = cols[3 + k]
                    # d(g - c)/dq_k = w^2 A S_k;  d(g - c)/dq'_k = -2 w J A S_k
                    out_s[ca, ck] += m * wt * wt * (lx[a] * lx[3 + k] + ly[a] * ly[3 + k])
                    out_v[ca, ck] += m * (-2.0 * wt) * (-lx[a] * ly[3 + k] + ly[a] * lx[3 + k])
            _add_d(out_s, m, nnz, apx, apy, lx, ly, cols, vx, vy)
        i0 = np.int64(0)  # not the literal 0: callees would compile a second, Literal[int] signature
        while i0 < sp_int.shape[0]:
            # -d2Pi/dq2, eq. (6); with Kelvin-Voigt damping also -d2D/dq'dq and -d2D/dq'2, eq. (9)
            size = _membrane_group(s, i0, sp_int, sp_real, shp, idx, slope, eps, kappa, coef)
            off, nnz, iptr, pptr = sp_int[i0, 0], sp_int[i0, 1], sp_int[i0, 3], sp_int[i0, 5]
            beta = sp_real[i0, 2]
            if beta != 0.0:
                _membrane_rate_group(sdot, i0, sp_int, sp_real, shp, idx, slope, slope_rate,
                                     eps_rate, kappa_rate, coef_rate)
            for g in range(size):
                ptr = sp_int[i0 + g, 2]
                ea, ei = sp_real[i0 + g, 0], sp_real[i0 + g, 1]
                for k in range(nnz):
                    grad[k] = shp[ptr + k]
                    grad_rate[k] = 0.0
                for j in range(size):
                    pj = shp[pptr + g * size + j] * slope[j]
                    ptr_j = sp_int[i0 + j, 2]
                    for k in range(nnz):
                        grad[k] += pj * shp[ptr_j + nnz + k]
                    if beta != 0.0:
                        pj_rate = shp[pptr + g * size + j] * slope_rate[j]
                        for k in range(nnz):
                            grad_rate[k] += pj_rate * shp[ptr_j + nnz + k]
                for k in range(nnz):
                    ck = off + 3 + idx[iptr + k]
                    for j in range(nnz):
                        cj = off + 3 + idx[iptr + j]
                        out_s[ck, cj] -= (
                            ea * grad[k] * grad[j]
                            + coef[g] * shp[ptr + nnz + k] * shp[ptr + nnz + j]
                            + ei * shp[ptr + 2 * nnz + k] * shp[ptr + 2 * nnz + j])
                        if beta != 0.0:
                            out_s[ck, cj] -= (coef_rate[g] * shp[ptr + nnz + k] * shp[ptr + nnz + j]
                                              + beta * ea * grad[k] * grad_rate[j])
                            out_v[ck, cj] -= beta * (
                                ea * grad[k] * grad[j]
                                + ei * shp[ptr + 2 * nnz + k] * shp[ptr + 2 * nnz + j])
            i0 += size
        n = s.shape[0]
        if k0.shape[0] == n:
            for a in range(n):
                for b in range(n):
                    out_s[a, b] -= k0[a, b]
                    out_v[a, b] -= c0[a, b]


@numba.njit(cache=True, forceinline=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _term_direction(s, frame, dx, dy):
    """The term's direction in the plane: ``d``, or ``e = A(theta_f) d`` in a link's frame."""
    if frame < 0:
        return dx, dy
    c = math.cos(s[frame + 2])
    sn = math.sin(s[frame + 2])
    return c * dx - sn * dy, sn * dx + c * dy


@numba.njit(cache=True, no_cfunc_wrapper=True, no_cpython_wrapper=True)
def _constraint_term(s, i, ct_int, ct_real, shp, idx, lx, ly, cols):
    """Constraint term ``i`` at ``s``: its row, link offset, active elastic count and frame offset
    (-1: fixed in the plane), ``A p`` (the point's offset from its link's origin, eq. 1) with its
    rows ``lx, ly`` on ``cols`` filled, and the term's direction ``e`` (``_term_direction``)."""
    row, off, nnz = ct_int[i, 0], ct_int[i, 1], ct_int[i, 2]
    ptr, iptr, frame = ct_int[i, 3], ct_int[i, 4], ct_int[i, 5]
    dx, dy, cx, cy = ct_real[i, 0], ct_real[i, 1], ct_real[i, 2], ct_real[i, 3]
    apx, apy = _fill_l(s, off, nnz, cx, cy, ptr, iptr, shp, idx, lx, ly, cols)
    ex, ey = _term_direction(s, frame, dx, dy)
    return row, off, nnz, frame, apx, apy, ex, ey


@numba.njit(cache=True, no_cfunc_wrapper=True)
def constraints(S, ct_int, ct_real, shp, idx, outs):
    """Phi[row] += d . (R + A p), or e . (R + A p - R_f) in a frame, over the constraint terms, at
    each sample of S (N, n); outs (N, r) holds the constant parts."""
    lx, ly, cols = _scratch(ct_int[:, 2])
    for sample in range(S.shape[0]):
        s, out = S[sample], outs[sample]
        for i in range(ct_int.shape[0]):
            row, off, nnz, frame, apx, apy, ex, ey = _constraint_term(s, i, ct_int, ct_real, shp, idx, lx, ly, cols)
            rx = s[off] + apx
            ry = s[off + 1] + apy
            if frame >= 0:
                rx -= s[frame]
                ry -= s[frame + 1]
            out[row] += ex * rx + ey * ry


@numba.njit(cache=True, no_cfunc_wrapper=True)
def constraint_jacobian(S, ct_int, ct_real, shp, idx, outs):
    """Phi_s[row] += d^T L (eq. 1), with a frame eq. (10), at each sample of S (N, n); outs
    (N, r, n) holds the constant (linear) rows."""
    lx, ly, cols = _scratch(ct_int[:, 2])
    for sample in range(S.shape[0]):
        s, out = S[sample], outs[sample]
        for i in range(ct_int.shape[0]):
            row, off, nnz, frame, apx, apy, ex, ey = _constraint_term(s, i, ct_int, ct_real, shp, idx, lx, ly, cols)
            for a in range(3 + nnz):
                out[row, cols[a]] += ex * lx[a] + ey * ly[a]
            if frame >= 0:
                out[row, frame] -= ex
                out[row, frame + 1] -= ey
                out[row, frame + 2] += -ey * (s[off] + apx - s[frame]) + ex * (s[off + 1] + apy
                                                                              - s[frame + 1])


@numba.njit(cache=True, no_cfunc_wrapper=True)
def constraint_gamma(S, Sd, ct_int, ct_real, shp, idx, outs):
    """gamma[row] -= d . c (eq. 2; the point constraints do not depend on t), with a frame also
    eq. (11), at each sample of S, Sd (N, n); outs (N, r) holds the drive rows' accelerations."""
    lx, ly, cols = _scratch(ct_int[:, 2])
    for sample in range(S.shape[0]):
        s, sdot, out = S[sample], Sd[sample], outs[sample]
        for i in range(ct_int.shape[0]):
            row, off, nnz, frame, apx, apy, ex, ey = _constraint_term(s, i, ct_int, ct_real, shp, idx, lx, ly, cols)
            wt = sdot[off + 2]
            asv_x, asv_y = _elastic_velocity(sdot, nnz, lx, ly, cols)
            cxv = -wt * wt * apx - 2.0 * wt * asv_y
            cyv = -wt * wt * apy + 2.0 * wt * asv_x
            out[row] -= ex * cxv + ey * cyv
            if frame >= 0:
                wf = sdot[frame + 2]
                delta_x = s[off] + apx - s[frame]
                delta_y = s[off + 1] + apy - s[frame + 1]
                rate_x = -sdot[frame]
                rate_y = -sdot[frame + 1]
                for a in range(3 + nnz):
                    rate_x += lx[a] * sdot[cols[a]]
                    rate_y += ly[a] * sdot[cols[a]]
                out[row] += (-2.0 * wf * (-ey * rate_x + ex * rate_y)
                             + wf * wf * (ex * delta_x + ey * delta_y))


@numba.njit(cache=True, no_cfunc_wrapper=True)
def constraint_force_jacobian(S, Lam, ct_int, ct_real, shp, idx, outs):
    """d(Phi_s^T lam)/ds = sum lam[row] D(d) (eq. 3), with a frame also eq. (12), at each sample of
    S (N, n), Lam (N, r) into outs (N, n, n), zeroed."""
    lx, ly, cols = _scratch(ct_int[:, 2])
    for sample in range(S.shape[0]):
        s, lam, out = S[sample], Lam[sample], outs[sample]
        for i in range(ct_int.shape[0]):
            row, off, nnz, frame, apx, apy, ex, ey = _constraint_term(s, i, ct_int, ct_real, shp, idx, lx, ly, cols)
            scale = lam[row]
            _add_d(out, scale, nnz, apx, apy, lx, ly, cols, ex, ey)
            if frame >= 0:
                tf = frame + 2
                for a in range(3 + nnz):
                    value = scale * (-ey * lx[a] + ex * ly[a])
                    out[cols[a], tf] += value
                    out[tf, cols[a]] += value
                out[frame, tf] += scale * ey
                out[tf, frame] += scale * ey
                out[frame + 1, tf] -= scale * ex
                out[tf, frame + 1] -= scale * ex
                out[tf, tf] -= scale * (ex * (s[off] + apx - s[frame]) + ey * (s[off + 1] + apy
                                                                             - s[frame + 1]))


@numba.njit(cache=True, no_cfunc_wrapper=True)
def kinetic_energy(s, sdot, mp_int, mp_real, shp, idx):
    """T = sum 1/2 m |L s'|^2 + 1/2 J (theta' + g.q')^2 (J)."""
    lx, ly, cols = _scratch(mp_int[:, 1])
    energy = 0.0
    for i in range(mp_int.shape[0]):
        off, nnz, ptr, iptr = mp_int[i, 0], mp_int[i, 1], mp_int[i, 2], mp_int[i, 3]
        m, inertia, cx, cy = mp_real[i, 0], mp_real[i, 1], mp_real[i, 2], mp_real[i, 3]
        _fill_l(s, off, nnz, cx, cy, ptr, iptr, shp, idx, lx, ly, cols)
        vx = 0.0
        vy = 0.0
        for a in range(3 + nnz):
            vx += lx[a] * sdot[cols[a]]
            vy += ly[a] * sdot[cols[a]]
        omega = sdot[off + 2]
        for k in range(nnz):
            omega += shp[ptr + 2 * nnz + k] * sdot[cols[3 + k]]
        energy += 0.5 * m * (vx * vx + vy * vy) + 0.5 * inertia * omega * omega
    return energy


@numba.njit(cache=True, no_cfunc_wrapper=True)
def potential_energy(s, gx, gy, mp_int, mp_real, sp_int, sp_real, shp, idx, k0):
    """V = -sum m g.r + strain energy (seed eq. 2.13, with the projected membrane strain of eq. (4)
    at strain points and 1/2 s^T K0 s for the links without geometric stiffening) (J)."""
    lx, ly, cols = _scratch(mp_int[:, 1])
    energy = 0.0
    for i in range(mp_int.shape[0]):
        off, nnz, ptr, iptr = mp_int[i, 0], mp_int[i, 1], mp_int[i, 2], mp_int[i, 3]
        m, cx, cy = mp_real[i, 0], mp_real[i, 2], mp_real[i, 3]
        apx, apy = _fill_l(s, off, nnz, cx, cy, ptr, iptr, shp, idx, lx, ly, cols)
        energy -= m * (gx * (s[off] + apx) + gy * (s[off + 1] + apy))
    slope, eps, kappa, coef = _group_scratch(sp_int)
    i0 = np.int64(0)  # not the literal 0: callees would compile a second, Literal[int] signature
    while i0 < sp_int.shape[0]:
        size = _membrane_group(s, i0, sp_int, sp_real, shp, idx, slope, eps, kappa, coef)
        for g in range(size):
            energy += 0.5 * (sp_real[i0 + g, 0] * eps[g] ** 2 + sp_real[i0 + g, 1] * kappa[g] ** 2)
        i0 += size
    n = s.shape[0]
    if k0.shape[0] == n:
        for a in range(n):
            for b in range(n):
                energy += 0.5 * s[a] * k0[a, b] * s[b]
    return energy


@numba.njit(cache=True, no_cfunc_wrapper=True)
def damping_power(s, sdot, sp_int, sp_real, shp, idx, c0):
    """Power dissipated by the damping (W, >= 0): 2 D of eq. (7)-(8), sum_g beta (w EA eps'_g^2 +
    w EI kappa'_g^2) over the strain points with Kelvin-Voigt damping, plus s'^T C0 s'."""
    slope, eps, kappa, coef = _group_scratch(sp_int)
    slope_rate, eps_rate, kappa_rate, coef_rate = _group_scratch(sp_int)
    power = 0.0
    i0 = np.int64(0)  # not the literal 0: callees would compile a second, Literal[int] signature
    while i0 < sp_int.shape[0]:
        size = _membrane_group(s, i0, sp_int, sp_real, shp, idx, slope, eps, kappa, coef)
        beta = sp_real[i0, 2]
        if beta != 0.0:
            _membrane_rate_group(sdot, i0, sp_int, sp_real, shp, idx, slope, slope_rate,
                                 eps_rate, kappa_rate, coef_rate)
            for g in range(size):
                power += beta * (sp_real[i0 + g, 0] * eps_rate[g] ** 2
                                 + sp_real[i0 + g, 1] * kappa_rate[g] ** 2)
        i0 += size
    n = s.shape[0]
    if c0.shape[0] == n:
        for a in range(n):
            for b in range(n):
                power += sdot[a] * c0[a, b] * sdot[b]
    return power
