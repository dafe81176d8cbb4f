"""A periodic scheme from outside the packages, with public API only: the theta-method on the first-order form,
written in numpy (no kernel of ``periodic``), registered by ``periodic.register_scheme`` and run through
``periodic.steady_state`` and ``periodic.floquet``.  Checked against independent references on a
constant-coefficient system: the multipliers against ``scipy.linalg.expm`` of the first-order matrix over a
period, the steady state against the closed-form harmonic response, both at the declared order, and the state
against the built-in trapezoidal scheme at a fine grid.

The scheme is defined, and registered at import, in ``tests/_support/extensions.py``, which
``tests/test_periodic_numerics.py`` imports too: its convergence test runs over these schemes.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

import periodic
from tests._support.extensions import THETA_SCHEMES, ThetaMethod

# a constant-coefficient system: two coupled, lightly damped oscillators under a harmonic force of period T
PERIOD = 1.0
OMEGA = 2.0 * np.pi / PERIOD
MASS = np.diag([1.0, 2.0])
STIFFNESS = np.array([[60.0, -20.0], [-20.0, 90.0]])
DAMPING = 0.01 * STIFFNESS + 0.2 * MASS
FORCE = np.array([1.0, -0.5])
GRID = np.array([64, 128, 256, 512])


def constant_system(n_steps):
    def constant(value):
        return lambda t: value

    return periodic.PeriodicSystem.from_functions(
        PERIOD, constant(MASS), constant(DAMPING), constant(STIFFNESS), lambda t: FORCE * np.cos(OMEGA * t),
        n_steps=int(n_steps))


def exact_multipliers():
    """The eigenvalues of expm(A T), A the first-order matrix: the exact monodromy's."""
    inverse_mass = np.linalg.inv(MASS)
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-inverse_mass @ STIFFNESS, -inverse_mass @ DAMPING]])
    return np.linalg.eigvals(scipy.linalg.expm(A * PERIOD))


def exact_steady_state(t):
    """The harmonic response x(t) = Re(X e^{i omega t}), X = (K - omega^2 M + i omega C)^-1 f, (N+1, n)."""
    amplitude = np.linalg.solve(STIFFNESS - OMEGA**2 * MASS + 1j * OMEGA * DAMPING, FORCE)
    return np.real(np.exp(1j * OMEGA * t)[:, None] * amplitude[None, :])


def multiplier_error(computed, exact):
    """max over the exact multipliers of the distance to the nearest computed one."""
    return float(np.abs(exact[:, None] - computed[None, :]).min(axis=1).max())


def observed_order(grid, errors):
    return -np.polyfit(np.log(grid), np.log(errors), 1)[0]


def test_registered_schemes_are_in_the_read_only_registry_and_resolve_by_name():
    for name, scheme in THETA_SCHEMES.items():
        assert periodic.SCHEMES[name] is scheme
        assert periodic.get_scheme(name) is scheme
        assert isinstance(scheme, periodic.Scheme)
    assert periodic.get_scheme("trapezoidal") == periodic.Newmark()
    with pytest.raises(TypeError):
        periodic.SCHEMES["theta-0.7"] = ThetaMethod(0.7)  # read-only: registration goes through the function


def test_registration_refuses_duplicates_and_objects_that_are_not_schemes():
    with pytest.raises(periodic.PeriodicError, match="'theta-0.6' is already registered"):
        periodic.register_scheme("theta-0.6", ThetaMethod(0.6))
    with pytest.raises(periodic.PeriodicError, match="'trapezoidal' is already registered"):
        periodic.register_scheme("trapezoidal", ThetaMethod(0.5))

    class NoMarch:
        order, error_factor = 2, 1.0 / 3.0

    with pytest.raises(TypeError, match="NoMarch does not satisfy periodic.Scheme: it lacks symmetric, march"):
        periodic.register_scheme("no-march", NoMarch())
    wrong_factor = ThetaMethod(0.6)
    wrong_factor.error_factor = 1.0 / 3.0  # order 1 needs 1 / (2 - 1)
    with pytest.raises(periodic.PeriodicError, match=r"error_factor: expected 1 / \(2\*\*order - 1\) = 1 for order 1"):
        periodic.register_scheme("wrong-factor", wrong_factor)
    with pytest.raises(periodic.PeriodicError, match="name: expected a non-empty name"):
        periodic.register_scheme(" ", ThetaMethod(0.6))
    with pytest.raises(TypeError, match="name: expected a string"):
        periodic.register_scheme(0.6, ThetaMethod(0.6))
    assert not {"no-march", "wrong-factor", " "} & set(periodic.SCHEMES)  # nothing half-registered


