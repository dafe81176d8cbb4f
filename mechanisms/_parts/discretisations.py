"""Discretisations of an elastic link (``ElasticLink.discretisation``): the registry and what a
discretisation declares.

A discretisation is a frozen class that carries its shape functions and checks; nothing else in
``mechanisms`` or ``linearize`` asks which one a link has (mass, stiffness, stiffening, damping, the
observables and the linear-range measures all follow from the shapes). It declares:

* ``TYPE`` (its scene-file ``type``), ``KEYS`` (its scene-table keys, ``"type"`` among them),
  ``from_table(table)`` and ``to_table()`` (the scene file both ways; ``table`` reads keys with
  their units and checks, ``mechanisms/_parts/table.py``), so that a mechanism using it reaches every
  study, the result file, the resume identity and the worker pool through its scene text;
* ``layout(link, attachments) -> ShapeLayout``: the names of the link's elastic coordinates and,
  optionally, the Gauss rule along the link (``None``: one is found by doubling the points until
  the shapes' integrals converge, ``_beams``) and a basis the shapes are multiplied by;
  ``attachments`` are the ``(x, moment)`` where the mechanism loads the link (a reduced model's
  static corrections need them; others ignore them); bad options raise ``MechanismError``;
* ``values(link, x, basis) -> ShapeValues``: the shapes and their derivatives at abscissae ``x``
  (m, (m,)), each (m, n_elastic);
* ``check_boundary`` (class attribute): whether ``_beams`` checks the shapes' values at the ends
  against the link's boundary conditions (``u(0) = w(0) = 0``, and ``w(L) = 0`` or ``w'(0) = 0``);
  ``False`` for shapes exact by construction;
* optionally ``breakpoints(link)``: abscissae (m, evenly spaced, the ends included) where the
  shapes' curvature may jump (element nodes), where the linear-range measures look too.
* optionally a modal reduction: ``modes`` (the reduced model's mode count, ``None`` when unreduced)
  and ``with_modes(modes)`` (the same discretisation with another mode count, ``None``: unreduced),
  which ``linearize.reduction_error`` uses to solve the reference with more modes;
* ``COUNT_KEYS`` (class attribute, optional, default none): the scene-table keys that are counts
  (elements, modes), which a study sweeping or optimising them rounds to integers;
* optionally a refinement, which the studies' mesh term of the error budget reads
  (``studies/_mesh_error.py``): ``refined()``, the same discretisation one level finer (``Fem``:
  twice the elements, the same modes; ``Ritz``: two more bending and two more axial modes; a
  count past its limit raises ``MechanismError``), and ``convergence_order(quantity)``, the order
  ``p`` in the element size ``h`` of the error of ``quantity`` when ``refined()`` halves ``h``
  (``quantity``: the name of an observable's quantity on this link, ``"deflection"``,
  ``"moment"``, ..., or ``""`` for one elsewhere: a joint force, another link's point), ``None``
  when not known. Without ``refined`` the mesh term is unknown for the link's mechanism; without
  ``convergence_order``, or where it says ``None`` (a refinement that adds modes has no ``h``),
  the mesh term observes the rate from three levels (``refined().refined()``).

``register_discretisation(cls)`` enters a class in ``DISCRETISATION_TYPES``; ``Fem`` (the default
of a scene), ``Ritz`` and ``UserShapes`` register themselves in their modules (``fem``, ``ritz``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .checks import register_class

#: The discretisations a scene file can name, by ``type``; filled by ``register_discretisation``.
DISCRETISATION_TYPES: dict[str, type] = {}
#: The ``type`` of a scene's elastic link without one.
DEFAULT_DISCRETISATION = "fem"

_INTERFACE = ("TYPE", "KEYS", "from_table", "to_table", "layout", "values", "check_boundary")

Discretisation = Any


@dataclass(frozen=True)
class ShapeValues:
    """Shape functions at ``m`` abscissae, each (m, n_elastic): axial ``u, du`` (value and d/dx),
    transverse ``w, dw, ddw`` (value, slope, curvature). Units: 1, 1/m, 1/m^2 per unit coordinate."""

    u: np.ndarray
    du: np.ndarray
    w: np.ndarray
    dw: np.ndarray
    ddw: np.ndarray

    @classmethod
    def from_functions(cls, bending, axial) -> "ShapeValues":
        """Bending coordinates first, then axial: ``bending`` and ``axial`` are sequences of
        ``(value, d/dx, d2/dx2)`` arrays (m,), one per coordinate (the axial second derivative is
        not used)."""
        bending, axial = list(bending), list(axial)
        m = len(bending[0][0]) if bending else len(axial[0][0]) if axial else 0
        nb, na = len(bending), len(axial)
        u, du, w, dw, ddw = (np.zeros((m, nb + na)) for _ in range(5))
        for i, (value, slope, curvature) in enumerate(bending):
            w[:, i], dw[:, i], ddw[:, i] = value, slope, curvature
        for j, (value, slope, _) in enumerate(axial):
            u[:, nb + j], du[:, nb + j] = value, slope
        return cls(u, du, w, dw, ddw)


@dataclass(frozen=True)
class ShapeLayout:
    """What a discretisation makes of a link: ``labels`` of its elastic coordinates (without the
    link name), ``quadrature`` ``(x (m), weights (m))`` along it or ``None`` (found adaptively),
    ``basis`` (n_shapes, n_elastic) the shapes are multiplied by (a reduced element model) or
    ``None``."""

    labels: tuple[str, ...]
    quadrature: tuple[np.ndarray, np.ndarray] | None = None
    basis: np.ndarray | None = None


def bending_and_axial_labels(n_bending: int, n_axial: int) -> tuple[str, ...]:
    """``b1 .. b<n_bending>, a1 .. a<n_axial>``: the labels of a Ritz-type basis."""
    return tuple(f"b{i + 1}" for i in range(n_bending)) + tuple(f"a{k + 1}" for k in range(n_axial))


def register_discretisation(cls: type) -> type:
    """Enter the discretisation class ``cls`` in ``DISCRETISATION_TYPES`` under its ``TYPE`` and
    return it (usable as a class decorator). ``cls`` declares the interface of the module
    docstring; a ``TYPE`` already taken by another class is refused (``MechanismError``)."""
    return register_class(DISCRETISATION_TYPES, cls, _INTERFACE, "discretisation", "mechanisms.Ritz")
