"""The nominal rigid motion: the mechanism with its elastic coordinates held at zero, over one period.

With the elastic coordinates fixed, the rigid coordinates ``s_r`` (x, y, theta of every link frame)
and the constraints (joints and drives) form a square system, solved on the uniform grid
``t_k = k T / N``:

* positions: ``Phi(s, t_k) = 0`` by Newton-Raphson, continued along the crank angle from the
  previous grid point with the predictor ``s + h s' + h^2/2 s''`` (steps halved when Newton struggles);
* velocities: ``Phi_s s' = -Phi_t``;
* accelerations: ``Phi_s s'' = gamma(s, s', t)``;
* multipliers from the rigid rows of ``M s'' = Q - Phi_s^T lam`` (protocol equations in
  ``mechanisms._protocol``): ``Phi_r^T lam = Q_r - (M s'')_r``, and the drive torques from them.

The scaled Jacobian's condition number is tracked: a toggle position (singular Jacobian) raises
``MechanismError`` naming the joints and the crank angle, an ill-conditioned one warns. A
continuation that fails on a mechanism that is fine (it switched assembly branch, or cannot reach
the required residual) raises ``ConvergenceError``.
"""

from __future__ import annotations

import logging
import math
import time
import warnings
from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from ._assemble import assemble
from ._batch import constraint_terms_along, inertia_residual_along, scaled_correction
from ._model import Model
from ._parts import GROUND, ArgumentError, Mechanism, MechanismError

logger = logging.getLogger(__name__)

# Newton stops once max |Phi| < _NEWTON_STOP (positions in m, drive rows in rad): quadratic
# convergence from a residual of 1e-9 already lands at rounding (~1e-17 m for 0.1 m links); the
# result must meet the 1e-12 required of the nominal motion.
_NEWTON_STOP = 1e-14
_RESIDUAL_REQUIRED = 1e-12
# Condition numbers of the Jacobian scaled to metres: position errors are amplified by it, so above
# 1e6 (errors of 1e-10 m from rounding) we warn and above 1e10 (a toggle) we stop.
_COND_WARN, _COND_SINGULAR = 1e6, 1e10
# A Newton correction larger than 0.05 (rad, or a twentieth of the link scale) after a second-order
# predictor means a jump towards another assembly branch: the step is halved instead. Both
# continuation paths (the numba one of an assembled model and _RigidSystem's) measure the
# correction alike: how far Newton moved from the predictor (``_batch.scaled_correction``).
_MAX_CORRECTION = 0.05
_MAX_HALVINGS = 12


class ConvergenceError(RuntimeError):
    """A numerical method failed on a valid mechanism: the nominal motion's continuation switched
    assembly branch or could not reach its residual (``mechanisms.SimulationError``, a failed
    nonlinear run, is one too). Invalid input raises ``MechanismError`` (a ``ValueError``)."""


@dataclass(frozen=True)
class NominalMotion:
    """The rigid mechanism's motion over one period on ``t_k = k T / N``, ``k = 0..N``.

    ``s, sdot, sddot`` (N+1, n): full coordinate vectors (m, rad; elastic entries zero) and their
    first and second time derivatives; ``lam`` (N+1, r): multipliers of the rigid inverse dynamics
    (``M s'' = Q - Phi_s^T lam``); ``drive_torque`` (N+1, n_drives): torque (N m) each drive applies
    to its ``link_b``. Error estimates: ``constraint_residual`` max |Phi| (m or rad),
    ``velocity_residual`` max |Phi_s s' + Phi_t|, ``acceleration_residual`` max |Phi_s s'' - gamma|,
    ``closure_error`` how far the rigid state at ``T`` differs from that at 0 (whole turns removed),
    ``jacobian_condition`` (N+1,) condition number of the rigid Jacobian scaled to metres.
    ``run_time`` in s.
    """

    t: np.ndarray
    s: np.ndarray
    sdot: np.ndarray
    sddot: np.ndarray
    lam: np.ndarray
    drive_torque: np.ndarray
    constraint_residual: float
    velocity_residual: float
    acceleration_residual: float
    closure_error: float
    jacobian_condition: np.ndarray
    model: Any
    period: float
    run_time: float

    @property
    def n_steps(self) -> int:
        return len(self.t) - 1


