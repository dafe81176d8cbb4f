"""The period map of a mechanism with lagged controllers (mechanisms.PeriodMap with shooting state
(z, z', y)) against independent references: central finite differences of the map for its monodromy,
and a long transient of mechanisms.simulate (lag states included) for the nonlinear periodic state."""

import numpy as np
import pytest

import mechanisms
import studies
from studies._kinds.nonlinear_steady_state import shooting_setup  # the kind's period maps: no public face
from tests._support.tangent_twin import central_differences, tangent_numpy, tight_period_map

SPEC = "coupler.deflection@0.5"
TAU = 5e-3           # the strain feedback's lag, s: h / tau = 0.1 at N = 128 (period 63 ms)
N_STEPS = 128


@pytest.fixture(scope="module")
def lagged():
    return mechanisms.load("four_bar_controlled").with_parameter("controllers.strain.lag", TAU)


@pytest.fixture(scope="module")
def problem(lagged):
    return studies.MechanismProblem.from_mechanism(lagged, observables=(SPEC,))


def test_shooting_state_ends_with_the_lag_states(lagged, problem):
    setup = shooting_setup(problem, None, 32)
    fine, steady = setup.fine, setup.steady
    m = fine.independent.size
    assert fine.n_lags == 1 and fine.n_state == 2 * m + 1
    assert fine.labels[-1] == "lag.strain" == setup.linear.labels[-1]
    # the guess carries the linear periodic state's lag state (its last coordinate at t = 0)
    assert setup.guess[-1] == steady.state.x[0, -1] != 0.0
    assert fine.lag_states_of(setup.guess).tolist() == [setup.guess[-1]]
    s, sdot = fine.start_state(setup.guess)
    np.testing.assert_array_equal(fine.state_of(s, sdot, lag_states=setup.guess[-1:]), setup.guess)
    assert fine.state_of(s, sdot)[-1] == 0.0                 # default: the lag at rest
    run = fine.run(setup.guess, tangent=False)
    assert run.lag_states[0, 0] == setup.guess[-1] and run.end_state[-1] == run.lag_states[-1, 0]
    with pytest.raises(mechanisms.ArgumentError, match=r"then the lag states \['strain'\]"):
        fine.run(setup.guess[:-1])
    with pytest.raises(mechanisms.ArgumentError, match=r"`lag_states` must have shape \(1,\)"):
        fine.state_of(s, sdot, lag_states=[0.0, 1.0])


@pytest.mark.slow
def test_monodromy_with_lags_matches_finite_differences_of_the_period_map(problem):
    setup = shooting_setup(problem, None, 64)
    period_map = tight_period_map(setup)
    x0 = setup.guess
    monodromy = period_map.run(x0).monodromy
    m = period_map.independent.size
    # coordinates and rates: steps 1e-5 of the block's size, as the unlagged test; the lag states: 1e-3,
    # the map being nearly linear in y (the force it adds is linear), where smaller steps only raise
    # the noise of the integrator's Newton tolerance (~1e-12 / step: 2e-7 at 1e-3, 3e-6 at 1e-5)
    blocks = ((slice(0, m), 1e-5), (slice(m, 2 * m), 1e-5), (slice(2 * m, None), 1e-3))
    differences = central_differences(period_map, x0, blocks)
    scale = np.abs(monodromy).max()
    assert np.abs(monodromy - differences).max() <= 1e-4 * scale
    # the lag's row and column, each against its own size (other units than the rest): the row as
    # closely as the whole (its largest error in the stiff axial column, as every row's), the column
    # much closer
    lag = 2 * m
    row_error = np.abs(monodromy[lag] - differences[lag]).max() / np.abs(monodromy[lag]).max()
    column_error = np.abs(monodromy[:, lag] - differences[:, lag]).max() / np.abs(monodromy[:, lag]).max()
    assert row_error <= 1e-4 and column_error <= 1e-6
    leading = np.sort(np.abs(np.linalg.eigvals(monodromy)))[::-1][:2]
    leading_fd = np.sort(np.abs(np.linalg.eigvals(differences)))[::-1][:2]
    np.testing.assert_allclose(leading, leading_fd, rtol=1e-4)


