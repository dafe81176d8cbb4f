"""Parameter derivatives of steady states (issue 20): ``periodic.response_derivative`` on a forced damped
Mathieu equation against central differences of a high-accuracy scipy solution, the multiplier's
derivative against the differentiated multiplier of a scipy monodromy, ``studies.sensitivity`` on the
thesis four-bar against central differences of fresh steady states (a parameter that moves the
kinematics, section and damping parameters, and the speed), and the study's table, verdicts and file."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import periodic
import studies

W0 = 1.0


def _system(zeta, eps, force, speed, n_steps):
    period = 2.0 * math.pi / speed
    return periodic.PeriodicSystem.from_functions(
        period, lambda t: np.eye(1), lambda t: np.array([[2.0 * zeta * W0]]),
        lambda t: np.array([[W0**2 * (1.0 + eps * math.cos(speed * t))]]),
        lambda t: np.array([force * math.cos(speed * t)]), n_steps=n_steps)


def _flow(zeta, eps, force, speed, start, times):
    """x(t) of the Mathieu equation from ``start`` at the ``times`` (DOP853, rtol 1e-12)."""
    def rhs(t, y):
        return [y[1], -2.0 * zeta * W0 * y[1] - W0**2 * (1.0 + eps * math.cos(speed * t)) * y[0]
                + force * math.cos(speed * t)]
    return solve_ivp(rhs, (0.0, times[-1]), start, method="DOP853", rtol=1e-12, atol=1e-14, t_eval=times).y


def _exact(zeta, eps, force, speed, phases):
    """The periodic solution at the phases (fractions of the period) and the monodromy, by scipy."""
    period = 2.0 * math.pi / speed
    end = [period]
    rest = _flow(zeta, eps, force, speed, [0.0, 0.0], end)[:, -1]
    phi = np.column_stack([_flow(zeta, eps, 0.0, speed, unit, end)[:, -1] for unit in ([1.0, 0.0], [0.0, 1.0])])
    start = np.linalg.solve(np.eye(2) - phi, rest)
    return _flow(zeta, eps, force, speed, start, phases * period)[0], phi


def _derivatives(zeta, eps, force, speed, t):
    """SystemDerivative of zeta, eps, force and the speed (fixed phase: only the period moves)."""
    ones = np.ones((t.size, 1, 1))
    return [periodic.SystemDerivative(C=2.0 * W0 * ones),
            periodic.SystemDerivative(K=(W0**2 * np.cos(speed * t))[:, None, None]),
            periodic.SystemDerivative(f=np.cos(speed * t)[:, None]),
            periodic.SystemDerivative(log_period=-1.0 / speed)]


POINT = np.array([0.05, 0.3, 1.0, 1.3])   # zeta, eps, force, speed


@pytest.fixture(scope="module")
def mathieu():
    n_steps = 256
    system = _system(*POINT, n_steps)
    state = periodic.steady_state(system)
    return system, state, periodic.response_derivative(system, state, _derivatives(*POINT, system.t))


def test_response_derivative_against_scipy_reference(mathieu):
    system, _, found = mathieu
    phases = np.arange(system.n_steps + 1) / system.n_steps
    for j in range(4):
        h = 1e-4 * POINT[j]
        up, down = POINT.copy(), POINT.copy()
        up[j] += h
        down[j] -= h
        reference = (_exact(*up, phases)[0] - _exact(*down, phases)[0]) / (2.0 * h)
        error = np.abs(found.x[j, :, 0] - reference).max()
        # the N/2 estimate is the actual error to leading order (within 20 % here), and small
        assert error <= 1.2 * found.error_estimate[j]
        assert error >= 0.8 * found.error_estimate[j]
        assert found.error_estimate[j] < 1e-3 * np.abs(reference).max() + 1e-3


def test_response_derivative_is_the_discrete_solutions_derivative(mathieu):
    """Direct differentiation of the discrete problem: the derivative of the N-step solution itself
    (central differences of fresh shootings), to the differences' truncation."""
    system, _, found = mathieu
    for j in range(4):
        h = 1e-4 * POINT[j]
        up, down = POINT.copy(), POINT.copy()
        up[j] += h
        down[j] -= h
        a = periodic.steady_state(_system(*up, system.n_steps))
        b = periodic.steady_state(_system(*down, system.n_steps))
        difference = (a.x - b.x)[:, 0] / (2.0 * h)
        assert np.abs(found.x[j, :, 0] - difference).max() <= 1e-6 * np.abs(difference).max()
        radius = (abs(a.critical_multiplier) - abs(b.critical_multiplier)) / (2.0 * h)
        assert found.radius[j] == pytest.approx(radius, rel=1e-6, abs=1e-9)


