"""Tangent of the discrete generalized-alpha step map (for shooting: the monodromy of a run,
``mechanisms.PeriodMap``): ``_propagate_tangent`` carries the sensitivity of the integrator's state, and of
the lagged controllers' states, through the converged steps of a run."""

from __future__ import annotations

from typing import Any, Mapping

import numba
import numpy as np

from periodic import lapack

from ._alpha_kernel import _fill_iteration_matrix
from ._alpha_step import _generalized_alpha_parameters, _lu_factor
from ._batch import linear_terms_along


def _propagate_tangent(model, run: Mapping[str, Any], h: float, rho_inf: float, start: np.ndarray,
                       lag_start: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Carry the sensitivity of the integrator's state through the converged steps of ``run``.

    ``start`` (4, n, p): d(q, v, a, sddot) / d(p start parameters) at ``t0``; ``lag_start`` (L, p)
    d y / d(parameters) of the model's L lag states (default 0). Returns the same two at the run's
    last step. Differentiating (GA1)-(GA3) and the converged step equations (NR) gives, per step,
    with the Jacobians at the new state (``q, v, sddot, lam`` at ``t_{n+1}``):

        G [d sddot_{n+1}; d lam_{n+1}] = -[K_t d qhat + C_t d vhat - H^T d c_n;  Phi_s d qhat / beta']

    ``G`` the exact iteration matrix of (NR) (``K_t``, ``C_t`` from ``linear_terms_along``: the
    same analytic derivatives Newton uses), ``d qhat``, ``d vhat`` the differentiated predictors of
    ``_start_step``; then ``d q = d qhat + beta' d sddot``, ``d v = d vhat + gamma' d sddot`` and
    (GA1) for ``d a``. ``lam`` does not enter the next step (only its predictor), so the state is
    (q, v, a, sddot). The run must have taken every step at ``h`` (no substeps): the caller checks
    ``run["n_substeps"]``. A singular ``G`` gives NaN sensitivities.

    Lags (``_Lags``): ``y_{n+1} = c_n + w u(q_{n+1}, v_{n+1})`` with the known part ``c_n = ((1 - r)
    y_n + r u_n) / (1 + r)``, ``w = r / (1 + r)``, enters Q as ``H^T y_{n+1}`` (``H`` the lags'
    gradients, (L, n)): ``K_t``, ``C_t`` gain ``-H^T w du/ds``, ``-H^T w du/ds'`` (the terms
    ``_Lags.add_force_jacobians`` gives Newton) and the right-hand side the known part ``d c_n``.
    """
    alpha_m, alpha_f, beta, gamma = _generalized_alpha_parameters(rho_inf)
    beta_p = h * h * beta * (1.0 - alpha_f) / (1.0 - alpha_m)
    gamma_p = h * gamma * (1.0 - alpha_f) / (1.0 - alpha_m)
    terms = linear_terms_along(model, run["t"][1:], run["s"][1:], run["sdot"][1:],
                               run["sddot"][1:], run["lam"][1:])
    state = np.array(start, dtype=np.float64, order="C")
    lags = _LagTangent(model, run, h, state.shape[2], lag_start)
    stiffness, damping = lags.with_force_jacobians(terms.stiffness, terms.damping)
    _tangent_steps(np.ascontiguousarray(terms.mass), np.ascontiguousarray(stiffness),
                   np.ascontiguousarray(damping), np.ascontiguousarray(terms.jacobian), h,
                   alpha_m, alpha_f, beta, gamma, beta_p, gamma_p, state, lags.gradients,
                   lags.decay, lags.weight, lags.du_ds, lags.du_dv, lags.state)
    return state, lags.state


class _LagTangent:
    """The lag terms of ``_propagate_tangent`` along ``run``: ``gradients`` H (L, n), per lag the
    trapezoidal rule's ``decay`` (1 - r) / (1 + r) and ``weight`` r / (1 + r) (L,), the inputs'
    derivatives ``du_ds``, ``du_dv`` (N+1, L, n) at the run's states and the sensitivity ``state``
    (L, p) (L = 0 without lags: empty arrays, and the kernel's lag loops do nothing)."""

    def __init__(self, model, run, h, n_columns, lag_start):
        n, n_samples = run["s"].shape[1], run["s"].shape[0]
        n_lags = len(getattr(model, "lag_names", ()))
        self.state = (np.zeros((n_lags, n_columns)) if lag_start is None
                      else np.array(lag_start, dtype=np.float64, order="C").reshape(n_lags, n_columns))
        if not n_lags:
            self.gradients = np.zeros((0, n))
            self.decay = self.weight = np.zeros(0)
            self.du_ds = self.du_dv = np.zeros((n_samples, 0, n))
            return
        ratio = 0.5 * h / np.asarray(model.lag_time_constants, dtype=np.float64)
        self.decay, self.weight = (1.0 - ratio) / (1.0 + ratio), ratio / (1.0 + ratio)
        self.gradients = np.ascontiguousarray(model.lag_gradients, dtype=np.float64)
        _, du_ds, du_dv = model.lag_inputs_along(run["t"], run["s"], run["sdot"])
        self.du_ds = np.ascontiguousarray(du_ds, dtype=np.float64)
        self.du_dv = np.ascontiguousarray(du_dv, dtype=np.float64)

    def with_force_jacobians(self, stiffness, damping):
        """``K_t``, ``C_t`` (N, n, n) at the steps' new states with the lag force's Jacobians (the
        arrays themselves without lags)."""
        if not self.decay.size:
            return stiffness, damping
        weighted = self.gradients.T * self.weight                      # (n, L)
        return (stiffness - weighted @ self.du_ds[1:], damping - weighted @ self.du_dv[1:])


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _tangent_steps(mass, K, C, Phi_s, h, alpha_m, alpha_f, beta, gamma, beta_p, gamma_p, state,
                   lag_gradients, lag_decay, lag_weight, du_ds, du_dv, lag_state):
    """The step loop of ``_propagate_tangent``, in place on ``state`` (4, n, p) = d(q, v, a, sddot)
    and ``lag_state`` (L, p) = d y: per step the differentiated predictors (``_start_step``) and the
    known part of the lags, ``d c_n = decay d y_n + weight (du/ds d q_n + du/ds' d v_n)``, the exact
    iteration matrix from ``mass``, ``K``, ``C`` (N, n, n, the lags' force Jacobians included) and
    ``Phi_s`` (N, r, n) factorised (LAPACK) and solved for the p columns (right-hand side with
    ``lag_gradients^T d c_n``), then (GA2), (GA3), (GA1) and ``d y_{n+1} = d c_n + weight (du/ds
    d q_{n+1} + du/ds' d v_{n+1})``; ``du_ds``, ``du_dv`` (N+1, L, n) at the grid's states. A zero
    pivot fills ``state`` with NaN.

    One factorisation per step replaced a batched ``np.linalg.inv`` of all N matrices and BLAS
    products: 11 ms instead of 17 ms per period on ``four_bar_fem4`` (N = 256, n + r = 30, p = 24),
    and no BLAS threads, which on a loaded machine made the old kernel ~100x slower."""
    n, p = state.shape[1], state.shape[2]
    r = Phi_s.shape[1]
    dq, dv, da, dsddot = state[0], state[1], state[2], state[3]
    dqhat = np.empty((n, p))
    dvhat = np.empty((n, p))
    tangent = np.empty((n, n))
    G_T = np.empty((n + r, n + r))
    piv = np.empty(n + r, dtype=np.int32)
    solution = np.empty((n + r, p))       # the right-hand sides, then d(sddot, lam), as columns
    n_lags = lag_state.shape[0]
    lag_known = np.empty((n_lags, p))     # d c_n, the lags' part known at t_n
    for step in range(mass.shape[0]):
        _lag_input_change(du_ds[step], du_dv[step], dq, dv, lag_weight, lag_known)
        for k in range(n_lags):
            for j in range(p):
                lag_known[k, j] += lag_decay[k] * lag_state[k, j]
        for i in range(n):
            for j in range(p):
                da_known = (alpha_f * dsddot[i, j] - alpha_m * da[i, j]) / (1.0 - alpha_m)
                dqhat[i, j] = dq[i, j] + h * dv[i, j] + h * h * ((0.5 - beta) * da[i, j]
                                                                 + beta * da_known)
                dvhat[i, j] = dv[i, j] + h * ((1.0 - gamma) * da[i, j] + gamma * da_known)
        # the right-hand sides row by row, the p columns innermost (contiguous, vectorised) and the
        # zero entries of K, C and Phi_s skipped (an element couples only its neighbours' coordinates
        # and the frames): on six_bar with 8 elements per link (n + r = 78, p = 96) 0.50 -> 0.12 s
        # per period against the column-by-column dot products this replaced
        for i in range(n):
            for j in range(p):
                solution[i, j] = 0.0
            for k in range(n):
                stiff, damp = K[step, i, k], C[step, i, k]
                if stiff != 0.0 or damp != 0.0:
                    for j in range(p):
                        solution[i, j] -= stiff * dqhat[k, j] + damp * dvhat[k, j]
            for k in range(n_lags):
                weight = lag_gradients[k, i]
                if weight != 0.0:
                    for j in range(p):
                        solution[i, j] += weight * lag_known[k, j]
        for k in range(r):
            for j in range(p):
                solution[n + k, j] = 0.0
            for i in range(n):
                entry = Phi_s[step, k, i] / beta_p
                if entry != 0.0:
                    for j in range(p):
                        solution[n + k, j] -= entry * dqhat[i, j]
        for i in range(n):
            for j in range(n):
                tangent[i, j] = beta_p * K[step, i, j] + gamma_p * C[step, i, j]
        _fill_iteration_matrix(mass[step], tangent, Phi_s[step], G_T)
        if not _lu_factor(G_T, piv) > 0.0:
            state[:] = np.nan
            lag_state[:] = np.nan
            return
        lapack.solve_columns_loops(G_T, piv, solution)
        for i in range(n):
            for j in range(p):
                dsddot_new = solution[i, j]
                dq[i, j] = dqhat[i, j] + beta_p * dsddot_new
                dv[i, j] = dvhat[i, j] + gamma_p * dsddot_new
                da[i, j] = (alpha_f * dsddot[i, j] + (1.0 - alpha_f) * dsddot_new
                            - alpha_m * da[i, j]) / (1.0 - alpha_m)
                dsddot[i, j] = dsddot_new
        _lag_input_change(du_ds[step + 1], du_dv[step + 1], dq, dv, lag_weight, lag_state)
        for k in range(n_lags):
            for j in range(p):
                lag_state[k, j] += lag_known[k, j]


@numba.njit(cache=True, no_cfunc_wrapper=True)
def _lag_input_change(du_ds, du_dv, dq, dv, weight, out):
    """``out[k] = weight[k] (du_ds[k] dq + du_dv[k] dv)`` (L, p), the weighted change of the lags'
    inputs ``u`` (L,) for the changes ``dq``, ``dv`` (n, p) of the state; ``du_ds``, ``du_dv`` (L, n)."""
    for k in range(out.shape[0]):
        for j in range(out.shape[1]):
            acc = 0.0
            for i in range(dq.shape[0]):
                acc += du_ds[k, i] * dq[i, j] + du_dv[k, i] * dv[i, j]
            out[k, j] = weight[k] * acc
