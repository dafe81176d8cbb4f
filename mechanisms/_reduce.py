"""Modal reduction of an elastic link's finite-element model, and the few equivalent points that
let the kernels evaluate a reduced link at a cost set by its modes, not its elements.

The reduction (``Fem(n_elements, modes=k)``) is a Ritz basis ``T`` (n_full, n) of the element model's
kept coordinates (``_beams``: the link's boundary conditions already removed), so the reduced link's
shape functions are ``S(x) T``: everything downstream (mass, stiffness, stiffening, damping,
observables, linear-range measures) follows from the shapes unchanged. ``T`` holds

* the ``k`` lowest eigenmodes of the element model, ``K phi = omega^2 M phi`` under the link's
  boundary conditions (the floating frame's: chord frame for pinned-pinned, tangent frame for
  clamped-free), axial and bending by frequency; labels ``m1 .. mk``;
* static correction modes ``K^-1 F`` (residual flexibility, the "attachment modes" of MacNeal and
  Rubin, the counterpart of Craig-Bampton's constraint modes in a frame that already holds the
  link's supports): ``F`` the load vectors of the concentrated loads the link carries (each joint
  end on the link: axial and transverse force at its point; each drive at a joint of the link: the
  moment there; each point mass: its force, and moment with rotary inertia) and of the floating
  frame's distributed axial inertia load ``mu (a + b x)`` (the rigid motion's acceleration along the
  link, uniform plus linear in ``x``), whose static response no low mode carries when no axial mode
  is among the lowest (axial modes of a slender link lie far above its bending modes). They are
  made mass- and stiffness-orthogonal to the eigenmodes and to each other (Rayleigh-Ritz on the
  correction space); labels ``c1 ..``.

Every column is normalised to a largest displacement of 1 along the link (sampled at the nodes and at
the element model's Gauss points), so a coordinate is a displacement amplitude in metres. The nodes
alone do not do: an eigenmode of a pinned-pinned link of n elements whose wave number is a multiple
of n (the n-th bending mode, ``sin(n pi x / L)``) has every nodal displacement zero to round-off,
and dividing by that round-off scaled its column by ~1e16, which made the reduced mass matrix
numerically singular (issue 23: 4 elements with 2 or more modes, 8 with 8).

Equivalent points. A reduced link's shape rows are dense (every mode is nonzero along the whole
link), so its 4 n_elements Gauss points would each cost ``n^2`` in the kernels. They are replaced by
fewer points that give the *same* sums to round-off (``_kernels`` module docstring for the tables):

* mass points: every inertia quantity is a sum over points of ``m`` times a quadratic form in the
  point's features ``z = (1, cx, Su, Sw)``, so only the Gram matrix ``G = sum m_g z_g z_g^T``
  matters. Factor ``G = F F^T`` (rank r) and rotate ``F`` by a Householder reflection so that its
  first row is constant: the columns are r points of equal mass ``m_total / r`` with first feature 1.
  Rotary inertia likewise, with features ``(1, Sw')`` and the weights ``rho I w_g``.
* strain points: with the projected membrane strain (``_beams.membrane_projection``,
  ``sqrt(W) Su' = U S V^T``) the strain energy is ``EA/2 sum_k c_k^2`` with
  ``c_k = S_k V_k . q + 1/2 q^T H_k q``, ``H_k = sum_g U_gk sqrt(w_g) Sw'_g^T Sw'_g``: one strain
  point per axial direction k whose projection row reads the eigenpairs of ``H_k`` as slope points;
  the bending energy ``1/2 q^T K_b q`` is carried by the eigenpairs of ``K_b`` as curvature rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.linalg import cho_factor, cho_solve, eigh
from scipy.sparse.linalg import LinearOperator, eigsh, splu

#: Relative size below which an eigenvalue of a Gram matrix is round-off: dropping it changes the
#: sums by that fraction of their largest.
_RANK_TOL = 1e-13
#: A static correction whose part outside the eigenmodes (and the other corrections) has less than
#: this fraction of its mass norm squared is a dependent direction (round-off: the projection leaves
#: ~1e-16 of the norm) and is dropped. A small but real part is kept: a point load's static shape
#: has a kink no smooth mode carries, and even 1e-5 of it moves the frequencies (measured).
_SPAN_TOL = 1e-20
#: Blocks of at most this many coordinates are solved with dense LAPACK (ARPACK's Krylov space needs
#: room, and a small dense solve costs less than setting up the sparse one).
_DENSE_BELOW = 48


@dataclass(frozen=True)
class Reduction:
    """A reduction basis: ``basis`` (n_full, n) over the element model's kept coordinates, ``labels``
    (n,) ``m1 ..`` eigenmodes then ``c1 ..`` static corrections, ``frequencies`` (n,) rad/s of each
    column's Rayleigh quotient (the eigenmodes' natural frequencies)."""

    basis: np.ndarray
    labels: tuple[str, ...]
    frequencies: np.ndarray


def reduction_basis(mass, stiffness, axial: np.ndarray, n_modes: int, loads: np.ndarray,
                    displacements: np.ndarray) -> Reduction:
    """The reduction basis of an element model with ``mass``, ``stiffness`` (n_full, n_full), sparse
    or dense, ``axial`` (n_full,) bool marking its axial coordinates, keeping ``n_modes`` eigenmodes
    plus the static corrections of ``loads`` (n_full, k) load vectors; ``displacements``
    (p, n_full) maps the coordinates to displacements (m) at p samples along the link (nodes and
    Gauss points, axial and transverse), whose largest magnitude normalises each column.

    Axial and transverse coordinates are uncoupled in ``mass`` and ``stiffness`` (the frame is held
    fixed), so each block is solved on its own: one sparse factorisation of its stiffness serves
    both its lowest eigenpairs (shift-invert Lanczos about 0) and its static corrections."""
    mass, stiffness = sparse.csc_matrix(mass), sparse.csc_matrix(stiffness)
    n_full = len(axial)
    modes, omega2, static = [], [], np.zeros_like(loads, dtype=float)
    for block in _blocks(axial):
        count = min(n_modes, block.size)   # only the lowest: the rest cannot be chosen
        values, vectors, solve = _lowest_modes(stiffness[block][:, block], mass[block][:, block],
                                               count)
        full = np.zeros((n_full, count))
        full[block] = vectors
        modes.append(full)
        omega2.append(values)
        static[block] = solve(loads[block])
    modes, omega2 = np.hstack(modes), np.concatenate(omega2)
    lowest = np.argsort(omega2, kind="stable")[:n_modes]
    phi = modes[:, lowest]
    # static corrections, block by block (axial loads give axial shapes, transverse ones bending)
    corrections = []
    for block in _blocks(axial):
        part = np.zeros_like(static)
        part[block] = static[block]
        corrections.append(_orthogonal_complement(part, phi, mass, stiffness))
    psi = np.hstack(corrections)
    basis = np.hstack([phi, psi])
    # each column's largest displacement along the link becomes +1 (the sign too: the eigensolver's is
    # arbitrary); every column moves the link (the stiffness is definite), so the peak is not round-off.
    # A symmetric link has peaks of both signs equal to round-off (an antisymmetric mode's +a and -a):
    # the first sample within 1e-6 of the largest, not whichever round-off makes larger, or a change of
    # 1e-6 in a section property flips a column's sign and every difference across it (the
    # sensitivities' forward steps) is O(1) wrong
    sampled = displacements @ basis
    magnitude = np.abs(sampled)
    peak = np.argmax(magnitude >= (1.0 - 1e-6) * magnitude.max(axis=0), axis=0)
    basis = basis / sampled[peak, np.arange(basis.shape[1])]
    labels = tuple(f"m{i + 1}" for i in range(phi.shape[1])) + tuple(
        f"c{i + 1}" for i in range(psi.shape[1]))
    frequencies = np.sqrt(np.einsum("ij,ij->j", basis, stiffness @ basis)
                          / np.einsum("ij,ij->j", basis, mass @ basis))
    return Reduction(basis, labels, frequencies)


def _blocks(axial):
    """The axial and the transverse coordinates' indices, the empty ones left out."""
    return [block for block in (np.flatnonzero(axial), np.flatnonzero(~axial)) if block.size]


