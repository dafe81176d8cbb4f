"""Hermite beam finite elements (``Fem``, seed eq. 2.5-2.8), with an optional modal reduction.

``n_elements`` equal Hermite elements: linear axial and cubic transverse interpolation, three DOF
per node ``(u, w, w')``, ordered node by node; removed DOF: ``u0, w0, wN`` for pinned-pinned,
``u0, w0, w'0`` for clamped-free, and every ``u`` when the link has no axial deformation. With
``modes`` the element shapes times the reduction basis (``mechanisms/_reduce.py``): modal
coordinates ``m1 ..`` then static corrections ``c1 ..``, on the element model's quadrature (4 Gauss
points per element, exact for the degree-6 mass integrands and for geometric stiffening, whose
projected membrane strain is constant on an element).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from scipy import sparse

from .._reduce import reduction_basis
from .checks import MAX_ELEMENTS, MAX_MODES, MechanismError, _check_count
from .discretisations import ShapeLayout, ShapeValues, register_discretisation

#: why the mode counts are bounded (``MAX_MODES``)
MODES_LIMIT = "more modes than an Euler-Bernoulli beam describes"

#: The order in the element size ``h`` of the error of a link's quantities on Hermite elements (cubic
#: transverse, linear axial): displacements and what they load (positions, angles, joint forces,
#: drive torques: ``""``, a quantity elsewhere in the mechanism) as ``h^4``, the curvature's moment
#: as ``h^2``, the membrane strain of the linear axial interpolation as ``h``, a stress as its
#: slower part. Measured on four_bar_fem4 at 100 rad/s, 2 to 32 elements: successive error ratios
#: 15-17 for deflections, joint forces and the drive torque, 4.3-5.2 for the moment at midspan,
#: 2.0-3.0 for the strain (docs/methods.md, the mesh term). "multipliers": the Floquet multipliers
#: (a spectral radius, the frequencies) as the eigenvalues of cubics, h^4: ratios 15.8-16.1 at 100,
#: 150 and 185 rad/s.
ELEMENT_ORDERS = {"": 4, "deflection": 4, "transverse": 4, "angle": 4, "point_error_x": 4,
                  "point_error_y": 4, "point_error": 4, "moment": 2, "strain": 1,
                  "stress_top": 1, "stress_bottom": 1, "multipliers": 4}


@register_discretisation
@dataclass(frozen=True)
class Fem:
    """Hermite beam finite elements (seed eq. 2.5-2.8): ``n_elements`` equal elements, three DOF per
    node (axial, transverse, rotation), the link's boundary conditions removed.

    ``modes`` (optional): reduce the element model to its ``modes`` lowest modes under the link's
    boundary conditions plus the static correction modes its joints, drives and point masses and the
    floating frame's distributed inertia load need (``mechanisms._reduce``); the cost then grows with
    the modes, not the elements. ``None`` (the default): the full element model.
    """

    n_elements: int = 1
    modes: int | None = None

    TYPE: ClassVar[str] = "fem"
    KEYS: ClassVar[tuple[str, ...]] = ("type", "n_elements", "modes")
    COUNT_KEYS: ClassVar[tuple[str, ...]] = ("n_elements", "modes")

    #: why the element count is bounded (``MAX_ELEMENTS``)
    LIMIT: ClassVar[str] = "each element adds 3 coordinates, and the matrices grow as their square"

    def __post_init__(self) -> None:
        _check_count("Fem", "n_elements", self.n_elements, 1, MAX_ELEMENTS, self.LIMIT)
        if self.modes is not None:
            _check_count("Fem", "modes", self.modes, 1, MAX_MODES, MODES_LIMIT)

    @classmethod
    def from_table(cls, table) -> "Fem":
        modes = (table.integer("modes", minimum=1, maximum=MAX_MODES, why=MODES_LIMIT)
                 if table.has("modes") else None)
        return cls(table.integer("n_elements", 1, minimum=1, maximum=MAX_ELEMENTS, why=cls.LIMIT),
                   modes)

    def to_table(self) -> dict[str, Any]:
        table = {"type": self.TYPE, "n_elements": self.n_elements}
        if self.modes is not None:
            table["modes"] = self.modes
        return table


    check_boundary: ClassVar[bool] = False     # the removed DOF are the boundary conditions

    def layout(self, link, attachments=None) -> ShapeLayout:
        """The element model's labels and Gauss rule; with ``modes`` its reduction for the loads at
        ``attachments`` (``(x, moment)`` pairs; ``None``: both ends, with moments)."""
        labels, quadrature = _element_layout(link, self)
        if self.modes is None:
            return ShapeLayout(labels, quadrature)
        if attachments is None:
            attachments = ((0.0, True), (link.length, True))
        labels, basis = _reduced(link, tuple((float(x), bool(moment)) for x, moment in attachments))
        return ShapeLayout(labels, quadrature, basis)

    def values(self, link, x: np.ndarray, basis: np.ndarray | None = None) -> ShapeValues:
        return _fem_values(link, self, x, basis)

    def with_modes(self, modes: int | None) -> "Fem":
        """The same element model reduced to ``modes`` modes (``None``: unreduced), the optional
        modal reduction of the interface (``linearize.reduction_error``'s reference)."""
        return Fem(self.n_elements, modes)

    def refined(self) -> "Fem":
        """Twice the elements, the same modes (the optional refinement of the interface: the
        mesh term of the studies' error budget; the reduction's own error is another term)."""
        return Fem(2 * self.n_elements, self.modes)

    def convergence_order(self, quantity: str) -> int | None:
        """The order in the element size of the error of ``quantity`` (``ELEMENT_ORDERS``; 4 for
        a quantity elsewhere in the mechanism, ``""``); None for a quantity it does not know (a
        user's registered one: the mesh term then observes the rate)."""
        return ELEMENT_ORDERS.get(quantity)

    def breakpoints(self, link) -> np.ndarray:
        """The nodes (m), where the elements' curvature jumps (the optional ``breakpoints`` of the
        interface: the linear-range measures look at and just before each)."""
        return np.linspace(0.0, link.length, self.n_elements + 1)


def _element_layout(link, disc: Fem) -> tuple[tuple[str, ...], tuple[np.ndarray, np.ndarray]]:
    """The unreduced element model's labels and its 4 Gauss points per element."""
    labels = tuple(f"{kind}{node}" for node, kind in _fem_kept_dofs(link, disc)[1])
    xg, wg = np.polynomial.legendre.leggauss(4)
    h = link.length / disc.n_elements
    starts = h * np.arange(disc.n_elements)
    x = (starts[:, None] + 0.5 * h * (xg + 1.0)[None, :]).ravel()
    weights = np.tile(0.5 * h * wg, disc.n_elements)
    return labels, (x, weights)


@functools.lru_cache(maxsize=32)
def _reduced(link, attachments: tuple[tuple[float, bool], ...]) -> tuple[tuple[str, ...], np.ndarray]:
    """The labels and reduction basis (``_reduce.reduction_basis``) of ``link``'s element model: its
    eigenmodes plus the static corrections of the loads at ``attachments`` and of the frame's
    distributed axial inertia load ``mu (a + b x)``. Cached by the link and its attachments (a speed
    sweep reduces the same link at every point); the basis is read-only."""
    disc = link.discretisation
    labels, (x, weights) = _element_layout(link, disc)
    modes = disc.modes
    if modes > len(labels):
        raise MechanismError(f"link {link.name!r}: discretisation.modes must be at most the "
                             f"{len(labels)} coordinates of its {disc.n_elements}-element model; "
                             f"received {modes}")
    mass, stiffness = element_matrices(link)
    kinds = np.array([label[0] for label in labels])
    loads = []
    for xa, moment in attachments:
        v = _fem_values(link, disc, np.array([xa]))
        loads += [v.u[0], v.w[0]] + ([v.dw[0]] if moment else [])
    along = _fem_values(link, disc, x)
    loads += [weights @ along.u, (weights * x) @ along.u]
    # displacements at the nodes and the Gauss points normalise the columns (_reduce.reduction_basis)
    nodal = np.eye(len(labels))[kinds != "r"]
    reduction = reduction_basis(mass, stiffness, kinds == "u", modes, np.array(loads).T,
                                np.vstack([nodal, along.u, along.w]))
    reduction.basis.setflags(write=False)
    return reduction.labels, reduction.basis


def _fem_kept_dofs(link, disc: Fem):
    """Indices of the kept DOF in the full node-wise vector ``(u_j, w_j, w'_j)``, and their names."""
    n_nodes = disc.n_elements + 1
    removed = {0, 1} | ({2} if link.boundary == "clamped-free" else {3 * (n_nodes - 1) + 1})
    if not link.axial:
        removed |= {3 * j for j in range(n_nodes)}
    kept = [d for d in range(3 * n_nodes) if d not in removed]
    names = [(d // 3, "uwr"[d % 3]) for d in kept]
    return np.array(kept, dtype=np.int64), names


def _hermite_local(h: float, n_el: int, x: np.ndarray):
    """Each abscissa's element (of ``n_el`` elements of length ``h``, m) and its local shape
    values: ``dofs`` (m, 6) indices of the element's DOF ``(u_i, w_i, w'_i, u_j, w_j, w'_j)`` in the
    full node-wise vector, and ``u, du, w, dw, ddw`` (m, 6) the six local shape functions and their
    derivatives there (seed eq. 2.6 and 2.8)."""
    element = np.minimum((x / h).astype(np.int64), n_el - 1)
    xi = x / h - element
    zero, one = np.zeros_like(xi), np.ones_like(xi)
    xi2, xi3 = xi * xi, xi * xi * xi
    # seed eq. 2.8: linear axial interpolation
    u = np.stack([1.0 - xi, zero, zero, xi, zero, zero], axis=1)
    du = np.stack([-one / h, zero, zero, one / h, zero, zero], axis=1)
    # seed eq. 2.6: cubic Hermite transverse interpolation (w_i, w'_i, w_{i+1}, w'_{i+1})
    w = np.stack([zero, 1.0 - 3.0 * xi2 + 2.0 * xi3, h * (xi - 2.0 * xi2 + xi3),
                  zero, 3.0 * xi2 - 2.0 * xi3, h * (xi3 - xi2)], axis=1)
    dw = np.stack([zero, (6.0 * xi2 - 6.0 * xi) / h, 1.0 - 4.0 * xi + 3.0 * xi2,
                   zero, (6.0 * xi - 6.0 * xi2) / h, 3.0 * xi2 - 2.0 * xi], axis=1)
    ddw = np.stack([zero, (12.0 * xi - 6.0) / h**2, (6.0 * xi - 4.0) / h,
                    zero, (6.0 - 12.0 * xi) / h**2, (6.0 * xi - 2.0) / h], axis=1)
    dofs = 3 * element[:, None] + np.arange(6)[None, :]
    return dofs, (u, du, w, dw, ddw)


def _kept_rows(link, disc: Fem, basis: np.ndarray | None) -> np.ndarray:
    """The map from the full node-wise DOF vector to the link's coordinates, as rows (n_full + 1,
    n): row ``d`` the coordinates DOF ``d`` contributes to (a unit row for a kept DOF, the reduction
    basis's row when reduced, zeros for a removed DOF); the last row is unused padding."""
    kept, _ = _fem_kept_dofs(link, disc)
    columns = len(kept) if basis is None else basis.shape[1]
    rows = np.zeros((3 * (disc.n_elements + 1), columns))
    rows[kept] = np.eye(len(kept)) if basis is None else basis
    return rows


def _fem_values(link, disc: Fem, x: np.ndarray, basis=None) -> ShapeValues:
    """Element shapes at ``x`` (m,), each (m, n_kept), or times ``basis`` (n_kept, n) when reduced.
    Each point touches its element's six DOF only: the rows are gathered, not a dense product."""
    dofs, local = _hermite_local(link.length / disc.n_elements, disc.n_elements, x)
    if basis is None:
        kept, _ = _fem_kept_dofs(link, disc)
        column = np.full(3 * (disc.n_elements + 1), len(kept))   # removed DOF: a padding column
        column[kept] = np.arange(len(kept))
        rows = np.arange(len(x))[:, None]
        values = []
        for part in local:
            out = np.zeros((len(x), len(kept) + 1))
            out[rows, column[dofs]] = part     # an element's six DOF are distinct: no sums
            values.append(out[:, :-1])
        return ShapeValues(*values)
    gathered = _kept_rows(link, disc, basis)[dofs]              # (m, 6, n)
    return ShapeValues(*(np.einsum("ml,mln->mn", part, gathered) for part in local))


def element_matrices(link):
    """The unreduced ``Fem`` link's mass and stiffness matrices (``beam_matrices`` of its element
    model: the same integrals, the same Gauss rule) as sparse CSC matrices (n_kept, n_kept), kg and
    N/m, assembled element by element without a dense matrix or a Python loop over elements:
    every element is the same, so its 6 x 6 matrices are integrated once and scattered."""
    disc = link.discretisation
    h = link.length / disc.n_elements
    xg, wg = np.polynomial.legendre.leggauss(4)
    x = 0.5 * h * (xg + 1.0)
    weights = 0.5 * h * wg
    _, (u, du, w, dw, ddw) = _hermite_local(h, 1, x)

    def gram(a):
        return a.T @ (weights[:, None] * a)

    mass = link.density * link.area * (gram(u) + gram(w))
    if link.rotary_inertia:
        mass = mass + link.density * link.second_moment * gram(dw)
    stiffness = link.youngs_modulus * (link.area * gram(du) + link.second_moment * gram(ddw))
    dofs = 3 * np.arange(disc.n_elements)[:, None] + np.arange(6)[None, :]   # (n_el, 6)
    rows = np.repeat(dofs, 6, axis=1).ravel()
    cols = np.tile(dofs, (1, 6)).ravel()
    full = 3 * (disc.n_elements + 1)
    kept, _ = _fem_kept_dofs(link, disc)
    matrices = []
    for element in (mass, stiffness):
        data = np.tile(element.ravel(), disc.n_elements)
        assembled = sparse.csr_matrix((data, (rows, cols)), shape=(full, full))  # sums duplicates
        matrices.append(sparse.csc_matrix(assembled[kept][:, kept]))
    return tuple(matrices)
