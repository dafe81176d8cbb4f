"""Elastic-link discretisations against closed forms: natural frequencies of pinned-pinned, free-free,
fixed-free (axial) and clamped-free beams, exact Ritz integrals, and the observed order of
convergence of Hermite elements (h^4 for bending, h^2 for linear axial elements)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.linalg import eigh, null_space

from mechanisms import (GROUND, ElasticLink, Fem, Mechanism, ModalDamping, PrescribedDrive,
                        Revolute, Ritz, UserShapes, assemble, beam_matrices, beam_shapes)
from mechanisms._beams import clamped_free_roots

LENGTH = 0.2794
SECTION = dict(width=0.02, thickness=0.0016, density=7800.0, youngs_modulus=2.0e11)
EI = 2.0e11 * 0.02 * 0.0016**3 / 12.0
EA = 2.0e11 * 0.02 * 0.0016
MU = 7800.0 * 0.02 * 0.0016
BENDING_SCALE = math.sqrt(EI / MU) / LENGTH**2     # omega = (beta L)^2 * this, rad/s
AXIAL_SCALE = math.sqrt(2.0e11 / 7800.0) / LENGTH  # omega = k pi / 2 * this for a fixed-free bar
CANTILEVER = (1.875104068711961, 4.694091132974175, 7.854757438237613)  # cos b cosh b = -1


def beam(discretisation, boundary="pinned-pinned", **options):
    return ElasticLink.rectangular("beam", LENGTH, discretisation=discretisation,
                                   boundary=boundary, **SECTION, **options)


def split_frequencies(link):
    """Bending and axial natural frequencies (rad/s) of the link with its frame held fixed. The
    linear M and K do not couple axial and transverse coordinates (Su and Sw use disjoint DOF), so
    the two families are the eigenvalues of their own blocks."""
    shapes = beam_shapes(link)
    mass, stiffness = beam_matrices(shapes)
    axial = np.array([label[0] in "ua" for label in shapes.labels])
    out = []
    for keep in (~axial, axial):
        block = np.ix_(keep, keep)
        omega2 = eigh(stiffness[block], mass[block], eigvals_only=True) if keep.any() else []
        out.append(np.sqrt(omega2))
    return out


def observed_order(element_counts, errors):
    """Least-squares slope of log(error) against log(h)."""
    return np.polyfit(np.log(1.0 / np.asarray(element_counts)), np.log(errors), 1)[0]


def test_clamped_free_roots():
    assert clamped_free_roots(3) == pytest.approx(CANTILEVER, rel=1e-14)


def test_ritz_matrices_are_the_closed_form_integrals():
    """int mu sin(i pi x/L) sin(j pi x/L) = mu L/2 delta_ij and likewise for EI (i pi/L)^4 and the
    axial modes sin((2k-1) pi x/(2L)): the adaptive Gauss rule reaches them to round-off."""
    shapes = beam_shapes(beam(Ritz(3, 2)))
    mass, stiffness = beam_matrices(shapes)
    bending = np.arange(1, 4) * math.pi / LENGTH
    axial = (2 * np.arange(1, 3) - 1) * math.pi / (2 * LENGTH)
    expected_m = np.diag(np.full(5, MU * LENGTH / 2))
    expected_k = np.diag(np.concatenate([EI * bending**4, EA * axial**2]) * LENGTH / 2)
    assert np.abs(mass - expected_m).max() <= 1e-13 * expected_m.max()
    assert np.abs(stiffness - expected_k).max() <= 1e-13 * expected_k.max()


def test_ritz_pinned_pinned_and_clamped_free_frequencies_are_exact():
    """With the exact eigenfunctions as Ritz modes the Ritz frequencies are the exact ones:
    pinned-pinned (i pi)^2, clamped-free (beta_i L)^2 times sqrt(EI/mu)/L^2; axial fixed-free
    (2k-1) pi/2 sqrt(E/rho)/L."""
    bending, axial = split_frequencies(beam(Ritz(3, 2)))
    assert bending == pytest.approx((np.arange(1, 4) * math.pi) ** 2 * BENDING_SCALE, rel=1e-12)
    assert axial == pytest.approx([math.pi / 2 * AXIAL_SCALE, 3 * math.pi / 2 * AXIAL_SCALE],
                                  rel=1e-12)
    bending, _ = split_frequencies(beam(Ritz(3, 1), boundary="clamped-free"))
    assert bending == pytest.approx(np.array(CANTILEVER) ** 2 * BENDING_SCALE, rel=1e-10)


def test_user_shapes_reproduce_ritz():
    def sine(i):
        return lambda x, length: (np.sin(i * math.pi * x / length),
                                  i * math.pi / length * np.cos(i * math.pi * x / length),
                                  -(i * math.pi / length) ** 2 * np.sin(i * math.pi * x / length))

    def axial_sine(x, length):
        k = math.pi / (2 * length)
        return np.sin(k * x), k * np.cos(k * x), -k * k * np.sin(k * x)

    user = beam_matrices(beam_shapes(beam(UserShapes((sine(1), sine(2)), (axial_sine,)))))
    ritz = beam_matrices(beam_shapes(beam(Ritz(2, 1))))
    for a, b in zip(user, ritz):
        assert np.abs(a - b).max() <= 1e-13 * np.abs(b).max()


@pytest.mark.parametrize("boundary, roots", [
    ("pinned-pinned", tuple(i * math.pi for i in (1, 2))),
    ("clamped-free", CANTILEVER[:2]),
])
def test_fem_bending_converges_at_fourth_order(boundary, roots):
    """Cubic Hermite elements: eigenvalue errors O(h^(2(p+1-m))) = O(h^4) (p = 3, m = 2), the
    same order for the frequencies; the fitted slope over N = 4..32 must lie within 0.3 of 4."""
    counts = (4, 8, 16, 32)
    errors = []
    for n in counts:
        bending, _ = split_frequencies(beam(Fem(n), boundary=boundary))
        exact = np.array(roots) ** 2 * BENDING_SCALE
        errors.append(np.max(np.abs(bending[:2] - exact) / exact))
    assert observed_order(counts, errors) == pytest.approx(4.0, abs=0.3)


def test_fem_axial_converges_at_second_order():
    """Linear axial elements of a fixed-free bar (u(0) = 0): frequency errors O(h^2)."""
    counts = (4, 8, 16, 32)
    errors = []
    for n in counts:
        _, axial = split_frequencies(beam(Fem(n)))
        exact = np.array([1, 3]) * math.pi / 2 * AXIAL_SCALE
        errors.append(np.max(np.abs(axial[:2] - exact) / exact))
    assert observed_order(counts, errors) == pytest.approx(2.0, abs=0.2)


def test_one_element_keeps_the_seed_coordinates():
    """Seed eq. 2.5-2.8 with one element: q1 = u0, q2 = w0, q5 = w1 removed for pinned ends,
    leaving q3 (r0), q4 (u1), q6 (r1)."""
    assert beam_shapes(beam(Fem(1))).labels == ("r0", "u1", "r1")
    assert beam_shapes(beam(Fem(1), boundary="clamped-free")).labels == ("u1", "w1", "r1")
    assert beam_shapes(beam(Fem(2), axial=False)).labels == ("r0", "w1", "r1", "r2")


# ---------------------------------------------------------------------------------------------------
# The floating frame in the assembler: a pinned-pinned (chord-frame) link clamped at its root by a
# pin and a zero-rate drive on the material angle is a cantilever.
# ---------------------------------------------------------------------------------------------------
def cantilever_model(link):
    mech = Mechanism("cantilever", (link,), (Revolute("root", GROUND, (0.0, 0.0), "beam", "start"),),
                     (PrescribedDrive("root", rate=0.0),), period=1.0)
    return assemble(mech)


def constrained_frequencies(model):
    """Linearised about s = 0 at rest: M V'' + K V = 0 on the null space V of Phi_s, with
    K = -dQ/ds (the constraint forces vanish with lam = 0 at rest)."""
    s = np.zeros(model.n_coords)
    basis = null_space(model.constraint_jacobian(s, 0.0))
    mass = basis.T @ model.mass_matrix(s) @ basis
    stiffness = -basis.T @ model.force_jacobians(s, s, 0.0)[0] @ basis
    return np.sqrt(eigh(0.5 * (stiffness + stiffness.T), mass, eigvals_only=True))


def test_chord_frame_link_clamped_by_the_drive_is_a_cantilever():
    """The chord-frame coordinates plus the frame rotation represent cantilever modes: the same
    cubic-spline space as clamped-free elements, so the frequencies equal those of the link's own
    clamped-free FEM matrices (to the round-off of the eigensolver, ~1e-12), and converge at h^4 to
    the closed form (bending, axial=False; N = 2 is pre-asymptotic, so N = 4..32)."""
    counts = (4, 8, 16, 32)
    exact = np.array(CANTILEVER[:2]) ** 2 * BENDING_SCALE
    errors = []
    for n in counts:
        options = dict(axial=False, geometric_stiffening=False)
        omega = constrained_frequencies(cantilever_model(beam(Fem(n), **options)))[:2]
        own, _ = split_frequencies(beam(Fem(n), boundary="clamped-free", **options))
        if n <= 8:
            assert omega == pytest.approx(own[:2], rel=1e-9)
        errors.append(np.max(np.abs(omega - exact) / exact))
    assert observed_order(counts, errors) == pytest.approx(4.0, abs=0.3)


def test_clamped_free_link_in_the_assembler_matches_its_own_modes():
    """A clamped-free link whose frame is tangent at the root, held by the same pin and drive:
    the constrained system has exactly the link's own frequencies (Ritz modes are exact)."""
    model = cantilever_model(beam(Ritz(3, 1), boundary="clamped-free"))
    omega = np.sort(constrained_frequencies(model))
    assert omega[:3] == pytest.approx(np.array(CANTILEVER) ** 2 * BENDING_SCALE, rel=1e-10)