def test_radius_derivative_against_exact_monodromy():
    """Inside the principal instability tongue (speed = 2 w0) the critical multiplier is real and its
    modulus depends on every parameter: its derivative against central differences of the critical
    eigenvalue of the scipy monodromy."""
    point = np.array([0.02, 0.3, 0.0, 2.0])
    system = _system(*point, 512)
    state = periodic.steady_state(system)
    found = periodic.response_derivative(system, state, _derivatives(*point, system.t))
    assert not found.repeated
    for j in (0, 1, 3):
        h = 1e-4 * point[j]
        up, down = point.copy(), point.copy()
        up[j] += h
        down[j] -= h
        moduli = [np.abs(np.linalg.eigvals(_exact(*p, np.array([0.0, 1.0]))[1])).max() for p in (up, down)]
        exact = (moduli[0] - moduli[1]) / (2.0 * h)
        assert abs(found.radius[j] - exact) <= 3.0 * found.radius_error[j] + 1e-9
        assert found.radius_error[j] < 1e-2 * abs(exact)


def test_repeated_multiplier_is_said():
    """Two identical uncoupled oscillators: every multiplier is double, the derivative is not defined."""
    n_steps = 64
    t = np.arange(n_steps + 1) * (2.0 * math.pi / n_steps)
    system = periodic.PeriodicSystem(2.0 * math.pi, np.repeat(np.eye(2)[None], n_steps + 1, 0),
                                     np.repeat(0.1 * np.eye(2)[None], n_steps + 1, 0),
                                     np.repeat(2.0 * np.eye(2)[None], n_steps + 1, 0),
                                     np.column_stack([np.cos(t), np.zeros_like(t)]))
    state = periodic.steady_state(system)
    found = periodic.response_derivative(system, state, [periodic.SystemDerivative(
        C=np.repeat(np.eye(2)[None], n_steps + 1, 0))])
    assert found.repeated and np.isnan(found.radius).all()
    assert "repeated" in found.message


def test_response_derivative_refuses_bad_input(mathieu):
    system, state, _ = mathieu
    with pytest.raises(periodic.PeriodicError, match="derivatives"):
        periodic.response_derivative(system, state, [])
    with pytest.raises(periodic.PeriodicError, match=r"derivatives\[0\]\.K"):
        periodic.response_derivative(system, state, [periodic.SystemDerivative(K=np.zeros((3, 1, 1)))])
    extrapolated = periodic.steady_state(system, extrapolate=True)
    with pytest.raises(periodic.PeriodicError, match="extrapolate"):
        periodic.response_derivative(system, extrapolated, [periodic.SystemDerivative(log_period=1.0)])


