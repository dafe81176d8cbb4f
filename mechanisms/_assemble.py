"""The generic assembler: a ``Mechanism`` -> a ``Model`` of its constrained equations of motion.

Formulation (redundant coordinates, Lagrange's equations with multipliers, seed eq. 2.9-2.13).
Each link contributes ``(x, y, theta)`` of its frame origin (first pin) and angle, then its elastic
coordinates ``q``. A material point at abscissa ``x`` of a link sits at

    r = R + A(theta) (xbar + S(x) q),     xbar = (x, 0),   S = [Su; Sw] (2 x n_elastic),

(``S = 0`` for a rigid link, whose points have any local position). With ``L = dr/ds``,
d'Alembert's principle gives the generalized inertia force ``int L^T r'' dm``, so

    M = sum_g m_g L_g^T L_g + J_g h_g h_g^T,         h = (0, 0, 1, Sw'(x)) (section rotation),
    Q = sum_g m_g L_g^T (gravity - Ldot_g s') - dPi/ds - C s' + drive torques,

summed over *mass points*: Gauss points of the elastic links (``m = w mu``, ``J = w rho I`` with rotary
inertia), the centroid of each rigid link (its mass and centroidal inertia) and the point masses.
This is exactly the kinetic energy of seed eq. 2.12 (every Coriolis, centrifugal and elastic
coupling term) integrated by Gauss quadrature, exact for FEM and to 1e-14 for Ritz modes (see
``_beams``). The strain energy is ``1/2 int EA eps^2 + EI w''^2 dx`` with ``eps = u'`` (seed eq. 2.13,
``geometric_stiffening=False``: the constant matrix ``K0``) or the projected membrane strain
``eps = Su'(x) q + P[w'^2/2](x)`` (``geometric_stiffening=True``: evaluated at Gauss points), ``P``
the L2 projection onto the span of the link's axial strain functions ``Su'_i`` (``_beams``): the
pointwise ``u' + w'^2/2`` would lock (``u'`` cannot represent ``w'^2/2``, so bending would stretch
the chord). At ``q = 0`` under an axial strain ``Su' p`` the bending Hessian of this energy is
``int N Sw'^T Sw' dx``, the usual geometric stiffness. A link with geometric stiffening but no axial
coordinates has nothing to project onto: it falls back to seed eq. 2.13 (``K0``), with a warning.
Damping acts on the elastic coordinates. Rayleigh ``alpha M_ee + beta K_ee`` (``K_ee`` the linear
stiffness, so Kelvin-Voigt ``beta`` damps bending and axial strain) is the constant matrix ``C0``
on a link without geometric stiffening. On a link with it, ``alpha M_ee`` stays constant and the
Kelvin-Voigt part acts on the rates of the strains the strain energy uses (damping stress
``beta E eps'``, ``_kernels`` eq. 7-9): the linear ``beta EA int u' du'`` would see the chord
shortening ``u' = -P[w'^2/2]`` of a bent link as a strain rate and resist it with a large spurious
force ("damping locking"). At ``q = 0`` the two agree, so the linearisation is the same. Modal ratios
of the link's own modes (frame held fixed) and the explicit matrix are constant ``C0`` on every link:
on a stiffened link they still damp the chord shortening's axial motion (a limitation; use
Rayleigh ``beta`` there).

Constraints: a revolute joint makes two rows ``r_a - r_b = 0``, a slider one row
``n . (r - origin) = 0``, a prescribed drive one row: the material angle of ``link_b`` at the joint
(``theta_b + Sw_b'(x) q_b``) minus that of ``link_a`` (0 for the ground) equals ``angle(t)``. A
torque drive adds ``tau h`` to ``Q`` with ``h`` the gradient of that relative angle.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np
from scipy.linalg import eigh
from scipy.sparse.csgraph import connected_components

from . import _batch, _kernels
from ._batch import ConstraintTerms, LinearTerms
from ._beams import BeamShapes, beam_matrices, beam_shapes, membrane_projection
from ._observables import make_observable
from ._parts import (
    GROUND,
    ArgumentError,
    DampingMatrix,
    ElasticLink,
    Mechanism,
    MechanismError,
    ModalDamping,
    ObservableFeedback,
    PDController,
    PrescribedDrive,
    Rayleigh,
    Revolute,
    RigidLink,
    Slider,
    TorqueDrive,
)
from ._reduce import equivalent_mass_points, equivalent_strain_points

logger = logging.getLogger(__name__)


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

    ``kind``: ``"revolute"`` (rows ``"J.x", "J.y"``, ``Phi = r_a - r_b``) or ``"slider"`` (row
    ``"J.n"``, ``Phi = n . (r - origin)``); ``rows``: indices into ``Phi`` and ``lam``; ``ends``:
    ``(link name, (x, y))`` for each side of the joint on a link (the ground side left out), with
    the attachment point's position (m) in the undeformed link frame. ``point_force``: the joint
    acts at one material point of each link it joins (its ``ends``), with the force
    ``-Phi_J,R^T lam_J`` on the link (``Phi_J,R`` the joint's rows of the constraint Jacobian on the
    link's frame position R); true of both kinds, and what the geometric stiffness of ``linearize``
    needs to know of a joint, so a new point-force joint needs no change there.
    """

    name: str
    kind: str
    rows: tuple[int, ...]
    ends: tuple[tuple[str, tuple[float, float]], ...]
    point_force: bool = True