def test_modal_damping_gives_the_requested_ratios():
    """C = M Phi diag(2 zeta w) Phi^T M: in the link's own mass-normalised modes the damping is
    diag(2 zeta_i w_i) for the ratios given and zero beyond."""
    ratios = (0.02, 0.05)
    link = beam(Fem(3), boundary="clamped-free", damping=ModalDamping(ratios))
    model = cantilever_model(link)
    lay = model.layouts["beam"]
    zero = np.zeros(model.n_coords)
    damping = -model.force_jacobians(zero, zero, 0.0)[1][lay.elastic, lay.elastic]
    mass, stiffness = beam_matrices(lay.shapes)
    omega2, modes = eigh(stiffness, mass)
    modal = modes.T @ damping @ modes
    expected = np.zeros_like(modal)
    expected[[0, 1], [0, 1]] = 2 * np.array(ratios) * np.sqrt(omega2[:2])
    assert np.abs(modal - expected).max() <= 1e-10 * expected.max()


def test_user_shapes_violating_the_boundary_conditions_are_rejected():
    cosine = lambda x, length: (np.cos(x / length), -np.sin(x / length) / length,
                                -np.cos(x / length) / length**2)
    with pytest.raises(ValueError, match=r"user shape b1 has w\(0\) = 1"):
        beam_shapes(beam(UserShapes((cosine,))))
    parabola = lambda x, length: (x * x, 2 * x, 2 + 0 * x)
    beam_shapes(beam(UserShapes((parabola,)), boundary="clamped-free"))  # w(0) = w'(0) = 0
    with pytest.raises(ValueError, match=r"w\(L\)"):
        beam_shapes(beam(UserShapes((parabola,))))


FREE_FREE = (4.730040744862704, 7.853204624095838)  # cos b cosh b = 1


def test_unconstrained_link_is_a_free_free_beam():
    """M and -dQ/ds of the model do not involve the joints: for the one link alone at rest they are
    the equations of a free floating beam, i.e. three rigid-body modes (zero frequency) and the
    free-free bending frequencies; the chord frame plus Hermite elements converge at h^4."""
    counts = (4, 8, 16, 32)
    exact = np.array(FREE_FREE) ** 2 * BENDING_SCALE
    errors = []
    for n in counts:
        model = cantilever_model(beam(Fem(n), axial=False, geometric_stiffening=False))
        zero = np.zeros(model.n_coords)
        stiffness = -model.force_jacobians(zero, zero, 0.0)[0]
        omega2 = eigh(0.5 * (stiffness + stiffness.T), model.mass_matrix(zero), eigvals_only=True)
        # three rigid-body modes: zero up to the round-off of an eigensolver on K ~ 1e6 |M|
        assert np.abs(omega2[:3]).max() < 1e-9 * omega2[3]
        errors.append(np.max(np.abs(np.sqrt(omega2[3:5]) - exact) / exact))
    assert observed_order(counts, errors) == pytest.approx(4.0, abs=0.3)