@pytest.mark.parametrize("name", sorted(THETA_SCHEMES))
def test_multipliers_converge_to_expm_at_the_declared_order(name):
    scheme = periodic.SCHEMES[name]
    exact = exact_multipliers()
    errors = []
    for n_steps in GRID:
        result = periodic.floquet(constant_system(n_steps), scheme=name, estimate_error=True)
        assert result.scheme is scheme and result.multipliers.size == 4
        errors.append(multiplier_error(result.multipliers, exact))
    assert observed_order(GRID, errors) == pytest.approx(scheme.order, abs=0.1)
    # the N/2 estimate (error_factor) measures the finest grid's error
    assert result.multiplier_errors.max() / errors[-1] == pytest.approx(1.0, abs=0.25)


@pytest.mark.parametrize("name", sorted(THETA_SCHEMES))
def test_steady_state_converges_to_the_harmonic_response_at_the_declared_order(name):
    scheme = periodic.SCHEMES[name]
    errors = []
    for n_steps in GRID:
        system = constant_system(n_steps)
        result = periodic.steady_state(system, scheme=name)
        errors.append(np.abs(result.x - exact_steady_state(system.t)).max())
        assert result.is_stable and result.periodicity_residual < 1e-10
    assert observed_order(GRID, errors) == pytest.approx(scheme.order, abs=0.1)
    assert result.error_estimate / errors[-1] == pytest.approx(1.0, abs=0.2)


def test_the_state_agrees_with_the_built_in_trapezoidal_scheme_at_a_fine_grid():
    """theta = 1/2 is the trapezoidal rule on the first-order form, as is Newmark's average acceleration: the
    same numbers to rounding; theta = 0.6 (order 1) is within its own error estimate of them."""
    system = constant_system(2048)
    built_in = periodic.steady_state(system, scheme="trapezoidal")
    same_rule = periodic.steady_state(system, scheme="theta-0.5")
    scale = np.abs(built_in.x).max()
    np.testing.assert_allclose(same_rule.x, built_in.x, rtol=0, atol=1e-10 * scale)
    np.testing.assert_allclose(same_rule.v, built_in.v, rtol=0, atol=1e-9 * np.abs(built_in.v).max())
    first_order = periodic.steady_state(system, scheme="theta-0.6")
    difference = np.abs(first_order.x - built_in.x).max()
    assert difference <= 1.2 * first_order.error_estimate
    assert difference >= 0.5 * first_order.error_estimate  # and the estimate is not a loose bound
    assert built_in.error_estimate < 0.01 * first_order.error_estimate  # order 2 against order 1


def test_a_scheme_refusing_first_order_coordinates_says_so():
    n_steps = 8
    M = np.tile(np.diag([1.0, 0.0]), (n_steps + 1, 1, 1))  # coordinate 1 is first order
    C = np.tile(np.eye(2), (n_steps + 1, 1, 1))
    K = np.tile(np.eye(2), (n_steps + 1, 1, 1))
    system = periodic.PeriodicSystem(1.0, M, C, K)
    with pytest.raises(periodic.PeriodicError, match=r"does not integrate first-order coordinates \[1\]"):
        periodic.floquet(system, scheme="theta-0.6")
