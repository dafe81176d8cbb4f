"""Shape functions of an elastic link and its own mass and stiffness matrices.

An elastic link (``ElasticLink``) is an Euler-Bernoulli beam in a floating frame (see ``_parts``).
Its displacement field relative to the frame is ``u(x) = Su(x) q`` (axial) and ``w(x) = Sw(x) q``
(transverse), ``q`` the link's ``n_elastic`` elastic coordinates. This module builds ``Su, Sw`` and
their derivatives for the three discretisations (seed eq. 2.1-2.8):

* ``Ritz``: pinned-pinned bending ``sin(i pi x / L)`` (eq. 2.2), axial ``sin((2k-1) pi x / (2L))``
  (eq. 2.4); for ``boundary="clamped-free"`` the clamped-free beam eigenfunctions
  ``cosh bx - cos bx - sigma (sinh bx - sin bx)``, ``cos bL cosh bL = -1``. Bending coordinates
  first, then axial.
* ``UserShapes``: the user's callables, bending first, then axial.
* ``Fem``: ``n_elements`` equal Hermite elements (eq. 2.5-2.8): linear axial and cubic transverse
  interpolation, three DOF per node ``(u, w, w')``, ordered node by node; removed DOF: ``u0, w0, wN``
  for pinned-pinned, ``u0, w0, w'0`` for clamped-free, and every ``u`` when the link has no axial
  deformation. With ``modes`` the element shapes times the reduction basis (``_reduce``): modal
  coordinates ``m1 ..`` then static corrections ``c1 ..``, on the element model's quadrature.

Integrals along the link use Gauss-Legendre quadrature (``BeamShapes.quadrature``): per element
4 points for FEM, exact for the degree-6 mass integrands and for geometric stiffening too, whose
projected membrane strain (``membrane_projection``) is constant on an element and needs the element
integrals of ``w'^2`` (degree 4). Ritz and user shapes are not polynomials: the number of points is
doubled until the Gram integrals of all shapes and derivatives and the cubic integrals
``int u_k' w_i' w_j'`` (the projection of ``w'^2/2``) agree to 1e-14 relative, and the smaller rule
that already agrees is kept.

Geometric stiffening uses the *projected* membrane strain (assumed strain, "B-bar"):
``eps(x) = Su'(x) q + P[w'^2/2](x)``, ``P`` the L2 projection onto span{Su'_i}. The pointwise
``u' + w'^2/2`` locks: ``u'`` (linear FEM or Ritz axial modes) cannot represent ``w'^2/2``, so any
bending would stretch the chord and over-stiffen the link (membrane locking).
"""

from __future__ import annotations

import functools
import logging
import math
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import brentq

from ._parts import ArgumentError, ElasticLink, Fem, MechanismError, Ritz, UserShapes
from ._reduce import reduction_basis

logger = logging.getLogger(__name__)

_BOUNDARIES = ("pinned-pinned", "clamped-free")
_QUADRATURE_RTOL = 1e-14
_MAX_GAUSS_POINTS = 512


@dataclass(frozen=True)
class ShapeValues:
    """Shape functions at ``m`` abscissae, each (m, n_elastic): axial ``u, du`` (value and d/dx),
    transverse ``w, dw, ddw`` (value, slope, curvature). Units: 1, 1/m, 1/m^2 per unit coordinate."""

    u: np.ndarray
    du: np.ndarray
    w: np.ndarray
    dw: np.ndarray
    ddw: np.ndarray


@dataclass(frozen=True)
class BeamShapes:
    """The discretised displacement field of one elastic link.

    ``labels`` name the elastic coordinates (without the link name); ``quadrature`` is
    ``(x, weights)``, arrays (n_gauss,) in m, for integrals along the link. ``basis``
    (n_element_dofs, n_elastic): a reduced ``Fem`` link's reduction basis (``_reduce``), its shapes
    the element shapes times it; ``None`` otherwise.
    """

    link: ElasticLink
    labels: tuple[str, ...]
    quadrature: tuple[np.ndarray, np.ndarray]
    basis: np.ndarray | None = None

    @property
    def reduced(self) -> bool:
        """The link is a modally reduced element model (``Fem(..., modes=k)``)."""
        return self.basis is not None

    @property
    def n_elastic(self) -> int:
        return len(self.labels)

    def evaluate(self, x) -> ShapeValues:
        """Shape functions at abscissae ``x`` (m, in ``[0, length]``), arrays (m, n_elastic)."""
        x = np.atleast_1d(np.asarray(x, dtype=float))
        length = self.link.length
        if x.ndim != 1 or not np.all(np.isfinite(x)) or np.any(x < -1e-12 * length) or np.any(
                x > length * (1 + 1e-12)):
            raise ArgumentError(f"x must be finite abscissae in [0, {length}] m on link "
                             f"{self.link.name!r}; received {x!r}")
        x = np.clip(x, 0.0, length)  # only round-off beyond the ends (checked above) is clipped
        disc = self.link.discretisation
        if isinstance(disc, Fem):
            return _fem_values(self.link, disc, x, self.basis)
        return _ritz_values(self.link, x)


