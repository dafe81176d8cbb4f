"""Geometric stiffness of axially loaded elastic links along the nominal rigid motion.

With geometric stiffening the strain of a link is ``u' + w'^2/2`` and its strain energy
``1/2 int EA (u' + w'^2/2)^2 dx`` contributes ``int N w' dw' dx`` to the bending forces, ``N = EA eps``
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
"""

from __future__ import annotations

import math

import numpy as np

from mechanisms import GROUND, Revolute

__all__ = ["axial_force", "geometric_stiffness"]


def _loads_on_link(model, name, s, sdot, sddot, lam):
    """Concentrated loads on link ``name``: a list of ``(abscissa (m), force (2,) N)`` from the joints
    (through the multipliers) and from the point masses (their inertia and weight)."""
    layout = model.layouts[name]
    link = layout.link
    off = layout.offset
    Phi_s = model.constraint_jacobian(s, 0.0)
    labels = model.constraint_labels
    loads = []
    for joint in model.mechanism.joints:
        if isinstance(joint, Revolute):
            ends = [(joint.link_a, joint.point_a), (joint.link_b, joint.point_b)]
            rows = [labels.index(f"{joint.name}.x"), labels.index(f"{joint.name}.y")]
        else:
            ends = [(joint.link, joint.point)]
            rows = [labels.index(f"{joint.name}.n")]
        for link_name, point in ends:
            if link_name == name:
                loads.append((_abscissa(point, link), -Phi_s[rows, off:off + 2].T @ lam[rows]))
    g = np.asarray(model.mechanism.gravity, dtype=float)
    for mass in model.mechanism.point_masses:
        if mass.link == name:
            xi = _abscissa(mass.point, link)
            loads.append((xi, mass.mass * (g - _rigid_acceleration(s, sdot, sddot, off, xi))))
    return loads


def _rigid_acceleration(s, sdot, sddot, off, xi):
    """Acceleration (2,) of the point at abscissa ``xi`` of a link moving rigidly."""
    theta = s[off + 2]
    e = np.array([math.cos(theta), math.sin(theta)])
    e_perp = np.array([-e[1], e[0]])
    return sddot[off:off + 2] + xi * (sddot[off + 2] * e_perp - sdot[off + 2] ** 2 * e)


def axial_force(model, name: str, s, sdot, sddot, lam, x) -> np.ndarray:
    """Axial force ``N`` (N, tension positive) at abscissae ``x`` (m) of elastic link ``name`` in the
    rigid motion ``s, sdot, sddot`` (n,) with multipliers ``lam`` (r,); returns shape of ``x``."""
    layout = model.layouts[name]
    link = layout.link
    off = layout.offset
    x = np.asarray(x, dtype=float)
    theta = s[off + 2]
    e = np.array([math.cos(theta), math.sin(theta)])
    g = np.asarray(model.mechanism.gravity, dtype=float)
    mu = link.density * link.area
    L = link.length
    # Distributed inertia and gravity beyond x (closed form, module docstring).
    N = mu * ((e @ (g - sddot[off:off + 2])) * (L - x) + sdot[off + 2] ** 2 * (L**2 - x**2) / 2)
    for xi, force in _loads_on_link(model, name, s, sdot, sddot, lam):
        N = N + np.where(x < xi, e @ force, 0.0)
    return N


def geometric_stiffness(model, s, sdot, sddot, lam) -> np.ndarray:
    """``K_G`` (n, n): the geometric stiffness of every link with geometric stiffening on, for the
    rigid motion ``s, sdot, sddot`` (n,) and multipliers ``lam`` (r,)."""
    n = model.n_coords
    K_G = np.zeros((n, n))
    for name, layout in model.layouts.items():
        if layout.shapes is None or not layout.stiffening:
            continue
        x, weights = layout.shapes.quadrature
        slopes = layout.shapes.evaluate(x).dw               # (n_gauss, n_elastic)
        N = axial_force(model, name, s, sdot, sddot, lam, x)
        K_G[layout.elastic, layout.elastic] = slopes.T @ ((weights * N)[:, None] * slopes)
    return K_G


def _abscissa(point, link) -> float:
    if point == "start":
        return 0.0
    if point == "end":
        return float(link.length)
    return float(point)
