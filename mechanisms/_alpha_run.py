"""A generalized-alpha run on a uniform grid (``_integrate``): the consistent start (accelerations and
multipliers from the index-1 equations, optionally Arnold & Bruls' perturbed alpha acceleration), the steps of
``_alpha_step._Stepper``, and a failed step retried as 2, 4, ... equal substeps (``_substeps``)."""

from __future__ import annotations

import logging

import numpy as np

from ._alpha_step import _Stepper, fused_step_wanted
from ._parts import ArgumentError

logger = logging.getLogger(__name__)


def _lag_force(model, lag_states):
    """``sum_i h_i y_i`` (n,), the force of the lagged controllers' states ``y`` (L,) N m on the
    coordinates, or None with the lags at rest (``y = 0``: the force is zero)."""
    if not np.any(lag_states):
        return None
    return np.asarray(lag_states, dtype=np.float64) @ np.asarray(model.lag_gradients, dtype=np.float64)


def _consistent_accelerations(model, q, v, t, lag_force=None):
    """Solve ``[[M, Phi_s^T], [Phi_s, 0]] [sddot; lam] = [Q; gamma]`` (the index-1 form at ``t``);
    ``lag_force`` (n,), the lagged controllers' ``H^T y``, is added to ``Q`` when given."""
    n = q.shape[0]
    r = int(model.n_constraints)
    A = np.zeros((n + r, n + r))
    A[:n, :n] = model.mass_matrix(q)
    Phi_s = np.asarray(model.constraint_jacobian(q, t), dtype=np.float64)
    A[:n, n:] = Phi_s.T
    A[n:, :n] = Phi_s
    forces = model.forces(q, v, t)
    if lag_force is not None:
        forces = forces + lag_force
    b = np.concatenate([forces, model.constraint_gamma(q, v, t)])
    cond = np.linalg.cond(A)
    if not np.isfinite(cond) or cond > 1e13:
        raise ArgumentError(f"the augmented mass matrix at t = {t} s is singular (condition number "
                         f"{cond:.3g}): check for redundant constraints or massless coordinates.")
    x = np.linalg.solve(A, b)
    return x[:n], x[n:]


def _integrate(model, q0, v0, t0, h, n_steps, rho, abs_tol, max_iterations, jacobian_reuse,
               max_halvings, length_scale, perturbed_start, lag0=None):
    """The generalized-alpha loop on the uniform grid ``t0 + k h``; a step whose Newton solve fails
    is retried as 2, 4, ..., ``2**max_halvings`` equal substeps. Returns a dict of the arrays and
    counts (see ``simulate``)."""
    n = q0.shape[0]
    r = int(model.n_constraints)
    stepper = _Stepper(model, rho, abs_tol, max_iterations, jacobian_reuse, length_scale,
                       fused=fused_step_wanted(n_steps))
    if stepper.lags is not None:
        stepper.lags.start(q0, v0, t0, lag0)

    t_grid = t0 + h * np.arange(n_steps + 1)
    S = np.empty((n_steps + 1, n))
    V = np.empty((n_steps + 1, n))
    A = np.empty((n_steps + 1, n))
    L = np.empty((n_steps + 1, r))
    residual = np.empty(n_steps + 1)

    # the lags' force at t0 is part of Q in the index-1 equations, as in every step's
    start_force = None if stepper.lags is None else _lag_force(model, stepper.lags.y)
    sddot0, lam0 = _consistent_accelerations(model, q0, v0, t0, start_force)
    S[0], V[0], A[0], L[0] = q0, v0, sddot0, lam0
    residual[0] = np.max(np.abs(model.constraints(q0, t0)), initial=0.0)

    if perturbed_start:
        a = _perturbed_alpha_acceleration(model, q0, v0, sddot0, t0,
                                          (stepper.alpha_m - stepper.alpha_f) * h)
    else:
        a = sddot0.copy()      # alpha acceleration a_0 = sddot_0: an O(h) error in a_0
    n_rejected, n_substeps, status, message, done = 0, 0, 0, "", 0
    for step in range(1, n_steps + 1):
        t = t_grid[step]
        # predictor: linear extrapolation of sddot and lam (an O(h^2) guess, about one Newton
        # iteration fewer per step than sddot_{n+1} = sddot_n)
        failure = stepper.solve(S[step - 1], V[step - 1], a, A[step - 1], L[step - 1],
                                A[max(step - 2, 0)], L[max(step - 2, 0)], step >= 2, t, h)
        if failure and max_halvings:
            n_rejected += 1
            failure, failed_subdivisions, substeps = _substeps(
                stepper, S[step - 1], V[step - 1], a, A[step - 1], L[step - 1], t - h, h,
                max_halvings)
            n_rejected += failed_subdivisions
            n_substeps += substeps
        elif not failure:
            stepper.advance_alpha_acceleration(a, A[step - 1])
        if failure:
            status = -1
            retried = f" (also in {2 ** max_halvings} substeps)" if max_halvings else ""
            message = (f"generalized-alpha failed in the step from t = {t - h:.9g} s to "
                       f"t = {t:.9g} s: {failure}{retried}. Try a smaller `dt` or `rho_inf`, or "
                       "check the initial state.")
            break
        S[step], V[step], A[step], L[step] = stepper.q, stepper.v, stepper.sddot, stepper.lam
        residual[step] = stepper.residual
        if stepper.lags is not None:
            stepper.lags.history.append(stepper.lags.y.copy())
        done = step
    if status == 0:
        message = (f"generalized-alpha reached t = {t_grid[-1]:.9g} s in {n_steps} steps of "
                   f"{h:.6g} s")
        message += (f" ({n_rejected} rejected and retried in {n_substeps} substeps)."
                    if n_rejected else ".")
    end = done + 1
    return {"t": t_grid[:end], "s": S[:end], "sdot": V[:end], "sddot": A[:end], "lam": L[:end],
            "residual": residual[:end], "n_steps": done, "n_rejected": n_rejected,
            "n_substeps": n_substeps, "status": status, "message": message,
            "min_pivot_ratio": float(stepper.min_pivot_ratio), **stepper.counts,
            "lag_states": (np.zeros((end, 0)) if stepper.lags is None
                           else np.array(stepper.lags.history[:end]))}


