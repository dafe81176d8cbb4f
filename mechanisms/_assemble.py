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

import logging
from collections import OrderedDict
from typing import Callable, Mapping

import numpy as np
from scipy.sparse.csgraph import connected_components

from ._beams import beam_matrices, beam_shapes, membrane_projection
from ._model import JointRows, LinkLayout, Model, _DriveInfo, _Tables
from ._parts import (
    ElasticLink,
    Mechanism,
    MechanismError,
    RigidLink,
)
from ._reduce import equivalent_mass_points, equivalent_strain_points

logger = logging.getLogger(__name__)


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
            beta = link.damping.strain_rate_beta if link.damping is not None else 0.0
            if link.damping is not None and link.damping.constant_on_stiffened:
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

    # constraints: each joint's rows (``mechanisms/_parts/rows.py``) stored through the writer
    writer = _ConstraintWriter(layouts, push, n)
    constraint_labels, angle_rows = [], []
    joint_rows = {}
    for joint in mechanism.joints:
        row = len(constraint_labels)
        rows = tuple(joint.constraint_rows())
        if len(rows) != joint.n_equations:
            raise MechanismError(f"joint {joint.name!r}: constraint_rows() gave {len(rows)} rows, "
                                 f"but its n_equations is {joint.n_equations}")
        for k, constraint in enumerate(rows):
            constraint_labels.append(f"{joint.name}.{constraint.label}")
            angle_rows.append(constraint.unit == "rad")
            writer.new_row()
            constraint.store(writer, row + k)
        ends = tuple((link, layouts[link].link.point_position(point)) for link, point in joint.ends)
        joint_rows[joint.name] = JointRows(joint.name, joint.TYPE, tuple(range(row, row + len(rows))),
                                           ends, bool(joint.point_force))

    # drives (a Mechanism has checked them: each names a joint with drive terms, finite numbers)
    if feedforward is not None and not callable(feedforward) and not isinstance(feedforward,
                                                                                 Mapping):
        raise TypeError(f"feedforward must be a callable tau(t) or a mapping joint name -> "
                        f"callable; received {type(feedforward).__name__}")
    torque_joints = [d.joint for d in mechanism.torque_drives]
    if callable(feedforward) and len(torque_joints) != 1:
        raise MechanismError(f"feedforward is a single callable but the mechanism has "
                             f"{len(torque_joints)} torque drives; pass a mapping joint name -> "
                             f"callable")
    if isinstance(feedforward, Mapping):
        for key in feedforward:
            if key not in torque_joints:
                raise MechanismError(f"feedforward names joint {key!r}, which has no TorqueDrive; "
                                     f"torque drives act at {torque_joints}")
    drives = []
    for drive in mechanism.drives:
        terms = mechanism.joint(drive.joint).drive_terms()
        gradient = writer.angle_gradient(terms)
        if drive.inertia > 0.0:
            # rotor and flywheel: a rotary inertia turning with the driven side (the first term,
            # link_b) about the joint, a mass point of no mass (exact when link_a is the ground)
            lay = layouts[terms[0].link]
            cx, cy, su, sw, dw = _point_local(lay, terms[0].point)
            mp_int.append((lay.offset, *push(su, sw, dw)))
            mp_real.append((0.0, float(drive.inertia), cx, cy))
        if drive.IMPOSES_MOTION:   # one rheonomic row; its multiplier is the drive torque
            row = len(constraint_labels)
            constraint_labels.append(f"drive:{drive.joint}")
            angle_rows.append(True)
            writer.new_row()
            writer.linear[row] = gradient
            drives.append(_DriveInfo(drive, gradient, row, None))
        else:
            law = feedforward if callable(feedforward) else (feedforward or {}).get(drive.joint)
            drives.append(_DriveInfo(drive, gradient, -1, law))
    r = len(constraint_labels)
    h_lin = np.zeros((r, n))
    for row, gradient in writer.linear.items():
        h_lin[row] = gradient

    has_matrices = bool(np.any(k0) or np.any(c0))
    tables = _Tables(
        np.array(mp_int, dtype=np.int64).reshape(-1, 4),
        np.array(mp_real, dtype=np.float64).reshape(-1, 4),
        np.array(sp_int, dtype=np.int64).reshape(-1, 6),
        np.array(sp_real, dtype=np.float64).reshape(-1, 3),
        np.array(writer.ct_int, dtype=np.int64).reshape(-1, 6),
        np.array(writer.ct_real, dtype=np.float64).reshape(-1, 4),
        np.array(shp, dtype=np.float64),
        np.array(idx, dtype=np.int64),
        np.array(writer.phi0, dtype=np.float64),
        h_lin,
        k0 if has_matrices else np.zeros((0, 0)),
        c0 if has_matrices else np.zeros((0, 0)))
    # A Mechanism always has its period (given, or 2 pi / |rate| of the first drive).
    model = Model(mechanism, layouts, coord_labels, constraint_labels, tables, tuple(drives),
                  float(mechanism.period), joint_rows, np.array(angle_rows, dtype=bool))
    model._attach_controllers()
    return model