def beam_shapes(link: ElasticLink, *, attachments=None) -> BeamShapes:
    """Shape functions and quadrature of ``link``; raises ``ValueError`` on bad options.

    ``attachments``: for a reduced ``Fem`` link (``modes`` given), the points where the mechanism
    loads the link, ``(x, moment)`` pairs (abscissa in m, and whether a moment acts there: a drive),
    which choose its static correction modes (``_reduce``); ``None``: both ends, with moments (what
    a link pinned at its ends can carry). Other discretisations ignore it.
    """
    if link.boundary not in _BOUNDARIES:
        raise MechanismError(f"link {link.name!r}: boundary must be one of {_BOUNDARIES}; "
                         f"received {link.boundary!r}")
    for key in ("length", "density", "youngs_modulus", "area", "second_moment"):
        value = getattr(link, key)
        if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
            raise MechanismError(f"link {link.name!r}: {key} must be a positive finite number; "
                             f"received {value!r}")
    disc = link.discretisation
    if isinstance(disc, Fem):
        if not (isinstance(disc.n_elements, int) and disc.n_elements >= 1):
            raise MechanismError(f"link {link.name!r}: Fem.n_elements must be an integer >= 1; "
                             f"received {disc.n_elements!r}")
        if disc.modes is None:
            return _element_model(link)
        if attachments is None:
            attachments = ((0.0, True), (link.length, True))
        return _reduced(link, tuple((float(x), bool(moment)) for x, moment in attachments))
    if isinstance(disc, Ritz):
        if not (isinstance(disc.n_bending, int) and disc.n_bending >= 0
                and isinstance(disc.n_axial, int) and disc.n_axial >= 0):
            raise MechanismError(f"link {link.name!r}: Ritz.n_bending and Ritz.n_axial must be "
                             f"integers >= 0; received {disc!r}")
        n_axial = disc.n_axial if link.axial else 0
        labels = tuple(f"b{i + 1}" for i in range(disc.n_bending)) + tuple(
            f"a{k + 1}" for k in range(n_axial))
    elif isinstance(disc, UserShapes):
        for kind in ("bending", "axial"):
            if not all(callable(f) for f in getattr(disc, kind)):
                raise MechanismError(f"link {link.name!r}: UserShapes.{kind} must hold callables "
                                f"f(x, length) -> (value, d/dx, d2/dx2)")
        n_axial = len(disc.axial) if link.axial else 0
        labels = tuple(f"b{i + 1}" for i in range(len(disc.bending))) + tuple(
            f"a{k + 1}" for k in range(n_axial))
    else:
        raise MechanismError(f"link {link.name!r}: discretisation must be Ritz, UserShapes or Fem; "
                        f"received {type(disc).__name__}")
    shapes = BeamShapes(link, labels, (np.zeros(0), np.zeros(0)))
    shapes = BeamShapes(link, labels, _adaptive_quadrature(shapes))
    if isinstance(disc, UserShapes):
        _check_user_boundary(shapes)
    return shapes