def _perturbed_alpha_acceleration(model, q0, v0, sddot0, t0, delta):
    """Arnold & Bruls' (2007, sec. 4) perturbed starting value ``a_0 = sddot(t0 + delta)``, with
    ``delta = (alpha_m - alpha_f) h``, to O(h^2).

    (GA1) holds with an O(h^2) defect only when ``a_n`` approximates ``sddot(t_n + delta)``; the
    plain start ``a_0 = sddot_0`` is off by O(h), which the multipliers and accelerations carry
    as an O(h) error through the first steps (decaying like ``(alpha_m / alpha_f)^n``). Here
    ``sddot(t0 + delta) = sddot_0 + (sddot_+ - sddot_-) / 2 + O(delta^3)`` from the index-1
    accelerations at the Taylor states ``q0 +- delta v0 + delta^2 / 2 sddot_0``,
    ``v0 +- delta sddot_0`` and ``t0 +- delta`` (central difference of ``sddot``)."""
    if delta == 0.0:
        return sddot0.copy()
    sides = []
    for sign in (1.0, -1.0):
        d = sign * delta
        q = q0 + d * v0 + 0.5 * d * d * sddot0
        v = v0 + d * sddot0
        sides.append(_consistent_accelerations(model, q, v, t0 + d)[0])
    return sddot0 + 0.5 * (sides[0] - sides[1])


def _substeps(stepper, q_n, v_n, a, sddot_n, lam_n, t_n, h, max_halvings):
    """Retry the step from ``t_n`` as ``2**k`` equal substeps, k = 1 ... ``max_halvings``, until
    all of them converge (full Newton from constant predictors: the extrapolation's history has the
    wrong spacing).
    On success the end state is in ``stepper`` and ``a`` (in place) is its alpha acceleration.
    Returns (failure or "", failed attempts after the full step's, substeps taken)."""
    q, v, a_n = np.empty_like(q_n), np.empty_like(v_n), a.copy()
    sddot, lam = np.empty_like(sddot_n), np.empty_like(lam_n)
    lags_n = stepper.lags.snapshot() if stepper.lags is not None else None
    failure = ""
    for level in range(1, max_halvings + 1):
        m = 2 ** level
        hs = h / m
        q[:], v[:], a[:], sddot[:], lam[:] = q_n, v_n, a_n, sddot_n, lam_n
        if lags_n is not None:
            stepper.lags.restore(lags_n)
        for j in range(1, m + 1):
            failure = stepper.solve(q, v, a, sddot, lam, sddot, lam, False, t_n + j * hs, hs,
                                    full_newton=True)
            if failure:
                break
            stepper.advance_alpha_acceleration(a, sddot)
            q[:], v[:], sddot[:], lam[:] = stepper.q, stepper.v, stepper.sddot, stepper.lam
        if not failure:
            logger.debug("step from t = %.9g s taken in %d substeps", t_n, m)
            stepper.drop_tangent()     # the next full step needs tangent terms scaled for h
            return "", level - 1, m
    a[:] = a_n
    return failure, max_halvings, 0