def nominal_motion(mechanism_or_model: Any, *, n_steps: int = 360, period: float | None = None,
                   s0: np.ndarray | None = None) -> NominalMotion:
    """The rigid nominal motion of a ``Mechanism`` (assembled here) or of an assembled model.

    ``n_steps`` N >= 2 grid intervals over one period (default 360: a degree of crank angle).
    For a bare model (no ``model.mechanism``) give ``period`` (s) unless the model has one, and
    ``s0`` (n,), a guess of the coordinates at ``t = 0`` (its elastic entries are ignored); for a
    mechanism the guess comes from its ``initial_angles`` and drives. Torque drives follow their
    nominal law here, and their torque is the inverse-dynamics one.

    Raises ``MechanismError`` when the linkage cannot be assembled, the crank cannot turn through
    the period or the constraint Jacobian is singular (toggle), naming joints and crank angle;
    ``ConvergenceError`` when the continuation fails on a mechanism that is fine.
    """
    started = time.perf_counter()
    if isinstance(n_steps, bool) or not isinstance(n_steps, (int, np.integer)) or n_steps < 2:
        raise ArgumentError(f"n_steps must be an integer >= 2, got {n_steps!r}")
    model, mechanism = _model_of(mechanism_or_model)
    if period is None:
        period = mechanism.period if mechanism is not None else getattr(model, "period", None)
    if period is None or not (isinstance(period, (int, float)) and math.isfinite(period)
                              and period > 0):
        raise ArgumentError(f"period must be a positive number of seconds (give period=...), got "
                         f"{period!r}")
    n, r = model.n_coords, model.n_constraints
    rigid = np.asarray(model.rigid_index, dtype=np.int64)
    if r != len(rigid):
        hint = ("; a model assembled with torque drives has no drive rows: pass the Mechanism, "
                "whose nominal motion follows the drives' nominal laws"
                if mechanism is not None and mechanism.torque_drives else "")
        raise MechanismError(f"the rigid subsystem is not square: {len(rigid)} rigid coordinates "
                             f"but {r} constraint equations{hint}")
    labels = list(model.coord_labels)
    system = _RigidSystem(model, rigid, mechanism, float(period))
    if s0 is None:
        if mechanism is None:
            raise ArgumentError("s0 (a guess of the coordinates at t = 0) is required for a model "
                             "without a mechanism")
        s0 = _initial_guess(mechanism, labels, n, float(period))
    s0 = np.array(s0, dtype=np.float64)
    if s0.shape != (n,) or not np.isfinite(s0).all():
        raise ArgumentError(f"s0 must be a finite vector of shape ({n},), got shape {s0.shape}")
    s0[np.asarray(model.elastic_index, dtype=np.int64)] = 0.0  # the rigid mechanism

    times = np.linspace(0.0, period, n_steps + 1)
    h = period / n_steps
    s = np.zeros((n_steps + 1, n))
    s[0] = system.assemble(s0)
    # Positions by continuation. The predictor s + h s' + h^2/2 s'' uses exact rates for the first
    # steps and then the quadratic extrapolation of the last three positions (the same predictor to
    # O(h^3), without solving for rates inside the loop).
    # An assembled model runs the plain steps in one numba loop, which hands back the first step
    # that needs care (a large correction or a struggling Newton) to the step-halving path here.
    fast = isinstance(model, Model)    # the numba path reads the assembled model's tables
    k = 1
    while k <= n_steps:
        if fast and k >= 3:
            k = model._continue_positions(s, k, times, newton_stop=_NEWTON_STOP,
                                          max_correction=_MAX_CORRECTION,
                                          column_scale=system.column_scale)
            if k > n_steps:
                break
        if k >= 3:
            sdot_k = (3.0 * s[k - 1] - 4.0 * s[k - 2] + s[k - 3]) / (2.0 * h)
            sddot_k = (s[k - 1] - 2.0 * s[k - 2] + s[k - 3]) / (h * h)
        else:
            sdot_k, sddot_k, _ = system.rates(s[k - 1], times[k - 1])
        s[k] = system.continue_to(s[k - 1], sdot_k, sddot_k, times[k - 1], times[k])
        k += 1

    # Conditioning, rates and multipliers along the whole grid, with stacked linear algebra.
    positions = constraint_terms_along(model, times, s, values=True)
    jacobians, rates = positions.jacobian, positions.rate
    rigid_jacobians = jacobians[:, :, rigid]
    scaled = system.row_scale[None, :, None] * rigid_jacobians * system.column_scale[None, None, :]
    singular_values = np.linalg.svd(scaled, compute_uv=False)
    with np.errstate(divide="ignore"):
        condition = singular_values[:, 0] / singular_values[:, -1]
    if not condition.max() < _COND_WARN:
        # Raise (toggle) or warn at the first offending sample, with the joints and angle named.
        system.check_jacobian(s[int(np.argmax(~(condition < _COND_WARN)))],
                              times[int(np.argmax(~(condition < _COND_WARN)))])
    sdot = np.zeros_like(s)
    sdot[:, rigid] = np.linalg.solve(rigid_jacobians, -rates[..., None])[..., 0]
    gamma = constraint_terms_along(model, times, s, sdot).gamma
    sddot = np.zeros_like(s)
    sddot[:, rigid] = np.linalg.solve(rigid_jacobians, gamma[..., None])[..., 0]
    inertia = inertia_residual_along(model, times, s, sdot, sddot)      # M s'' - Q, (N+1, n)
    lam = np.linalg.solve(np.swapaxes(rigid_jacobians, 1, 2), -inertia[:, rigid, None])[..., 0]

    drive_torque = _drive_torques(model, s, sdot, lam, times)
    residual = float(np.abs(positions.values).max())
    if residual > _RESIDUAL_REQUIRED:
        raise ConvergenceError(f"the nominal motion's constraint residual {residual:.3g} exceeds "
                               f"{_RESIDUAL_REQUIRED:g}: the Jacobian is too ill-conditioned "
                               f"(max condition number {condition.max():.3g})")
    velocity_residual = float(np.abs(np.einsum("krn,kn->kr", jacobians, sdot) + rates).max())
    acceleration_residual = float(np.abs(np.einsum("krn,kn->kr", jacobians, sddot)
                                         - gamma).max())
    closure = _closure_error(s[0], s[-1], labels, rigid)
    # The continuation closes on itself up to Newton's accuracy amplified by the conditioning; a
    # closure error of 1e-6 or more means it ended on another assembly branch.
    if closure > 1e-6:
        raise ConvergenceError(f"the nominal motion does not close over one period (state at T "
                               f"differs from t = 0 by {closure:.3g}): the continuation switched "
                               f"assembly branch; check for toggle positions or give a larger "
                               f"n_steps")
    run_time = time.perf_counter() - started
    logger.debug("nominal motion: %d steps in %.3f s, residual %.2e, max condition %.3g",
                n_steps, run_time, residual, condition.max())
    return NominalMotion(t=times, s=s, sdot=sdot, sddot=sddot, lam=lam, drive_torque=drive_torque,
                         constraint_residual=residual, velocity_residual=velocity_residual,
                         acceleration_residual=acceleration_residual, closure_error=closure,
                         jacobian_condition=condition, model=model, period=float(period),
                         run_time=run_time)


