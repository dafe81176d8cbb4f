"""studies on plain periodic problems whose numbers are known independently: the forced damped
oscillator (closed form), the Mathieu equation (scipy.special.mathieu_a / mathieu_b), a two-mode
system with crossing frequencies (closed form), a scipy DOP853 shooting solution."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.special import mathieu_a, mathieu_b

import studies


def forced_amplitude(speed, w0=1.0, zeta=0.05, force=1.0):
    """Steady amplitude and phase lag of x'' + 2 zeta w0 x' + w0^2 x = F cos(W t)."""
    return (force / np.hypot(w0**2 - speed**2, 2 * zeta * w0 * speed),
            np.arctan2(2 * zeta * w0 * speed, w0**2 - speed**2))


# ---------------------------------------------------------------------------------------------------
# steady state
# ---------------------------------------------------------------------------------------------------
def test_steady_state_matches_closed_form_and_its_error_estimate():
    problem = studies.mathieu_problem(epsilon=0.0, damping_ratio=0.05)
    result = studies.steady_state(problem, {"speed": 0.7}, n_steps=256)
    amplitude, lag = forced_amplitude(0.7)
    exact = amplitude * np.cos(0.7 * result.t - lag)
    error = np.abs(result.response["x"] - exact).max()
    # Newmark (gamma = 1/2) is of order 2: the N/2 difference over 3 estimates the N-step error to
    # leading order, so the true error lies within a factor 1.5 of the estimate at this resolution.
    estimate = result.response_error["x"]
    assert estimate / 1.5 <= error <= 1.5 * estimate
    assert result.status == "ok" and result.run_time > 0 and result.shooting_run_time > 0
    # Time-invariant, damped: |mu| = exp(-zeta w0 T) exactly (Liouville with a complex pair).
    period = 2 * math.pi / 0.7
    assert result.spectral_radius == pytest.approx(math.exp(-0.05 * period), rel=1e-3)


def _scipy_periodic_solution(problem, values, times):
    """Periodic solution of the problem by shooting with DOP853 (rtol 1e-12): an independent route."""
    c = problem.coefficients(problem.resolve(values))
    m = len(problem.labels)

    def rhs(t, y):
        x, v = y[:m], y[m:]
        return np.concatenate([v, np.linalg.solve(c.mass(t), c.force(t) - c.damping(t) @ v - c.stiffness(t) @ x)])

    def flow(y0):
        return solve_ivp(rhs, (0, c.period), y0, method="DOP853", rtol=1e-12, atol=1e-14).y[:, -1]

    b = flow(np.zeros(2 * m))
    # monodromy of the homogeneous part: flow(e_i) - b
    phi = np.column_stack([flow(e) - b for e in np.eye(2 * m)])
    y0 = np.linalg.solve(np.eye(2 * m) - phi, b)
    return solve_ivp(rhs, (0, c.period), y0, method="DOP853", t_eval=times, rtol=1e-12, atol=1e-14).y[:m].T


def test_steady_state_of_mathieu_oscillator_matches_scipy_shooting():
    problem = studies.mathieu_problem(epsilon=0.3, damping_ratio=0.05)
    result = studies.steady_state(problem, {"speed": 1.3}, n_steps=256)
    reference = _scipy_periodic_solution(problem, {"speed": 1.3}, result.t)[:, 0]
    error = np.abs(result.response["x"] - reference).max()
    estimate = result.response_error["x"]
    assert estimate / 1.5 <= error <= 1.5 * estimate


# ---------------------------------------------------------------------------------------------------
# sweep
# ---------------------------------------------------------------------------------------------------
def test_speed_sweep_peak_to_peak_and_resonances():
    problem = studies.mathieu_problem(epsilon=0.0, damping_ratio=0.05)
    speeds = np.linspace(0.2, 1.6, 15)
    result = studies.sweep(problem, "speed", speeds, n_steps=128, max_harmonic=4)
    exact = 2 * forced_amplitude(speeds)[0]
    # the reported peak-to-peak error bounds the actual one (twice the max-error estimate, itself
    # within a factor 1.5 of the truth)
    assert np.all(np.abs(result.peak_to_peak["x"] - exact) <= result.peak_to_peak_error["x"])
    np.testing.assert_allclose(result.speed, speeds, rtol=1e-12)
    np.testing.assert_allclose(result.frozen_mean[:, 0], 1.0, rtol=1e-12)
    # k Omega = w0 crosses at Omega = 1/k; linear interpolation of a linear function is exact
    found = sorted((k, mode, round(value, 12)) for k, mode, value in result.resonances)
    expected = sorted((k, 0, round(1.0 / k, 12)) for k in (1, 2, 3, 4) if 0.2 <= 1.0 / k <= 1.6)
    assert found == expected
    assert result.instabilities == () and np.all(result.point_status == "ok") and result.done.all()


