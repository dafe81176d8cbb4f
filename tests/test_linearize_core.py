"""The linearisation core on hand-written models whose linearised equations are known in closed
form from their minimal-coordinate models (tests/_support/pendulum.py)."""

import math

import numpy as np
import pytest

from linearize import LinearizationError, linear_coefficients, spectral_derivatives
from linearize._core import choose_independent  # internal helper of the linearisation: no public face
from tests._support.pendulum import CentroidPendulum


def test_spectral_derivatives_of_a_trigonometric_polynomial_are_exact():
    period, n_steps = 0.7, 64
    t = np.linspace(0.0, period, n_steps + 1)
    w = 2 * math.pi / period
    values = np.stack([np.sin(3 * w * t) + 0.5 * np.cos(w * t), np.cos(7 * w * t)], axis=1)
    d1, d2, tail = spectral_derivatives(values, period)
    exact_d1 = np.stack([3 * w * np.cos(3 * w * t) - 0.5 * w * np.sin(w * t),
                         -7 * w * np.sin(7 * w * t)], axis=1)
    exact_d2 = np.stack([-9 * w**2 * np.sin(3 * w * t) - 0.5 * w**2 * np.cos(w * t),
                         -49 * w**2 * np.cos(7 * w * t)], axis=1)
    # Round-off of an FFT of length 64 scaled by the largest derivative (49 w^2 ~ 4e3).
    np.testing.assert_allclose(d1, exact_d1, atol=1e-12 * 7 * w)
    np.testing.assert_allclose(d2, exact_d2, atol=1e-12 * 49 * w**2)
    assert tail < 1e-13


def test_spectral_tail_flags_an_unresolved_function():
    period, n_steps = 1.0, 32
    t = np.linspace(0.0, period, n_steps + 1)
    # A sharp periodic pulse whose spectrum is far from decayed at harmonic 16.
    values = (1.0 / (1.05 - np.cos(2 * math.pi * t)))[:, None]
    assert spectral_derivatives(values, period)[2] > 1e-3


def _whirl_path(radius, speed):
    def path(t):
        e = np.array([math.cos(speed * t), math.sin(speed * t)])
        ep = np.array([-e[1], e[0]])
        return radius * e, radius * speed * ep, -radius * speed**2 * e
    return path


def _whirl_nominal(model, radius, speed, n_steps):
    period = 2 * math.pi / speed
    t = np.linspace(0.0, period, n_steps + 1)
    e = np.stack([np.cos(speed * t), np.sin(speed * t)], axis=1)
    ep = np.stack([-e[:, 1], e[:, 0]], axis=1)
    reach = radius + model.arm
    s = np.column_stack([reach * e, speed * t])
    sd = np.column_stack([reach * speed * ep, np.full(t.size, speed)])
    sdd = np.column_stack([-reach * speed**2 * e, np.zeros(t.size)])
    lam = model.mass * reach * speed**2 * e
    return period, t, s, sd, sdd, lam


def test_whirling_pendulum_linearises_to_its_minimal_model():
    """A pendulum whose pivot runs on a circle, radially outward in its relative equilibrium:
    the minimal model gives (J + m a^2) phi'' + m a rho Omega^2 phi = 0. The redundant (centroid)
    coordinates make V(t) rotate, so the V' and V'' terms of the elimination are exercised."""
    radius, speed = 0.3, 5.0
    model = CentroidPendulum(mass=2.0, inertia=0.05, arm=0.4, path=_whirl_path(radius, speed))
    period, t, s, sd, sdd, lam = _whirl_nominal(model, radius, speed, 32)
    independent = choose_independent(model.constraint_jacobian(s[0], 0.0), np.array([], int))
    lin = linear_coefficients(model, t, s, sd, sdd, lam, period=period, independent=independent)
    m, J, a = model.mass, model.inertia, model.arm
    # The generalized coordinate chosen may be x, y or theta; the closed form is for theta.
    # Scale by dtheta/dz = V[theta] (constant for this motion up to sign, as |V| is constant).
    scale = lin.V[:, 2, 0]
    np.testing.assert_allclose(lin.M[:, 0, 0] / scale**2, J + m * a**2, rtol=1e-12)
    np.testing.assert_allclose(lin.K[:, 0, 0] / scale**2, m * a * radius * speed**2, rtol=1e-10)
    np.testing.assert_allclose(lin.C[:, 0, 0] / scale**2, 0.0, atol=1e-10 * (J + m * a**2) * speed)
    np.testing.assert_allclose(lin.f, 0.0, atol=1e-12 * m * a * radius * speed**2)
    assert lin.rigid_residual < 1e-12 * m * (radius + a) * speed**2


def test_centroid_coordinates_give_time_varying_basis_with_exact_derivatives():
    radius, speed = 0.3, 5.0
    model = CentroidPendulum(path=_whirl_path(radius, speed))
    period, t, s, sd, sdd, lam = _whirl_nominal(model, radius, speed, 32)
    lin = linear_coefficients(model, t, s, sd, sdd, lam, period=period, independent=np.array([2]))
    a = model.arm
    # theta independent: x = -a sin(theta) z, y = a cos(theta) z (from Phi_s V = 0).
    theta = s[:, 2]
    np.testing.assert_allclose(lin.V[:, 0, 0], -a * np.sin(theta), atol=1e-15)
    np.testing.assert_allclose(lin.Vdot[:, 0, 0], -a * speed * np.cos(theta), atol=1e-12)
    np.testing.assert_allclose(lin.Vddot[:, 1, 0], -a * speed**2 * np.cos(theta), atol=1e-11)


def test_parametrically_excited_pendulum_matches_mathieu_coefficients():
    """Pivot oscillating vertically, p_y = h cos(w t): linearised about hanging, the minimal model
    is (J + m a^2) phi'' + m a (g - h w^2 cos w t) phi = 0 (Mathieu's equation)."""
    h, w, g = 0.01, 40.0, 9.81

    def path(t):
        return (np.array([0.0, h * math.cos(w * t)]), np.array([0.0, -h * w * math.sin(w * t)]),
                np.array([0.0, -h * w**2 * math.cos(w * t)]))

    model = CentroidPendulum(g=g, path=path)
    period = 2 * math.pi / w
    t, s, sd, sdd, lam = model.hanging_nominal(period, 24)
    lin = linear_coefficients(model, t, s, sd, sdd, lam, period=period, independent=np.array([2]))
    m, J, a = model.mass, model.inertia, model.arm
    np.testing.assert_allclose(lin.M[:, 0, 0], J + m * a**2, rtol=1e-14)
    np.testing.assert_allclose(lin.K[:, 0, 0], m * a * (g - h * w**2 * np.cos(w * t)),
                               rtol=1e-12, atol=1e-12 * m * a * g)


def test_toggle_position_is_named():
    model = CentroidPendulum()
    s = np.array([[0.4, 0.0, 0.0]] * 3)
    t = np.array([0.0, 0.5, 1.0])
    zeros = np.zeros_like(s)
    # With x independent, y and theta must absorb the x-constraint, but at theta = 0 neither moves
    # the pivot along x to first order: the dependent block is singular.
    with pytest.raises(LinearizationError, match=r"t = 0 s.*toggle"):
        linear_coefficients(model, t, s, zeros, zeros, np.zeros((3, 2)), period=1.0,
                            independent=np.array([0]))