def nominal_dynamics(mechanism: Mechanism, kinematics: NominalMotion) -> NominalMotion:
    """The nominal motion of ``mechanism`` when its kinematics are those of ``kinematics`` (the
    nominal motion of a mechanism that differs from it only in what does not move the linkage:
    section properties, densities, masses, damping, gains): the same ``t, s, sdot, sddot``, the
    multipliers and drive torques of ``mechanism``'s rigid inverse dynamics recomputed along them,
    without the continuation.  Raises ``ArgumentError`` when ``kinematics`` does not meet
    ``mechanism``'s constraints to ten times its own residual (and 1e-11: the linkage moved), or its
    rates the velocity constraints to ten times theirs (and 1e-9 of the largest rate: the drives
    moved)."""
    started = time.perf_counter()
    rigid_mechanism = _rigid_mechanism(mechanism)
    if _same_mechanism(getattr(kinematics.model, "mechanism", None), rigid_mechanism):
        return kinematics      # the same rigid dynamics (only a controller's gains differ, say)
    model = assemble(rigid_mechanism)
    rigid = np.asarray(model.rigid_index, dtype=np.int64)
    t, s, sdot, sddot = kinematics.t, kinematics.s, kinematics.sdot, kinematics.sddot
    if model.n_coords != s.shape[1] or model.n_constraints != kinematics.lam.shape[1]:
        raise ArgumentError(f"kinematics: a motion of {s.shape[1]} coordinates and "
                            f"{kinematics.lam.shape[1]} multipliers, but the mechanism has "
                            f"{model.n_coords} and {model.n_constraints}")
    positions = constraint_terms_along(model, t, s, values=True)
    residual = float(np.abs(positions.values).max())
    if residual > 10.0 * kinematics.constraint_residual + 1e-11:
        raise ArgumentError(f"kinematics: the motion leaves a constraint residual {residual:.3g} on "
                            f"this mechanism (its own {kinematics.constraint_residual:.3g}): the "
                            f"linkage moved; compute its nominal_motion instead")
    # the rates too: positions that meet the constraints at the samples could come from a law that
    # differs between them (a harmonic of order k + N against one of order k)
    velocity = float(np.abs(np.einsum("krn,kn->kr", positions.jacobian, sdot) + positions.rate).max())
    if velocity > 10.0 * kinematics.velocity_residual + 1e-9 * max(1.0, float(np.abs(sdot).max())):
        raise ArgumentError(f"kinematics: the rates leave a velocity constraint residual {velocity:.3g} on "
                            f"this mechanism (their own {kinematics.velocity_residual:.3g}): the drives "
                            f"moved; compute its nominal_motion instead")
    rigid_jacobians = positions.jacobian[:, :, rigid]
    inertia = inertia_residual_along(model, t, s, sdot, sddot)      # M s'' - Q, (N+1, n)
    lam = np.linalg.solve(np.swapaxes(rigid_jacobians, 1, 2), -inertia[:, rigid, None])[..., 0]
    return replace(kinematics, lam=lam, drive_torque=_drive_torques(model, s, sdot, lam, t), model=model,
                   constraint_residual=residual, run_time=time.perf_counter() - started)


