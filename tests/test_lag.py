"""First-order coordinates (sensor and actuator lags, ``tau y' + y = u``) in ``periodic``, against
closed forms: the steady response of a harmonically driven lag, the characteristic roots of a
mass-spring with a lagged feedback (multipliers ``exp(s T)``), Routh-Hurwitz's stability limit, and
the observed order 2.  Lagged controllers of a mechanism: the limit tau -> 0 (the unlagged closed
loop), the linear lag state against the filtered controller law, the nonlinear run's lag state
against the exact lag of its own input, and the nonlinear run against the linear steady state."""

import numpy as np
import pytest

import linearize
import mechanisms
import periodic
import studies
from periodic import PeriodicError, PeriodicSystem
from tests._support.paths import PATHS, kernel_path


@pytest.fixture(params=PATHS)
def each_kernel_path(request):
    """The test runs once on each path of the Newmark kernels (tests/_support/paths.py)."""
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


# ---------------------------------------------------------------------------------------------------
# Lagged controllers of a mechanism (four_bar_controlled's coupler strain feedback)
# ---------------------------------------------------------------------------------------------------
STRAIN, DEFLECTION, TORQUE = "coupler.strain@0.5", "coupler.deflection@0.5", "drive.O.torque"
LAG_STEPS = 128


@pytest.fixture(scope="module")
def controlled():
    return mechanisms.load("four_bar_controlled")


def lagged(mechanism, tau):
    return mechanism.with_parameter("controllers.strain.lag", tau)


def linear_steady(mechanism):
    linear = linearize.about(mechanism, n_steps=LAG_STEPS, observables=[STRAIN, DEFLECTION, TORQUE])
    steady = periodic.steady_state(linear.system)
    return linear, steady, linear.observe(steady.x)


def test_lag_key_is_a_scene_parameter_written_only_when_set(controlled):
    mechanism = lagged(controlled, 2e-3)
    strain = {c.name: c for c in mechanism.controllers}["strain"]
    assert strain.lag == 2e-3 and strain.to_table()["lag"] == 2e-3
    assert "lag" not in {c.name: c for c in controlled.controllers}["crank_pd"].to_table()
    with pytest.raises(mechanisms.MechanismError, match="lag must be zero or positive"):
        controlled.with_parameter("controllers.crank_pd.lag", -1.0)
    model = mechanisms.assemble(mechanism)
    assert model.lag_names == ("strain",) and model.lag_joints == ("O",)
    assert model.lag_time_constants.tolist() == [2e-3]


def test_lag_state_is_an_extra_first_order_coordinate_and_tends_to_the_unlagged_loop(controlled):
    _, reference, observed = linear_steady(controlled)
    gaps = []
    for tau in (1e-3, 1e-4):  # resolved by the step (h = 0.49 ms): h / tau = 0.5 and 5
        linear, steady, lag_observed = linear_steady(lagged(controlled, tau))
        assert linear.labels[-1] == "lag.strain"
        m = len(linear.labels)
        assert linear.system.first_order.tolist() == [m - 1] and linear.system.n_state == 2 * m - 1
        assert steady.status == "ok", steady.message
        gaps.append(max(np.abs(lag_observed[spec] - observed[spec]).max() / np.abs(observed[spec]).max()
                        for spec in (DEFLECTION, TORQUE)))
        # the multipliers of the mechanism's modes tend to the unlagged ones; the lag adds exp(-T/tau)
        assert matched_error(steady.multipliers, reference.multipliers) < 2.0 * tau / linear.system.period * 0.1
    # first order in tau: a tenth of the lag, a tenth of the difference
    assert gaps[0] < 0.03 and 8.0 < gaps[0] / gaps[1] < 12.0


