"""``periodic.harmonic_balance`` (issue 24's second route, its core): the periodic solution by harmonic
balance with alternating frequency-time evaluation, against

- the closed form of a linear forced oscillator (to round-off, every other harmonic zero);
- the forced, parametrically pumped Duffing oscillator's orbit by Newton shooting
  (``periodic.duffing_period_map``, trapezoidal steps): the shooting converges to the balance's
  state at order 2 as its step halves, within its own N/2 error estimate;
- itself: chord iterations with the tangent at the start reach Newton's solution; the truncation
  estimate (H against H/2) bounds the error (against 32 harmonics) where it says it is trusted, and
  says it is not where the spectrum does not decay yet.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import periodic

DUFFING = {"damping": 0.05, "cubic": 0.5, "force": 0.3, "pump": 0.1}
OMEGA = 1.1


def _duffing_equations(damping, cubic, force, pump, stiffness=1.0, omega=OMEGA):
    """(residual, tangent) of ``x'' + c x' + (k + e cos(w t)) x + k3 x^3 = F cos(w t)``."""
    def residual(t, x, v, a):
        cos = np.cos(omega * t)[:, None]
        return a + damping * v + (stiffness + pump * cos) * x + cubic * x**3 - force * cos

    def tangent(t, x, v, a):
        ones = np.ones((t.size, 1, 1))
        stiff = (stiffness + pump * np.cos(omega * t))[:, None, None] + 3.0 * cubic * x[:, :, None] ** 2
        return ones, damping * ones, stiff

    return residual, tangent


def test_a_linear_forced_oscillator_against_its_closed_form():
    k, c, force, w = 1.0, 0.05, 0.3, 1.1
    residual, tangent = _duffing_equations(c, 0.0, force, 0.0, stiffness=k, omega=w)
    found = periodic.harmonic_balance(residual, tangent, np.zeros(1), 2 * math.pi / w, harmonics=3)
    amplitude = force / (k - w**2 + 1j * c * w)       # x = Re(Z e^{i w t})
    assert found.converged and found.iterations <= 2, found.message
    np.testing.assert_allclose(found.coefficients[[1, 4], 0], [amplitude.real, -amplitude.imag], rtol=1e-12)
    others = np.delete(found.coefficients[:, 0], [1, 4])
    assert np.abs(others).max() <= 1e-14 * abs(amplitude)


@pytest.fixture(scope="module")
def balanced():
    residual, tangent = _duffing_equations(**DUFFING)
    return periodic.harmonic_balance(residual, tangent, np.zeros(1), 2 * math.pi / OMEGA, harmonics=16,
                                     estimate_error=True)


