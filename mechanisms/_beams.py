"""Shape functions of an elastic link and its own mass and stiffness matrices.

An elastic link (``ElasticLink``) is an Euler-Bernoulli beam in a floating frame (see ``_parts``).
Its displacement field relative to the frame is ``u(x) = Su(x) q`` (axial) and ``w(x) = Sw(x) q``
(transverse), ``q`` the link's ``n_elastic`` elastic coordinates. The shapes ``Su, Sw`` and their
derivatives are the link's discretisation's (``mechanisms/_parts/discretisations.py``: ``Fem``,
``Ritz``, ``UserShapes`` and any registered one carry their own); this module asks it for them and
never which one it is: ``BeamShapes`` holds what the discretisation laid out (labels, quadrature,
basis) and evaluates its shapes; the link's own matrices, the membrane projection and the Gauss
rule of shapes that are not polynomials follow from the shapes alone.

Integrals along the link use Gauss-Legendre quadrature (``BeamShapes.quadrature``): the
discretisation's own rule when it gives one (per element 4 points for FEM, exact for the degree-6
mass integrands and for geometric stiffening too, whose projected membrane strain
(``membrane_projection``) is constant on an element and needs the element integrals of ``w'^2``
(degree 4)). Otherwise (Ritz and user shapes are not polynomials) the number of points is
doubled until the Gram integrals of all shapes and derivatives and the cubic integrals
``int u_k' w_i' w_j'`` (the projection of ``w'^2/2``) agree to 1e-14 relative, and the smaller rule
that already agrees is kept.

Geometric stiffening uses the *projected* membrane strain (assumed strain, "B-bar"):
``eps(x) = Su'(x) q + P[w'^2/2](x)``, ``P`` the L2 projection onto span{Su'_i}. The pointwise
``u' + w'^2/2`` locks: ``u'`` (linear FEM or Ritz axial modes) cannot represent ``w'^2/2``, so any
bending would stretch the chord and over-stiffen the link (membrane locking).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from ._parts import ArgumentError, ElasticLink, MechanismError, ShapeValues

logger = logging.getLogger(__name__)

_QUADRATURE_RTOL = 1e-14
_MAX_GAUSS_POINTS = 512


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
        return self.link.discretisation.values(self.link, x, self.basis)


def beam_shapes(link: ElasticLink, *, attachments=None) -> BeamShapes:
    """Shape functions and quadrature of ``link`` (its discretisation's ``layout``); raises
    ``MechanismError`` on bad options or shapes that break the link's boundary conditions.

    ``attachments``: for a reduced ``Fem`` link (``modes`` given), the points where the mechanism
    loads the link, ``(x, moment)`` pairs (abscissa in m, and whether a moment acts there: a drive),
    which choose its static correction modes (``_reduce``); ``None``: both ends, with moments (what
    a link pinned at its ends can carry). Other discretisations ignore it.
    """
    disc = link.discretisation
    layout = disc.layout(link, attachments)
    labels = tuple(layout.labels)
    if layout.quadrature is not None:
        shapes = BeamShapes(link, labels, layout.quadrature, layout.basis)
    else:
        shapes = BeamShapes(link, labels, (np.zeros(0), np.zeros(0)), layout.basis)
        shapes = BeamShapes(link, labels, _adaptive_quadrature(shapes), layout.basis)
    if disc.check_boundary:
        _check_boundary(shapes)
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


def _check_boundary(shapes: BeamShapes) -> None:
    """Shapes must keep the frame's meaning: ``u(0) = w(0) = 0`` and ``w(L) = 0``
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
            raise MechanismError(f"link {link.name!r}: {link.discretisation.TYPE} shape "
                                 f"{shapes.labels[bad[0]]} has {name} = {at_end[bad[0]]:.3g}, but a "
                                 f"{link.boundary} link needs {name} = 0 (see mechanisms._parts "
                                 f"for the frame conventions)")


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