def nominal_at_period(mechanism: Mechanism, kinematics: NominalMotion) -> NominalMotion:
    """The nominal motion of ``mechanism`` whose drives follow the same law of the phase ``2 pi t /
    period`` as those of ``kinematics``' mechanism in ``mechanism``'s own period (another speed):
    ``kinematics``' positions at the same phases, the rates and accelerations scaled by the ratio of the
    periods and its square, the inverse dynamics recomputed (``nominal_dynamics``, which checks the
    positions and rates against ``mechanism``'s constraints), without the continuation. Raises
    ``ArgumentError`` when they do not meet them (a drive law of time rather than of the phase, another
    linkage): compute its ``nominal_motion`` instead."""
    period = float(mechanism.period)
    ratio = kinematics.period / period          # the speed ratio: the phase turns this much faster
    # the grid nominal_motion makes at this period (t / ratio may end an ulp off it)
    scaled = replace(kinematics, t=np.linspace(0.0, period, kinematics.n_steps + 1), sdot=kinematics.sdot * ratio,
                     sddot=kinematics.sddot * ratio**2, period=period,
                     velocity_residual=kinematics.velocity_residual * ratio,
                     acceleration_residual=kinematics.acceleration_residual * ratio**2)
    return nominal_dynamics(mechanism, scaled)


def _rigid_mechanism(mechanism: Mechanism) -> Mechanism:
    """The mechanism whose model the nominal motion uses: torque drives following their nominal
    law, prescribed (their inverse-dynamics torque is what the drive's multiplier gives), without
    controllers; ``mechanism`` itself when every drive is prescribed."""
    if not mechanism.torque_drives:
        return mechanism
    return mechanism.replace(drives=tuple(d.kinematic() for d in mechanism.drives), period=mechanism.period,
                             controllers=())


def _same_mechanism(a: Any, b: Any) -> bool:
    try:
        return isinstance(a, Mechanism) and bool(a == b)
    except (TypeError, ValueError):   # a part holding an array compares element-wise
        return False


def _model_of(obj: Any) -> tuple[Any, Mechanism | None]:
    if isinstance(obj, Mechanism):
        obj = _rigid_mechanism(obj)
        return assemble(obj), obj
    for name in ("n_coords", "n_constraints", "rigid_index", "constraints",
                 "constraint_jacobian", "constraint_rate", "constraint_gamma", "mass_matrix",
                 "forces"):
        if not hasattr(obj, name):
            raise TypeError(f"nominal_motion() takes a Mechanism or a model implementing "
                            f"mechanisms.ConstrainedModel; {type(obj).__name__} lacks {name!r}")
    mechanism = getattr(obj, "mechanism", None)
    return obj, mechanism if isinstance(mechanism, Mechanism) else None


