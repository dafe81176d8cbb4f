"""The period map of the full nonlinear constrained mechanism, for shooting (``periodic.find_orbit``).

The shooting state ``x = (z, z')`` (2m,) is the deviation of the m independent coordinates and their
rates from the nominal rigid motion at ``t = 0`` (for a prescribed drive: the elastic coordinates;
the deviation, not the coordinate, so that a crank angle that gains 2 pi per period is periodic).
The dependent coordinates and rates follow from the position and velocity constraints at ``t = 0``
(Newton on the dependent block), the accelerations and multipliers from the index-1 equations, and
``mechanisms.simulate``'s generalized-alpha integrator runs one period of N steps. The map returns
the same deviation at ``t = T`` and its Jacobian, the monodromy of the discrete step map:

    d x(T) / d x(0) = P_T  Y_N  Y_0,

``Y_0`` (4n, 2m) the sensitivity of the integrator's start (q, v, a = sddot, sddot) to ``x`` (the
constraints' null space and the differentiated index-1 equations; see ``_start_sensitivity``),
``Y_N`` the product of the step tangents from the integrator's own iteration matrices
(``_alpha_tangent._propagate_tangent``) and ``P_T`` the selection of the independent positions and rates.

Each period starts afresh from a consistent state (alpha acceleration ``a_0 = sddot_0``), so a fixed
point is the periodic orbit of the discrete scheme to its O(h^2) error, which the N against N/2
estimate measures.

Lagged controllers (``tau y' + y = u``, ``_alpha_step._Lags``): their L states ``y`` (N m) are part of
the orbit, so the shooting state becomes ``x = (z, z', y)`` (2m + L,), the run starts them at ``y``
and the monodromy (2m + L, 2m + L) carries ``d y`` through each step (``_propagate_tangent``). ``y``
does not move the start's positions and rates; it enters the start's accelerations through the lag
force ``H^T y`` as the integrator's start does (``_start_sensitivity``).

A period asked for again from the same state (the observables of the orbit a shooting has just found
at its last map call) is not run again.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._alpha_run import _consistent_accelerations, _integrate, _lag_force
from ._alpha_step import _generalized_alpha_parameters
from ._alpha_tangent import _propagate_tangent
from ._kinematics import ConvergenceError
from ._parts import ArgumentError
from ._simulate import SimulationError, _resolve_model

__all__ = ["PeriodMap", "PeriodRun"]

#: Step (relative to the configuration scale) of the central differences of the constraints'
#: second-order terms in ``Y_0``: truncation ~ step^2 and rounding ~ 1e-16 / step balance near 1e-5.
_START_STEP = 1.0e-5


@dataclass(frozen=True)
class PeriodRun:
    """One period of the nonlinear model from a shooting state.

    ``state`` (2m + L,) and ``end_state`` (2m + L,): the deviations ``(z, z')`` at t = 0 and t = T (m
    or rad, per s), followed by the L lag states ``y`` (N m; L = 0 without lagged controllers);
    ``monodromy`` (2m + L, 2m + L) d end_state / d state (None when not asked for); ``t`` (k N + 1,)
    s, ``s``, ``sdot`` (k N + 1, n) the full coordinates and rates over the k periods run, ``lam``
    (k N + 1, r) the multipliers, ``lag_states`` (k N + 1, L) N m (the arrays are the run's own
    copies); ``period_states`` (k + 1, 2m + L) the shooting state at t = 0, T, ..., k T;
    ``n_substeps`` steps the integrator had to subdivide (then the monodromy is that of the uniform
    grid's steps only, an approximation); ``run_time`` s.
    """

    state: np.ndarray
    end_state: np.ndarray
    monodromy: np.ndarray | None
    t: np.ndarray
    s: np.ndarray
    sdot: np.ndarray
    period_states: np.ndarray
    n_substeps: int
    run_time: float
    lag_states: np.ndarray | None = None
    lam: np.ndarray | None = None


class PeriodMap:
    """``x(0) -> x(T)`` of the full nonlinear model of a mechanism over one period of N steps.

    ``system``: a ``mechanisms.Mechanism`` (or a model assembled from one). ``independent`` (m,):
    indices of the independent coordinates (default: the elastic ones, plus the coordinates the
    constraints leave free at t = 0, picked by QR with column pivoting); pass the linearisation's
    (``linearize.about(...).coefficients.independent``) to shoot in its coordinates. ``rho_inf``,
    ``tol``, ``max_step_halvings``: the integrator's (``mechanisms.simulate``). ``nominal``: the
    mechanism's ``NominalMotion`` if already computed (only its samples at t = 0 and T are used).
    With lagged controllers the shooting state ends with their L states ``y`` (N m) at t = 0, and
    ``labels`` with their names (``lag.<controller>``, as ``linearize`` labels them).

    Calling it, ``period_map(x, parameter=None) -> (end_state, monodromy)``, is the ``PeriodMap``
    of ``periodic.find_orbit`` (the parameter is fixed by the mechanism and ignored).
    """

    def __init__(self, system: Any, *, n_steps: int = 256, independent: Any = None,
                 rho_inf: float = 0.8, tol: float = 1e-10, max_step_halvings: int = 6,
                 nominal: Any = None):
        if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 2:
            raise ArgumentError(f"`n_steps` must be an integer >= 2 (steps per period); got {n_steps!r}.")
        if not 0.0 <= float(rho_inf) < 1.0:
            raise ArgumentError(f"`rho_inf` must lie in [0, 1) (the stiff axial modes need damping); "
                                f"got {rho_inf!r}.")
        self.model, self.mechanism, computed = _resolve_model(system, need_nominal=nominal is None)
        nominal = computed if nominal is None else nominal
        if nominal is None:
            raise ArgumentError("`system` must be a mechanisms.Mechanism (or a model assembled from "
                                "one): the period map shoots about its nominal rigid motion.")
        self.n_steps = int(n_steps)
        self.period = float(nominal.t[-1] - nominal.t[0])
        self.h = self.period / self.n_steps
        self.rho_inf = float(rho_inf)
        self.nominal_start = (np.array(nominal.s[0]), np.array(nominal.sdot[0]))
        self.nominal_end = (np.array(nominal.s[-1]), np.array(nominal.sdot[-1]))
        n = int(self.model.n_coords)
        if independent is None:
            independent = _free_coordinates(self.model, self.nominal_start[0])
        self.independent = np.sort(np.asarray(independent, dtype=np.int64))
        if self.independent.ndim != 1 or np.unique(self.independent).size != self.independent.size or \
                (self.independent.size and not 0 <= self.independent.min() <= self.independent.max() < n):
            raise ArgumentError(f"`independent` must be distinct coordinate indices in [0, {n}); got "
                                f"{independent!r}.")
        if self.independent.size != n - int(self.model.n_constraints):
            raise ArgumentError(f"`independent` must name n - r = {n - int(self.model.n_constraints)} "
                                f"coordinates (the degrees of freedom); got {self.independent.size}.")
        self.dependent = np.setdiff1d(np.arange(n), self.independent)
        labels = tuple(getattr(self.model, "coord_labels", ()))
        self.lag_names = tuple(getattr(self.model, "lag_names", ()))
        self._coordinate_labels = tuple(labels[i] for i in self.independent) if labels else ()
        self.labels = self._coordinate_labels + tuple(f"lag.{name}" for name in self.lag_names)
        self.length_scale = max(1.0, float(np.abs(self.nominal_start[0]).max()))
        self._options = (self.rho_inf, float(tol) * self.length_scale, 20, True, int(max_step_halvings),
                         self.length_scale, False)
        self._last: tuple[np.ndarray, dict] | None = None    # the last period: its state, the arrays

    @property
    def n_lags(self) -> int:
        """L, the number of lagged controllers (their states end the shooting state)."""
        return len(self.lag_names)

    @property
    def n_state(self) -> int:
        """2m + L, the size of the shooting state."""
        return 2 * self.independent.size + self.n_lags

    # --- states ----------------------------------------------------------------------------------------
    def state_of(self, s: np.ndarray, sdot: np.ndarray, *, at_end: bool = False,
                 lag_states: np.ndarray | None = None) -> np.ndarray:
        """The shooting state ``(z, z', y)`` (2m + L,) of full coordinates and rates (n,) at t = 0
        (or T) and the lag states ``lag_states`` (L,) N m (default 0, the lags at rest)."""
        s_nom, sdot_nom = self.nominal_end if at_end else self.nominal_start
        ind = self.independent
        lags = np.zeros(self.n_lags) if lag_states is None else np.asarray(lag_states, dtype=np.float64)
        if lags.shape != (self.n_lags,):
            raise ArgumentError(f"`lag_states` must have shape ({self.n_lags},) (one per lagged controller "
                                f"{list(self.lag_names)}); got shape {lags.shape}.")
        return np.concatenate([s[ind] - s_nom[ind], sdot[ind] - sdot_nom[ind], lags])

    def lag_states_of(self, x: np.ndarray) -> np.ndarray:
        """The lag states ``y`` (L,) N m of the shooting state ``x`` (2m + L,): its last L entries."""
        return np.array(self._checked(x)[2 * self.independent.size:])

    def _checked(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.n_state,) or not np.all(np.isfinite(x)):
            lags = f", then the lag states {list(self.lag_names)}" if self.n_lags else ""
            raise ArgumentError(f"the shooting state must be {self.n_state} finite numbers (deviations "
                                f"of {self._coordinate_labels or 'the independent coordinates'}"
                                f" and their rates{lags}); got shape {x.shape}.")
        return x

    def start_state(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Full coordinates and rates (n,) at t = 0 that satisfy the position and velocity
        constraints, with the independent ones ``x[:2m]`` away from the nominal motion (the lag
        states ``x[2m:]``: ``lag_states_of``)."""
        x = self._checked(x)
        m, ind, dep, model = self.independent.size, self.independent, self.dependent, self.model
        s, sdot = self.nominal_start[0].copy(), self.nominal_start[1].copy()
        s[ind] += x[:m]
        for _ in range(30):
            phi = np.asarray(model.constraints(s, 0.0), dtype=np.float64)
            if np.abs(phi).max(initial=0.0) <= 1e-14 * self.length_scale:
                break
            s[dep] -= np.linalg.solve(model.constraint_jacobian(s, 0.0)[:, dep], phi)
        else:
            raise ConvergenceError(
                f"no configuration satisfies the constraints with this shooting state (residual "
                f"{np.abs(phi).max():.3g} after 30 Newton steps on the dependent coordinates): the "
                f"deviation of {self._coordinate_labels} is too large for the linkage")
        jacobian = np.asarray(model.constraint_jacobian(s, 0.0), dtype=np.float64)
        sdot[ind] += x[m:2 * m]
        rhs = -np.asarray(model.constraint_rate(s, 0.0)) - jacobian[:, ind] @ sdot[ind]
        sdot[dep] = np.linalg.solve(jacobian[:, dep], rhs)
        return s, sdot

    def _start_sensitivity(self, x: np.ndarray) -> np.ndarray:
        """``Y_0`` (4, n, 2m + L): d(q, v, a, sddot)/dx of the integrator's start.

        Positions: ``dq = V0 dz`` with ``V0`` the null-space basis ``[I; -Phi_d^-1 Phi_i]`` of the
        constraint Jacobian. Rates: ``dv = V0 dz' - [0; Phi_d^-1 (d/dq (Phi_s v + Phi_t)) V0 dz]``.
        Accelerations (index-1 equations differentiated, ``K``, ``D`` the linearisation's terms):

            [[M, Phi_s^T], [Phi_s, 0]] [d sddot; d lam] = [-K dq - D dv; d(gamma - Phi_s sddot)].

        The two derivatives of the constraints' second-order terms are central differences along
        the 2m directions (no Newton solves), the constraint terms at all perturbed states in one
        batch (``constraint_terms_along``: a Python call per state made this 15-20 ms of a monodromy
        on six_bar). The lag states move neither the positions nor the
        rates; their force ``H^T y`` enters the start's index-1 equations (as in ``_integrate``), so
        their columns are ``[d sddot; d lam] = [[M, Phi_s^T], [Phi_s, 0]]^-1 [H^T; 0]``."""
        from ._batch import constraint_terms_along, linear_terms_along

        model, ind, dep, m = self.model, self.independent, self.dependent, self.independent.size
        s, sdot = self.start_state(x)
        lags = self.lag_states_of(x)
        sddot, lam = _consistent_accelerations(model, s, sdot, 0.0, _lag_force(model, lags))
        terms = linear_terms_along(model, np.zeros(1), s[None], sdot[None], sddot[None], lam[None])
        Phi_s = terms.jacobian[0]
        n = s.size
        null = np.zeros((n, m))
        null[ind, np.arange(m)] = 1.0
        null[dep] = -np.linalg.solve(Phi_s[:, dep], Phi_s[:, ind])

        dq = np.concatenate([null, np.zeros((n, m))], axis=1)
        dv = np.concatenate([np.zeros((n, m)), null], axis=1)
        step = _START_STEP * self.length_scale
        # d/dq of the velocity constraints Phi_s(q) sdot + Phi_t along each null-space direction
        # (Phi_t of a prescribed drive does not depend on q): one batch at s +- step null_j
        shifted = np.concatenate([s + step * null.T, s - step * null.T])
        jacobians = constraint_terms_along(model, np.zeros(2 * m), shifted).jacobian
        change = (jacobians[:m] - jacobians[m:]) @ sdot / (2.0 * step)           # (m, r)
        dv[dep, :m] = -np.linalg.solve(Phi_s[:, dep], change.T)
        # d(gamma - Phi_s sddot) along the 2m directions (dq, dv): one batch at the 4m states
        sizes = step / np.maximum(1.0, np.abs(dv).max(axis=0) / np.maximum(np.abs(dq).max(axis=0), 1.0))
        positions = np.concatenate([s + (sizes * dq).T, s - (sizes * dq).T])
        rates = np.concatenate([sdot + (sizes * dv).T, sdot - (sizes * dv).T])
        perturbed = constraint_terms_along(model, np.zeros(4 * m), positions, rates)
        acceleration = perturbed.gamma - perturbed.jacobian @ sddot                        # (4m, r)
        rhs_constraints = ((acceleration[:2 * m] - acceleration[2 * m:]) / (2.0 * sizes[:, None])).T
        r = Phi_s.shape[0]
        augmented = np.zeros((n + r, n + r))
        augmented[:n, :n], augmented[:n, n:], augmented[n:, :n] = terms.mass[0], Phi_s.T, Phi_s
        rhs = np.concatenate([-(terms.stiffness[0] @ dq + terms.damping[0] @ dv), rhs_constraints])
        lag_rhs = np.zeros((n + r, lags.size))
        if lags.size:
            lag_rhs[:n] = np.asarray(model.lag_gradients, dtype=np.float64).T
        dsddot = np.linalg.solve(augmented, np.concatenate([rhs, lag_rhs], axis=1))[:n]
        zeros = np.zeros((n, lags.size))
        dq, dv = np.concatenate([dq, zeros], axis=1), np.concatenate([dv, zeros], axis=1)
        return np.stack([dq, dv, dsddot, dsddot])

    # --- one period ---------------------------------------------------------------------------------
    def run(self, x: np.ndarray, *, tangent: bool = True, n_periods: int = 1) -> PeriodRun:
        """Integrate ``n_periods`` periods from the shooting state ``x`` (2m + L,); the end state and (with
        ``tangent``, one period only) the monodromy. Raises ``mechanisms.SimulationError`` when the
        integrator fails."""
        started = time.perf_counter()
        if tangent and n_periods != 1:
            raise ArgumentError("`tangent` needs `n_periods` = 1 (the monodromy of one period).")
        x = np.array(x, dtype=np.float64)
        raw = self._period_arrays(x, int(n_periods))
        monodromy = self._monodromy_of(x, raw) if tangent else None
        return self._period_run(x, raw, monodromy, started)

    def _period_arrays(self, x: np.ndarray, n_periods: int) -> dict:
        """The integrator's arrays over ``n_periods`` from ``x``: the last period again when ``x`` is
        its state (a shooting's last map call is at the orbit whose observables are asked next)."""
        if n_periods == 1 and self._last is not None and np.array_equal(self._last[0], x):
            return self._last[1]
        s0, sdot0 = self.start_state(x)
        raw = _integrate(self.model, s0, sdot0, 0.0, self.h, self.n_steps * n_periods, *self._options,
                         lag0=self.lag_states_of(x) if self.n_lags else None)
        if raw["status"] != 0:
            raise SimulationError(f"the period map failed: {raw['message']}", None)
        if n_periods == 1:
            self._last = (x.copy(), raw)    # a copy: the caller keeps ``x`` (``PeriodRun.state``)
        return raw

    def _monodromy_of(self, x: np.ndarray, raw: dict) -> np.ndarray:
        """The monodromy (2m + L, 2m + L) of the period ``raw`` run from ``x``."""
        lag_start = np.eye(self.n_lags, self.n_state, 2 * self.independent.size)   # y(0) = x[2m:]
        final, lag_final = _propagate_tangent(self.model, raw, self.h, self.rho_inf,
                                              self._start_sensitivity(x), lag_start)
        ind = self.independent
        return np.concatenate([final[0][ind], final[1][ind], lag_final])

    def _period_run(self, x: np.ndarray, raw: dict, monodromy: np.ndarray | None, started: float
                    ) -> PeriodRun:
        # the nominal motion repeats itself up to the crank's whole turns per period
        winding = self.nominal_end[0] - self.nominal_start[0]
        ind = self.independent
        ends = np.arange(0, raw["s"].shape[0], self.n_steps)
        positions = raw["s"][ends][:, ind] - (self.nominal_start[0][ind]
                                              + np.outer(np.arange(ends.size), winding[ind]))
        period_states = np.concatenate([positions, raw["sdot"][ends][:, ind] - self.nominal_end[1][ind],
                                        raw["lag_states"][ends]], axis=1)
        # copies of the arrays: the map keeps the last period's to differentiate or return it again,
        # and a caller that writes into a PeriodRun must not change them (read-only arrays instead
        # would make numba compile read-only variants of the kernels they reach)
        return PeriodRun(state=x, end_state=period_states[-1], monodromy=monodromy, t=raw["t"].copy(),
                         s=raw["s"].copy(), sdot=raw["sdot"].copy(), period_states=period_states,
                         n_substeps=int(raw["n_substeps"]), run_time=time.perf_counter() - started,
                         lag_states=raw["lag_states"].copy(), lam=raw["lam"].copy())

    def warm_up(self) -> None:
        """Compile (or load from numba's cache) every kernel a period uses: one step with its tangent
        from the nominal start, so that timings of ``run`` exclude JIT compilation."""
        s0, sdot0 = self.start_state(np.zeros(self.n_state))
        run = _integrate(self.model, s0, sdot0, 0.0, self.h, 1, *self._options)
        if run["status"] == 0:
            _propagate_tangent(self.model, run, self.h, self.rho_inf, np.zeros((4, s0.size, 1)))

    def __call__(self, x: np.ndarray, parameter: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        period = self.run(x)
        return period.end_state, period.monodromy

    def end_state(self, x: np.ndarray, parameter: float | None = None) -> np.ndarray:
        """The end state (2m + L,) of one period from ``x`` without its monodromy (the chord
        iterations of ``periodic.find_orbit``); the period is kept, so that asking for the monodromy
        at the same state next (``__call__``) does not run it again."""
        return self.run(x, tangent=False).end_state

    @property
    def blocks(self) -> tuple[tuple[int, int], ...]:
        """The shooting state's parts in one unit each, as (start, stop) index ranges: the coordinates'
        deviations (m or rad), their rates (per s) and the lag states (N m) where there are any
        (``periodic.find_orbit`` judges an error level's accuracy in each apart)."""
        m = self.independent.size
        return ((0, m), (m, 2 * m)) + (((2 * m, self.n_state),) if self.n_lags else ())

    @property
    def resolution(self) -> np.ndarray:
        """(2m + L,) the round-off of the end state that the integrator's Newton tolerance leaves
        (``periodic.find_orbit``: a residual at this level that Newton no longer reduces is converged):
        a step accepts positions to ``tol`` (``abs_tol``, m), which a period of N steps accumulates
        to about ``abs_tol sqrt(N)``, and the rates follow from the last step's positions through
        ``v = vhat + gamma' sddot``, ``q = qhat + beta' sddot``: ``abs_tol gamma' / beta' = abs_tol
        gamma / (beta h)``. Measured on ``two_link_arm`` at N = 512 (tol 1e-10): Newton stalls at
        3.2e-9 m and 8.5e-8 m/s, this model 2.3e-9 and 1.0e-7. The lag states: 0 (not relaxed)."""
        abs_tol, m = self._options[1], self.independent.size
        _, _, beta, gamma = _generalized_alpha_parameters(self.rho_inf)
        return np.concatenate([np.full(m, abs_tol * np.sqrt(self.n_steps)),
                               np.full(m, abs_tol * gamma / (beta * self.h)), np.zeros(self.n_lags)])


def _free_coordinates(model: Any, s: np.ndarray) -> np.ndarray:
    """The elastic coordinates, plus as many coordinates as the constraint Jacobian at ``s``, t = 0
    leaves free, picked by QR with column pivoting (best-conditioned dependent block)."""
    import scipy.linalg

    jacobian = np.asarray(model.constraint_jacobian(s, 0.0), dtype=np.float64)
    elastic = np.asarray(model.elastic_index, dtype=np.int64)
    others = np.setdiff1d(np.arange(jacobian.shape[1]), elastic)
    n_free = jacobian.shape[1] - jacobian.shape[0] - elastic.size
    if n_free <= 0:
        return np.sort(elastic)
    _, _, pivots = scipy.linalg.qr(jacobian[:, others], pivoting=True, mode="economic")
    return np.sort(np.concatenate([elastic, others[pivots[jacobian.shape[0]:]][:n_free]]))
