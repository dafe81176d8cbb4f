"""The assembled equations of motion of a mechanism: ``Model`` and the tables its kernels read.

The formulation (redundant coordinates, Lagrange's equations with multipliers, mass points,
strain points, constraint rows) is in ``_assemble``, which builds a ``Model``; the kernels are in
``_kernels`` and ``_batch``. A torque drive's law (feedforward, PD, motor, controllers, limits) is
``Model.drive_torque_terms``, the one place nonlinear runs and the linearisation read it.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from . import _batch, _kernels
from ._alpha_kernel import StepKernel
from ._batch import ConstraintTerms, LinearTerms
from ._beams import BeamShapes
from ._observables import make_observable
from ._parts import (
    ArgumentError,
    ElasticLink,
    MechanismError,
    PrescribedDrive,
    RigidLink,
    TorqueDrive,
    drive_law,
)


@dataclass(frozen=True)
class LinkLayout:
    """Where a link lives in ``s``: coordinates ``offset .. offset + 3 + n_elastic``; ``shapes`` is
    ``None`` for a rigid link. ``stiffening`` tells whether its strain is the projected membrane
    strain; ``membrane`` is then its projection ``R`` (n_elastic, n_gauss)
    (``membrane_projection``)."""

    link: RigidLink | ElasticLink
    offset: int
    n_elastic: int
    shapes: BeamShapes | None
    stiffening: bool
    membrane: np.ndarray | None = None

    @property
    def coords(self) -> slice:
        return slice(self.offset, self.offset + 3 + self.n_elastic)

    @property
    def elastic(self) -> slice:
        return slice(self.offset + 3, self.offset + 3 + self.n_elastic)


@dataclass(frozen=True)
class _Tables:
    """The point tables and constant matrices the kernels read (layouts in ``_kernels``): mass
    points, strain points, constraint terms, sparse shape values ``shp`` and their indices ``idx``,
    the constant part ``phi0`` (r,) and drive rows ``h_lin`` (r, n) of the constraints, and ``k0``,
    ``c0`` (n, n): linear stiffness of the links without geometric stiffening and constant damping of
    the elastic coordinates (stiffened links' Kelvin-Voigt ``beta`` is on the strain points instead)
    ((0, 0) arrays when both vanish)."""

    mp_int: np.ndarray
    mp_real: np.ndarray
    sp_int: np.ndarray
    sp_real: np.ndarray
    ct_int: np.ndarray
    ct_real: np.ndarray
    shp: np.ndarray
    idx: np.ndarray
    phi0: np.ndarray
    h_lin: np.ndarray
    k0: np.ndarray
    c0: np.ndarray


@dataclass(frozen=True)
class _Feedback:
    """An ``ObservableFeedback`` at a torque drive: the observable (``make_observable``), its gains,
    and its constant gradient (n,) when it is linear in ``s`` (else ``None``: evaluated per
    sample)."""

    observable: Any
    gain: float
    rate_gain: float
    gradient: np.ndarray | None


@dataclass(frozen=True)
class _DriveInfo:
    """A drive in the model. A torque drive's law (``Model.drive_torque_terms``): ``kp``, ``kd``
    the total gains on the driven angle's deviation (the drive's own, its PD controllers' and, in
    ``kd``, the motor's back-EMF damping ``back_emf``), ``feedback`` its observable feedbacks,
    ``command_limit`` the motor's largest command ``G stall_torque`` (inf without a motor),
    ``torque_limit`` (N m, inf without one)."""

    drive: PrescribedDrive | TorqueDrive
    gradient: np.ndarray        # h (n,): d(relative material angle)/ds
    row: int                    # constraint row of a prescribed drive, -1 for a torque drive
    feedforward: Callable | None
    kp: float = 0.0
    kd: float = 0.0
    back_emf: float = 0.0
    command_limit: float = math.inf
    torque_limit: float = math.inf
    position_gain: np.ndarray | None = None   # P (n,): dtau/ds of the linear part of the law
    rate_gain: np.ndarray | None = None       # D (n,): dtau/ds' of the linear part of the law
    feedback: tuple[_Feedback, ...] = ()       # the feedbacks of observables nonlinear in s


@dataclass(frozen=True)
class _Lag:
    """A controller with a first-order lag ``tau y' + y = u``: ``law`` its unlagged law ``u`` as a
    drive law (``Model._torque_terms``; no feedforward, limits or back EMF), ``law.gradient`` the
    ``h`` of its drive."""

    name: str
    tau: float
    law: _DriveInfo


@dataclass(frozen=True)
class JointRows:
    """Where a joint lives in the constraints: ``model.joint_rows(name)``.

    ``kind``: the joint's scene ``TYPE`` (``"revolute"``: rows ``"J.x", "J.y"``, ``Phi = r_a - r_b``;
    ``"slider"``: row ``"J.n"``, ``Phi = n . (r - origin)``; a registered joint: its own rows);
    ``rows``: indices into ``Phi`` and ``lam``; ``ends``: ``(link name, (x, y))`` for each side of
    the joint on a link (the ground side left out), with the attachment point's position (m) in
    the undeformed link frame. ``point_force`` (the joint class's): the joint acts at one material
    point of each link it joins (its ``ends``), with the force ``-Phi_J,R^T lam_J`` on the link
    (``Phi_J,R`` the joint's rows of the constraint Jacobian on the link's frame position R) and no
    moment; what the geometric stiffness of ``linearize`` needs to know of a joint.
    """

    name: str
    kind: str
    rows: tuple[int, ...]
    ends: tuple[tuple[str, tuple[float, float]], ...]
    point_force: bool = True


class Model:
    """The assembled equations of motion of a mechanism (implements ``ConstrainedModel``).

    ``M(s) s'' = Q(s, s', t) - Phi_s^T lam``, ``Phi(s, t) = 0``; see ``mechanisms._protocol`` for the
    meaning and shapes of every method. Extra attributes: ``mechanism``, ``period`` (s),
    ``layouts`` (name -> ``LinkLayout``), ``drive_rows`` (constraint rows of prescribed drives);
    ``joint_rows(name)`` the rows of a joint; the batched evaluations along a sampled motion
    ``linear_terms_along``, ``inertia_residual_along``, ``constraint_terms_along``.
    """

    def __init__(self, mechanism, layouts, coord_labels, constraint_labels, tables, drives,
                 period, joint_rows, angle_rows):
        self.mechanism = mechanism
        self.layouts: dict[str, LinkLayout] = layouts
        self.coord_labels = tuple(coord_labels)
        self.constraint_labels = tuple(constraint_labels)
        self.n_coords = len(coord_labels)
        self.n_constraints = len(constraint_labels)
        self.period = period
        rigid, elastic = [], []
        for lay in layouts.values():
            rigid.extend(range(lay.offset, lay.offset + 3))
            elastic.extend(range(lay.offset + 3, lay.offset + 3 + lay.n_elastic))
        self.rigid_index = np.array(rigid, dtype=np.int64)
        self.elastic_index = np.array(elastic, dtype=np.int64)
        self._tables: _Tables = tables
        # Kelvin-Voigt damping on the strain rates of a stiffened link (``_kernels`` eq. 7)
        self._strain_rate_damping = bool(np.any(tables.sp_real[:, 2] != 0.0))
        self._gx, self._gy = (float(g) for g in mechanism.gravity)
        self._drives: tuple[_DriveInfo, ...] = drives
        self._torque_drives = tuple(d for d in drives if d.row < 0)
        self._prescribed = tuple(d for d in drives if d.row >= 0)
        self._lags: tuple[_Lag, ...] = ()  # the lagged controllers (``_attach_controllers``)
        self.drive_rows = np.array([d.row for d in self._prescribed], dtype=np.int64)
        self._joint_rows: dict[str, JointRows] = joint_rows
        #: (r,) bool: the constraint rows in radians (drive rows, ``AngleRow``); the others in metres
        self.angle_rows = angle_rows

    # --- input checks --------------------------------------------------------------------------
    def _vector(self, value, size, name):
        array = np.ascontiguousarray(value, dtype=np.float64)
        if array.shape != (size,):
            raise ArgumentError(f"{name} must have shape ({size},); received shape {array.shape}")
        if not math.isfinite(array.sum()):  # fast path; a sum can overflow, so look closer
            bad = np.flatnonzero(~np.isfinite(array))
            if bad.size:
                raise ArgumentError(f"{name} must be finite; received non-finite entries at "
                                 f"{bad.tolist()}")
        return array

    # --- equations of motion -------------------------------------------------------------------
    def mass_matrix(self, s):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        out = np.zeros((self.n_coords, self.n_coords))
        _kernels.mass_matrix(s[None], tb.mp_int, tb.mp_real, tb.shp, tb.idx, out[None])
        return out

    def forces(self, s, sdot, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        sdot = self._vector(sdot, self.n_coords, "sdot")
        out = np.zeros(self.n_coords)
        _kernels.forces(s[None], sdot[None], self._gx, self._gy, tb.mp_int, tb.mp_real, tb.sp_int,
                        tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, out[None])
        for info in self._torque_drives:
            tau, _, _ = self._torque_terms(info, np.array([t], dtype=float), s[None], sdot[None],
                                           derivatives=False)
            out += tau[0] * info.gradient
        return out

    def constraints(self, s, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        out = tb.phi0 + tb.h_lin @ s
        for info in self._prescribed:
            out[info.row] -= drive_law(info.drive, self.period, t)[0]
        _kernels.constraints(s[None], tb.ct_int, tb.ct_real, tb.shp, tb.idx, out[None])
        return out

    def constraint_jacobian(self, s, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        out = tb.h_lin.copy()
        _kernels.constraint_jacobian(s[None], tb.ct_int, tb.ct_real, tb.shp, tb.idx, out[None])
        return out

    def constraint_rate(self, s, t):
        out = np.zeros(self.n_constraints)
        for info in self._prescribed:
            out[info.row] = -drive_law(info.drive, self.period, t)[1]
        return out

    def constraint_gamma(self, s, sdot, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        sdot = self._vector(sdot, self.n_coords, "sdot")
        out = np.zeros(self.n_constraints)
        for info in self._prescribed:
            out[info.row] = drive_law(info.drive, self.period, t)[2]  # -Phi_tt
        _kernels.constraint_gamma(s[None], sdot[None], tb.ct_int, tb.ct_real, tb.shp, tb.idx, out[None])
        return out

    # --- analytic derivatives ------------------------------------------------------------------
    def mass_matrix_jacobian(self, s, sddot):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        sddot = self._vector(sddot, self.n_coords, "sddot")
        out = np.zeros((self.n_coords, self.n_coords))
        _kernels.mass_matrix_jacobian(s[None], sddot[None], tb.mp_int, tb.mp_real, tb.shp, tb.idx, out[None])
        return out

    def force_jacobians(self, s, sdot, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        sdot = self._vector(sdot, self.n_coords, "sdot")
        d_s = np.zeros((self.n_coords, self.n_coords))
        d_v = np.zeros((self.n_coords, self.n_coords))
        _kernels.force_jacobians(s[None], sdot[None], self._gx, self._gy, tb.mp_int, tb.mp_real,
                                 tb.sp_int, tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, d_s[None], d_v[None])
        for info in self._torque_drives:
            # tau h enters Q: its derivatives are h dtau/ds^T and h dtau/ds'^T
            _, dtau_ds, dtau_dv = self._torque_terms(info, np.array([t], dtype=float), s[None],
                                                     sdot[None], value=False)
            d_s += np.outer(info.gradient, dtau_ds[0])
            d_v += np.outer(info.gradient, dtau_dv[0])
        return d_s, d_v

    def constraint_force_jacobian(self, s, lam, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        lam = self._vector(lam, self.n_constraints, "lam")
        out = np.zeros((self.n_coords, self.n_coords))
        _kernels.constraint_force_jacobian(s[None], lam[None], tb.ct_int, tb.ct_real, tb.shp, tb.idx, out[None])
        return out

    def step_kernel(self):
        """This model's equations for the fused generalized-alpha step (``_alpha_kernel.StepKernel``),
        or None when a torque law is not affine in ``s, s'`` at fixed t (a controller's feedback of
        an observable nonlinear in s): the step then calls the methods above."""
        if any(info.feedback for info in self._torque_drives) or any(
                lag.law.feedback for lag in self._lags):
            return None
        return StepKernel(self._tables, (self._gx, self._gy), self.period, self._prescribed,
                          self._torque_drives, self._lags, self.n_coords)

    # --- energies and drives -------------------------------------------------------------------
    def kinetic_energy(self, s, sdot) -> float:
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        sdot = self._vector(sdot, self.n_coords, "sdot")
        return float(_kernels.kinetic_energy(s, sdot, tb.mp_int, tb.mp_real, tb.shp, tb.idx))

    def potential_energy(self, s) -> float:
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        return float(_kernels.potential_energy(s, self._gx, self._gy, tb.mp_int, tb.mp_real,
                                               tb.sp_int, tb.sp_real, tb.shp, tb.idx, tb.k0))

    def damping_power(self, sdot, s=None) -> float:
        """Power dissipated by the damping of the elastic coordinates (W, >= 0): ``s'^T C0 s'``
        plus, on links with geometric stiffening and Rayleigh ``beta``,
        ``beta int EA eps'^2 + EI w''_t^2 dx`` of the projected membrane strain (``_kernels``
        eq. 7), which depends on the positions ``s`` (required then; the rest does not need it)."""
        tb = self._tables
        sdot = self._vector(sdot, self.n_coords, "sdot")
        if s is None:
            if self._strain_rate_damping:
                raise ArgumentError("s is required: Kelvin-Voigt damping of a link with geometric "
                                 "stiffening depends on the positions; call damping_power(sdot, s)")
            s = np.zeros(self.n_coords)
        else:
            s = self._vector(s, self.n_coords, "s")
        return float(_kernels.damping_power(s, sdot, tb.sp_int, tb.sp_real, tb.shp, tb.idx, tb.c0))

    def drive_torques(self, s, sdot, t, lam=None, lag_states=None) -> np.ndarray:
        """Torque (N m) each drive applies to its ``link_b`` (reaction on ``link_a``), in the order of
        ``mechanism.drives``: ``-lam[row]`` for a prescribed drive (needs ``lam``), the torque law for
        a torque drive, plus the states ``lag_states`` (n_lags,) of its lagged controllers when given
        (``SimulationResult.lag_states[k]``: they are not functions of ``s, sdot, t``)."""
        s = self._vector(s, self.n_coords, "s")
        sdot = self._vector(sdot, self.n_coords, "sdot")
        if self._prescribed and lam is None:
            raise ArgumentError("lam is required: the torque of a prescribed drive is its multiplier")
        if lam is not None:
            lam = self._vector(lam, self.n_constraints, "lam")
        torques = np.array([-lam[info.row] if info.row >= 0 else self._torque_terms(
            info, np.array([t], dtype=float), s[None], sdot[None], derivatives=False)[0][0]
            for info in self._drives])
        if lag_states is not None:
            lag_states = self._vector(lag_states, len(self._lags), "lag_states")
            joints = [info.drive.joint for info in self._drives]
            for lag, y in zip(self._lags, lag_states):
                torques[joints.index(lag.law.drive.joint)] += y
        return torques

    def drive_power(self, s, sdot, t, lam=None) -> float:
        """Power the drives put in, ``sum tau_i * (relative angle rate)_i`` (W)."""
        torques = self.drive_torques(s, sdot, t, lam)
        sdot = self._vector(sdot, self.n_coords, "sdot")
        return float(sum(tau * (info.gradient @ sdot) for tau, info in zip(torques, self._drives)))

    def drive_torque_terms(self, joint: str, t, s, sdot, *, saturate: bool = True
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The torque (N m) of the torque drive at ``joint`` along the samples ``t`` (N,), ``s``,
        ``sdot`` (N, n), with its derivatives: ``(tau (N,), dtau/ds (N, n), dtau/ds' (N, n))``.
        ``saturate=False`` gives the demanded torque of the unsaturated law (docs/scenes.md,
        torque drives and controllers)."""
        infos = [info for info in self._torque_drives if info.drive.joint == joint]
        if not infos:
            raise ArgumentError(f"joint: expected a joint with a torque drive "
                                f"{[i.drive.joint for i in self._torque_drives]}; received "
                                f"{joint!r}")
        n = self.n_coords
        t, (s, sdot) = self._samples(t, {"s": s, "sdot": sdot}, (n, n))
        return self._torque_terms(infos[0], t, s, sdot, saturate=saturate)

    def drive_gradient(self, joint: str) -> np.ndarray:
        """``h`` (n,): the gradient of the driven relative angle at ``joint`` with respect to ``s``
        (constant: the angle is linear in ``s``)."""
        for info in self._drives:
            if info.drive.joint == joint:
                return info.gradient.copy()
        raise ArgumentError(f"joint: expected a driven joint {[i.drive.joint for i in self._drives]}; "
                            f"received {joint!r}")

    def with_drive_profiles(self, profile_of: Callable[[Any], Any]) -> "Model":
        """A copy of this model whose drives follow ``offset + profile.law(t)`` with ``profile =
        profile_of(drive)`` (a ``SpeedRamp``: a run-up or run-down) instead of ``offset + rate t``. A
        torque drive's reference angle and rate follow the profile; its feedforward (the nominal
        torque at its own rate, periodic in t) is read where the nominal motion has the reference's
        angle, at time ``profile angle(t) / rate``."""
        ramped = copy.copy(self)

        def follow(info: _DriveInfo) -> _DriveInfo:
            drive = info.drive
            profile = profile_of(drive)
            feedforward = info.feedforward
            if feedforward is not None and drive.rate:
                def feedforward(t, nominal=info.feedforward, law=profile.law, rate=drive.rate):
                    return nominal(law(t)[0] / rate)
            return dataclasses.replace(info, drive=dataclasses.replace(drive, profile=profile),
                                       feedforward=feedforward)

        ramped._drives = tuple(follow(info) for info in self._drives)
        ramped._torque_drives = tuple(d for d in ramped._drives if d.row < 0)
        ramped._prescribed = tuple(d for d in ramped._drives if d.row >= 0)
        ramped._lags = tuple(dataclasses.replace(lag, law=follow(lag.law)) for lag in self._lags)
        return ramped

    def _torque_terms(self, info, t, s, sdot, *, value=True, derivatives=True, saturate=True):
        """``(tau, dtau/ds, dtau/ds')`` of torque drive ``info`` along ``t`` (N,), ``s``, ``sdot``
        (N, n); ``tau`` is ``None`` without ``value`` (when no limit needs it) and the derivatives
        ``None`` without ``derivatives`` (read-only arrays when they are the same at every sample).
        The unsaturated law is

            tau = ff(t) + kp angle(t) + kd rate(t) + P.s + D.s' - sum (g o(s) + g_r o'(s, s'))

        with ``P = -kp h - sum g grad o``, ``D = -kd h - sum g_r grad o`` over the observables that
        are linear in ``s`` (``_DriveInfo.position_gain``, ``rate_gain``) and the sum over the
        others; a motor's command ``u = tau + c h.s'`` is clipped to ``+-command_limit`` (the
        supply voltage), then ``tau`` to ``+-torque_limit``."""
        limited = saturate and (math.isfinite(info.command_limit) or math.isfinite(info.torque_limit))
        value = value or limited
        tau = d_s = d_v = None
        if value:
            angle, rate, _ = drive_law(info.drive, self.period, t)
            tau = info.kp * angle + info.kd * rate + s @ info.position_gain + sdot @ info.rate_gain
            if info.feedforward is not None:
                tau = tau + np.array([float(info.feedforward(tk)) for tk in t])
        if derivatives:
            shape = (len(t), self.n_coords)
            d_s = np.broadcast_to(info.position_gain, shape)
            d_v = np.broadcast_to(info.rate_gain, shape)
            if info.feedback or limited:
                d_s, d_v = d_s.copy(), d_v.copy()
        for fb in info.feedback:                      # observables nonlinear in s
            for k in range(len(t)):
                g = fb.observable.gradient(s[k])
                if value:
                    tau[k] -= fb.gain * fb.observable.value(s[k]) + fb.rate_gain * (g @ sdot[k])
                if derivatives:
                    d_s[k] -= fb.gain * g + fb.rate_gain * _hessian_times(fb.observable, s[k],
                                                                          sdot[k])
                    d_v[k] -= fb.rate_gain * g
        if not limited:
            return tau, d_s, d_v
        if math.isfinite(info.command_limit):
            back_emf = info.back_emf * (sdot @ info.gradient)
            command = tau + back_emf
            clipped = np.abs(command) > info.command_limit
            tau = np.clip(command, -info.command_limit, info.command_limit) - back_emf
            if derivatives and clipped.any():
                d_s[clipped] = 0.0
                d_v[clipped] = -info.back_emf * info.gradient
        if math.isfinite(info.torque_limit):
            clipped = np.abs(tau) > info.torque_limit
            tau = np.clip(tau, -info.torque_limit, info.torque_limit)
            if derivatives and clipped.any():
                d_s[clipped] = 0.0
                d_v[clipped] = 0.0
        return tau, d_s, d_v

    # --- along a sampled motion: one numba call per quantity ----------------------------------
    def _samples(self, t, arrays, widths):
        """``t`` as a float array (N,) and each of ``arrays`` as a contiguous float array
        (N, width), checked."""
        t = np.asarray(t, dtype=np.float64)
        if t.ndim != 1:
            raise ArgumentError(f"t must be a 1-d array of sample times (s); received shape {t.shape}")
        out = []
        for (name, value), width in zip(arrays.items(), widths):
            array = np.ascontiguousarray(value, dtype=np.float64)
            if array.shape != (len(t), width):
                raise ArgumentError(f"{name} must have shape ({len(t)}, {width}) (samples of t, "
                                 f"entries); received shape {array.shape}")
            out.append(array)
        return t, out

    def linear_terms_along(self, t, s, sdot, sddot, lam) -> LinearTerms:
        """``LinearTerms`` (mass, damping ``-dQ/ds'``, stiffness, residual, constraint Jacobian)
        along the samples ``t`` (N,), ``s, sdot, sddot`` (N, n), ``lam`` (N, r); equal to the
        per-sample methods (up to summation order). One kernel call per quantity, numpy for the
        sums; torque drives (whose law is Python) added vectorised."""
        n, r = self.n_coords, self.n_constraints
        t, (s, sdot, sddot, lam) = self._samples(
            t, {"s": s, "sdot": sdot, "sddot": sddot, "lam": lam}, (n, n, n, r))
        M, D, K, R, J = _batch.tables_linear_terms(self._tables, self._gx, self._gy, s, sdot, sddot, lam)
        for info in self._torque_drives:
            # tau h enters Q: K = -dQ/ds gets -h dtau/ds^T, D = -dQ/ds' gets -h dtau/ds'^T
            tau, dtau_ds, dtau_dv = self._torque_terms(info, t, s, sdot)
            R -= tau[:, None] * info.gradient
            K -= np.einsum("i,kj->kij", info.gradient, dtau_ds)
            D -= np.einsum("i,kj->kij", info.gradient, dtau_dv)
        return LinearTerms(mass=M, damping=D, stiffness=K, residual=R, jacobian=J)

    def inertia_residual_along(self, t, s, sdot, sddot) -> np.ndarray:
        """``M(s) s'' - Q(s, s', t)`` (N, n) along the samples ``t`` (N,), ``s, sdot, sddot``
        (N, n), torque drives included: minus the constraint forces of the inverse dynamics."""
        n = self.n_coords
        t, (s, sdot, sddot) = self._samples(t, {"s": s, "sdot": sdot, "sddot": sddot}, (n, n, n))
        out = _batch.tables_inertia_residual(self._tables, self._gx, self._gy, s, sdot, sddot)
        for info in self._torque_drives:
            tau, _, _ = self._torque_terms(info, t, s, sdot, derivatives=False)
            out -= tau[:, None] * info.gradient
        return out

    def constraint_terms_along(self, t, s, sdot=None, *, values: bool = False) -> ConstraintTerms:
        """``ConstraintTerms`` along the samples ``t`` (N,), ``s`` (N, n): Phi_s, Phi_t, with
        ``sdot`` (N, n) also gamma, with ``values`` also Phi; equal to the per-sample methods (up
        to summation order)."""
        n, r = self.n_coords, self.n_constraints
        arrays = {"s": s} if sdot is None else {"s": s, "sdot": sdot}
        t, checked = self._samples(t, arrays, (n, n))
        s = checked[0]
        n_samples = len(t)
        tb = self._tables
        J = np.empty((n_samples, r, n))
        rate = np.zeros((n_samples, r))
        gamma = np.zeros((n_samples, r))
        phi = np.tile(tb.phi0, (n_samples, 1)) if values else None
        for info in self._prescribed:
            angle, angle_rate, angle_acc = drive_law(info.drive, self.period, t)
            rate[:, info.row] = -angle_rate
            gamma[:, info.row] = angle_acc          # -Phi_tt of the drive row
            if values:
                phi[:, info.row] -= angle
        _batch.tables_constraint_terms(tb, s, None if sdot is None else checked[1], J, gamma, phi)
        return ConstraintTerms(jacobian=J, rate=rate, gamma=gamma if sdot is not None else None,
                               values=phi)

    def _continue_positions(self, s, start, times, *, newton_stop, max_correction, column_scale):
        """Fill ``s[start:]`` (N+1, n) by the nominal motion's fast continuation
        (``_batch.continue_positions_kernel``); returns the first sample it could not do
        (``len(s)`` when all are done). Needs ``start >= 3``; ``column_scale`` (n_rigid,) scales
        the corrections as the careful path (``_kinematics``) does."""
        tb = self._tables
        times = np.asarray(times, dtype=np.float64)
        angles = np.zeros((len(times), len(self._prescribed)))
        for j, info in enumerate(self._prescribed):     # the order of self.drive_rows
            angles[:, j] = drive_law(info.drive, self.period, times)[0]
        return _batch.continue_positions_kernel(
            s, start, self.drive_rows, angles, self.rigid_index, tb.phi0, tb.h_lin, tb.ct_int,
            tb.ct_real, tb.shp, tb.idx, newton_stop, max_correction,
            np.ascontiguousarray(column_scale, dtype=np.float64), 8)

    def _attach_controllers(self) -> None:
        """Fold the mechanism's controllers and motors into the torque drives' laws (they need
        the assembled model for the observables' gradients)."""
        infos, lags = [], []
        for info in self._drives:
            drive = info.drive
            if info.row >= 0:
                infos.append(info)
                continue
            motor = drive.motor
            back_emf = motor.back_emf_damping if motor is not None else 0.0
            here = [c for c in self.mechanism.controllers if c.joint == drive.joint]
            # a lagged controller's law is a lag's input (``_Lag``); the drive adds the lag's state
            law = self._controller_law(info, [c for c in here if not c.lag], drive.kp,
                                       drive.kd + back_emf)
            infos.append(dataclasses.replace(
                law, back_emf=float(back_emf),
                command_limit=motor.peak_command if motor is not None else math.inf,
                torque_limit=float(drive.torque_limit)))
            lags.extend(_Lag(c.name, float(c.lag), self._controller_law(info, [c], 0.0, 0.0,
                                                                        feedforward=None))
                        for c in here if c.lag)
        self._drives = tuple(infos)
        self._torque_drives = tuple(d for d in infos if d.row < 0)
        self._lags = tuple(lags)

    def _controller_law(self, info, controllers, kp, kd, **replace) -> _DriveInfo:
        """``info`` with the unsaturated law (``_torque_terms``) of the gains ``kp``, ``kd`` on the
        driven angle plus those of ``controllers``."""
        nonlinear, feedbacks = [], []
        for controller in controllers:
            law = controller.law()          # each controller class says what it adds
            kp, kd = kp + law.kp, kd + law.kd
            if law.observable is not None:
                feedbacks.append(self._feedback(controller.name, law))
        position_gain, rate_gain = -kp * info.gradient, -kd * info.gradient
        for fb in feedbacks:
            if fb.gradient is None:
                nonlinear.append(fb)
            else:   # o = g.s (zero on the rigid nominal motion), o' = g.s'
                position_gain = position_gain - fb.gain * fb.gradient
                rate_gain = rate_gain - fb.rate_gain * fb.gradient
        return dataclasses.replace(info, kp=float(kp), kd=float(kd), position_gain=position_gain,
                                   rate_gain=rate_gain, feedback=tuple(nonlinear), **replace)

    # --- lags of controllers: first-order states ``lag y' + y = u`` --------------------------------
    @property
    def lag_names(self) -> tuple[str, ...]:
        """The controllers with a ``lag``, in scene order: each has one state ``y`` (N m), the torque
        it adds to its drive, with ``lag y' + y = u(t, s, s')`` its unlagged law."""
        return tuple(lag.name for lag in self._lags)

    @property
    def lag_joints(self) -> tuple[str, ...]:
        """The joint of each lag's torque drive."""
        return tuple(lag.law.drive.joint for lag in self._lags)

    @property
    def lag_time_constants(self) -> np.ndarray:
        """(n_lags,) s."""
        return np.array([lag.tau for lag in self._lags], dtype=float)

    @property
    def lag_gradients(self) -> np.ndarray:
        """(n_lags, n): ``h`` of each lag's drive (its torque ``y`` enters Q as ``y h``)."""
        return np.array([lag.law.gradient for lag in self._lags], dtype=float).reshape(
            len(self._lags), self.n_coords)

    def lag_inputs_along(self, t, s, sdot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lags' inputs, each controller's unlagged law, along ``t`` (N,), ``s``, ``sdot`` (N, n):
        ``(u (N, n_lags) N m, du/ds (N, n_lags, n), du/ds' (N, n_lags, n))``."""
        n = self.n_coords
        t, (s, sdot) = self._samples(t, {"s": s, "sdot": sdot}, (n, n))
        u = np.zeros((len(t), len(self._lags)))
        du_ds, du_dv = np.zeros(u.shape + (n,)), np.zeros(u.shape + (n,))
        for i, lag in enumerate(self._lags):
            u[:, i], du_ds[:, i], du_dv[:, i] = self._torque_terms(lag.law, t, s, sdot, saturate=False)
        return u, du_ds, du_dv

    def _feedback(self, name: str, law) -> _Feedback:
        """The feedback of the observable of controller ``name``'s ``ControllerLaw``."""
        owner = f"controller {name!r}: observable {law.observable!r}"
        try:
            observable = make_observable(self, law.observable)
        except ArgumentError as error:
            raise MechanismError(f"{owner}: {error}") from None
        if not getattr(observable, "depends_on_elastic_only", False) or getattr(
                observable, "kind", "") == "angle":
            raise MechanismError(f"{owner}: expected a quantity of the elastic coordinates alone "
                                 f"(deflection, transverse, strain, moment of a link), zero on "
                                 f"the rigid motion; received one that is not (a link angle: use "
                                 f"a PD controller)")
        # linear in s when the gradient is the same at rest and at a random deformed state
        rest = observable.gradient(np.zeros(self.n_coords))
        probe = np.random.default_rng(0).normal(scale=1e-3, size=self.n_coords)
        linear = np.allclose(observable.gradient(probe), rest, rtol=1e-12,
                             atol=1e-12 * max(np.abs(rest).max(), 1e-300))
        return _Feedback(observable, float(law.gain), float(law.rate_gain), rest if linear else None)

    # --- joints and observables ----------------------------------------------------------------
    def joint_rows(self, name: str) -> JointRows:
        """The constraint rows, kind and attachment points of joint ``name`` (``JointRows``)."""
        if name not in self._joint_rows:
            raise ArgumentError(f"unknown joint {name!r}; joints are {list(self._joint_rows)}")
        return self._joint_rows[name]

    def observable(self, spec: str):
        """A scalar of ``s`` named by ``spec`` (see ``mechanisms._observables``). Built once per
        model and spec (an observable is a frozen description of the model; building one evaluates
        its link's shape functions, about 2 ms: a nonlinear steady state asked for the same 8 24
        times)."""
        cache = self.__dict__.setdefault("_observables", {})
        if not isinstance(spec, str) or spec not in cache:
            observable = make_observable(self, spec)     # raises for a bad spec: nothing kept
            cache[spec] = observable
        return cache[spec]

    def link_coordinates(self, name: str) -> slice:
        """The slice of ``s`` holding link ``name``'s coordinates ``(x, y, theta, q...)``."""
        if name not in self.layouts:
            raise ArgumentError(f"unknown link {name!r}; links are {list(self.layouts)}")
        return self.layouts[name].coords

    def __repr__(self):
        return (f"Model({self.mechanism.name!r}, n_coords={self.n_coords}, "
                f"n_constraints={self.n_constraints})")




def _hessian_times(observable, s: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """``H(s) direction`` (n,) of a nonlinear observable: the central difference of its analytic
    gradient along ``direction`` (error O(eps^2) relative, eps ~ 1e-5 of the state's scale)."""
    norm = float(np.abs(direction).max())
    if norm == 0.0:
        return np.zeros_like(s)
    eps = 1e-5 * max(1.0, float(np.abs(s).max())) / norm
    return (observable.gradient(s + eps * direction) - observable.gradient(s - eps * direction)) / (
        2.0 * eps)


