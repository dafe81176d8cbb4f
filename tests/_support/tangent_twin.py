"""Slow, obvious numpy references for the monodromy of ``mechanisms.PeriodMap``: a twin of the
tangent kernel (``mechanisms._alpha_tangent._propagate_tangent``) written from the differentiated
generalized-alpha step, one dense ``np.linalg.solve`` per step, and central finite differences of
the period map itself."""

import numpy as np

import mechanisms


def tangent_numpy(model, run, h, rho_inf, start, lag_start):
    """d(q, v, a, sddot) (4, n, p) and d y (L, p) at the end of ``run`` from ``start`` (4, n, p) and
    ``lag_start`` (L, p) at its start.

    Per step, with the Jacobians at the new state: the predictors ``qhat = q + h v + h^2 ((1/2 - beta)
    a + beta a_known)``, ``vhat = v + h ((1 - gamma) a + gamma a_known)``, ``a_known = (alpha_f sddot -
    alpha_m a) / (1 - alpha_m)``; ``[[M + beta' K + gamma' C, Phi^T], [Phi, 0]] [d sddot; d lam] =
    -[K dqhat + C dvhat - H^T dc; Phi dqhat / beta']`` where the lag force ``H^T y`` moves ``K`` and
    ``C`` by ``-H^T w du/ds``, ``-H^T w du/ds'`` and ``dc = decay dy + w (du_n)`` is the known part
    of the trapezoidal rule ``y_{n+1} = decay y_n + w (u_n + u_{n+1})``."""
    alpha_m = (2.0 * rho_inf - 1.0) / (rho_inf + 1.0)
    alpha_f = rho_inf / (rho_inf + 1.0)
    gamma = 0.5 + alpha_f - alpha_m
    beta = 0.25 * (gamma + 0.5) ** 2
    beta_p = h * h * beta * (1.0 - alpha_f) / (1.0 - alpha_m)
    gamma_p = h * gamma * (1.0 - alpha_f) / (1.0 - alpha_m)
    terms = mechanisms.linear_terms_along(model, run["t"][1:], run["s"][1:], run["sdot"][1:],
                                          run["sddot"][1:], run["lam"][1:])
    dq, dv, da, dsddot = (np.array(block, dtype=float) for block in start)
    dy = np.array(lag_start, dtype=float)
    n_lags = dy.shape[0]
    if n_lags:
        ratio = 0.5 * h / np.asarray(model.lag_time_constants, dtype=float)
        decay, weight = (1.0 - ratio) / (1.0 + ratio), ratio / (1.0 + ratio)
        H = np.asarray(model.lag_gradients, dtype=float)
        _, du_ds, du_dv = model.lag_inputs_along(run["t"], run["s"], run["sdot"])
    n, r = dq.shape[0], terms.jacobian.shape[1]
    for k in range(terms.mass.shape[0]):
        K, C, Phi = terms.stiffness[k].copy(), terms.damping[k].copy(), terms.jacobian[k]
        lag_force = 0.0
        if n_lags:
            K -= (H.T * weight) @ du_ds[k + 1]
            C -= (H.T * weight) @ du_dv[k + 1]
            known = decay[:, None] * dy + weight[:, None] * (du_ds[k] @ dq + du_dv[k] @ dv)
            lag_force = H.T @ known
        a_known = (alpha_f * dsddot - alpha_m * da) / (1.0 - alpha_m)
        dqhat = dq + h * dv + h * h * ((0.5 - beta) * da + beta * a_known)
        dvhat = dv + h * ((1.0 - gamma) * da + gamma * a_known)
        G = np.zeros((n + r, n + r))
        G[:n, :n] = terms.mass[k] + beta_p * K + gamma_p * C
        G[:n, n:], G[n:, :n] = Phi.T, Phi
        rhs = np.concatenate([K @ dqhat + C @ dvhat - lag_force, Phi @ dqhat / beta_p])
        new = -np.linalg.solve(G, rhs)[:n]
        dq, dv = dqhat + beta_p * new, dvhat + gamma_p * new
        da = (alpha_f * dsddot + (1.0 - alpha_f) * new - alpha_m * da) / (1.0 - alpha_m)
        dsddot = new
        if n_lags:
            dy = known + weight[:, None] * (du_ds[k + 1] @ dq + du_dv[k + 1] @ dv)
    return np.stack([dq, dv, da, dsddot]), dy


def central_differences(period_map, x0, blocks):
    """(2m + L, 2m + L) central differences of ``period_map.run(x).end_state`` at ``x0``; ``blocks``:
    (slice of the state, step relative to that block's largest entry) covering it."""
    size = x0.size
    differences = np.empty((size, size))
    for block, relative_step in blocks:
        step = relative_step * np.abs(x0[block]).max()
        for j in range(size)[block]:
            plus, minus = x0.copy(), x0.copy()
            plus[j] += step
            minus[j] -= step
            differences[:, j] = (period_map.run(plus, tangent=False).end_state
                                 - period_map.run(minus, tangent=False).end_state) / (2.0 * step)
    return differences


def tight_period_map(setup):
    """The period map of a shooting ``setup`` (``shooting_setup``'s) with the integrator's Newton
    tolerance at 1e-12 m, far below what finite differences of it resolve."""
    return mechanisms.PeriodMap(setup.linear.context.mechanism, n_steps=setup.fine.n_steps,
                                independent=setup.fine.independent, tol=1e-12)