def beam_matrices(shapes: BeamShapes) -> tuple[np.ndarray, np.ndarray]:
    """The link's own mass and linear stiffness matrices, each (n_elastic, n_elastic).

    ``M = int mu (Su^T Su + Sw^T Sw) dx (+ int rho I Sw'^T Sw' dx with rotary inertia)``,
    ``K = int EA Su'^T Su' + EI Sw''^T Sw'' dx`` (seed eq. 2.13, frame held fixed); kg and N/m.
    """
    link = shapes.link
    x, weights = shapes.quadrature
    v = shapes.evaluate(x)
    mu = link.density * link.area
    mass = mu * (v.u.T @ (weights[:, None] * v.u) + v.w.T @ (weights[:, None] * v.w))
    if link.rotary_inertia:
        mass += link.density * link.second_moment * (v.dw.T @ (weights[:, None] * v.dw))
    stiffness = (link.youngs_modulus * link.area * (v.du.T @ (weights[:, None] * v.du))
                 + link.youngs_modulus * link.second_moment * (v.ddw.T @ (weights[:, None] * v.ddw)))
    return 0.5 * (mass + mass.T), 0.5 * (stiffness + stiffness.T)


def membrane_projection(shapes: BeamShapes) -> np.ndarray | None:
    """The L2 projection onto the link's axial strain functions, as ``R`` (n_elastic, n_gauss).

    For values ``f_g`` of a function at the Gauss points, ``P f (x) = Su'(x) . (R f)`` is its
    projection onto span{Su'_i}; at the Gauss points ``P = B R``, ``B = Su'(x_g)``. With ``W`` the
    weights, ``R = (B^T W B)^+ B^T W``, computed from the SVD ``W^1/2 B = U S V^T`` as
    ``V S^-1 U^T W^1/2`` (so ``P = W^-1/2 U U^T W^1/2``, W-orthogonal even when the functions are
    dependent). Singular values below 1e-10 of the largest count as dependent directions. ``None``
    when the link has no axial coordinates (nothing to project onto).
    """
    x, weights = shapes.quadrature
    root = np.sqrt(weights)
    u, sigma, vt = np.linalg.svd(root[:, None] * shapes.evaluate(x).du, full_matrices=False)
    if sigma.size == 0 or sigma[0] == 0.0:
        return None
    rank = int(np.sum(sigma > 1e-10 * sigma[0]))
    n_axial = int(np.sum(np.any(shapes.evaluate(x).du != 0.0, axis=0)))
    if rank < n_axial:
        logger.warning("link %r: its %d axial strain functions span only %d dimensions (singular "
                       "values below 1e-10 of the largest); the membrane strain is projected onto "
                       "that span", shapes.link.name, n_axial, rank)
    return (vt[:rank].T / sigma[:rank]) @ (u[:, :rank].T * root[None, :])


def _element_model(link: ElasticLink) -> BeamShapes:
    """The Hermite element shapes of a ``Fem`` link (unreduced): labels and 4 Gauss points per
    element."""
    disc = link.discretisation
    labels = tuple(f"{kind}{node}" for node, kind in _fem_kept_dofs(link, disc)[1])
    xg, wg = np.polynomial.legendre.leggauss(4)
    h = link.length / disc.n_elements
    starts = h * np.arange(disc.n_elements)
    x = (starts[:, None] + 0.5 * h * (xg + 1.0)[None, :]).ravel()
    weights = np.tile(0.5 * h * wg, disc.n_elements)
    return BeamShapes(link, labels, (x, weights))


@functools.lru_cache(maxsize=32)
def _reduced(link: ElasticLink, attachments: tuple[tuple[float, bool], ...]) -> BeamShapes:
    """The element model of ``link`` reduced (``_reduce.reduction_basis``): its eigenmodes plus the
    static corrections of the loads at ``attachments`` and of the frame's distributed axial inertia
    load ``mu (a + b x)``. Cached by the link and its attachments (a speed sweep reduces the same
    link at every point); the basis is read-only."""
    element_model = _element_model(link)
    modes = link.discretisation.modes
    if modes > element_model.n_elastic:
        raise MechanismError(f"link {link.name!r}: discretisation.modes must be at most the "
                             f"{element_model.n_elastic} coordinates of its "
                             f"{link.discretisation.n_elements}-element model; received {modes}")
    mass, stiffness = element_matrices(link)
    kinds = np.array([label[0] for label in element_model.labels])
    loads = []
    for x, moment in attachments:
        v = element_model.evaluate([x])
        loads += [v.u[0], v.w[0]] + ([v.dw[0]] if moment else [])
    x, weights = element_model.quadrature
    u = element_model.evaluate(x).u
    loads += [weights @ u, (weights * x) @ u]
    reduction = reduction_basis(mass, stiffness, kinds == "u", modes,
                                np.array(loads).T, kinds != "r")
    reduction.basis.setflags(write=False)
    return BeamShapes(link, reduction.labels, element_model.quadrature, reduction.basis)