def test_sweep_marks_the_principal_parametric_instability(principal_tongue):
    problem = studies.mathieu_problem(epsilon=0.4, damping_ratio=0.0, force=0.0)
    speeds = np.linspace(1.5, 2.5, 41)
    result = studies.sweep(problem, "speed", speeds, n_steps=128)
    assert len(result.instabilities) == 1
    start, end = result.instabilities[0]
    low, high = principal_tongue(1.0, 0.4)
    # The ends are interpolated between the last stable and the first unstable grid point; Newmark's
    # frequency error (w h)^2 / 12 < 1e-4 here is far below the spacing, so each true boundary lies
    # within one grid spacing of the marked one.
    spacing = speeds[1] - speeds[0]
    assert abs(start - low) <= spacing and abs(end - high) <= spacing


def test_failed_point_is_recorded_not_raised():
    problem = studies.mathieu_problem(epsilon=0.0)
    result = studies.sweep(problem, "speed", [0.5, -1.0, 0.8], n_steps=32)  # N/4 = 8 resolves it
    assert list(result.point_status) == ["ok", "failed", "ok"]
    assert "speed" in result.point_message[1] and "positive" in result.point_message[1]
    assert np.isnan(result.spectral_radius[1]) and np.isfinite(result.spectral_radius[[0, 2]]).all()


def test_bad_input_names_the_argument():
    problem = studies.mathieu_problem()
    with pytest.raises(ValueError, match="did you mean 'epsilon'"):
        studies.sweep(problem, "epsilon_", [0.1])
    with pytest.raises(ValueError, match="n_steps"):
        studies.steady_state(problem, n_steps=15)
    with pytest.raises(ValueError, match="values"):
        studies.sweep(problem, "speed", [])
    with pytest.raises(ValueError, match="no parameter 'sped'"):
        studies.steady_state(problem, {"sped": 1.0})


# ---------------------------------------------------------------------------------------------------
# stability chart
# ---------------------------------------------------------------------------------------------------
def _mathieu_unstable(a, q, order=6):
    """Undamped Mathieu equation unstable at (a, q >= 0): a < a_0(q) or b_r(q) < a < a_r(q)."""
    if a < float(mathieu_a(0, q)):
        return True
    return any(float(mathieu_b(r, q)) < a < float(mathieu_a(r, q)) for r in range(1, order))


def _distance_to_boundary(a, q, order=6):
    curves = [float(mathieu_a(0, q))] + [float(f(r, q)) for r in range(1, order) for f in (mathieu_a, mathieu_b)]
    return min(abs(a - c) for c in curves)


def test_stability_chart_matches_mathieu_characteristic_curves():
    problem = studies.mathieu_problem(damping_ratio=0.0, force=0.0)
    speeds, epsilons = np.linspace(0.6, 3.0, 13), np.linspace(0.05, 0.8, 6)
    chart = studies.stability_chart(problem, ("speed", speeds), ("epsilon", epsilons), n_steps=64)
    compared = 0
    for i, speed in enumerate(speeds):
        for j, eps in enumerate(epsilons):
            a = 4.0 / speed**2
            q = eps * a / 2
            # Newmark's relative frequency error (w h)^2 / 12 <= 0.006 here shifts a (~ w^2) by at most
            # ~1.2 %; points within 5 % of a characteristic curve are too close to call.
            if _distance_to_boundary(a, q) < 0.05 * a:
                continue
            compared += 1
            assert (chart.spectral_radius[i, j] > 1 + chart.stability_tol) == _mathieu_unstable(a, q), (speed, eps)
    assert compared >= 50
    assert chart.spectral_radius.shape == (13, 6) and chart.done.all()


def test_stability_chart_error_estimate_of_a_damped_oscillator():
    problem = studies.mathieu_problem(epsilon=0.0, force=0.0)
    speeds, zetas = np.array([0.4, 0.9, 2.5]), np.array([0.02, 0.1])
    chart = studies.stability_chart(problem, ("speed", speeds), ("damping_ratio", zetas), n_steps=32)
    period = 2 * np.pi / speeds[:, None]
    exact = np.exp(-zetas[None, :] * period)  # |mu| of an underdamped pair: exp(-zeta w0 T)
    error = np.abs(chart.spectral_radius - exact)
    # order 2: the N/2 difference over 3 is the leading error term; 1.5 allows the next one at 32 steps
    assert np.all(error <= 1.5 * chart.spectral_radius_error) and np.all(error > 0)