class _RigidSystem:
    """The constraints restricted to the rigid coordinates, elastic ones held at zero."""

    def __init__(self, model: Any, rigid: np.ndarray, mechanism: Mechanism | None, period: float):
        self.model, self.rigid, self.mechanism, self.period = model, rigid, mechanism, period
        labels = list(model.coord_labels)
        constraint_labels = list(model.constraint_labels)
        # Scale to metres: x, y columns by the link scale L (so a column is a displacement per
        # unit of L) and joint rows (m) by 1/L; angles and drive rows (rad) stay.
        scale = 1.0
        if mechanism is not None:
            scale = max(link.length for link in mechanism.links)
        self.column_scale = np.array([1.0 if labels[i].endswith(".theta") else scale
                                      for i in rigid])
        # rows in radians (drives, angle relations) stay; a model that does not say which rows
        # are angles has them labelled "drive:..."
        angle_rows = getattr(model, "angle_rows", None)
        if angle_rows is None:
            angle_rows = [label.startswith("drive:") for label in constraint_labels]
        self.row_scale = np.array([1.0 if angle else 1.0 / scale for angle in angle_rows])
        self.constraint_labels = constraint_labels

    def jacobian(self, s: np.ndarray, t: float) -> np.ndarray:
        return self.model.constraint_jacobian(s, t)[:, self.rigid]

    def condition(self, jac: np.ndarray) -> float:
        return float(np.linalg.cond(self.row_scale[:, None] * jac * self.column_scale[None, :]))

    def where(self, t: float) -> str:
        if self.mechanism is None:
            return f"t = {t:.6g} s"
        drive = self.mechanism.drives[0]
        angle = drive.angle(t, self.period)[0]
        return (f"crank angle {math.degrees(angle):.2f} deg (drive at joint {drive.joint!r}, "
                f"t = {t:.6g} s)")

    def singular_joints(self, jac: np.ndarray) -> list[str]:
        """Joints whose constraint rows make up the (near) null space of Phi_s^T."""
        u, _, _ = np.linalg.svd(self.row_scale[:, None] * jac * self.column_scale[None, :])
        weights = np.abs(u[:, -1])
        joints: list[str] = []
        for label, weight in zip(self.constraint_labels, weights):
            if weight >= 0.2 * weights.max():
                joint = label.split(":", 1)[1] if label.startswith("drive:") else \
                    label.rsplit(".", 1)[0]
                if joint not in joints:
                    joints.append(joint)
        return joints

    def newton(self, s: np.ndarray, t: float, max_iterations: int) -> tuple[np.ndarray, bool,
                                                                             float]:
        """Newton on the rigid coordinates from the predictor ``s``; returns (s, converged, how
        far it moved from the predictor, ``scaled_correction``)."""
        predicted = s
        s = s.copy()
        for _ in range(max_iterations):
            phi = self.model.constraints(s, t)
            if np.abs(phi).max() < _NEWTON_STOP:
                return s, True, self.correction(s, predicted)
            jac = self.jacobian(s, t)
            try:
                step = np.linalg.solve(jac, phi)
            except np.linalg.LinAlgError:
                return s, False, np.inf
            if not np.isfinite(step).all():
                return s, False, np.inf
            s[self.rigid] -= step
        phi = self.model.constraints(s, t)
        return s, bool(np.abs(phi).max() < _RESIDUAL_REQUIRED), self.correction(s, predicted)

    def correction(self, corrected: np.ndarray, predicted: np.ndarray) -> float:
        return float(scaled_correction(np.ascontiguousarray(corrected, dtype=np.float64),
                                       np.ascontiguousarray(predicted, dtype=np.float64),
                                       self.rigid, self.column_scale))

    def assemble(self, guess: np.ndarray) -> np.ndarray:
        """Positions at t = 0 from a rough guess: damped Newton (backtracking on |Phi|)."""
        s = guess.copy()
        for _ in range(100):
            phi = self.model.constraints(s, 0.0)
            norm = float(np.abs(phi).max())
            if norm < _NEWTON_STOP:
                break
            step = np.linalg.lstsq(self.jacobian(s, 0.0), phi, rcond=None)[0]
            for _ in range(30):
                trial = s.copy()
                trial[self.rigid] -= step
                if float(np.abs(self.model.constraints(trial, 0.0)).max()) < norm:
                    break
                step = 0.5 * step
            else:
                break
            s = trial
        s, converged, _ = self.newton(s, 0.0, 10)
        if not converged:
            phi = self.model.constraints(s, 0.0)
            worst = [self.constraint_labels[i] for i in np.argsort(-np.abs(phi))[:2]]
            raise MechanismError(
                f"the linkage cannot be assembled at {self.where(0.0)}: Newton-Raphson from the "
                f"initial angles left a residual {np.abs(phi).max():.3g} (largest at {worst}); "
                f"check the link lengths and ground points, or give initial_angles near the "
                f"intended configuration")
        self.check_jacobian(s, 0.0)
        return s

    def check_jacobian(self, s: np.ndarray, t: float) -> float:
        jac = self.jacobian(s, t)
        cond = self.condition(jac)
        if not cond < _COND_SINGULAR:
            raise MechanismError(
                f"singular constraint Jacobian (toggle position) at {self.where(t)}: joints "
                f"{self.singular_joints(jac)} (condition number {cond:.3g}); links meeting there "
                f"are aligned. Change the link lengths (Grashof: s + l < p + q with the crank "
                f"shortest) or the drive's range")
        if cond > _COND_WARN:
            message = (f"ill-conditioned constraint Jacobian at {self.where(t)}: condition number "
                       f"{cond:.3g} near joints {self.singular_joints(jac)}")
            logger.warning(message)
            warnings.warn(message, RuntimeWarning, stacklevel=4)
        return cond

    def continue_to(self, s: np.ndarray, sdot: np.ndarray, sddot: np.ndarray, t0: float,
                    t1: float) -> np.ndarray:
        """Positions at t1 by continuation from the solved state at t0."""
        target, depth = t1, 0
        while True:
            h = target - t0
            predicted = s + h * sdot + 0.5 * h * h * sddot
            solved, converged, correction = self.newton(predicted, target, 8)
            if converged and correction < _MAX_CORRECTION:
                if target == t1:
                    return solved
                # Accept the substep and carry on from it towards t1.
                s, t0 = solved, target
                sdot, sddot, _ = self.rates(s, t0)
                target, depth = t1, 0
                continue
            depth += 1
            if depth > _MAX_HALVINGS:
                jac = self.jacobian(s, t0)
                raise MechanismError(
                    f"the crank cannot turn through the period: the rigid linkage stops near "
                    f"{self.where(t0)}; beyond it the loop does not close (condition number "
                    f"{self.condition(jac):.3g}, joints {self.singular_joints(jac)}). Check "
                    f"Grashof's condition and the link lengths")
            target = t0 + 0.5 * (target - t0)

    def rates(self, s: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, float]:
        """Velocities from Phi_s s' = -Phi_t and accelerations from Phi_s s'' = gamma."""
        cond = self.check_jacobian(s, t)
        jac = self.jacobian(s, t)
        sdot = np.zeros_like(s)
        sdot[self.rigid] = np.linalg.solve(jac, -self.model.constraint_rate(s, t))
        sddot = np.zeros_like(s)
        sddot[self.rigid] = np.linalg.solve(jac, self.model.constraint_gamma(s, sdot, t))
        return sdot, sddot, cond