# ---------------------------------------------------------------------------------------------------
# the study
# ---------------------------------------------------------------------------------------------------
def test_mathieu_study_forcing_normalised_and_input_band():
    """The response is linear in the force: d ln(peak-to-peak) / d ln(force) = 1 exactly, and a
    tolerance on the force gives the band peak_to_peak * tol / force."""
    problem = studies.mathieu_problem(speed=0.7)
    result = studies.sensitivity(problem, parameters=["force", "damping_ratio"], n_steps=128,
                                 tolerances={"force": 0.01})
    assert result.normalised["peak_to_peak"]["x"]["force"] == pytest.approx(1.0, rel=1e-9)
    assert result.normalised["rms"]["x"]["force"] == pytest.approx(1.0, rel=1e-9)
    assert result.input_band["peak_to_peak"]["x"] == pytest.approx(result.peak_to_peak["x"] * 0.01, rel=1e-9)
    # the force does not enter the multipliers
    assert result.radius_derivative["force"] == 0.0
    # damping: the radius |mu| = exp(-zeta w0 T) of the complex pair (Liouville), exactly differentiated
    period = 2.0 * math.pi / 0.7
    expected = -W0 * period * math.exp(-0.02 * W0 * period)
    assert abs(result.radius_derivative["damping_ratio"] - expected) <= (
        3.0 * result.radius_derivative_error["damping_ratio"] + 1e-9)


def test_peak_that_switches_instant_is_said():
    """Without parametric excitation the response is a pure harmonic: its maximum and minimum have the
    same magnitude, so which one is the peak (and the peak's derivative) is not defined."""
    result = studies.sensitivity(studies.mathieu_problem(epsilon=0.0, speed=0.7), parameters=["force"],
                                 n_steps=64)
    assert result.status == "inaccurate"
    assert "the maximum and the minimum" in result.message


@pytest.fixture(scope="module")
def four_bar():
    names = ["speed", "links.coupler.thickness", "links.crank.length", "links.coupler.damping.ratio"]
    problem = studies.MechanismProblem.from_scene(
        "four_bar_fem4", parameter_paths=names[1:],
        observables=["coupler.deflection@0.5", "joint.B.force", "drive.O.torque"])
    return problem, studies.sensitivity(problem, parameters=names, n_steps=128)


def test_four_bar_against_fresh_steady_states(four_bar):
    """Central differences of fresh steady states (linearisation and shooting at each value): the
    derivative of the same N-step solution, so they agree far below the time step's error (the
    coefficients' forward difference and the differences' own truncation remain)."""
    problem, result = four_bar
    assert result.methods["links.crank.length"] == "central"        # it moves the kinematics
    assert result.methods["links.coupler.thickness"] == "analytic"   # exact: it moves the mass, not the linkage
    assert result.methods["links.coupler.damping.ratio"] == "analytic"  # its damping kind differentiates it
    for name in result.names:
        value = result.parameters[name]
        h = 1e-4 * value
        up = studies.steady_state(problem, {name: value + h}, n_steps=128)
        down = studies.steady_state(problem, {name: value - h}, n_steps=128)
        for spec in result.derivative:
            for mine, field in ((result.derivative, "peak_to_peak"), (result.peak_derivative, "peak")):
                difference = (getattr(up, field)[spec] - getattr(down, field)[spec]) / (2.0 * h)
                assert mine[spec][name] == pytest.approx(difference, rel=1e-3), (name, spec, field)


def test_four_bar_radius_against_fresh_multipliers(four_bar):
    """Central differences of fresh multipliers. Their step is 1e-3 of the value: the radius of a
    fresh solve (nominal motion, linearisation, shooting) scatters by about 4.5e-12 as the crank
    length moves (nine values within 1e-5 of it about a quadratic, the code before and after the
    model kernels took samples along an axis alike), which at a step of 1e-4 is up to 1.5e-4 of
    this derivative, above the tolerance; at 1e-3 it is 1.5e-5."""
    problem, result = four_bar
    for name in result.names:
        value = result.parameters[name]
        h = 1e-3 * value
        moduli = [abs(periodic.steady_state(problem.linearize({name: v}, n_steps=128).system).critical_multiplier)
                  for v in (value + h, value - h)]
        assert result.radius_derivative[name] == pytest.approx((moduli[0] - moduli[1]) / (2.0 * h), rel=1e-4)


def test_four_bar_errors_and_round_trip(four_bar, tmp_path):
    _, result = four_bar
    for spec, row in result.derivative.items():
        for name, value in row.items():
            assert 0.0 < result.derivative_error[spec][name] < abs(value), (spec, name)
    path = tmp_path / "sensitivity.h5"
    result.save(path)
    back = studies.load(path)["sensitivity"]
    assert back.derivative == result.derivative
    assert back.normalised == result.normalised
    assert back.names == result.names
    figure = result.plot()
    assert len(figure.axes) == len(result.derivative) + 1