def test_the_duffing_orbit_is_the_limit_of_the_shooting_at_order_2(balanced):
    assert balanced.converged, balanced.message
    x0, v0, _ = balanced.at(0.0)
    exact = np.array([x0[0, 0], v0[0, 0]])
    distances, bars = [], []
    for n_steps in (256, 512, 1024):
        orbit = periodic.find_orbit(periodic.duffing_period_map("omega", n_steps=n_steps, **DUFFING),
                                    exact, OMEGA, tol=1e-11,
                                    estimate=periodic.duffing_period_map("omega", n_steps=n_steps // 2, **DUFFING))
        assert orbit.converged, orbit.message
        distances.append(float(np.abs(orbit.state - exact).max()))
        bars.append(orbit.state_error)
    # each halving of the step divides the shooting's distance from the balance by about 4 (order 2) ...
    ratios = np.array(distances[:-1]) / np.array(distances[1:])
    assert np.all(np.abs(ratios - 4.0) < 0.05), ratios
    # ... and the distance is the shooting's own error, which its N/2 estimate gives to within 1 %
    np.testing.assert_allclose(distances, bars, rtol=0.01)
    # the balance far nearer the true orbit, by its own (conservative) estimate
    assert balanced.truncation_error < 0.05 * distances[-1]


def test_chord_iterations_with_the_start_tangent_reach_newtons_solution(balanced):
    # started, as a mechanism's balance would be from its linearisation, near the solution: here the
    # solution at a 5 % smaller force, whose tangent the chord keeps
    residual, tangent = _duffing_equations(**DUFFING)
    period = 2 * math.pi / OMEGA
    nearby = periodic.harmonic_balance(*_duffing_equations(**dict(DUFFING, force=0.95 * DUFFING["force"])),
                                       np.zeros(1), period, harmonics=16)
    newton = periodic.harmonic_balance(residual, tangent, nearby.coefficients, period, harmonics=16)
    chord = periodic.harmonic_balance(residual, tangent, nearby.coefficients, period, harmonics=16,
                                      update_jacobian=False)
    assert nearby.converged and newton.converged and chord.converged, chord.message
    assert chord.iterations > newton.iterations and "chord" in chord.message
    np.testing.assert_allclose(chord.coefficients, balanced.coefficients, rtol=0, atol=1e-9)
    np.testing.assert_allclose(newton.coefficients, balanced.coefficients, rtol=0, atol=1e-12)


def test_the_truncation_estimate_bounds_the_error_where_it_is_trusted():
    """Against 32 harmonics: at H = 2 and 4 the spectrum does not decay yet (the H/2 difference is
    smaller than the error at H = 2): not trusted; at 8 and 16 trusted, and at least the error."""
    residual, tangent = _duffing_equations(**DUFFING)
    period = 2 * math.pi / OMEGA
    reference = periodic.harmonic_balance(residual, tangent, np.zeros(1), period, harmonics=32)
    t = np.linspace(0.0, period, 301)
    for harmonics, trusted in ((2, False), (4, False), (8, True), (16, True)):
        found = periodic.harmonic_balance(residual, tangent, reference.coefficients, period, harmonics=harmonics,
                                          estimate_error=True)
        actual = float(np.abs(found.at(t)[0] - reference.at(t)[0]).max())
        assert found.converged and found.error_trusted == trusted, (harmonics, found.message)
        assert ("trusted: the differences decay" in found.message) == trusted
        if trusted:
            assert actual <= found.truncation_error, (harmonics, actual, found.truncation_error)
    assert not reference.error_trusted and math.isnan(reference.truncation_error)   # not asked for


def test_a_failing_equation_is_reported_not_raised():
    residual, tangent = _duffing_equations(**DUFFING)

    def fails(t, x, v, a):
        if np.abs(x).max() > 0.5:
            raise RuntimeError("outside the model")
        return residual(t, x, v, a)

    found = periodic.harmonic_balance(fails, tangent, np.zeros(1), 2 * math.pi / OMEGA, harmonics=8)
    assert not found.converged and "RuntimeError: outside the model" in found.message
    nan = periodic.harmonic_balance(lambda t, x, v, a: x * np.nan, tangent, np.zeros(1), 1.0, harmonics=2)
    assert not nan.converged and nan.message == "the residual is not finite at the start"


def test_bad_input_names_the_argument():
    residual, tangent = _duffing_equations(**DUFFING)
    with pytest.raises(periodic.PeriodicError, match="harmonics: expected an integer >= 1, got 0"):
        periodic.harmonic_balance(residual, tangent, np.zeros(1), 1.0, harmonics=0)
    with pytest.raises(periodic.PeriodicError, match="samples: expected an integer >= 10, got 8"):
        periodic.harmonic_balance(residual, tangent, np.zeros(1), 1.0, harmonics=4, samples=8)
    with pytest.raises(periodic.PeriodicError, match="period: expected a duration > 0 s"):
        periodic.harmonic_balance(residual, tangent, np.zeros(1), -1.0, harmonics=4)
    with pytest.raises(periodic.PeriodicError, match=r"guess: expected coefficients \(2H \+ 1, n\)"):
        periodic.harmonic_balance(residual, tangent, np.zeros((2, 1)), 1.0, harmonics=4)
    with pytest.raises(periodic.PeriodicError, match="guess: expected finite values"):
        periodic.harmonic_balance(residual, tangent, np.array([np.nan]), 1.0, harmonics=2)
    with pytest.raises(periodic.PeriodicError, match="residual: expected to return shape"):
        periodic.harmonic_balance(lambda t, x, v, a: x[:, :0], tangent, np.zeros(1), 1.0, harmonics=2)
