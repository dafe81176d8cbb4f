"""Elastic-link discretisations against closed forms: natural frequencies of pinned-pinned, free-free,
fixed-free (axial) and clamped-free beams, exact Ritz integrals, and the observed order of
convergence of Hermite elements (h^4 for bending, h^2 for linear axial elements), and the projected
membrane strain of geometric stiffening (no locking when the chord may shorten, the closed-form
string force when it may not), and Kelvin-Voigt damping of that strain's rate (no damping
locking: the chord shortening of a bent link is not damped, a stretching rate is)."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest
from scipy.linalg import eigh, null_space

from mechanisms import (
    GROUND,
    ElasticLink,
    Fem,
    Mechanism,
    MechanismError,
    ModalDamping,
    PrescribedDrive,
    Rayleigh,
    Revolute,
    Ritz,
    TorqueDrive,
    UserShapes,
    assemble,
    beam_matrices,
    beam_shapes,
)
from mechanisms._parts.ritz import clamped_free_roots  # the Ritz basis's internal roots: no public face

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
    def cosine(x, length):
        return (np.cos(x / length), -np.sin(x / length) / length,
                                    -np.cos(x / length) / length**2)
    with pytest.raises(ValueError, match=r"user shape b1 has w\(0\) = 1"):
        beam_shapes(beam(UserShapes((cosine,))))
    def parabola(x, length):
        return (x * x, 2 * x, 2 + 0 * x)
    beam_shapes(beam(UserShapes((parabola,)), boundary="clamped-free"))  # w(0) = w'(0) = 0
    with pytest.raises(ValueError, match=r"w\(L\)"):
        beam_shapes(beam(UserShapes((parabola,))))


def test_user_shapes_that_raise_or_return_the_wrong_thing_are_bad_input():
    """A user function that fails on an array of abscissae (math.hypot takes scalars) or returns one
    array instead of three is a MechanismError naming the shape and the expected signature."""
    with pytest.raises(MechanismError, match=r"bending\[0\] raised TypeError.*f\(x, length\) -> \(value"):
        beam_shapes(beam(UserShapes((math.hypot,))))
    def one_array(x, length):
        return x * (length - x)
    with pytest.raises(MechanismError, match=r"bending\[0\] must return"):
        beam_shapes(beam(UserShapes((one_array,))))


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


# ---------------------------------------------------------------------------------------------------
# Geometric stiffening: the projected membrane strain does not lock, and still stiffens a string
# ---------------------------------------------------------------------------------------------------
W0 = 2e-3   # mid-span deflection (m): w'^2/2 ~ 4e-4 and EA w'^2/2 ~ 5e3 N, EI w'' ~ 0.15 N m


def pinned_model(link):
    """The link pinned to the ground at its start, with an idle torque drive (a mechanism needs
    one). In the state below the frame lies on the x-axis (theta = 0) and the chord-frame convention
    w(L) = 0 puts the far end on that axis: with u(L) free this is the end on a slider along the
    chord, with u(L) = 0 an immovable second pin."""
    mech = Mechanism("bent", (link,), (Revolute("pin", GROUND, (0.0, 0.0), "beam", "start"),),
                     (TorqueDrive("pin", kp=0.0, kd=0.0),), period=1.0)
    return assemble(mech)


def scale_shortening():
    """int_0^L w'^2/2 dx / L for the sine of amplitude W0: the chord's relative shortening."""
    return (math.pi * W0 / LENGTH) ** 2 / 4


def bent_state(model, n_elements):
    """s with the frame at rest on the x-axis and the link bent into w = W0 sin(pi x / L) (exact
    for Ritz mode b1, the Hermite interpolant for elements); axial coordinates zero."""
    lay = model.layouts["beam"]
    s = np.zeros(model.n_coords)
    k = math.pi / LENGTH
    for i, label in enumerate(lay.shapes.labels):
        kind, where = label[0], int(label[1:])
        x = where * LENGTH / n_elements if n_elements else 0.0
        value = {"w": W0 * math.sin(k * x), "r": W0 * k * math.cos(k * x),
                 "b": W0 * (where == 1)}.get(kind, 0.0)
        s[lay.offset + 3 + i] = value
    return s


def relax_axial(model, s, free):
    """Minimise the potential energy over the coordinates ``free`` (the axial ones): with the
    transverse field fixed the membrane strain is linear in them, so the energy is quadratic and
    Newton on -dV/ds = Q(s, 0) converges in one step (a second one only polishes round-off)."""
    zero = np.zeros(model.n_coords)
    s = s.copy()
    for _ in range(2):
        residual = model.forces(s, zero, 0.0)[free]
        tangent = model.force_jacobians(s, zero, 0.0)[0][np.ix_(free, free)]
        s[free] -= np.linalg.solve(tangent, residual)
    return s


def axial_indices(model, keep=lambda label: True):
    lay = model.layouts["beam"]
    return np.array([lay.offset + 3 + i for i, label in enumerate(lay.shapes.labels)
                     if label[0] in "ua" and keep(label)])


def bending_energy(model, s):
    """1/2 int EI w''^2 from the link's own linear stiffness restricted to its bending block (K has
    no axial-transverse coupling)."""
    lay = model.layouts["beam"]
    _, stiffness = beam_matrices(lay.shapes)
    bending = np.array([label[0] not in "ua" for label in lay.shapes.labels])
    q = s[lay.elastic] * bending
    return 0.5 * q @ stiffness @ q


@pytest.mark.parametrize("discretisation", [Fem(1), Fem(2), Fem(4), Ritz(2, 1), Ritz(1, 3)],
                         ids=["fem1", "fem2", "fem4", "ritz2-1", "ritz1-3"])
def test_projected_membrane_strain_does_not_lock(discretisation):
    """A pinned link whose far end slides freely along the chord, bent statically into its first
    pinned-pinned mode: the chord shortens freely, so once the axial coordinates minimise the energy
    the projected membrane strain and the axial strain energy vanish. Exactly, not approximately:
    P[w'^2/2] lies in the span of Su', so u' = -P[w'^2/2] is reachable. Checked to round-off: the
    strain against 1e-12 of w'^2/2 (~4e-4), the axial energy against 1e-11 of the bending energy
    (V and the bending energy are sums of ~1e2 terms each, cancelling to ~1e-14 relative). The old
    pointwise strain u' + w'^2/2 on the same Gauss points cannot vanish: u' (piecewise constant,
    or cosines of odd quarter waves) cannot represent cos^2(pi x / L); its minimum axial energy is
    computed here by least squares and is a sizeable fraction of the bending energy (locking:
    0.2 to 1.9 times it for these discretisations at W0 = 2 mm)."""
    model = pinned_model(beam(discretisation))
    n_elements = discretisation.n_elements if isinstance(discretisation, Fem) else 0
    s = relax_axial(model, bent_state(model, n_elements), axial_indices(model))
    assert np.abs(model.constraints(s, 0.0)).max() < 1e-15
    tip = s[model.layouts["beam"].elastic] @ model.layouts["beam"].shapes.evaluate([LENGTH]).u[0]
    assert tip < -0.1 * LENGTH * scale_shortening()    # the chord did shorten
    scale = 0.5 * (math.pi * W0 / LENGTH) ** 2
    for fraction in np.linspace(0.0, 1.0, 7):
        strain = model.observable(f"beam.strain@{fraction}").value(s)
        assert abs(strain) < 1e-12 * scale
    bending = bending_energy(model, s)
    assert abs(model.potential_energy(s) - bending) < 1e-11 * bending

    # the pointwise strain's best axial field, on the assembler's own Gauss rule
    lay = model.layouts["beam"]
    x, weights = lay.shapes.quadrature
    v = lay.shapes.evaluate(x)
    q = s[lay.elastic]
    root = np.sqrt(weights)
    target = -0.5 * (v.dw @ q) ** 2
    best = np.linalg.lstsq(root[:, None] * v.du, root * target, rcond=None)[0]
    residual = v.du @ best - target
    locked = 0.5 * EA * weights @ residual**2
    assert locked > 0.05 * bending


def test_clamped_chord_keeps_the_string_stiffening():
    """Both ends pinned to the ground: the chord cannot shorten, bending stretches the bar. For
    w = w0 sin(pi x / L) the axial equilibrium makes N = EA eps uniform and the end condition
    int_0^L eps dx = u(L) - u(0) + int w'^2/2 dx = 0 + (pi w0 / L)^2 / 2 * L / 2 fixes it:
    N = EA pi^2 w0^2 / (4 L^2) (the membrane of an extensible string), axial energy
    N^2 L / (2 EA) = EA pi^4 w0^4 / (32 L^3), growing as w0^4 (the cubic stiffening of the bar).
    Linear axial elements represent a uniform N exactly, so the only error is the Hermite
    interpolation of the sine in int w'^2 (seed eq. 2.6), which converges at h^4 (w' interpolated to
    O(h^3), its square integrated with superconvergent cancellation; observed order checked)."""
    exact_force = EA * math.pi**2 * W0**2 / (4 * LENGTH**2)
    counts = (2, 4, 8, 16)
    errors = []
    for n in counts:
        model = pinned_model(beam(Fem(n)))
        free = axial_indices(model, keep=lambda label: label != f"u{n}")  # u(L) = 0: immovable
        s = relax_axial(model, bent_state(model, n), free)
        forces = [EA * model.observable(f"beam.strain@{f}").value(s)
                  for f in np.linspace(0.0, 1.0, 2 * n + 1)]
        # uniform to round-off (equilibrium is exact in the element space)
        assert np.ptp(forces) < 1e-10 * exact_force
        energy = model.potential_energy(s) - bending_energy(model, s)
        # the energy is N^2 L / (2 EA) with the same N, to round-off
        assert energy == pytest.approx(forces[0] ** 2 * LENGTH / (2 * EA), rel=1e-10)
        errors.append(abs(forces[0] - exact_force) / exact_force)
    assert errors[-1] < 1e-5                      # 4e-6 observed at 16 elements
    assert observed_order(counts, errors) == pytest.approx(4.0, abs=0.3)


def test_stiffening_without_axial_coordinates_falls_back_and_dependent_axial_shapes_are_flagged(
        caplog):
    """No axial coordinate (Ritz n_axial = 0): nothing carries a membrane strain, so the link keeps
    seed eq. 2.13 (linear forces -K q, K the link's own stiffness) and says so. Two identical user
    axial shapes span one dimension: the projection uses that span and the rank loss is logged."""
    with caplog.at_level(logging.WARNING, logger="mechanisms"):
        model = pinned_model(beam(Ritz(2, 0)))
    assert "falls back to the thesis's, without stiffening (eq. 2.13)" in caplog.text
    lay = model.layouts["beam"]
    assert not lay.stiffening
    s = bent_state(model, 0)
    _, stiffness = beam_matrices(lay.shapes)
    zero = np.zeros(model.n_coords)
    forces = model.forces(s, zero, 0.0)[lay.elastic]
    assert forces == pytest.approx(-stiffness @ s[lay.elastic], rel=1e-12)

    def sine(x, length):
        return (np.sin(math.pi * x / length), math.pi / length * np.cos(
            math.pi * x / length), -(math.pi / length) ** 2 * np.sin(math.pi * x / length))
    def ramp(x, length):
        return (x / length, 0 * x + 1 / length, 0 * x)
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="mechanisms"):
        model = pinned_model(beam(UserShapes((sine,), (ramp, ramp))))
    assert "2 axial strain functions span only 1 dimensions" in caplog.text
    # the membrane strain of a bent link with free axial coordinates still relaxes to zero
    s = relax_axial(model, bent_state(model, 0), axial_indices(model)[:1])
    assert abs(model.observable("beam.strain@0.5").value(s)) < 1e-12 * scale_shortening()


# ---------------------------------------------------------------------------------------------------
# Kelvin-Voigt damping acts on the rate of the projected membrane strain: no damping locking
# ---------------------------------------------------------------------------------------------------
BETA = 1.0e-4   # s: beta EA ~ 6e2 N s, beta EI ~ 7e-6 N m^2 s


def _bending_and_axial_stiffness(lay):
    """The bending and the axial blocks of the link's linear stiffness (K has no coupling)."""
    _, stiffness = beam_matrices(lay.shapes)
    axial = np.array([label[0] in "ua" for label in lay.shapes.labels])
    return stiffness * np.outer(~axial, ~axial), stiffness * np.outer(axial, axial)


def _damping_force(model, s, sdot):
    """With the frame at rest (theta' = 0) the velocity terms of the inertia forces vanish
    (``_kernels`` eq. 2: c = -theta'^2 A p + 2 theta' J A S q'), so Q(s, s') - Q(s, 0) is the
    damping force alone."""
    return model.forces(s, sdot, 0.0) - model.forces(s, np.zeros(model.n_coords), 0.0)


@pytest.mark.parametrize("discretisation", [Fem(2), Fem(4), Ritz(2, 1)],
                         ids=["fem2", "fem4", "ritz2-1"])
def test_chord_shortening_feels_no_axial_damping(discretisation):
    """The pinned link with a free sliding end, moving along the path s(lam) = lam q_b + lam^2 a
    (q_b the bent shape, a the axial field that relaxes its membrane strain to zero at lam = 1,
    exactly quadratic in lam since the strain is linear in a): the projected strain stays zero,
    so Kelvin-Voigt damping must give only the bending force -beta K_bend q' (K_bend the bending
    block of the link's linear stiffness, from ``beam_matrices``) and dissipate
    beta q'^T K_bend q'. The old constant beta K_ee also damped the axial rate 2 a: its spurious
    force beta K_axial 2a is 2e2 to 1e3 times the bending force here; the check is to 1e-10 of it
    (round-off of sums of beta EA-sized terms cancelling to zero) plus 1e-9 of the bending force."""
    model = pinned_model(beam(discretisation, damping=Rayleigh(0.0, BETA)))
    lay = model.layouts["beam"]
    n_elements = discretisation.n_elements if isinstance(discretisation, Fem) else 0
    bent = bent_state(model, n_elements)
    s = relax_axial(model, bent, axial_indices(model))
    sdot = np.zeros(model.n_coords)
    sdot[lay.elastic] = bent[lay.elastic] + 2.0 * (s - bent)[lay.elastic]   # d s / d lam at 1
    k_bend, k_axial = _bending_and_axial_stiffness(lay)
    qdot = sdot[lay.elastic]
    expected = np.zeros(model.n_coords)
    expected[lay.elastic] = -BETA * k_bend @ qdot
    spurious = BETA * np.linalg.norm(k_axial @ qdot)
    assert spurious > 1e2 * np.linalg.norm(expected)      # what the linear damping got wrong
    error = np.linalg.norm(_damping_force(model, s, sdot) - expected)
    assert error < 1e-10 * spurious + 1e-9 * np.linalg.norm(expected)
    power = BETA * qdot @ k_bend @ qdot
    assert model.damping_power(sdot, s) == pytest.approx(power, rel=1e-9)
    with pytest.raises(ValueError, match="s is required"):
        model.damping_power(sdot)


@pytest.mark.parametrize("n_elements", [2, 4])
def test_axial_stretching_rate_feels_beta_ea(n_elements):
    """At the same bent, relaxed state, a uniform axial stretching rate e (nodal axial velocities
    e x_i of the linear elements) with no bending rate: eps' = e everywhere, so the dissipated
    power is beta EA L e^2 and the damping force is -beta EA e d/dq int eps dx =
    -beta EA e (Su(L) - Su(0) + G q), G = int Sw'^T Sw' dx (the projection keeps the integral: the
    constants lie in the span of the elements' strains). G is built here with scipy quad on each
    element, independently of the assembler's Gauss rule; agreement to 1e-9 (quad asked for 1e-12;
    the force sums terms ~1e2 times larger than the result)."""
    from scipy.integrate import quad

    model = pinned_model(beam(Fem(n_elements), damping=Rayleigh(0.0, BETA)))
    lay = model.layouts["beam"]
    s = relax_axial(model, bent_state(model, n_elements), axial_indices(model))
    rate = 3.0e-2    # 1/s
    sdot = np.zeros(model.n_coords)
    for i, label in enumerate(lay.shapes.labels):
        if label[0] == "u":
            sdot[lay.offset + 3 + i] = rate * int(label[1:]) * LENGTH / n_elements
    assert model.damping_power(sdot, s) == pytest.approx(BETA * EA * LENGTH * rate**2, rel=1e-12)
    n_e = lay.n_elastic
    gram = np.zeros((n_e, n_e))
    nodes = np.linspace(0.0, LENGTH, n_elements + 1)
    def slope(x):
        return lay.shapes.evaluate([x]).dw[0]
    for a in range(n_e):
        for b in range(a, n_e):
            gram[a, b] = gram[b, a] = sum(
                quad(lambda x: slope(x)[a] * slope(x)[b], lo, hi, epsabs=0.0, epsrel=1e-12)[0]
                for lo, hi in zip(nodes[:-1], nodes[1:]))
    ends = lay.shapes.evaluate([0.0, LENGTH]).u
    expected = np.zeros(model.n_coords)
    expected[lay.elastic] = -BETA * EA * rate * (ends[1] - ends[0] + gram @ s[lay.elastic])
    force = _damping_force(model, s, sdot)
    assert np.linalg.norm(force - expected) < 1e-9 * np.linalg.norm(expected)


@pytest.mark.parametrize("discretisation", [Fem(3), Ritz(2, 1)], ids=["fem3", "ritz2-1"])
def test_strain_rate_damping_is_rayleigh_at_zero_deflection(discretisation):
    """At q = 0 the strain-rate form reduces to C = alpha M_ee + beta K_ee (M_ee, K_ee from
    ``beam_matrices``): the linearisation about an undeformed motion is unchanged. With the frame at
    rest the elastic block of -dQ/ds' is C alone; both sides are the same Gauss sums in another
    order, so they agree to round-off (1e-12 of |C|)."""
    alpha = 0.5
    model = pinned_model(beam(discretisation, damping=Rayleigh(alpha, BETA)))
    lay = model.layouts["beam"]
    s = np.zeros(model.n_coords)
    s[lay.offset + 2] = 0.7
    damping = -model.force_jacobians(s, np.zeros(model.n_coords), 0.0)[1][lay.elastic, lay.elastic]
    mass, stiffness = beam_matrices(lay.shapes)
    expected = alpha * mass + BETA * stiffness
    assert np.abs(damping - expected).max() <= 1e-12 * np.abs(expected).max()
