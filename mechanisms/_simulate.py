"""Full nonlinear runs (``mechanisms.simulate``): the options checked, the model and its start resolved, a
generalized-alpha run on a uniform grid (``_alpha_run``; the method and its Newton iteration in
``_alpha_step``), observables and the Richardson error estimate of a run at twice the step.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ._alpha_run import _integrate
from ._kinematics import ConvergenceError
from ._observables import default_observables
from ._parts import ArgumentError

__all__ = ["SimulationError", "SimulationResult", "simulate"]

logger = logging.getLogger(__name__)

_METHODS = ("generalized-alpha",)


class SimulationError(ConvergenceError):
    """A nonlinear run failed (Newton divergence, singular iteration matrix); ``.result`` holds the
    steps computed before the failure. A ``ConvergenceError``, hence a ``RuntimeError``."""

    def __init__(self, message: str, result: "SimulationResult"):
        super().__init__(message)
        self.result = result


@dataclass(frozen=True)
class SimulationResult:
    """A nonlinear run on the grid ``t``.

    Attributes
    ----------
    t : (n_t,) s
    s, sdot, sddot : (n_t, n) coordinates and their first and second time derivatives (SI units of
        each coordinate: m or rad, per s, per s^2).
    lam : (n_t, r) Lagrange multipliers (the constraint force on the coordinates is
        ``-Phi_s^T lam``).
    observables : {spec: (n_t,)} values of the requested observables (units in ``observable_units``).
    constraint_residual : (n_t,) ``max |Phi(s, t)|`` at the accepted state (m, or rad for angle
        constraints); bounded by the Newton tolerance, it does not drift.
    observable_error : {spec: float} Richardson estimate of the maximum global error of each
        observable over the run (``max |o_h - o_2h| / 3`` for a second-order method, on the common
        grid points), or of the coordinates (key ``"s"``) without observables; empty with
        ``estimate_error=False`` or after a failure.
    n_steps, n_newton, n_jacobian, n_factorizations : counts of accepted steps of the grid, Newton
        iterations, evaluations of the analytic derivatives (tangent terms) and LU factorisations of
        the iteration matrix (all attempts included).
    n_rejected, n_substeps : step attempts whose Newton solve failed and was retried with half the
        step (2, 4, ... substeps), and the substeps that replaced the rejected grid steps; 0 when
        every step converged at the user's step.
    min_pivot_ratio : smallest ``min |u_kk| / max |u_kk|`` of the LU factors of the iteration
        matrices of the converged Newton solves (failed attempts excluded: their matrices are
        evaluated at diverging iterates), a cheap conditioning indicator; below ~1e-13 (logged as a warning) the
        Newton increments may carry large rounding errors.
    status : 0 success, -1 failure (the arrays then end at the last accepted step).
    message : what happened, naming the time of a failure.
    run_time : wall-clock seconds of the whole call (including an error-estimate run).
    lag_states, lag_names : (N+1, L) the states ``y`` (N m) of the lagged controllers (the torques
        they add to their drives, ``tau y' + y = u``), integrated with the mechanism; L = 0 without.
    """

    t: np.ndarray
    s: np.ndarray
    sdot: np.ndarray
    sddot: np.ndarray
    lam: np.ndarray
    observables: Mapping[str, np.ndarray]
    observable_units: Mapping[str, str]
    constraint_residual: np.ndarray
    observable_error: Mapping[str, float]
    n_steps: int
    n_newton: int
    n_jacobian: int
    n_factorizations: int
    n_rejected: int
    n_substeps: int
    min_pivot_ratio: float
    status: int
    message: str
    run_time: float
    method: str
    rho_inf: float
    dt: float
    coord_labels: tuple[str, ...] = field(default=())
    lag_states: np.ndarray | None = None
    lag_names: tuple[str, ...] = field(default=())

    @property
    def success(self) -> bool:
        return self.status == 0


def _as_vector(value: Any, n: int, name: str) -> np.ndarray:
    arr = np.array(value, dtype=np.float64)
    if arr.shape != (n,):
        raise ArgumentError(f"`{name}` must have shape ({n},) (one value per coordinate); got shape "
                         f"{arr.shape}.")
    if not np.all(np.isfinite(arr)):
        raise ArgumentError(f"`{name}` must be finite; got non-finite entries at indices "
                         f"{np.flatnonzero(~np.isfinite(arr)).tolist()}.")
    return arr


def _positive(value: Any, name: str) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a real number; got {value!r}.") from None
    if not (math.isfinite(x) and x > 0.0):
        raise ArgumentError(f"`{name}` must be positive and finite; got {value!r}.")
    return x


def _period_of(model: Any, period: float | None) -> float | None:
    """The drive period (s): the ``period`` argument, else the model's (the assembler sets it from
    ``Mechanism.period`` or the first drive's rate), else None."""
    if period is not None:
        return _positive(period, "period")
    model_period = getattr(model, "period", None)
    return None if model_period is None else float(model_period)


def _time_grid(t0: float, t_end, n_periods, dt, steps_per_period, period) -> tuple[float, int]:
    """(h, n_steps) of the uniform grid from the (t_end | n_periods) and (dt | steps_per_period)
    options; the step is shortened so that the grid ends exactly at ``t_end``."""
    if (t_end is None) == (n_periods is None):
        raise TypeError("give exactly one of `t_end` (s) and `n_periods`; got "
                        f"t_end={t_end!r}, n_periods={n_periods!r}.")
    if (dt is None) == (steps_per_period is None):
        raise TypeError("give exactly one of `dt` (s) and `steps_per_period`; got "
                        f"dt={dt!r}, steps_per_period={steps_per_period!r}.")
    needs_period = n_periods is not None or steps_per_period is not None
    if needs_period and period is None:
        raise ArgumentError("`n_periods` and `steps_per_period` need the period: this system has no "
                         "drive rate or `period` attribute; pass `period=` (s) or use `t_end`, "
                         "`dt`.")
    duration = (_positive(t_end, "t_end") - t0 if t_end is not None
                else _positive(n_periods, "n_periods") * period)
    if duration <= 0.0:
        raise ArgumentError(f"`t_end` must be after `t0` = {t0}; got t_end={t_end!r}.")
    if steps_per_period is not None:
        if int(steps_per_period) != steps_per_period or steps_per_period < 1:
            raise ArgumentError("`steps_per_period` must be a positive integer; got "
                             f"{steps_per_period!r}.")
        h_wanted = period / int(steps_per_period)
    else:
        h_wanted = _positive(dt, "dt")
    n_steps = max(1, int(math.ceil(duration / h_wanted - 1e-9)))
    return duration / n_steps, n_steps


def integrated_model(mechanism: Any, nominal: Any = None) -> Any:
    """The model ``simulate`` and ``PeriodMap`` integrate for the ``mechanism``: ``assemble(mechanism)``,
    and with torque drives the nominal inverse-dynamics torque as their feedforward
    (``feedforward_torques`` of ``nominal``, the mechanism's ``nominal_motion``, computed when not
    given). Its ``drive_torques`` is the torque a run applies (feedforward plus feedback clipped to the
    drive's limits, plus the lag states given)."""
    from ._assemble import assemble
    from ._kinematics import feedforward_torques, nominal_motion

    if not mechanism.torque_drives:
        return assemble(mechanism)
    nominal = nominal_motion(mechanism) if nominal is None else nominal
    return assemble(mechanism, feedforward=feedforward_torques(mechanism, nominal))


def _resolve_model(system: Any, need_nominal: bool):
    """(model, mechanism or None, nominal motion or None) from a Mechanism or a protocol model.

    A Mechanism is assembled here; with torque drives its nominal inverse-dynamics torque
    (``feedforward_torques``) is the drives' feedforward. The nominal motion is computed when a
    start state is needed or for the feedforward."""
    from ._parts import Mechanism
    if isinstance(system, Mechanism):
        from ._kinematics import nominal_motion
        nominal = nominal_motion(system) if (need_nominal or system.torque_drives) else None
        return integrated_model(system, nominal), system, nominal
    required = ("n_coords", "n_constraints", "mass_matrix", "forces", "constraints",
                "constraint_jacobian", "constraint_rate", "constraint_gamma",
                "mass_matrix_jacobian", "force_jacobians", "constraint_force_jacobian")
    missing = [name for name in required if not hasattr(system, name)]
    if missing:
        raise TypeError("`system` must be a mechanisms.Mechanism or a model implementing "
                        f"mechanisms/_protocol.py's ConstrainedModel; {type(system).__name__} lacks "
                        f"{missing}.")
    mechanism = getattr(system, "mechanism", None)
    mechanism = mechanism if isinstance(mechanism, Mechanism) else None
    nominal = None
    if need_nominal and mechanism is not None:
        from ._kinematics import nominal_motion
        nominal = nominal_motion(mechanism)
    return system, mechanism, nominal


def _initial_state(model, nominal, s0, sdot0, t0: float):
    n = int(model.n_coords)
    if s0 is None:
        if nominal is None:
            raise ArgumentError("`s0` is required when simulating a bare model: only a Mechanism (or a "
                             "model assembled from one) has a nominal rigid motion to start from.")
        if float(nominal.t[0]) != t0:
            raise ArgumentError(f"the nominal motion starts at t = {float(nominal.t[0])} s; pass `s0` "
                             f"and `sdot0` to start at t0 = {t0} s.")
        s_start = np.array(nominal.s[0], dtype=np.float64)
        v_start = np.array(nominal.sdot[0], dtype=np.float64)
    else:
        s_start = _as_vector(s0, n, "s0")
        v_start = np.zeros(n)
    if sdot0 is not None:
        v_start = _as_vector(sdot0, n, "sdot0")
    return s_start, v_start


def _values_along(evaluator, s):
    """An observable's values (K,) at the run's samples ``s`` (K, n): at once where it offers
    ``values_along`` (the built-in quantities of a link; about 5 us a sample in Python otherwise),
    else sample by sample."""
    along = getattr(evaluator, "values_along", None)
    if along is not None:
        return np.asarray(along(s), dtype=float)
    return np.array([evaluator.value(q) for q in s])


def _check_consistency(model, q, v, t, length_scale):
    """Raise if the initial state violates the position or velocity constraints."""
    phi = np.asarray(model.constraints(q, t), dtype=np.float64)
    if np.max(np.abs(phi), initial=0.0) > 1e-8 * length_scale:
        worst = int(np.argmax(np.abs(phi)))
        labels = list(getattr(model, "constraint_labels", ()))
        name = labels[worst] if worst < len(labels) else f"#{worst}"
        raise ArgumentError(f"`s0` violates the constraints at t0 = {t} s: "
                         f"|Phi| = {abs(phi[worst]):.3g} at constraint {name!r} (allowed 1e-8 x "
                         f"{length_scale:.3g}); start from an assembled configuration (e.g. "
                         "mechanisms.nominal_motion).")
    Phi_s = np.asarray(model.constraint_jacobian(q, t), dtype=np.float64)
    vel = Phi_s @ v + np.asarray(model.constraint_rate(q, t), dtype=np.float64)
    speed_scale = max(np.max(np.abs(v), initial=0.0), 1.0) * max(length_scale, 1.0)
    if np.max(np.abs(vel), initial=0.0) > 1e-8 * speed_scale:
        worst = int(np.argmax(np.abs(vel)))
        raise ArgumentError(f"`sdot0` violates the velocity constraints at t0 = {t} s: "
                         f"|Phi_s sdot + Phi_t| = {abs(vel[worst]):.3g} at constraint #{worst}; "
                         "project it onto the constraint tangent space or start from the nominal "
                         "motion.")


def _observable_evaluators(model, mechanism, observables):
    if observables is None:
        if mechanism is None or not hasattr(model, "observable"):
            return {}
        specs = list(default_observables(mechanism))
    else:
        if isinstance(observables, str):
            observables = (observables,)
        specs = list(observables)
        if specs and not hasattr(model, "observable"):
            raise TypeError(f"`observables` {specs} were asked for but the model "
                            f"{type(model).__name__} has no `observable(spec)` method.")
    return {spec: model.observable(spec) for spec in specs}


def simulate(system: Any, *, t_end: float | None = None, n_periods: float | None = None,
             dt: float | None = None, steps_per_period: int | None = None,
             s0: Sequence[float] | None = None, sdot0: Sequence[float] | None = None,
             t0: float = 0.0, period: float | None = None, method: str = "generalized-alpha",
             rho_inf: float = 0.8, observables: Sequence[str] | None = None, tol: float = 1e-10,
             max_iterations: int = 20, jacobian_reuse: bool = True, max_step_halvings: int = 6,
             perturbed_start: bool = False, estimate_error: bool = True,
             throw: bool = True, lag0: Sequence[float] | None = None) -> SimulationResult:
    """Integrate the full nonlinear constrained equations of motion on a uniform time grid.

    Parameters
    ----------
    system : a ``mechanisms.Mechanism`` (assembled with ``mechanisms.assemble``; torque drives get
        the nominal inverse-dynamics torque as feedforward) or any model implementing
        ``mechanisms._protocol.ConstrainedModel``.
    t_end, n_periods : the end time (s), or the number of drive periods, exactly one of them.
    dt, steps_per_period : the time step (s, shortened to end on ``t_end``), or steps per period.
    s0, sdot0 : initial coordinates and velocities (n,). Without ``s0`` a Mechanism (or a model
        with a ``mechanism`` attribute) starts on its nominal rigid motion
        (``mechanisms.nominal_motion``) at ``t0 = 0``, elastic coordinates zero; ``sdot0``
        defaults to the nominal velocities, or to zero with a given ``s0``. The state must
        satisfy the position and velocity constraints to 1e-8 relative; accelerations and
        multipliers are then solved for consistently.
    period : the period (s) used by ``n_periods`` / ``steps_per_period`` for a bare model without a
        ``period`` attribute.
    method : ``"generalized-alpha"``.
    rho_inf : spectral radius at infinite step in [0, 1]: smaller values damp unresolved
        high-frequency modes harder; second order for any value. Use ``rho_inf < 1`` whenever the
        model has stiff modes the step does not resolve (the axial modes of elastic links: h omega
        of 10-100 at ordinary steps): at 1 (no numerical damping, the trapezoidal rule) they keep
        their start-up energy, the index-3 multipliers oscillate undamped, and Newton fails on
        stiff nonlinear (geometrically stiffened) links; a warning is logged.
    observables : specs for ``model.observable(spec)`` (e.g. ``"coupler.deflection@0.5"``,
        ``"coupler.strain@0.25"``, ``"coupler.moment@0.5"``, ``"rocker.angle"``); default:
        ``mechanisms.default_observables`` of a Mechanism, none for a bare model.
    tol : Newton tolerance: iterations stop when the last position increment is below
        ``tol * max(1, max |s0|)`` (m or rad) and the constraint residual ``max |Phi|`` is below
        that times ``max(1, max row sum |Phi_s|)``.
    max_iterations : Newton iterations allowed per step (and per substep) before it is rejected.
        Newton also gives up early when its increments grow.
    max_step_halvings : a step whose Newton solve fails (no convergence, divergence, singular
        matrix, non-finite values) is retried as 2, 4, ..., ``2**max_step_halvings`` equal
        substeps (each by full Newton from the constant predictor) and the run goes on
        at the user's step; the output stays on the uniform grid and ``n_rejected`` counts the
        retries. 0 ends the run at the first failure. Substeps change the local error of that
        step only (the method stays second order).
    jacobian_reuse : keep the tangent terms of the iteration matrix across iterations and steps
        while Newton contracts well (modified Newton); ``False`` re-evaluates them at every
        iteration (full Newton).
    perturbed_start : start the alpha acceleration at Arnold & Bruls' (2007) perturbed value
        ``sddot(t0 + (alpha_m - alpha_f) h)`` (from two extra index-1 solves at ``t0 +- delta``)
        instead of ``sddot_0``: removes the O(h) start-up error that ``lam`` and ``sddot`` carry
        through the first steps (the first step's error drops from O(h^2) to O(h^3)). For smooth
        solutions only: with unresolved stiff (axial) modes the central difference picks up their
        huge jerk and excites them (the stiff double pendulum and the four-bar scenes then fail
        or lose accuracy), hence off by default.
    estimate_error : also run with twice the step and report the Richardson estimate of the global
        error of each observable in ``observable_error`` (costs about half a run more; ``False``
        for timing-critical loops).
    throw : raise ``SimulationError`` on failure; with ``False`` return the partial result with
        ``status = -1`` and a message naming the time.
    lag0 : the initial states (n_lags,) of the model's lagged controllers (N m; default 0, the lags
        at rest): e.g. the last entries of a linear steady state's ``z`` at t = 0.

    Returns
    -------
    SimulationResult
    """
    start_clock = time.perf_counter()
    if method not in _METHODS:
        raise ArgumentError(f"`method` must be one of {_METHODS}; got {method!r}.")
    rho = float(rho_inf)
    if not 0.0 <= rho <= 1.0:
        raise ArgumentError(f"`rho_inf` must lie in [0, 1]; got {rho_inf!r}.")
    if rho == 1.0:
        logger.warning("rho_inf = 1 damps nothing: unresolved stiff (axial) modes and the "
                       "multipliers keep their start-up oscillations, and Newton can fail on stiff "
                       "nonlinear links; use rho_inf < 1 (default 0.8) unless every mode is "
                       "resolved by the step.")
    if int(max_step_halvings) != max_step_halvings or not 0 <= max_step_halvings <= 20:
        raise ArgumentError("`max_step_halvings` must be an integer in [0, 20]; got "
                         f"{max_step_halvings!r}.")
    tol = _positive(tol, "tol")
    if int(max_iterations) != max_iterations or max_iterations < 1:
        raise ArgumentError(f"`max_iterations` must be a positive integer; got {max_iterations!r}.")
    model, mechanism, nominal = _resolve_model(system, need_nominal=s0 is None)
    t0 = float(t0)
    h, n_steps = _time_grid(t0, t_end, n_periods, dt, steps_per_period,
                            _period_of(model, period))
    q0, v0 = _initial_state(model, nominal, s0, sdot0, t0)
    length_scale = max(1.0, float(np.max(np.abs(q0), initial=0.0)))
    _check_consistency(model, q0, v0, t0, length_scale)
    evaluators = _observable_evaluators(model, mechanism, observables)

    options = (rho, tol * length_scale, int(max_iterations), jacobian_reuse,
               int(max_step_halvings), length_scale, bool(perturbed_start))
    n_lags = len(getattr(model, "lag_names", ()))
    lag0 = None if lag0 is None else _as_vector(lag0, n_lags, "lag0")
    run = _integrate(model, q0, v0, t0, h, n_steps, *options, lag0=lag0)
    obs = {spec: _values_along(ev, run["s"]) for spec, ev in evaluators.items()}
    obs_error: dict[str, float] = {}
    if estimate_error and run["status"] == 0 and n_steps < 2:
        run["message"] += " No error estimate: a single step has no coarser grid to compare with."
    elif estimate_error and run["status"] == 0:
        # the coarse grid t0 + 2 k h, k <= n_steps // 2, is every other point of the fine one
        coarse = _integrate(model, q0, v0, t0, 2.0 * h, n_steps // 2, *options, lag0=lag0)
        if coarse["status"] != 0:
            run["message"] += (" Error estimate unavailable: the 2 dt run failed "
                               f"({coarse['message']})")
        else:
            for spec, ev in evaluators.items():
                o_coarse = _values_along(ev, coarse["s"])
                # Richardson for an order-2 method: e_h ~ (o_h - o_2h) / (2^2 - 1)
                fine = obs[spec][::2][:o_coarse.size]
                obs_error[spec] = float(np.max(np.abs(fine - o_coarse)) / 3.0)
            # without observables the coordinates stand in, so the user still gets an estimate
            if not evaluators:
                fine = run["s"][::2][:coarse["s"].shape[0]]
                obs_error["s"] = float(np.max(np.abs(fine - coarse["s"])) / 3.0)

    result = SimulationResult(
        t=run["t"], s=run["s"], sdot=run["sdot"], sddot=run["sddot"], lam=run["lam"],
        observables=obs, observable_units={spec: getattr(ev, "unit", "") for spec, ev in
                                           evaluators.items()},
        constraint_residual=run["residual"], observable_error=obs_error,
        n_steps=run["n_steps"], n_newton=run["n_newton"], n_jacobian=run["n_jacobian"],
        n_factorizations=run["n_factorizations"], n_rejected=run["n_rejected"],
        n_substeps=run["n_substeps"], min_pivot_ratio=run["min_pivot_ratio"],
        status=run["status"], message=run["message"],
        run_time=time.perf_counter() - start_clock, method=method, rho_inf=rho, dt=h,
        coord_labels=tuple(getattr(model, "coord_labels", ())), lag_states=run["lag_states"],
        lag_names=tuple(getattr(model, "lag_names", ())))
    if result.min_pivot_ratio < 1e-13:
        logger.warning("the iteration matrix was ill-conditioned (pivot ratio %.2g): check the "
                       "constraint rows for near-redundancy or reduce extreme stiffness contrasts",
                       result.min_pivot_ratio)
    if result.status != 0:
        if throw:
            raise SimulationError(result.message, result)
        logger.warning(result.message)
    return result