def _lowest_modes(stiffness, mass, count):
    """The ``count`` lowest eigenpairs of ``stiffness phi = omega^2 mass phi`` (sparse (b, b),
    stiffness positive definite: the link's supports are removed), mass-normalised, and a solver
    ``K^-1 (b, k)`` from the same factorisation. Lanczos (ARPACK) in shift-invert mode about 0
    converges to the lowest modes in a few dozen solves with the sparse factor; it needs a block
    well above ``count`` (its Krylov space), so small blocks are solved dense."""
    if stiffness.shape[0] <= max(_DENSE_BELOW, 3 * count):
        dense_k, dense_m = stiffness.toarray(), mass.toarray()
        values, vectors = eigh(dense_k, dense_m, subset_by_index=(0, count - 1))
        factor = cho_factor(dense_k)
        return values, vectors, lambda rhs: cho_solve(factor, rhs)
    factor = splu(stiffness)
    inverse = LinearOperator(stiffness.shape, matvec=factor.solve, dtype=float)
    start = np.random.default_rng(0).standard_normal(stiffness.shape[0])   # reproducible
    values, vectors = eigsh(stiffness, k=count, M=mass, sigma=0.0, OPinv=inverse, v0=start,
                            tol=0.0)
    order = np.argsort(values)
    return values[order], vectors[:, order], factor.solve