@pytest.mark.slow
def test_lagged_periodic_state_equals_the_end_of_a_long_transient(lagged, problem):
    shot = studies.nonlinear_steady_state(problem, n_steps=N_STEPS)
    assert shot.status == "ok", shot.message
    assert shot.labels[-1] == "lag.strain" and shot.x.shape == (N_STEPS + 1, len(shot.labels))
    # the transient: mechanisms.simulate from the linear periodic state (lags started there too), not
    # the period map; the slowest multiplier (~0.44) leaves 0.44^30 ~ 2e-11 of the start
    setup = shooting_setup(problem, None, N_STEPS)
    lin = setup.linear.context
    x0 = setup.steady.state.x[0]
    s0, sdot0 = lin.start_state(x0, setup.steady.state.v[0])
    periods = 30
    run = mechanisms.simulate(lagged, n_periods=periods, steps_per_period=N_STEPS, s0=s0, sdot0=sdot0,
                              lag0=x0[-1:], observables=[SPEC], estimate_error=False)
    observable = setup.fine.model.observable(SPEC)
    nominal = np.array([observable.value(s) for s in lin.nominal.s])
    last = slice(-N_STEPS - 1, None)
    previous = slice(-2 * N_STEPS - 1, -N_STEPS)
    deflection = run.observables[SPEC][last] - nominal
    lag_state = run.lag_states[last, 0]
    # settled: successive periods agree far below the error estimates
    assert np.abs(deflection - (run.observables[SPEC][previous] - nominal)).max() <= 1e-6 * np.ptp(deflection)
    assert np.abs(lag_state - run.lag_states[previous, 0]).max() <= 1e-6 * np.ptp(lag_state)
    # the shooting's orbit is the transient's end within its error estimates (N against N/2), not closer:
    # each period of the shooting restarts the integrator (alpha acceleration a_0 = sddot_0), which the
    # transient does not, an O(h^2) difference
    assert np.abs(deflection - shot.response[SPEC]).max() <= shot.response_error[SPEC]
    assert np.abs(lag_state - shot.x[:, -1]).max() <= shot.error_estimate


def test_a_sweep_of_a_lag_must_stay_above_zero(lagged):
    problem = studies.MechanismProblem.from_mechanism(lagged, parameter_paths=["controllers.strain.lag"],
                                                      observables=(SPEC,))
    with pytest.raises(studies.StudiesError, match="a lag of 0 removes the controller's state"):
        studies.nonlinear_sweep(problem, "controllers.strain.lag", start=0.0, stop=TAU)


@pytest.mark.parametrize("scene, lag", [("four_bar_fem4", None), ("four_bar_controlled", TAU)])
def test_tangent_kernel_equals_its_numpy_twin(scene, lag):
    # the numba kernel (one LAPACK factorisation and loops per step, lag rows included) against the
    # differentiated step written out in numpy with a dense solve per step
    from mechanisms._alpha_tangent import _propagate_tangent  # internal kernel: no public face

    mechanism = mechanisms.load(scene)
    if lag is not None:
        mechanism = mechanism.with_parameter("controllers.strain.lag", lag)
    setup = shooting_setup(studies.MechanismProblem.from_mechanism(mechanism, observables=(SPEC,)), None, 32)
    period_map, x = setup.fine, setup.guess
    run = period_map._period_arrays(x, 1)
    start = period_map._start_sensitivity(x)
    lag_start = np.eye(period_map.n_lags, period_map.n_state, 2 * period_map.independent.size)
    kernel, kernel_lags = _propagate_tangent(period_map.model, run, period_map.h, period_map.rho_inf, start,
                                             lag_start)
    twin, twin_lags = tangent_numpy(period_map.model, run, period_map.h, period_map.rho_inf, start, lag_start)
    assert np.abs(kernel - twin).max() <= 1e-9 * np.abs(twin).max()
    assert kernel_lags.shape == twin_lags.shape == (period_map.n_lags, period_map.n_state)
    if period_map.n_lags:
        assert np.abs(kernel_lags - twin_lags).max() <= 1e-9 * np.abs(twin_lags).max()


def test_a_run_started_with_lag_states_starts_on_the_equations_with_their_force(lagged):
    # the start's accelerations and multipliers solve M sddot + Phi_s^T lam = Q + H^T y0 (the force
    # every step applies), not the equations without the lag force
    y0 = 0.125
    run = mechanisms.simulate(lagged, n_periods=0.25, steps_per_period=64, lag0=[y0], estimate_error=False)
    model = mechanisms.integrated_model(lagged)
    s, sdot, t = run.s[0], run.sdot[0], run.t[0]
    residual = (model.mass_matrix(s) @ run.sddot[0] + model.constraint_jacobian(s, t).T @ run.lam[0]
                - model.forces(s, sdot, t) - y0 * np.asarray(model.lag_gradients)[0])
    scale = np.abs(model.forces(s, sdot, t)).max()
    assert np.abs(residual).max() <= 1e-10 * scale
    without = residual + y0 * np.asarray(model.lag_gradients)[0]
    assert np.abs(without).max() > 1e3 * np.abs(residual).max()
