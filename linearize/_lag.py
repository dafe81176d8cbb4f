"""Lagged controllers as extra coordinates of the linearisation (docs/methods.md, lags).

A controller with a lag (``mechanisms.Model.lag_names``) adds to its drive's torque a state ``y``
(N m) that follows its unlagged law ``u(t, s, s')`` through ``tau y' + y = u``.  The torque enters
the generalized forces as ``y h`` (``h`` the drive's gradient), so about the nominal motion, with
``y`` itself a coordinate (nominal 0: ``u`` vanishes on the rigid motion), the full-coordinate
terms of ``linearize._core`` gain one row and one column per lag:

    mass      0 in the lag's row and column (a first-order coordinate for ``periodic``),
    damping   row ``[-du/ds', tau]``,
    stiffness row ``[-du/ds, 1]`` and column ``-h`` in the mechanical rows,
    residual  ``-u`` along the nominal motion (so ``f = u``).

The constraints do not involve ``y`` (zero columns): it is always an independent coordinate.
"""

from __future__ import annotations

import numpy as np


def lag_count(model) -> int:
    """Number of lagged controllers of ``model`` (0 for a model that knows none)."""
    return len(getattr(model, "lag_names", ()))


def with_lag_states(model, t, s, sdot, mass, damping, stiffness, residual, jacobian):
    """The full-coordinate terms ``mass, damping, stiffness`` (N, n, n), ``residual`` (N, n) and
    constraint ``jacobian`` (N, r, n) along ``t, s, sdot`` extended by the model's lag states to
    n + L coordinates (module notes)."""
    n_samples, n = residual.shape
    n_lags = lag_count(model)
    size = n + n_lags
    lag = slice(n, size)
    u, du_ds, du_dv = model.lag_inputs_along(t, s, sdot)
    out_mass = np.zeros((n_samples, size, size))
    out_damping = np.zeros_like(out_mass)
    out_stiffness = np.zeros_like(out_mass)
    out_mass[:, :n, :n] = mass
    out_damping[:, :n, :n] = damping
    out_stiffness[:, :n, :n] = stiffness
    out_damping[:, lag, :n] = -du_dv
    out_stiffness[:, lag, :n] = -du_ds
    out_damping[:, lag, lag] = np.diag(model.lag_time_constants)
    out_stiffness[:, lag, lag] = np.eye(n_lags)
    # Q gains y h: K = -dQ/ds has -h in the lag's column
    out_stiffness[:, :n, lag] = -model.lag_gradients.T
    out_residual = np.concatenate((residual, -u), axis=1)
    out_jacobian = np.concatenate((jacobian, np.zeros(jacobian.shape[:2] + (n_lags,))), axis=2)
    return out_mass, out_damping, out_stiffness, out_residual, out_jacobian