def test_table_checks():
    kind = studies.kinds()["sensitivity"]
    with pytest.raises(studies.StudiesError, match="missing parameters"):
        kind.check("studies.sensitivity", {}, 128)
    with pytest.raises(studies.StudiesError, match="count"):
        kind.check("studies.sensitivity", {"parameters": ["links.coupler.discretisation.n_elements"]}, 128)
    with pytest.raises(studies.StudiesError, match="not among the parameters"):
        kind.check("studies.sensitivity", {"parameters": ["speed"], "tolerances": {"links": {"a": 1.0}}}, 128)
    options = kind.check("studies.sensitivity", {"parameters": ["links.coupler.thickness"],
                                                 "tolerances": {"links": {"coupler": {"thickness": 5e-5}}}}, 128)
    assert options["tolerances"] == {"links.coupler.thickness": 5e-5}
    assert kind.varies(options) == ("links.coupler.thickness",)


def test_optimize_with_gradients_reaches_the_same_optimum_with_fewer_evaluations():
    """Den Hartog's absorber (tests/test_optimize.py) on a coarser band: the local method with the
    sensitivities' gradients and with forward differences of whole sweeps reach the same optimum; the
    gradients cost no sweeps (here 7 evaluations against 21)."""
    from tests.test_optimize import absorber_problem

    found = {gradient: studies.optimize(absorber_problem(), {"tuning": (0.85, 1.05), "damping_ratio": (0.05, 0.25)},
                                        objective="rms:x1", speeds=np.linspace(0.85, 1.10, 26), n_steps=64,
                                        check=False, gradient=gradient)
             for gradient in ("sensitivities", "differences")}
    ours, theirs = found["sensitivities"], found["differences"]
    assert ours.status == theirs.status == "ok"
    assert ours.x == pytest.approx(theirs.x, rel=1e-6)
    assert ours.objective_value == pytest.approx(theirs.objective_value, rel=1e-9)
    assert ours.n_evaluations < theirs.n_evaluations / 2
    assert ours.gradients.startswith("sensitivities") and "differences" in theirs.gradients


def test_optimize_says_when_it_falls_back_to_differences():
    """A mass budget offers no gradient: the local method takes forward differences and says so."""
    problem = studies.MechanismProblem.from_scene("four_bar_fem1", parameter_paths=["links.coupler.thickness"])
    found = studies.optimize(problem, {"links.coupler.thickness": (1.4e-3, 1.8e-3)},
                             objective="peak_to_peak:coupler.deflection@0.5", n_steps=32, max_evaluations=3,
                             check=False, constraints=[studies.MassBudget(10.0)])
    assert "forward differences" in found.gradients and "mass" in found.gradients


def test_a_scheme_without_march_forcings_marches_column_by_column():
    """A registered scheme of another family (the theta-method of tests/_support/extensions.py, which
    has no ``march_forcings``): the derivative is still its own discrete solution's (central
    differences of its fresh shootings)."""
    from tests._support import extensions

    scheme = extensions.THETA_SCHEMES["theta-0.6"]
    point, n_steps = POINT.copy(), 64
    system = _system(*point, n_steps)
    state = periodic.steady_state(system, scheme=scheme)
    found = periodic.response_derivative(system, state, _derivatives(*point, system.t)[:3], scheme=scheme)
    for j in range(3):
        h = 1e-4 * point[j]
        up, down = point.copy(), point.copy()
        up[j] += h
        down[j] -= h
        a = periodic.steady_state(_system(*up, n_steps), scheme=scheme)
        b = periodic.steady_state(_system(*down, n_steps), scheme=scheme)
        difference = (a.x - b.x)[:, 0] / (2.0 * h)
        assert np.abs(found.x[j, :, 0] - difference).max() <= 1e-6 * np.abs(difference).max()