# ---------------------------------------------------------------------------------------------------
# Ritz and user shapes
# ---------------------------------------------------------------------------------------------------
def clamped_free_roots(n: int) -> np.ndarray:
    """The first ``n`` roots ``beta L`` of ``cos(b) cosh(b) = -1`` (1.8751, 4.6941, ...)."""
    def f(b):
        return math.cos(b) + 1.0 / math.cosh(b)  # same roots, no overflow
    return np.array([brentq(f, (i - 1) * math.pi + 1e-3, i * math.pi, xtol=1e-15, rtol=1e-15)
                     for i in range(1, n + 1)])


def _clamped_free_mode(x: np.ndarray, beta: float, length: float):
    """Clamped-free eigenfunction ``cosh bx - cos bx - sigma (sinh bx - sin bx)`` and two
    derivatives, written with decaying exponentials so that high modes do not cancel."""
    bl = beta * length
    denominator = math.sinh(bl) + math.sin(bl)
    sigma = (math.cosh(bl) + math.cos(bl)) / denominator
    one_minus_sigma = (math.sin(bl) - math.cos(bl) - math.exp(-bl)) / denominator
    bx = beta * x
    grow = 0.5 * one_minus_sigma * np.exp(bx)      # e^{bx} (1 - sigma) / 2
    decay = 0.5 * (1.0 + sigma) * np.exp(-bx)      # e^{-bx} (1 + sigma) / 2
    value = decay + grow - np.cos(bx) + sigma * np.sin(bx)
    slope = beta * (grow - decay + np.sin(bx) + sigma * np.cos(bx))
    curvature = beta**2 * (grow + decay + np.cos(bx) - sigma * np.sin(bx))
    return value, slope, curvature


def _ritz_values(link: ElasticLink, x: np.ndarray) -> ShapeValues:
    disc = link.discretisation
    length = link.length
    bending, axial = [], []
    if isinstance(disc, Ritz):
        if link.boundary == "pinned-pinned":
            for i in range(1, disc.n_bending + 1):
                k = i * math.pi / length
                bending.append((np.sin(k * x), k * np.cos(k * x), -k * k * np.sin(k * x)))
        else:
            for beta_l in clamped_free_roots(disc.n_bending):
                bending.append(_clamped_free_mode(x, beta_l / length, length))
        if link.axial:
            for j in range(1, disc.n_axial + 1):
                k = (2 * j - 1) * math.pi / (2 * length)
                axial.append((np.sin(k * x), k * np.cos(k * x), -k * k * np.sin(k * x)))
    else:
        bending = [_call_user(f, x, link, "bending", i) for i, f in enumerate(disc.bending)]
        if link.axial:
            axial = [_call_user(f, x, link, "axial", i) for i, f in enumerate(disc.axial)]
    m, nb, na = len(x), len(bending), len(axial)
    u, du, w, dw, ddw = (np.zeros((m, nb + na)) for _ in range(5))
    for i, (value, slope, curvature) in enumerate(bending):
        w[:, i], dw[:, i], ddw[:, i] = value, slope, curvature
    for j, (value, slope, _) in enumerate(axial):
        u[:, nb + j], du[:, nb + j] = value, slope
    return ShapeValues(u, du, w, dw, ddw)


def _call_user(f, x, link, kind, index):
    result = f(x, link.length)
    try:
        arrays = tuple(np.broadcast_to(np.asarray(a, dtype=float), x.shape) for a in result)
    except (TypeError, ValueError) as error:
        raise MechanismError(f"link {link.name!r}: UserShapes.{kind}[{index}] must return "
                         f"(value, d/dx, d2/dx2), arrays shaped like x") from error
    if len(arrays) != 3 or not all(np.all(np.isfinite(a)) for a in arrays):
        raise MechanismError(f"link {link.name!r}: UserShapes.{kind}[{index}] must return three "
                         f"finite arrays (value, d/dx, d2/dx2)")
    return arrays