# ---------------------------------------------------------------------------------------------------
# Campbell diagram: two modes whose frequencies cross as the speed grows
# ---------------------------------------------------------------------------------------------------
def test_campbell_tracks_crossing_modes_by_mac(crossing_problem):
    speeds = np.linspace(0.5, 2.5, 11)  # crossing at sqrt(3) = 1.732, between grid points
    result = studies.campbell(crossing_problem(), speeds, n_steps=256, frozen_samples=8)
    first = result.mode_labels.index("mode 1 (x1)")
    second = result.mode_labels.index("mode 2 (x2)")
    np.testing.assert_allclose(result.band_mean[:, first], np.sqrt(1 + 0.5 * speeds**2), rtol=1e-12)
    np.testing.assert_allclose(result.band_mean[:, second], np.sqrt(4 - 0.5 * speeds**2), rtol=1e-12)
    assert np.all(result.tracking_mac[1:] > 0.999)
    # sorted by value the columns swap at the crossing; tracking undoes it
    assert result.order[0].tolist() == [0, 1] and result.order[-1].tolist() == [1, 0]
    # Floquet characteristic frequencies: the damped frequencies, to Newmark's relative frequency
    # error (w h)^2 / 12 (twice it as tolerance); the N/2 estimate within a factor 1.5 of the error
    for i, speed in enumerate(speeds):
        h = 2 * math.pi / speed / 256
        for w2 in (1 + 0.5 * speed**2, 4 - 0.5 * speed**2):
            damped = math.sqrt(w2 - 0.01**2)
            tol = 2 * (damped * h) ** 2 / 12 * damped
            k = np.argmin(np.abs(result.characteristic[i] - damped))
            error = abs(result.characteristic[i, k] - damped)
            assert error <= tol
            assert error / 1.5 <= result.characteristic_error[i, k] <= 1.5 * error


# ---------------------------------------------------------------------------------------------------
# nonlinear check
# ---------------------------------------------------------------------------------------------------
def test_nonlinear_check_without_nonlinearity_reproduces_the_linear_solution():
    problem = studies.mathieu_problem(epsilon=0.2, damping_ratio=0.1, cubic=0.0)
    check = studies.nonlinear_check(problem, {"speed": 0.7}, n_steps=256, n_periods=3, from_rest=True,
                                    max_periods_from_rest=20)
    # The linear model is exact here, so the differences are Newmark's error (DOP853 at rtol 1e-10 is
    # far more accurate): bounded by 1.5 x the estimate (see the steady-state test).
    assert check.difference["x"] <= 1.5 * check.linear_error["x"]
    # Started from a state off by the Newmark error e, the run carries a decaying free vibration of
    # size <= e: two consecutive periods then differ by at most 2 e (|mu| < 1).
    assert check.periodicity_defect["x"] <= 2 * 1.5 * check.linear_error["x"]
    # from rest the transient decays as exp(-zeta w0 t): after 20 periods (180 s) by exp(-18)
    assert check.rest_difference["x"] <= 1.5 * check.linear_error["x"] + 1e-6
    assert 2 <= check.periods_to_steady <= 20
    assert check.nonlinear_run_time > 0 and check.rest_run_time > 0 and check.linear_run_time > 0


def test_nonlinear_difference_is_first_order_in_the_nonlinearity():
    def difference(cubic):
        problem = studies.mathieu_problem(epsilon=0.2, damping_ratio=0.05, cubic=cubic)
        return studies.nonlinear_check(problem, {"speed": 0.7}, n_steps=512, n_periods=3).difference["x"]

    small, double = difference(1e-3), difference(2e-3)
    # d = c kappa + O(kappa^2) + Newmark error (~1e-5 << d ~ 1e-2): the ratio is 2 to O(kappa A^2) ~ 1 %
    assert double / small == pytest.approx(2.0, rel=0.05)


def test_nonlinear_check_needs_a_nonlinear_model(crossing_problem):
    with pytest.raises(ValueError, match="no nonlinear model"):
        studies.nonlinear_check(crossing_problem())


# ---------------------------------------------------------------------------------------------------
# error against run time
# ---------------------------------------------------------------------------------------------------
def test_error_cost_shows_second_order_and_a_sharp_estimate():
    problem = studies.mathieu_problem(epsilon=0.3, damping_ratio=0.05)
    result = studies.error_cost(problem, {"speed": 1.3}, n_steps=(32, 64, 128, 256))
    error = result.error["x"][0]
    slopes = np.log2(error[:-1] / error[1:])
    assert np.all(np.abs(slopes[1:] - 2.0) <= 0.1), slopes  # Newmark gamma = 1/2 is of order 2
    ratio = result.error_estimate["x"][0] / error
    assert np.all((ratio[1:] > 0.8) & (ratio[1:] < 1.25)), ratio
    assert result.point_run_time.shape == (1, 4) and np.all(result.point_run_time > 0)


def test_error_cost_over_a_resolution_parameter(crossing_problem):
    problem = crossing_problem()
    result = studies.error_cost(problem, {"speed": 0.8}, n_steps=(32, 64),
                                resolution=("damping", (0.02, 0.04)))
    assert result.error["x1"].shape == (2, 2) and result.resolution_parameter == "damping"
    # the reference uses the last resolution: its error falls with the steps, the other's does not
    # (a different damping is a different answer, not a coarser one)
    assert result.error["x1"][1, 1] < result.error["x1"][1, 0] < result.error["x1"][0, 1]