def drive_law(drive: PrescribedDrive | TorqueDrive, period: float | None, t
              ) -> tuple[float, float, float]:
    """Nominal relative angle of a drive at time ``t`` (s) with its first and second derivatives:
    ``offset + rate t + sum_k cos_k cos(k w t) + sin_k sin(k w t)``, ``w = 2 pi / period``.
    ``t`` may also be an array: the three results are then arrays of its shape."""
    angle = drive.offset + drive.rate * t
    rate = drive.rate + 0.0 * t
    acc = 0.0 * t
    if drive.harmonics:
        w = 2.0 * math.pi / period
        for k, ck, sk in drive.harmonics:
            kw = k * w
            c, s = np.cos(kw * t), np.sin(kw * t)
            angle += ck * c + sk * s
            rate += kw * (-ck * s + sk * c)
            acc -= kw * kw * (ck * c + sk * s)
    return angle, rate, acc


class Model:
    """The assembled equations of motion of a mechanism (implements ``ConstrainedModel``).

    ``M(s) s'' = Q(s, s', t) - Phi_s^T lam``, ``Phi(s, t) = 0``; see ``mechanisms._protocol`` for the
    meaning and shapes of every method. Extra attributes: ``mechanism``, ``period`` (s),
    ``layouts`` (name -> ``LinkLayout``), ``drive_rows`` (constraint rows of prescribed drives);
    ``joint_rows(name)`` the rows of a joint; the batched evaluations along a sampled motion
    ``linear_terms_along``, ``inertia_residual_along``, ``constraint_terms_along``.
    """

    def __init__(self, mechanism, layouts, coord_labels, constraint_labels, tables, drives,
                 period, joint_rows):
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
        _kernels.mass_matrix(s, tb.mp_int, tb.mp_real, tb.shp, tb.idx, out)
        return out

    def forces(self, s, sdot, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        sdot = self._vector(sdot, self.n_coords, "sdot")
        out = np.zeros(self.n_coords)
        _kernels.forces(s, sdot, self._gx, self._gy, tb.mp_int, tb.mp_real, tb.sp_int,
                        tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, out)
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
        _kernels.constraints(s, tb.ct_int, tb.ct_real, tb.shp, tb.idx, out)
        return out

    def constraint_jacobian(self, s, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        out = tb.h_lin.copy()
        _kernels.constraint_jacobian(s, tb.ct_int, tb.ct_real, tb.shp, tb.idx, out)
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
        _kernels.constraint_gamma(s, sdot, tb.ct_int, tb.ct_real, tb.shp, tb.idx, out)
        return out

    # --- analytic derivatives ------------------------------------------------------------------
    def mass_matrix_jacobian(self, s, sddot):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        sddot = self._vector(sddot, self.n_coords, "sddot")
        out = np.zeros((self.n_coords, self.n_coords))
        _kernels.mass_matrix_jacobian(s, sddot, tb.mp_int, tb.mp_real, tb.shp, tb.idx, out)
        return out

    def force_jacobians(self, s, sdot, t):
        tb = self._tables
        s = self._vector(s, self.n_coords, "s")
        sdot = self._vector(sdot, self.n_coords, "sdot")
        d_s = np.zeros((self.n_coords, self.n_coords))
        d_v = np.zeros((self.n_coords, self.n_coords))
        _kernels.force_jacobians(s, sdot, self._gx, self._gy, tb.mp_int, tb.mp_real, tb.sp_int,
                                 tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, d_s, d_v)
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
        _kernels.constraint_force_jacobian(s, lam, tb.ct_int, tb.ct_real, tb.shp, tb.idx, out)
        return out

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
        per-sample methods. Torque drives (whose law is Python) are added vectorised."""
        n, r = self.n_coords, self.n_constraints
        t, (s, sdot, sddot, lam) = self._samples(
            t, {"s": s, "sdot": sdot, "sddot": sddot, "lam": lam}, (n, n, n, r))
        n_samples = len(t)
        M, D, K = (np.zeros((n_samples, n, n)) for _ in range(3))
        R = np.zeros((n_samples, n))
        J = np.zeros((n_samples, r, n))
        tb = self._tables
        _batch.linear_terms_kernel(s, sdot, sddot, lam, self._gx, self._gy, tb.mp_int, tb.mp_real,
                                   tb.sp_int, tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, tb.ct_int,
                                   tb.ct_real, tb.h_lin, M, D, K, R, J)
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
        out = np.zeros(s.shape)
        tb = self._tables
        _batch.inertia_residual_kernel(s, sdot, sddot, self._gx, self._gy, tb.mp_int, tb.mp_real,
                                       tb.sp_int, tb.sp_real, tb.shp, tb.idx, tb.k0, tb.c0, out)
        for info in self._torque_drives:
            tau, _, _ = self._torque_terms(info, t, s, sdot, derivatives=False)
            out -= tau[:, None] * info.gradient
        return out

    def constraint_terms_along(self, t, s, sdot=None, *, values: bool = False) -> ConstraintTerms:
        """``ConstraintTerms`` along the samples ``t`` (N,), ``s`` (N, n): Phi_s, Phi_t, with
        ``sdot`` (N, n) also gamma, with ``values`` also Phi; equal to the per-sample methods."""
        n, r = self.n_coords, self.n_constraints
        arrays = {"s": s} if sdot is None else {"s": s, "sdot": sdot}
        t, checked = self._samples(t, arrays, (n, n))
        s = checked[0]
        sdot = checked[1] if sdot is not None else np.zeros((0, n))
        n_samples = len(t)
        tb = self._tables
        J = np.zeros((n_samples, r, n))
        rate = np.zeros((n_samples, r))
        gamma = np.zeros((n_samples, r))
        phi = np.tile(tb.phi0, (n_samples, 1)) if values else np.zeros((0, r))
        for info in self._prescribed:
            angle, angle_rate, angle_acc = drive_law(info.drive, self.period, t)
            rate[:, info.row] = -angle_rate
            gamma[:, info.row] = angle_acc          # -Phi_tt of the drive row
            if values:
                phi[:, info.row] -= angle
        _batch.constraint_terms_kernel(s, sdot, tb.ct_int, tb.ct_real, tb.shp, tb.idx, tb.h_lin, J,
                                       gamma, phi)
        return ConstraintTerms(jacobian=J, rate=rate, gamma=gamma if len(sdot) else None,
                               values=phi if values else None)

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
            if isinstance(controller, PDController):
                kp, kd = kp + controller.kp, kd + controller.kd
            elif isinstance(controller, ObservableFeedback):
                feedbacks.append(self._feedback(controller))
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

    def _feedback(self, controller: ObservableFeedback) -> _Feedback:
        owner = f"controller {controller.name!r}: observable {controller.observable!r}"
        try:
            observable = make_observable(self, controller.observable)
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
        return _Feedback(observable, float(controller.gain), float(controller.rate_gain),
                         rest if linear else None)

    # --- joints and observables ----------------------------------------------------------------
    def joint_rows(self, name: str) -> JointRows:
        """The constraint rows, kind and attachment points of joint ``name`` (``JointRows``)."""
        if name not in self._joint_rows:
            raise ArgumentError(f"unknown joint {name!r}; joints are {list(self._joint_rows)}")
        return self._joint_rows[name]

    def observable(self, spec: str):
        """A scalar of ``s`` named by ``spec`` (see ``mechanisms._observables``)."""
        return make_observable(self, spec)

    def link_coordinates(self, name: str) -> slice:
        """The slice of ``s`` holding link ``name``'s coordinates ``(x, y, theta, q...)``."""
        if name not in self.layouts:
            raise ArgumentError(f"unknown link {name!r}; links are {list(self.layouts)}")
        return self.layouts[name].coords

    def __repr__(self):
        return (f"Model({self.mechanism.name!r}, n_coords={self.n_coords}, "
                f"n_constraints={self.n_constraints})")


# ---------------------------------------------------------------------------------------------------
# Assembly
# ---------------------------------------------------------------------------------------------------
# Recently assembled models, by the identity of their (immutable) mechanism: studies, the nominal
# motion and the nonlinear runs assemble the same mechanism again and again. Each entry keeps its
# mechanism alive, so an identity cannot be reused while it is cached; a Model is never modified.
_RECENT_MODELS: "OrderedDict[int, tuple[Mechanism, Model]]" = OrderedDict()
_RECENT_MODELS_SIZE = 16


def assemble(mechanism: Mechanism, *, feedforward: Callable | Mapping[str, Callable] | None = None
             ) -> Model:
    """Assemble the equations of motion of ``mechanism``.

    ``feedforward`` is the nominal torque ``tau_nominal(t)`` (N m) of the torque drives: one callable
    when there is exactly one torque drive, or a mapping from the drive's joint name to a callable;
    missing ones are zero. Without it the model of a recently assembled mechanism (the same object)
    is returned again.
    """
    if not isinstance(mechanism, Mechanism):
        raise TypeError(f"mechanism must be a Mechanism; received {type(mechanism).__name__}")
    if feedforward is None:
        recent = _RECENT_MODELS.get(id(mechanism))
        if recent is not None and recent[0] is mechanism:
            _RECENT_MODELS.move_to_end(id(mechanism))
            return recent[1]
    model = _assemble(mechanism, feedforward)
    if feedforward is None:
        _RECENT_MODELS[id(mechanism)] = (mechanism, model)
        while len(_RECENT_MODELS) > _RECENT_MODELS_SIZE:
            _RECENT_MODELS.popitem(last=False)
    return model


def _assemble(mechanism: Mechanism, feedforward) -> Model:
    layouts, coord_labels = _layout(mechanism)
    n = len(coord_labels)

    shp: list[float] = []
    idx: list[int] = []

    def push(*rows) -> tuple[int, int, int]:
        """Store the shape rows of a point sparsely (the elastic coordinates where any row is
        nonzero); return (nnz, value pointer, index pointer)."""
        rows = [np.asarray(row, dtype=float) for row in rows]
        active = np.flatnonzero(np.any([row != 0.0 for row in rows], axis=0)) if len(
            rows[0]) else np.zeros(0, dtype=np.int64)
        pointer, index_pointer = len(shp), len(idx)
        for row in rows:
            shp.extend(row[active].tolist())
        idx.extend(active.tolist())
        return len(active), pointer, index_pointer

    def push_group(offset, du, dw, ddw, projection, rows):
        """Store a group of strain points (``_kernels`` eq. 4) with shape rows ``du, dw, ddw``
        (G, n_elastic) and projection (G, G): the rows on the group's common active coordinates,
        then the group's projection."""
        active = np.flatnonzero(np.any(np.abs(np.vstack([du, dw, ddw])) > 0.0, axis=0))
        index_pointer = len(idx)
        idx.extend(active.tolist())
        pointers = []
        for g in range(len(du)):
            pointers.append(len(shp))
            for row in (du[g], dw[g], ddw[g]):
                shp.extend(row[active].tolist())
        block_pointer = len(shp)
        shp.extend(projection.ravel().tolist())
        for k, pointer in enumerate(pointers):
            rows.append((offset, len(active), pointer, index_pointer,
                         len(du) if k == 0 else 0, block_pointer))

    # mass points (seed eq. 2.12) and strain points (eq. 2.13, projected membrane strain)
    mp_int, mp_real, sp_int, sp_real = [], [], [], []
    k0 = np.zeros((n, n))
    c0 = np.zeros((n, n))
    for lay in layouts.values():
        link = lay.link
        if lay.shapes is None:
            cx, cy = link.centroid if link.centroid is not None else (0.5 * link.length, 0.0)
            mp_int.append((lay.offset, 0, 0, 0))
            mp_real.append((link.mass, link.inertia, cx, cy))
            continue
        x, weights = lay.shapes.quadrature
        v = lay.shapes.evaluate(x)
        mu = link.density * link.area
        rho_i = link.density * link.second_moment if link.rotary_inertia else 0.0
        if lay.shapes.reduced:   # dense rows: fewer points with the same sums (``_reduce``)
            points = equivalent_mass_points(x, weights, mu, rho_i, v.u, v.w, v.dw)
            for k in range(len(points.mass)):
                mp_int.append((lay.offset, *push(points.u[k], points.w[k], points.dw[k])))
                mp_real.append((points.mass[k], points.inertia[k], points.cx[k], 0.0))
        else:
            for g in range(len(x)):
                mp_int.append((lay.offset, *push(v.u[g], v.w[g], v.dw[g])))
                mp_real.append((weights[g] * mu, weights[g] * rho_i, x[g], 0.0))
        m_ee, k_ee = beam_matrices(lay.shapes)
        if lay.stiffening:
            ea = link.youngs_modulus * link.area
            ei = link.youngs_modulus * link.second_moment
            beta = link.damping.beta if isinstance(link.damping, Rayleigh) else 0.0
            if isinstance(link.damping, (ModalDamping, DampingMatrix)):
                logger.warning("link %r: %s is a constant matrix on the elastic coordinates; with "
                               "geometric stiffening it also damps the axial motion of the chord "
                               "shortening of a bent link, which strains nothing (use Rayleigh "
                               "beta, which acts on the membrane strain rate)", link.name,
                               type(link.damping).__name__)
            if lay.shapes.reduced:
                points = equivalent_strain_points(weights, ea, ei, v.du, v.dw, v.ddw)
                push_group(lay.offset, points.du, points.dw, points.ddw, points.projection, sp_int)
                sp_real.extend((a, b, beta) for a, b in zip(points.ea, points.ei))
            else:
                projection = v.du @ lay.membrane  # P (n_gauss, n_gauss) at the Gauss points
                for group in _projection_groups(projection):
                    push_group(lay.offset, v.du[group], v.dw[group], v.ddw[group],
                               projection[np.ix_(group, group)], sp_int)
                    sp_real.extend((weights[g] * ea, weights[g] * ei, beta) for g in group)
        else:
            k0[lay.elastic, lay.elastic] = k_ee
        c0[lay.elastic, lay.elastic] = _damping_matrix(link, m_ee, k_ee,
                                                       strain_rate_beta=lay.stiffening)
    for pm in mechanism.point_masses:
        lay = layouts[pm.link]
        cx, cy, su, sw, dw = _point_local(lay, pm.point)
        mp_int.append((lay.offset, *push(su, sw, dw)))
        mp_real.append((pm.mass, pm.inertia, cx, cy))

    # constraints
    constraint_labels, ct_int, ct_real, phi0 = [], [], [], []
    joint_rows = {}
    for joint in mechanism.joints:
        row = len(constraint_labels)
        if isinstance(joint, Revolute):
            constraint_labels += [f"{joint.name}.x", f"{joint.name}.y"]
            phi0 += [0.0, 0.0]
            ends = []
            for link_name, point, sign in ((joint.link_a, joint.point_a, 1.0),
                                           (joint.link_b, joint.point_b, -1.0)):
                if link_name == GROUND:
                    phi0[row] += sign * float(point[0])
                    phi0[row + 1] += sign * float(point[1])
                    continue
                lay = layouts[link_name]
                cx, cy, su, sw, _ = _point_local(lay, point)
                ends.append((link_name, (cx, cy)))
                stored = push(su, sw)
                for axis in (0, 1):
                    ct_int.append((row + axis, lay.offset, *stored))
                    ct_real.append((sign * (axis == 0), sign * (axis == 1), cx, cy))
            joint_rows[joint.name] = JointRows(joint.name, "revolute", (row, row + 1), tuple(ends))
        elif isinstance(joint, Slider):
            constraint_labels.append(f"{joint.name}.n")
            lay = layouts[joint.link]
            ox, oy = (float(c) for c in joint.origin)
            nx, ny = -math.sin(joint.angle), math.cos(joint.angle)
            phi0.append(-(nx * ox + ny * oy))
            cx, cy, su, sw, _ = _point_local(lay, joint.point)
            ct_int.append((row, lay.offset, *push(su, sw)))
            ct_real.append((nx, ny, cx, cy))
            joint_rows[joint.name] = JointRows(joint.name, "slider", (row,),
                                               ((joint.link, (cx, cy)),))
        else:  # Mechanism accepts Revolute and Slider only: a new kind needs its rows here
            raise NotImplementedError(f"assemble() has no constraint rows for joint "
                                      f"{joint.name!r} of type {type(joint).__name__}")

    # drives (a Mechanism has checked them: each names a revolute joint, with finite numbers)
    if feedforward is not None and not callable(feedforward) and not isinstance(feedforward,
                                                                                 Mapping):
        raise TypeError(f"feedforward must be a callable tau(t) or a mapping joint name -> "
                        f"callable; received {type(feedforward).__name__}")
    torque_joints = [d.joint for d in mechanism.drives if isinstance(d, TorqueDrive)]
    if callable(feedforward) and len(torque_joints) != 1:
        raise MechanismError(f"feedforward is a single callable but the mechanism has "
                             f"{len(torque_joints)} torque drives; pass a mapping joint name -> "
                             f"callable")
    if isinstance(feedforward, Mapping):
        for key in feedforward:
            if key not in torque_joints:
                raise MechanismError(f"feedforward names joint {key!r}, which has no TorqueDrive; "
                                     f"torque drives act at {torque_joints}")
    drive_rows_h = []
    drives = []
    for drive in mechanism.drives:
        joint = mechanism.joint(drive.joint)
        gradient = np.zeros(n)
        for link_name, point, sign in ((joint.link_a, joint.point_a, -1.0),
                                       (joint.link_b, joint.point_b, 1.0)):
            if link_name == GROUND:
                continue
            lay = layouts[link_name]
            *_, dw = _point_local(lay, point)
            gradient[lay.offset + 2] += sign
            gradient[lay.elastic] += sign * dw
        if drive.inertia > 0.0:
            # rotor and flywheel: a rotary inertia turning with link_b (the driven side) about
            # the joint, a mass point of no mass (exact when link_a is the ground)
            side, point = ((joint.link_b, joint.point_b) if joint.link_b != GROUND
                           else (joint.link_a, joint.point_a))
            lay = layouts[side]
            cx, cy, su, sw, dw = _point_local(lay, point)
            mp_int.append((lay.offset, *push(su, sw, dw)))
            mp_real.append((0.0, float(drive.inertia), cx, cy))
        if isinstance(drive, PrescribedDrive):
            row = len(constraint_labels)
            constraint_labels.append(f"drive:{drive.joint}")
            phi0.append(0.0)
            drive_rows_h.append((row, gradient))
            drives.append(_DriveInfo(drive, gradient, row, None))
        else:
            law = feedforward if callable(feedforward) else (feedforward or {}).get(drive.joint)
            drives.append(_DriveInfo(drive, gradient, -1, law))
    r = len(constraint_labels)
    h_lin = np.zeros((r, n))
    for row, gradient in drive_rows_h:
        h_lin[row] = gradient

    has_matrices = bool(np.any(k0) or np.any(c0))
    tables = _Tables(
        np.array(mp_int, dtype=np.int64).reshape(-1, 4),
        np.array(mp_real, dtype=np.float64).reshape(-1, 4),
        np.array(sp_int, dtype=np.int64).reshape(-1, 6),
        np.array(sp_real, dtype=np.float64).reshape(-1, 3),
        np.array(ct_int, dtype=np.int64).reshape(-1, 5),
        np.array(ct_real, dtype=np.float64).reshape(-1, 4),
        np.array(shp, dtype=np.float64),
        np.array(idx, dtype=np.int64),
        np.array(phi0, dtype=np.float64),
        h_lin,
        k0 if has_matrices else np.zeros((0, 0)),
        c0 if has_matrices else np.zeros((0, 0)))
    # A Mechanism always has its period (given, or 2 pi / |rate| of the first drive).
    model = Model(mechanism, layouts, coord_labels, constraint_labels, tables, tuple(drives),
                  float(mechanism.period), joint_rows)
    model._attach_controllers()
    return model


def _layout(mechanism):
    """Where each link's coordinates live in ``s``, and their labels. The parts and how they fit
    were checked when the ``Mechanism`` was made (``_parts``): nothing is checked again here."""
    layouts: dict[str, LinkLayout] = {}
    labels: list[str] = []
    for link in mechanism.links:
        offset = len(labels)
        labels += [f"{link.name}.x", f"{link.name}.y", f"{link.name}.theta"]
        if isinstance(link, RigidLink):
            layouts[link.name] = LinkLayout(link, offset, 0, None, False)
            continue
        shapes = beam_shapes(link, attachments=_attachments(mechanism, link))
        membrane = membrane_projection(shapes) if link.geometric_stiffening else None
        if link.geometric_stiffening and membrane is None:
            logger.warning("link %r: geometric stiffening needs axial coordinates to carry the "
                           "membrane strain (axial=%s, none kept); its strain energy falls back "
                           "to seed eq. 2.13", link.name, link.axial)
        labels += [f"{link.name}.{label}" for label in shapes.labels]
        layouts[link.name] = LinkLayout(link, offset, shapes.n_elastic, shapes,
                                        membrane is not None, membrane)
    return layouts, labels


def _attachments(mechanism, link) -> tuple[tuple[float, bool], ...]:
    """Where the mechanism loads ``link`` with concentrated loads, ``(x, moment)`` (m, whether a
    moment acts: a drive at the joint, or a point mass's rotary inertia): what chooses a reduced
    link's static correction modes (``_beams.beam_shapes``)."""
    driven = {drive.joint for drive in mechanism.drives}
    found = []
    for joint in mechanism.joints:
        for link_name, point in joint.ends:
            if link_name == link.name:
                found.append((link.point_position(point)[0], joint.name in driven))
    found += [(link.point_position(pm.point)[0], pm.inertia > 0.0)
              for pm in mechanism.point_masses if pm.link == link.name]
    return tuple(found)


def _projection_groups(projection: np.ndarray) -> list[np.ndarray]:
    """Gauss points that the projection couples (an element for linear axial FEM, where ``P`` is
    the element average; the whole link for Ritz modes), as index arrays. Entries below 1e-12 of
    the largest are the round-off of exact zeros (the projection of a function supported on one
    element onto element-wise constants vanishes elsewhere) and do not couple."""
    coupled = np.abs(projection) > 1e-12 * np.max(np.abs(projection))
    count, labels = connected_components(coupled, directed=False)
    return [np.flatnonzero(labels == label) for label in range(count)]


def _damping_matrix(link: ElasticLink, m_ee: np.ndarray, k_ee: np.ndarray, *,
                    strain_rate_beta: bool) -> np.ndarray:
    """The constant damping matrix ``C0`` of a link's elastic coordinates (N s/m). With
    ``strain_rate_beta`` (geometric stiffening) Rayleigh's ``beta`` is left out: the strain points
    carry it (``_kernels`` eq. 7-9)."""
    damping = link.damping
    n_e = m_ee.shape[0]
    if damping is None:
        return np.zeros((n_e, n_e))
    if isinstance(damping, Rayleigh):
        if strain_rate_beta:
            return damping.alpha * m_ee
        return damping.alpha * m_ee + damping.beta * k_ee
    if isinstance(damping, ModalDamping):
        # The number of modes is the discretisation's: checked here, not by ModalDamping.
        ratios = np.asarray(damping.ratios, dtype=float)
        if len(ratios) > n_e:
            raise MechanismError(f"link {link.name!r}: damping.ratios must be at most {n_e} "
                                 f"numbers (one per elastic coordinate); received "
                                 f"{damping.ratios!r}")
        omega2, modes = eigh(k_ee, m_ee)  # mass-normalised: modes^T M modes = I
        omega = np.sqrt(np.maximum(omega2[:len(ratios)], 0.0))
        mphi = m_ee @ modes[:, :len(ratios)]
        return mphi @ np.diag(2.0 * ratios * omega) @ mphi.T
    # DampingMatrix (ElasticLink accepts these three kinds and None only); its size is the
    # discretisation's, checked here.
    matrix = np.asarray(damping.matrix, dtype=float)
    if matrix.shape != (n_e, n_e):
        raise MechanismError(f"link {link.name!r}: damping.matrix must be a ({n_e}, {n_e}) matrix "
                             f"(one row per elastic coordinate); received shape {matrix.shape}")
    return matrix


def _hessian_times(observable, s: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """``H(s) direction`` (n,) of a nonlinear observable: the central difference of its analytic
    gradient along ``direction`` (error O(eps^2) relative, eps ~ 1e-5 of the state's scale)."""
    norm = float(np.abs(direction).max())
    if norm == 0.0:
        return np.zeros_like(s)
    eps = 1e-5 * max(1.0, float(np.abs(s).max())) / norm
    return (observable.gradient(s + eps * direction) - observable.gradient(s - eps * direction)) / (
        2.0 * eps)


def _point_local(lay: LinkLayout, point):
    """Local position ``(cx, cy)`` (m) and shape rows ``(Su, Sw, Sw')`` of a point of a link (the
    position from the one point lookup, ``point_position``; a rigid link's rows are empty)."""
    cx, cy = lay.link.point_position(point)
    if lay.shapes is None:
        empty = np.zeros(0)
        return cx, cy, empty, empty, empty
    v = lay.shapes.evaluate([cx])
    return cx, cy, v.u[0], v.w[0], v.dw[0]
