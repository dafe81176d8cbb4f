"""Geometric stiffness of axially loaded elastic links along the nominal rigid motion.

With geometric stiffening the membrane strain of a link is ``eps = u' + P[w'^2/2]`` (``P`` the
projection onto the axial-strain functions, which keeps the discretised link free of membrane
locking; see ``mechanisms._beams``) and its strain energy ``1/2 int EA eps^2 dx`` contributes
``int N w' dw' dx`` to the bending forces at first order, ``N = EA eps``
the axial force. About a rigid nominal motion the elastic coordinates are zero, so a naive
linearisation sees ``N = 0``. The axial force is carried, to leading order, quasi-statically by the
stiff axial deformation; we take it from the rigid inverse dynamics instead (joint reactions from the
multipliers and the distributed inertia and gravity load) and add

    K_G = int_0^L N(x, t) Sw'(x)^T Sw'(x) dx            (on the link's elastic coordinates)

to the stiffness. ``N(x)`` (tension positive) is the axial component of every force acting on the
part of the link beyond ``x``:

    N(x) = e . [ sum_{joints at xi > x} F_J + sum_{point masses at xi > x} m (g - a(xi))
                 + int_x^L mu (g - a(xi)) dxi ],

with ``e`` the unit vector of the link's x-axis, ``a(xi) = R'' + xi (theta'' e_perp - theta'^2 e)`` the
rigid acceleration, and ``F_J = -Phi_J,R^T lam_J`` the force joint J exerts on the link (the block of
the constraint Jacobian on the link's frame position ``R``). Its axial part integrates in closed form:
``e . int_x^L mu (g - a) dxi = mu [ e.(g - R'') (L - x) + theta'^2 (L^2 - x^2) / 2 ]``.

The joints come from ``model.joint_rows(name)`` (``mechanisms.JointRows``): their constraint rows,
kind and attachment points.
"""

from __future__ import annotations

import numpy as np

import mechanisms

from ._core import LinearizationError

__all__ = ["geometric_stiffness", "axial_forces"]


class _LinkLoading:
    """What the axial force of one stiffened link needs, gathered once: quadrature, shape slopes,
    the constraint rows of its joints and the abscissae of its joints and point masses."""

    def __init__(self, model, name):
        layout = model.layouts[name]
        link = layout.link
        self.offset = layout.offset
        self.elastic = layout.elastic
        self.x, self.weights = layout.shapes.quadrature
        self.slopes = layout.shapes.evaluate(self.x).dw       # (n_gauss, n_elastic)
        self.mu = link.density * link.area
        self.length = link.length
        self.joints = []                                      # (abscissa, rows)
        for joint in model.mechanism.joints:
            rows = model.joint_rows(joint.name)
            # the axial force below is that of point loads -Phi_J,R^T lam_J (mechanisms.JointRows)
            if not rows.point_force:
                raise LinearizationError(
                    f"the geometric stiffness of link {name!r} needs the load of joint "
                    f"{joint.name!r} (kind {rows.kind!r}), which does not act at one point of the "
                    f"link; turn geometric_stiffening off on the link")
            # an elastic link's points lie on its axis: x is the abscissa
            self.joints += [(x, list(rows.rows)) for link_name, (x, _) in rows.ends
                            if link_name == name]
        self.masses = [(link.point_position(pm.point)[0], pm.mass)
                       for pm in model.mechanism.point_masses if pm.link == name]

    def axial_force(self, gravity, s, sdot, sddot, lam, jacobian, x):
        """``N`` (samples, len(x)), tension positive (N), at abscissae ``x`` (m) along the samples
        ``s, sdot, sddot`` (samples, n), ``lam`` (samples, r), ``jacobian`` (samples, r, n)."""
        off = self.offset
        theta, theta_d, theta_dd = s[:, off + 2], sdot[:, off + 2], sddot[:, off + 2]
        e = np.stack([np.cos(theta), np.sin(theta)], axis=1)
        e_perp = np.stack([-e[:, 1], e[:, 0]], axis=1)
        R_dd = sddot[:, off:off + 2]
        L = self.length
        along = np.einsum("kj,kj->k", e, gravity - R_dd)
        N = self.mu * (along[:, None] * (L - x) + (theta_d**2)[:, None] * (L**2 - x**2) / 2)
        for xi, rows in self.joints:
            # Force of the joint on the link: -(block of Phi_s on the link's R)^T lam.
            force = -np.einsum("krj,kr->kj", jacobian[:, rows, off:off + 2], lam[:, rows])
            N += np.einsum("kj,kj->k", e, force)[:, None] * (x < xi)
        for xi, mass in self.masses:
            acceleration = R_dd + xi * (theta_dd[:, None] * e_perp - (theta_d**2)[:, None] * e)
            N += mass * np.einsum("kj,kj->k", e, gravity - acceleration)[:, None] * (x < xi)
        return N


def geometric_stiffness(model, t, s, sdot, sddot, lam, jacobian=None) -> np.ndarray:
    """``K_G`` (N+1, n, n): the geometric stiffness of every link with geometric stiffening on of
    the assembled ``mechanisms.Model`` ``model``, along the rigid motion ``s, sdot, sddot``
    (N+1, n) at times ``t`` (N+1,) with multipliers ``lam`` (N+1, r); ``jacobian`` (N+1, r, n),
    the constraint Jacobian there, if already known."""
    n = model.n_coords
    K_G = np.zeros((len(t), n, n))
    loadings = [_LinkLoading(model, name) for name, layout in model.layouts.items()
                if layout.shapes is not None and layout.stiffening]
    if not loadings:
        return K_G
    if jacobian is None:
        jacobian = mechanisms.constraint_terms_along(model, t, s).jacobian
    gravity = np.asarray(model.mechanism.gravity, dtype=float)
    for link in loadings:
        N = link.axial_force(gravity, s, sdot, sddot, lam, jacobian, link.x)
        K_G[:, link.elastic, link.elastic] = np.einsum("gi,kg,gj->kij", link.slopes,
                                                       link.weights * N, link.slopes)
    return K_G



def axial_forces(model, t, s, sdot, sddot, lam, abscissae, jacobian=None) -> dict[str, np.ndarray]:
    """The axial force ``N`` (N+1, len(x)) in N, tension positive, of each elastic link of ``model``
    named in ``abscissae`` (link name -> abscissae ``x`` (m)), along the rigid motion ``s, sdot,
    sddot`` (N+1, n) at times ``t`` with multipliers ``lam`` (N+1, r): the rigid inverse dynamics
    of the module docstring, for every elastic link whether stiffened or not. A link loaded by a
    joint that is not a point force gets ``None``."""
    if jacobian is None:
        jacobian = mechanisms.constraint_terms_along(model, t, s).jacobian
    gravity = np.asarray(model.mechanism.gravity, dtype=float)
    forces = {}
    for name, x in abscissae.items():
        try:
            loading = _LinkLoading(model, name)
        except LinearizationError:
            forces[name] = None
            continue
        forces[name] = loading.axial_force(gravity, s, sdot, sddot, lam, jacobian, x)
    return forces