class _ConstraintWriter:
    """Where the joints' rows (``mechanisms/_parts/rows.py``, the ``RowWriter`` protocol) go: point
    terms into the kernels' constraint terms ``ct_int``, ``ct_real`` (``_kernels``), angle terms into
    the linear rows ``h_lin`` (``linear``: row -> (n,)), constants into ``phi0``."""

    def __init__(self, layouts, push, n):
        self.layouts, self.push, self.n = layouts, push, n
        self.ct_int: list[tuple] = []
        self.ct_real: list[tuple] = []
        self.phi0: list[float] = []
        self.linear: dict[int, np.ndarray] = {}
        self._stored: dict[tuple, tuple] = {}   # a point's position and stored shape rows, once

    def new_row(self) -> None:
        self.phi0.append(0.0)

    def _layout(self, link, kind):
        if link not in self.layouts:
            raise MechanismError(f"a {kind} term names {link!r}, which is not a link of the "
                                 f"mechanism ({list(self.layouts)}); a term on the ground is a "
                                 f"constant of the row")
        return self.layouts[link]

    def point_term(self, row, link, point, direction, frame=None):
        lay = self._layout(link, "point")
        key = (link, point)
        if key not in self._stored:
            cx, cy, su, sw, _ = _point_local(lay, point)
            self._stored[key] = (cx, cy, self.push(su, sw))
        cx, cy, stored = self._stored[key]
        frame_offset = -1 if frame is None else self._layout(frame, "frame").offset
        self.ct_int.append((row, lay.offset, *stored, frame_offset))
        self.ct_real.append((direction[0], direction[1], cx, cy))

    def angle_term(self, row, link, point, coefficient):
        gradient = self.linear.setdefault(row, np.zeros(self.n))
        self._add_angle(gradient, link, point, coefficient)

    def constant(self, row, value):
        self.phi0[row] += value

    def _add_angle(self, gradient, link, point, coefficient):
        """gradient += coefficient d(theta + w'(x))/ds of the link's section at ``point``."""
        lay = self._layout(link, "angle")
        *_, dw = _point_local(lay, point)
        gradient[lay.offset + 2] += coefficient
        gradient[lay.elastic] += coefficient * dw

    def angle_gradient(self, terms) -> np.ndarray:
        """``sum_i c_i d(theta_i + w_i'(x_i))/ds`` (n,) of ``AngleTerm``s (a drive's angle)."""
        gradient = np.zeros(self.n)
        for term in terms:
            self._add_angle(gradient, term.link, term.point, float(term.coefficient))
        return gradient


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
                           "to the thesis's, without stiffening (eq. 2.13)", link.name, link.axial)
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
    """The constant damping matrix ``C0`` of a link's elastic coordinates (N s/m), its damping's
    (``mechanisms/_parts/damping.py``). With ``strain_rate_beta`` (geometric stiffening) Rayleigh's
    ``beta`` is left out: the strain points carry it (``_kernels`` eq. 7-9)."""
    if link.damping is None:
        return np.zeros(m_ee.shape)
    return link.damping.constant_matrix(link.name, m_ee, k_ee, strain_rate_beta=strain_rate_beta)


def _point_local(lay: LinkLayout, point):
    """Local position ``(cx, cy)`` (m) and shape rows ``(Su, Sw, Sw')`` of a point of a link (the
    position from the one point lookup, ``point_position``; a rigid link's rows are empty)."""
    cx, cy = lay.link.point_position(point)
    if lay.shapes is None:
        empty = np.zeros(0)
        return cx, cy, empty, empty, empty
    v = lay.shapes.evaluate([cx])
    return cx, cy, v.u[0], v.w[0], v.dw[0]