def _orthogonal_complement(vectors, phi, mass, stiffness):
    """The part of span(``vectors``) mass-orthogonal to ``phi``, as Rayleigh-Ritz vectors of
    (stiffness, mass) on it (mass- and stiffness-orthogonal), lowest first; dependent directions
    (residual mass norm squared below ``_SPAN_TOL`` of the vector's) are dropped.

    Gram-Schmidt in the mass inner product, each vector projected twice (away from the eigenmodes
    and the directions kept before it), so a dependent vector leaves a residual of round-off size
    (~1e-16 of its norm, 1e-32 squared). An eigendecomposition of the residuals' Gram matrix cannot
    tell them apart: its eigenvalues carry an absolute error of ~1e-16 of the largest, so two equal
    load vectors (the axial load at the far end and the uniform axial inertia of a 1-element link:
    one axial coordinate) were both kept, and the reduced mass matrix was singular (issue 23)."""
    vectors = vectors[:, np.linalg.norm(vectors, axis=0) > 0.0]
    mass_phi = mass @ phi
    modal_mass = np.einsum("ij,ij->j", phi, mass_phi)       # phi^T M phi is diagonal
    kept: list[np.ndarray] = []
    for column in vectors.T:
        residual = column / np.sqrt(column @ (mass @ column))
        for _ in range(2):   # twice: the second pass removes what round-off left of the first
            residual = residual - phi @ ((mass_phi.T @ residual) / modal_mass)
            for direction in kept:
                residual = residual - direction * (direction @ (mass @ residual))
        norm2 = residual @ (mass @ residual)
        if norm2 > _SPAN_TOL:
            kept.append(residual / np.sqrt(norm2))
    if not kept:
        return np.zeros((mass.shape[0], 0))
    span = np.column_stack(kept)                              # mass-orthonormal
    _, ritz = eigh(span.T @ (stiffness @ span), span.T @ (mass @ span))
    return span @ ritz


# ---------------------------------------------------------------------------------------------------
# Equivalent points
# ---------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class EquivalentMassPoints:
    """Points with the link's inertia sums: ``mass``, ``inertia`` (p,) kg and kg m^2, ``cx`` (p,) m,
    ``u``, ``w``, ``dw`` (p, n) shape rows (1, 1, 1/m per unit coordinate)."""

    mass: np.ndarray
    inertia: np.ndarray
    cx: np.ndarray
    u: np.ndarray
    w: np.ndarray
    dw: np.ndarray


