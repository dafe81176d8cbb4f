"""First-order coordinates (sensor and actuator lags, ``tau y' + y = u``) in ``periodic``, against
closed forms: the steady response of a harmonically driven lag, the characteristic roots of a
mass-spring with a lagged feedback (multipliers ``exp(s T)``), Routh-Hurwitz's stability limit, and
the observed order 2."""

import numpy as np
import pytest

import periodic
from periodic import PeriodicError, PeriodicSystem
from tests._paths import PATHS, kernel_path


@pytest.fixture(params=PATHS)
def each_kernel_path(request):
    """The test runs once on each path of the Newmark kernels (tests/_paths.py)."""
    with kernel_path(request.param):
        yield request.param


def constant(matrix, n_steps):
    """(N+1, ...) samples of a constant array."""
    return np.broadcast_to(np.asarray(matrix, dtype=float), (n_steps + 1,) + np.shape(matrix)).copy()


def driven_lag(tau, omega, n_steps):
    """``tau y' + y = cos(omega t)`` over T = 2 pi / omega: a system of one first-order coordinate."""
    period = 2.0 * np.pi / omega
    t = np.arange(n_steps + 1) * period / n_steps
    system = PeriodicSystem(period, np.zeros((n_steps + 1, 1, 1)), constant([[tau]], n_steps),
                            constant([[1.0]], n_steps), np.cos(omega * t)[:, None])
    return system, t


def lag_steady_exact(tau, omega, t):
    """Closed form: amplitude 1 / sqrt(1 + (omega tau)^2), phase lag atan(omega tau)."""
    return np.cos(omega * t - np.arctan(omega * tau)) / np.hypot(1.0, omega * tau)


# mass-spring with a lagged feedback of its position and velocity:
#   m x'' + c x' + k x + y = F cos(omega t),   tau y' + y = g_p x + g_v x'
MASS, DAMPING, STIFFNESS = 1.0, 0.05, 4.0


def lagged_feedback(tau, g_p, g_v, n_steps, omega=1.3, force=1.0):
    """The feedback loop above as a PeriodicSystem (coordinates x, y), period 2 pi / omega."""
    M = [[MASS, 0.0], [0.0, 0.0]]
    C = [[DAMPING, 0.0], [-g_v, tau]]
    K = [[STIFFNESS, 1.0], [-g_p, 1.0]]
    period = 2.0 * np.pi / omega
    t = np.arange(n_steps + 1) * period / n_steps
    f = np.zeros((n_steps + 1, 2))
    f[:, 0] = force * np.cos(omega * t)
    return PeriodicSystem(period, constant(M, n_steps), constant(C, n_steps), constant(K, n_steps), f), t


def characteristic_roots(tau, g_p, g_v):
    """Roots of (m s^2 + c s + k)(tau s + 1) + g_p + g_v s = 0."""
    cubic = np.polymul([MASS, DAMPING, STIFFNESS], [tau, 1.0])
    cubic[-2:] += [g_v, g_p]
    return np.roots(cubic)


def frequency_response(tau, g_p, g_v, omega):
    """Complex amplitude X of x for the force cos(omega t): 1 / (m s^2 + c s + k + (g_p + g_v s)/(tau s + 1))."""
    s = 1j * omega
    return 1.0 / (MASS * s**2 + DAMPING * s + STIFFNESS + (g_p + g_v * s) / (tau * s + 1.0))


def matched_error(computed, exact):
    """max |computed - exact| after pairing each exact value with its nearest computed one."""
    return max(np.abs(computed - value).min() for value in exact)


@pytest.mark.usefixtures("each_kernel_path")
def test_driven_lag_steady_amplitude_and_phase_converge_at_order_2():
    tau, omega = 0.3, 2.0
    errors = []
    grid = [32, 64, 128, 256]
    for n_steps in grid:
        system, t = driven_lag(tau, omega, n_steps)
        assert system.first_order.tolist() == [0] and system.n_state == 1
        steady = periodic.steady_state(system)
        errors.append(np.abs(steady.x[:, 0] - lag_steady_exact(tau, omega, t)).max())
        # the rate is the row equation's, y' = (u - y) / tau, at every sample
        np.testing.assert_allclose(steady.v[:, 0], (np.cos(omega * t) - steady.x[:, 0]) / tau, atol=1e-12)
        assert steady.monodromy.shape == (1, 1)
        # exp(-T / tau), with the trapezoidal rule's error (h/tau)^3 / 12 per step in its logarithm
        rate = system.step / tau
        log_error = np.log(steady.multipliers[0].real) + system.period / tau
        assert abs(log_error) <= 1.1 * n_steps * rate**3 / 12.0
    order = -np.polyfit(np.log(grid), np.log(errors), 1)[0]
    assert order == pytest.approx(2.0, abs=0.1)
    assert errors[-1] < 2e-4
    assert steady.status == "ok" and steady.error_estimate == pytest.approx(errors[-1], rel=0.3)