def _check_user_boundary(shapes: BeamShapes) -> None:
    """User shapes must keep the frame's meaning: ``u(0) = w(0) = 0`` and ``w(L) = 0``
    (pinned-pinned) or ``w'(0) = 0`` (clamped-free), to 1e-10 of the shape's largest value."""
    link = shapes.link
    inner = shapes.evaluate(shapes.quadrature[0])
    ends = shapes.evaluate([0.0, link.length])
    checks = [("u(0)", ends.u[0], inner.u), ("w(0)", ends.w[0], inner.w)]
    if link.boundary == "pinned-pinned":
        checks.append(("w(L)", ends.w[1], inner.w))
    else:
        checks.append(("w'(0)", ends.dw[0], inner.dw))
    for name, at_end, values in checks:
        scale = np.max(np.abs(values), axis=0)
        bad = np.flatnonzero(np.abs(at_end) > 1e-10 * scale)
        if bad.size:
            raise MechanismError(f"link {link.name!r}: user shape {shapes.labels[bad[0]]} has "
                             f"{name} = {at_end[bad[0]]:.3g}, but a {link.boundary} link needs "
                             f"{name} = 0 (see mechanisms._parts for the frame conventions)")


def _quadrature_integrals(shapes: BeamShapes, n: int) -> np.ndarray:
    xg, wg = np.polynomial.legendre.leggauss(n)
    length = shapes.link.length
    x, weights = 0.5 * length * (xg + 1.0), 0.5 * length * wg
    v = shapes.evaluate(x)
    features = np.hstack([v.u, v.du, v.w, v.dw, v.ddw])
    gram = features.T @ (weights[:, None] * features)
    cubic = np.einsum("g,gk,gi,gj->kij", weights, v.du, v.dw, v.dw)
    # Cauchy-Schwarz: |int u_k' w_i' w_j'| <= (int u_k'^2 w_i'^2)^1/2 (int w_j'^2)^1/2, a bound made
    # of smooth integrals (converging with the rule, unlike int |u_k' w_i' w_j'|)
    cubic_bound = (np.sqrt(np.einsum("g,gk,gi->ki", weights, v.du**2, v.dw**2))[:, :, None]
                   * np.sqrt(weights @ v.dw**2)[None, None, :])
    # scale each integral by its Cauchy-Schwarz bound so that small entries are held to 1e-14 too
    diag = np.sqrt(np.abs(np.diag(gram)))
    scale = np.outer(diag, diag) + np.finfo(float).tiny
    return np.concatenate([(gram / scale).ravel(), (cubic / (cubic_bound + 1e-300)).ravel()])


def _adaptive_quadrature(shapes: BeamShapes) -> tuple[np.ndarray, np.ndarray]:
    n = 8
    previous = _quadrature_integrals(shapes, n)
    while True:
        if 2 * n > _MAX_GAUSS_POINTS:
            raise MechanismError(f"link {shapes.link.name!r}: the shape-function integrals do not "
                             f"converge with {_MAX_GAUSS_POINTS} Gauss points; are the user shapes "
                             f"smooth?")
        current = _quadrature_integrals(shapes, 2 * n)
        if np.max(np.abs(current - previous)) <= _QUADRATURE_RTOL * 10:
            break
        n, previous = 2 * n, current
    xg, wg = np.polynomial.legendre.leggauss(n)
    length = shapes.link.length
    return 0.5 * length * (xg + 1.0), 0.5 * length * wg


# ---------------------------------------------------------------------------------------------------
# Hermite finite elements
# ---------------------------------------------------------------------------------------------------
def _fem_kept_dofs(link: ElasticLink, disc: Fem):
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


def _kept_rows(link: ElasticLink, disc: Fem, basis: np.ndarray | None) -> np.ndarray:
    """The map from the full node-wise DOF vector to the link's coordinates, as rows (n_full + 1,
    n): row ``d`` the coordinates DOF ``d`` contributes to (a unit row for a kept DOF, the reduction
    basis's row when reduced, zeros for a removed DOF); the last row is unused padding."""
    kept, _ = _fem_kept_dofs(link, disc)
    columns = len(kept) if basis is None else basis.shape[1]
    rows = np.zeros((3 * (disc.n_elements + 1), columns))
    rows[kept] = np.eye(len(kept)) if basis is None else basis
    return rows


def _fem_values(link: ElasticLink, disc: Fem, x: np.ndarray, basis=None) -> ShapeValues:
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


def element_matrices(link: ElasticLink):
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