def test_linear_lag_state_is_the_filtered_strain_feedback(controlled):
    """Independent of the assembly: the lag state of the steady state is the controller's law
    ``u = -(gain o + rate_gain o')`` of the observed strain filtered by ``1 / (tau s + 1)``, harmonic by
    harmonic."""
    tau = 5e-3
    mechanism = lagged(controlled, tau)
    linear, steady, observed = linear_steady(mechanism)
    strain = {c.name: c for c in mechanism.controllers}["strain"]
    omega = 2.0 * np.pi / linear.system.period * np.arange(LAG_STEPS // 2 + 1)
    o = np.fft.rfft(observed[STRAIN][:-1])
    y = np.fft.irfft(-(strain.gain + strain.rate_gain * 1j * omega) * o / (1.0 + 1j * omega * tau), LAG_STEPS)
    lag_state = steady.x[:-1, -1]
    assert np.abs(lag_state - y).max() < 1e-3 * np.abs(y).max()


def test_lag_refusals_outside_the_linear_steady_state_and_the_run(controlled):
    with pytest.raises(mechanisms.ArgumentError, match=r"`lag0` must have shape \(1,\)"):
        mechanisms.simulate(lagged(controlled, 1e-3), n_periods=1, steps_per_period=16, lag0=[0.0, 1.0])
    with pytest.raises(periodic.PeriodicError, match="2 beta = gamma"):
        periodic.steady_state(linearize.about(lagged(controlled, 1e-3), n_steps=16).system, scheme="damped",
                              estimate_error=False)


def exact_lag_of_piecewise_linear(t, u, tau):
    """``y`` (N+1,) of ``tau y' + y = u``, ``y(t_0) = 0``, for ``u`` linear between the samples ``t``:
    per interval of length h, ``y_1 = e y_0 + u_1 - e u_0 - s tau (1 - e)``, ``e = exp(-h/tau)``, ``s``
    the slope of ``u`` (the particular solution ``u - s tau`` plus the decaying homogeneous one)."""
    y = np.zeros_like(u)
    for k in range(len(t) - 1):
        h = t[k + 1] - t[k]
        decay = np.exp(-h / tau)
        slope = (u[k + 1] - u[k]) / h
        y[k + 1] = decay * y[k] + u[k + 1] - decay * u[k] - slope * tau * (1.0 - decay)
    return y


def test_exact_lag_of_piecewise_linear_is_exact_for_a_ramp():
    t = np.linspace(0.0, 1.0, 11)
    tau = 0.1
    # tau y' + y = t, y(0) = 0: y = t - tau (1 - exp(-t / tau))
    np.testing.assert_allclose(exact_lag_of_piecewise_linear(t, t, tau), t - tau * (1.0 - np.exp(-t / tau)),
                               atol=1e-14)


@pytest.mark.slow
def test_lagged_closed_loop_nonlinear_run_agrees_with_the_linear_steady_state(controlled):
    """As the unlagged closed loop does: the last period of a run from the nominal motion against the
    linear steady state, the lag state of the run against the linear one."""
    differences = {}
    for tau in (0.0, 5e-3):
        mechanism = lagged(controlled, tau) if tau else controlled
        linear, steady, observed = linear_steady(mechanism)
        run = mechanisms.simulate(mechanism, n_periods=6, steps_per_period=LAG_STEPS,
                                  observables=[DEFLECTION], estimate_error=False)
        last = slice(-LAG_STEPS - 1, None)
        scale = np.abs(observed[DEFLECTION]).max()
        differences[tau] = np.abs(run.observables[DEFLECTION][last] - observed[DEFLECTION]).max() / scale
        if tau:
            assert run.lag_names == ("strain",) and run.lag_states.shape == (run.t.size, 1)
            # the run's lag state solves tau y' + y = u for the run's own controller input u (the
            # exact solution for u linear between samples; the step's trapezoidal rule is O((h/tau)^2))
            model = mechanisms.assemble(mechanism)
            u = model.lag_inputs_along(run.t, run.s, run.sdot)[0][:, 0]
            exact = exact_lag_of_piecewise_linear(run.t, u, tau)
            rate = (run.t[1] - run.t[0]) / tau
            assert np.abs(run.lag_states[:, 0] - exact).max() < rate**2 * np.abs(exact).max()
            # the torque the drive applies includes the lag state
            k = run.t.size - 1
            without = model.drive_torques(run.s[k], run.sdot[k], run.t[k])
            with_lag = model.drive_torques(run.s[k], run.sdot[k], run.t[k], lag_states=run.lag_states[k])
            assert with_lag[0] - without[0] == pytest.approx(run.lag_states[k, 0])
            started = mechanisms.simulate(mechanism, n_periods=0.25, steps_per_period=LAG_STEPS,
                                          lag0=[0.125], estimate_error=False)
            assert started.lag_states[0, 0] == 0.125
        else:
            assert run.lag_states.shape == (run.t.size, 0)
    assert differences[0.0] < 0.1
    assert differences[5e-3] < 1.5 * differences[0.0]


@pytest.mark.slow
def test_nonlinear_check_reports_the_drive_torque_with_its_lag_state(controlled):
    """The studies' nonlinear route adds the run's lag states to the drive torque and starts them at
    the linear state: its torque then agrees with the linear steady state's (which carries the lag
    state as a coordinate) about as well as the coupler's deflection does; without the lag states it
    was off by about 9 % of the peak to peak."""
    problem = studies.MechanismProblem.from_mechanism(lagged(controlled, 5e-3),
                                                      observables=(DEFLECTION, "drive.O.torque"))
    check = studies.nonlinear_check(problem, n_periods=4, n_steps=LAG_STEPS)
    assert check.relative_difference["drive.O.torque"] < 0.03
    assert check.relative_difference["drive.O.torque"] < check.relative_difference[DEFLECTION]