def _drive_torques(model: Any, s: np.ndarray, sdot: np.ndarray, lam: np.ndarray,
                   times: np.ndarray) -> np.ndarray:
    rows = getattr(model, "drive_rows", None)
    mechanism = getattr(model, "mechanism", None)
    if rows is not None and mechanism is not None and len(rows) == len(mechanism.drives):
        # Every drive prescribed (as in the nominal motion): the torque is minus its multiplier.
        return -lam[:, np.asarray(rows, dtype=np.int64)]
    if hasattr(model, "drive_torques"):
        return np.array([model.drive_torques(s[k], sdot[k], times[k], lam[k])
                         for k in range(len(times))]).reshape(len(times), -1)
    # Without the assembler's helper: a drive row written angle_b - angle_a - angle(t) = 0 exerts
    # the generalized force -lam on link_b's angle, which is the torque on it.
    rows = [i for i, label in enumerate(model.constraint_labels) if label.startswith("drive:")]
    return -lam[:, rows]


def _closure_error(first: np.ndarray, last: np.ndarray, labels: list[str],
                   rigid: np.ndarray) -> float:
    """Largest difference between the rigid coordinates at T and 0, angles modulo whole turns."""
    worst = 0.0
    for i in rigid:
        diff = last[i] - first[i]
        if labels[i].endswith(".theta"):
            diff -= 2.0 * math.pi * round(diff / (2.0 * math.pi))
        worst = max(worst, abs(diff))
    return worst


