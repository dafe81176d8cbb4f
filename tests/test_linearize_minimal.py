"""A rigid four-bar driven by a torque with PD feedback, written in redundant coordinates, against its
minimal model in the crank angle, built independently from the closed-form loop closure.

Minimal model: J(phi) phi'' + J'(phi) phi'^2 / 2 = tau, with tau = tau_ff(t) + kp (Omega t - phi) +
kd (Omega - phi'). About phi = Omega t (tau_ff the inverse-dynamics torque):

    J dphi'' + (J' Omega + kd) dphi' + (J'' Omega^2 / 2 + kp) dphi = 0.

J(phi) = sum_i m_i |d r_ci / d phi|^2 + I_i (d phi_i / d phi)^2 comes from the closed-form positions,
differentiated with fourth-order central differences (step 1e-3 rad: truncation ~1e-12).
"""

import math

import numpy as np
import pytest
import scipy.integrate

import linearize
import mechanisms as mc
import periodic

GROUND, CRANK, COUPLER, ROCKER = 0.254, 0.0508, 0.2794, 0.2794
SECTION = dict(width=0.02, thickness=0.0016, density=7800.0)
# PD gains giving a lightly damped crank oscillation near 1.3 times the crank speed (J ~ 2e-4 kg m^2),
# so the multipliers are of order one and strongly modulated by J(phi).
RATE, KP, KD = 60.0, 1.2, 1.5e-3


def _positions(phi):
    """Centroids (3, 2) and angles (3,) of crank, coupler, rocker at crank angle phi (open branch,
    coupler above the ground line, as the scene builder assembles it)."""
    a = np.array([CRANK * math.cos(phi), CRANK * math.sin(phi)])
    c = np.array([GROUND, 0.0])
    d = c - a
    dist = math.hypot(*d)
    along = (COUPLER**2 - ROCKER**2 + dist**2) / (2 * dist)
    height = math.sqrt(COUPLER**2 - along**2)
    b = a + (along * d + height * np.array([-d[1], d[0]])) / dist
    angles = np.array([phi, math.atan2(*(b - a)[::-1]), math.atan2(*(b - c)[::-1])])
    centroids = np.array([a / 2, (a + b) / 2, (c + b) / 2])
    return centroids, angles


def _generalized_inertia(phi, h=1e-3):
    """J(phi): kinetic energy per (crank rate)^2 / 2, from velocity ratios by central differences."""
    stencil = [(-2, 1 / 12), (-1, -8 / 12), (1, 8 / 12), (2, -1 / 12)]
    dc = sum(w * _positions(phi + k * h)[0] for k, w in stencil) / h
    angles = np.unwrap([_positions(phi + k * h)[1] for k, _ in stencil], axis=0)
    da = sum(w * angles[j] for j, (_, w) in enumerate(stencil)) / h
    masses = [SECTION["density"] * SECTION["width"] * SECTION["thickness"] * L
              for L in (CRANK, COUPLER, ROCKER)]
    inertias = [m * L**2 / 12 for m, L in zip(masses, (CRANK, COUPLER, ROCKER))]
    return sum(m * dc[i] @ dc[i] + J * da[i] ** 2 for i, (m, J) in enumerate(zip(masses, inertias)))


def _derivatives(phi, h=2e-3):
    J = [_generalized_inertia(phi + k * h) for k in (-2, -1, 0, 1, 2)]
    d1 = (J[0] - 8 * J[1] + 8 * J[3] - J[4]) / (12 * h)
    d2 = (-J[0] + 16 * J[1] - 30 * J[2] + 16 * J[3] - J[4]) / (12 * h**2)
    return J[2], d1, d2


@pytest.fixture(scope="module")
def rigid_four_bar():
    links = (mc.RigidLink.uniform("crank", CRANK, **SECTION),
             mc.RigidLink.uniform("coupler", COUPLER, **SECTION),
             mc.RigidLink.uniform("rocker", ROCKER, **SECTION))
    _, angles = _positions(0.0)
    return mc.Mechanism(
        name="rigid four-bar", links=links,
        joints=(mc.Revolute("O", "ground", (0.0, 0.0), "crank", "start"),
                mc.Revolute("A", "crank", "end", "coupler", "start"),
                mc.Revolute("B", "coupler", "end", "rocker", "end"),
                mc.Revolute("C", "ground", (GROUND, 0.0), "rocker", "start")),
        drives=(mc.TorqueDrive("O", rate=RATE, kp=KP, kd=KD),),
        initial_angles={"crank": 0.0, "coupler": angles[1], "rocker": angles[2]})


def test_torque_driven_rigid_four_bar_linearises_to_its_minimal_model(rigid_four_bar):
    lin = linearize.about(rigid_four_bar, n_steps=64)
    assert lin.labels == ("crank.theta",)
    phi = lin.crank_angle
    J, dJ, ddJ = np.array([_derivatives(p) for p in phi]).T
    # Finite differences of closed-form positions: ~1e-10 relative (step and round-off).
    np.testing.assert_allclose(lin.system.M[:, 0, 0], J, rtol=1e-9)
    np.testing.assert_allclose(lin.system.C[:, 0, 0], dJ * RATE + KD, rtol=1e-7,
                               atol=1e-9 * np.abs(dJ * RATE).max())
    np.testing.assert_allclose(lin.system.K[:, 0, 0], ddJ * RATE**2 / 2 + KP, rtol=1e-6,
                               atol=1e-7 * np.abs(ddJ * RATE**2).max())
    np.testing.assert_allclose(lin.system.f, 0.0, atol=1e-9 * np.abs(lin.system.K).max())


@pytest.mark.slow
def test_floquet_multipliers_match_the_minimal_model(rigid_four_bar):
    """Multipliers of the linearised redundant model (Newmark, Richardson-extrapolated) against a
    DOP853 integration of the minimal variational equation at rtol 1e-12."""
    from scipy.interpolate import CubicSpline

    period = 2 * math.pi / RATE
    # Tabulate the minimal model's coefficients once; periodic cubic splines on 1024 intervals
    # interpolate them to ~1e-11 relative (h^4 with h = 6e-3 rad).
    phi = np.linspace(0.0, 2 * math.pi, 1025)
    table = np.array([_derivatives(p) for p in phi])
    table[-1] = table[0]
    J, dJ, ddJ = (CubicSpline(phi, table[:, i], bc_type="periodic") for i in range(3))

    def rhs(t, y):
        p = RATE * t
        return [y[1], -((dJ(p) * RATE + KD) * y[1] + (ddJ(p) * RATE**2 / 2 + KP) * y[0]) / J(p)]

    columns = [scipy.integrate.solve_ivp(rhs, (0, period), e, method="DOP853", rtol=1e-12,
                                         atol=1e-14).y[:, -1] for e in ([1.0, 0.0], [0.0, 1.0])]
    reference = np.sort_complex(np.linalg.eigvals(np.column_stack(columns)))
    multipliers = {n: np.sort_complex(periodic.floquet(
        linearize.about(rigid_four_bar, n_steps=n).system).multipliers) for n in (128, 256, 512)}
    errors = [np.abs((4 * multipliers[n] - multipliers[n // 2]) / 3 - reference).max()
              for n in (256, 512)]
    # Richardson-extrapolated Newmark converges at order 4 to the minimal model's multipliers;
    # J(phi) varies fivefold over a turn, so the error constant is large: ~3e-7 at N = 512.
    assert 3.5 < math.log2(errors[0] / errors[1]) < 4.5, errors
    assert errors[1] < 1e-6, errors