@pytest.mark.usefixtures("each_kernel_path")
@pytest.mark.parametrize("tau, g_p, g_v", [(0.2, 0.0, 1.5), (0.05, 2.0, 0.8), (0.5, 1.0, 0.0)])
def test_lagged_feedback_multipliers_are_exp_of_the_characteristic_roots(tau, g_p, g_v):
    exact = np.exp(characteristic_roots(tau, g_p, g_v) * 2.0 * np.pi / 1.3)
    errors, gaps = [], []
    grid = [128, 256, 512]  # h / tau <= 0.3 on the finest: the lag's mode resolved
    for n_steps in grid:
        system, _ = lagged_feedback(tau, g_p, g_v, n_steps)
        result = periodic.floquet(system)
        # 2 n_massive + n_first_order multipliers: no spurious one
        assert result.multipliers.shape == (3,)
        errors.append(matched_error(result.multipliers, exact))
        # Liouville: log det Phi = int tr A dt, A the first-order form's matrix (the sum of the roots times T)
        assert result.liouville_log_det_exact == pytest.approx(np.sum(np.log(np.abs(exact))), rel=1e-12)
        gaps.append(abs(result.liouville_log_det - result.liouville_log_det_exact))
    assert -np.polyfit(np.log(grid), np.log(errors), 1)[0] == pytest.approx(2.0, abs=0.15)
    if np.abs(exact).min() > 1e-12:
        # (with tau = 0.05 the lag's multiplier exp(-T / tau) ~ 1e-41 is below the rounding of Phi, and so
        # is det Phi: the computed log det is rounding there, though every multiplier is right to 1e-5)
        assert -np.polyfit(np.log(grid), np.log(gaps), 1)[0] == pytest.approx(2.0, abs=0.15)
    assert errors[-1] < 1e-3
    # the lag's own mode is resolved, its step rate about h |s|
    assert result.resolved.all()


def routh_hurwitz_stable(tau, g_p, g_v):
    """a2 a1 > a3 a0 for the cubic a3 s^3 + a2 s^2 + a1 s + a0 (all coefficients positive here)."""
    a3, a2, a1, a0 = MASS * tau, MASS + DAMPING * tau, DAMPING + STIFFNESS * tau + g_v, STIFFNESS + g_p
    return a2 * a1 > a3 * a0


def test_lag_destabilises_a_stiff_position_feedback():
    """Lagged position feedback g_p: stable for a short lag, unstable for a long one (Routh-Hurwitz)."""
    g_p = 20.0
    for tau, expected in ((0.002, "ok"), (0.2, "unstable")):
        assert routh_hurwitz_stable(tau, g_p, 0.0) == (expected == "ok")
        result = periodic.floquet(lagged_feedback(tau, g_p, 0.0, 256)[0], estimate_error=True)
        assert result.status == expected, result.message
        assert result.is_stable == (expected == "ok")


@pytest.mark.usefixtures("each_kernel_path")
def test_lagged_feedback_steady_state_is_the_frequency_response():
    tau, g_p, g_v, omega = 0.1, 1.0, 0.7, 1.3
    amplitude = frequency_response(tau, g_p, g_v, omega)
    errors = []
    grid = [32, 64, 128]
    for n_steps in grid:
        system, t = lagged_feedback(tau, g_p, g_v, n_steps, omega=omega)
        steady = periodic.steady_state(system, estimate_error=False)
        errors.append(np.abs(steady.x[:, 0] - np.real(amplitude * np.exp(1j * omega * t))).max())
        # the lag state is (g_p x + g_v x') filtered by 1 / (tau s + 1)
        lag_amplitude = amplitude * (g_p + g_v * 1j * omega) / (1.0 + 1j * omega * tau)
        assert np.abs(steady.x[:, 1] - np.real(lag_amplitude * np.exp(1j * omega * t))).max() < 50 * errors[-1]
        assert steady.periodicity_residual < 1e-10
    assert -np.polyfit(np.log(grid), np.log(errors), 1)[0] == pytest.approx(2.0, abs=0.1)
    extrapolated = periodic.steady_state(lagged_feedback(tau, g_p, g_v, 128, omega=omega)[0], extrapolate=True)
    assert np.abs(extrapolated.x[:, 0] - np.real(amplitude * np.exp(1j * omega * t))).max() < 0.05 * errors[-1]


def test_first_order_coordinates_need_the_trapezoidal_member_and_an_invertible_damping_block():
    system, _ = lagged_feedback(0.1, 1.0, 0.0, 16)
    with pytest.raises(PeriodicError, match=r"scheme: first-order coordinates \[1\] need .*2 beta = gamma"):
        periodic.floquet(system, scheme="damped")
    n_steps = 16
    M = constant([[1.0, 0.0], [0.0, 0.0]], n_steps)
    with pytest.raises(PeriodicError, match=r"damping: the block of the first-order coordinates is singular.*\[1\]"):
        PeriodicSystem(1.0, M, np.zeros_like(M), constant(np.eye(2), n_steps))
    # a mass matrix singular with no zero row and column is refused as before
    with pytest.raises(PeriodicError, match="mass: the mass matrix is singular"):
        PeriodicSystem(1.0, constant(np.ones((2, 2)), n_steps), np.zeros_like(M), constant(np.eye(2), n_steps))