def equivalent_mass_points(x, weights, mu, rho_i, u, w, dw) -> EquivalentMassPoints:
    """Equivalent mass points of a link with Gauss points ``x``, ``weights`` (g,) m, mass per length
    ``mu`` (kg/m), rotary inertia per length ``rho_i`` (kg m), shape rows ``u, w, dw`` (g, n)."""
    n = u.shape[1]
    features = np.hstack([np.ones((len(x), 1)), x[:, None], u, w])
    weight, columns = _equal_weight_factor(features, mu * weights)
    points = EquivalentMassPoints(weight, np.zeros_like(weight), columns[1],
                                  columns[2:2 + n].T, columns[2 + n:].T, np.zeros((len(weight), n)))
    if rho_i == 0.0:
        return points
    weight, columns = _equal_weight_factor(np.hstack([np.ones((len(x), 1)), dw]), rho_i * weights)
    zeros = np.zeros((len(weight), n))
    return EquivalentMassPoints(np.concatenate([points.mass, np.zeros_like(weight)]),
                                np.concatenate([points.inertia, weight]),
                                np.concatenate([points.cx, np.zeros_like(weight)]),
                                np.vstack([points.u, zeros]), np.vstack([points.w, zeros]),
                                np.vstack([points.dw, columns[1:].T]))


def _equal_weight_factor(features, weights):
    """``(weight (r,), columns (d, r))`` with ``sum_k weight_k c_k c_k^T = sum_g weights_g z_g
    z_g^T`` (``features`` z (g, d), first feature 1) and every column's first entry 1."""
    gram = features.T @ (weights[:, None] * features)
    values, vectors = np.linalg.eigh(gram)
    keep = values > _RANK_TOL * values.max()
    factor = vectors[:, keep] * np.sqrt(values[keep])             # gram = factor factor^T
    first = factor[0]
    target = np.full_like(first, np.linalg.norm(first) / np.sqrt(len(first)))
    reflector = first - target
    if np.linalg.norm(reflector) > 0.0:                           # Householder: first row -> target
        factor = factor - 2.0 * np.outer(factor @ reflector, reflector) / (reflector @ reflector)
    return target**2, factor / target[None, :]


@dataclass(frozen=True)
class EquivalentStrainPoints:
    """One strain-point group (``_kernels`` eq. 4) with the link's strain energy: rows ``du``,
    ``dw``, ``ddw`` (G, n), projection ``projection`` (G, G), weights ``ea`` and ``ei`` (G,) (the
    quadrature weight times the rigidity, N and N m^2)."""

    du: np.ndarray
    dw: np.ndarray
    ddw: np.ndarray
    projection: np.ndarray
    ea: np.ndarray
    ei: np.ndarray


def equivalent_strain_points(weights, ea, ei, du, dw, ddw) -> EquivalentStrainPoints:
    """Equivalent strain points of a link with geometric stiffening: Gauss weights (g,) m, rigidities
    ``ea`` (N), ``ei`` (N m^2), shape rows ``du, dw, ddw`` (g, n) (see the module docstring)."""
    n = du.shape[1]
    root = np.sqrt(weights)
    u_svd, sigma, vt = np.linalg.svd(root[:, None] * du, full_matrices=False)
    rank = int(np.sum(sigma > 1e-10 * sigma[0]))           # as _beams.membrane_projection
    strain_rows = sigma[:rank, None] * vt[:rank]           # (r_a, n): c_k = row_k . q + ...
    slope_rows, slope_blocks = [], []
    for k in range(rank):
        h_k = dw.T @ ((u_svd[:, k] * root)[:, None] * dw)   # H_k (n, n)
        values, vectors = np.linalg.eigh(0.5 * (h_k + h_k.T))
        keep = np.abs(values) > _RANK_TOL * np.abs(values).max()
        slope_rows.append(vectors[:, keep].T)
        slope_blocks.append(values[keep])
    bending = ddw.T @ (weights[:, None] * ddw)
    curvature_values, curvature_vectors = np.linalg.eigh(0.5 * (bending + bending.T))
    keep = curvature_values > _RANK_TOL * curvature_values.max()
    n_slopes = sum(len(block) for block in slope_blocks)
    size = max(n_slopes, rank, int(keep.sum()), 1)
    points = EquivalentStrainPoints(*(np.zeros((size, n)) for _ in range(3)),
                                    np.zeros((size, size)), np.zeros(size), np.zeros(size))
    points.du[:rank] = strain_rows
    points.ea[:rank] = ea
    start = 0
    for k, (rows, block) in enumerate(zip(slope_rows, slope_blocks)):
        points.dw[start:start + len(block)] = rows
        points.projection[k, start:start + len(block)] = block
        start += len(block)
    points.ddw[:keep.sum()] = curvature_vectors[:, keep].T
    points.ei[:keep.sum()] = ei * curvature_values[keep]
    return points