def _initial_guess(mech: Mechanism, labels: list[str], n: int, period: float) -> np.ndarray:
    """Frame angles from the drives at t = 0 and ``initial_angles``; frame origins by walking the
    joints from the ground so that every tree joint closes (the loops are closed by Newton)."""
    index = {label: i for i, label in enumerate(labels)}
    angles = {link.name: float(mech.initial_angles.get(link.name, 0.0)) for link in mech.links}
    joints = {j.name: j for j in mech.joints}
    for _ in range(len(mech.drives)):
        for drive in mech.drives:
            # the driven side's frame angle from the drive's relative angle (the other terms'
            # frame angles as guessed so far)
            driven, *others = joints[drive.joint].drive_terms()
            base = -sum(term.coefficient * angles[term.link] for term in others)
            angles[driven.link] = (base + drive.angle(0.0, period)[0]) / driven.coefficient
    links = {link.name: link for link in mech.links}
    origins: dict[str, np.ndarray] = {}

    def world(name: str, point: Any) -> np.ndarray:
        local = np.array(links[name].point_position(point))
        c, s = math.cos(angles[name]), math.sin(angles[name])
        return origins[name] + np.array([c * local[0] - s * local[1], s * local[0] + c * local[1]])

    def place(name: str, point: Any, at: np.ndarray) -> None:
        origins[name] = np.zeros(2)
        origins[name] = at - world(name, point)

    # a ground side first, whichever side a joint names it on
    pins = [tuple(sorted(pin, key=lambda side: side[0] != GROUND))
            for pin in (joint.coincident_points() for joint in mech.joints) if pin]
    for (link_a, point_a), (link_b, point_b) in pins:
        if link_a == GROUND and link_b not in origins:
            place(link_b, point_b, np.array(point_a, dtype=float))
    for _ in range(len(pins)):
        for (link_a, point_a), (link_b, point_b) in pins:
            if link_a == GROUND:
                continue
            if link_a in origins and link_b not in origins:
                place(link_b, point_b, world(link_a, point_a))
            elif link_b in origins and link_a not in origins:
                place(link_a, point_a, world(link_b, point_b))
    s = np.zeros(n)
    for name in links:
        x, y = origins.get(name, np.zeros(2))
        s[index[f"{name}.x"]], s[index[f"{name}.y"]] = x, y
        s[index[f"{name}.theta"]] = angles[name]
    return s


def feedforward_torques(mechanism: Mechanism, nominal: NominalMotion
                        ) -> dict[str, Callable[[float], float]]:
    """The nominal inverse-dynamics torque (N m) of each ``TorqueDrive`` of ``mechanism`` that has
    its feedforward on (``TorqueDrive.feedforward``), by joint name, as a function of time: a
    periodic cubic spline through ``nominal.drive_torque`` (the mechanism's ``nominal_motion``).
    ``assemble(mechanism, feedforward=...)`` with it gives the model whose nominal motion solves the
    full equations when every feedforward is on: the one drive law of ``simulate`` and
    ``linearize``."""
    from scipy.interpolate import CubicSpline

    feedforward = {}
    for i, drive in enumerate(mechanism.drives):
        if drive.IMPOSES_MOTION or not drive.feedforward:
            continue   # a drive left out of the mapping applies no feedforward (assemble)
        torque = np.array(nominal.drive_torque[:, i], dtype=float)
        torque[-1] = torque[0]   # equal up to the nominal motion's closure error (round-off)
        spline = CubicSpline(nominal.t, torque, bc_type="periodic")
        feedforward[drive.joint] = (
            lambda t, spline=spline, period=nominal.period: float(spline(t % period)))
    return feedforward
