"""Analytic coefficient derivatives of the sensitivities (issue 20): a link's damping differentiated by its
damping kind (``matrix_derivative``) against central differences of the linearisation's coefficients and
maps, and the headlines' derivatives through that route against central differences of fresh steady
states (prescribed and torque-driven four-bars, Rayleigh alpha, beta and the ratio)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import linearize
import mechanisms
import studies

N_STEPS = 64
OBSERVABLES = ["coupler.deflection@0.5", "joint.B.force", "drive.O.torque"]


def _rayleigh_scene(scene: str, alpha: float, beta: float):
    """``scene`` with its coupler's damping as Rayleigh alpha and beta (instead of the ratio)."""
    text = mechanisms.load(scene).to_toml()
    marker = "[links.coupler.damping]"
    head, tail = text.split(marker)
    body, rest = tail.split("\n[", 1) if "\n[" in tail else (tail, "")
    table = f'{marker}\ntype = "rayleigh"\nalpha = {alpha!r}\nbeta = {beta!r}\n'
    return mechanisms.build(__import__("tomllib").loads(head + table + ("\n[" + rest if rest else "")),
                            source=f"{scene} with Rayleigh alpha, beta")


@pytest.fixture(scope="module")
def rayleigh_problem():
    mechanism = _rayleigh_scene("four_bar_fem4", alpha=3.0, beta=1.2e-4)
    return studies.MechanismProblem.from_mechanism(
        mechanism, parameter_paths=["links.coupler.damping.alpha", "links.coupler.damping.beta"],
        observables=OBSERVABLES)


def _central_coefficients(problem, name, relative=1e-4):
    value = problem.parameters[name]
    h = relative * value
    up = problem.linearize({name: value + h}, n_steps=N_STEPS)
    down = problem.linearize({name: value - h}, n_steps=N_STEPS)
    return up, down, h


@pytest.mark.parametrize("name", ["links.coupler.damping.alpha", "links.coupler.damping.beta"])
def test_rayleigh_coefficients_against_central_differences(rayleigh_problem, name):
    """dC (and dK, dM, df, d ln T: zero) of the damping kind's closed form against central differences
    of two fresh linearisations; the maps of the observables do not move."""
    problem = rayleigh_problem
    linear = problem.linearize({}, n_steps=N_STEPS)
    closed = linearize.analytic_derivative(linear.context, name)
    assert closed is not None
    up, down, h = _central_coefficients(problem, name)
    for field in "MCKf":
        difference = (getattr(up.system, field) - getattr(down.system, field)) / (2.0 * h)
        mine = getattr(closed, field)
        mine = np.zeros_like(difference) if mine is None else mine
        scale = max(np.abs(difference).max(), np.abs(linear.system.C).max() / problem.parameters[name])
        assert np.abs(mine - difference).max() <= 1e-7 * scale, field
    assert np.abs(closed.C).max() > 0.0
    assert closed.log_period == 0.0 == np.log(up.system.period / down.system.period)
    z = 1e-4 * np.random.default_rng(1).standard_normal(linear.system.f.shape)
    z[-1] = z[0]
    np.testing.assert_allclose(up.observe(z), down.observe(z), rtol=1e-12, atol=0.0)


def test_ratio_on_a_torque_drive_against_central_differences():
    """The ratio on the closed-loop four-bar (the crank angle an independent coordinate, lag states)."""
    name = "links.coupler.damping.ratio"
    problem = studies.MechanismProblem.from_scene("four_bar_controlled", parameter_paths=[name],
                                                  observables=OBSERVABLES)
    linear = problem.linearize({}, n_steps=N_STEPS)
    closed = linearize.analytic_derivative(linear.context, name)
    up, down, h = _central_coefficients(problem, name)
    for field in "CK":
        difference = (getattr(up.system, field) - getattr(down.system, field)) / (2.0 * h)
        assert np.abs(getattr(closed, field) - difference).max() <= 1e-7 * np.abs(difference).max(), field
    for field in "Mf":
        assert np.abs(getattr(up.system, field) - getattr(down.system, field)).max() <= 1e-9 * np.abs(
            getattr(linear.system, field)).max()


def test_no_closed_form_falls_back():
    """A parameter that no part differentiates (a section property, a length) gets None here, and the
    study differences linearisations for it."""
    problem = studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=["links.coupler.thickness"])
    linear = problem.linearize({}, n_steps=N_STEPS)
    assert linearize.analytic_derivative(linear.context, "links.coupler.thickness") is None
    assert linearize.analytic_derivative(linear.context, "links.crank.damping.ratio") is None  # a rigid link


def test_headlines_through_the_analytic_route_against_fresh_steady_states(rayleigh_problem):
    """Every headline's derivative with respect to alpha and beta (analytic route) against central
    differences of fresh steady states at the same N, and the result says which route it took.  The step
    is 1e-3 of the value: alpha's normalised sensitivities are about 1e-3, so at 1e-4 the steady states'
    own rounding (1e-12 of the value) is 1e-4 of the difference (measured: the differences at steps 1e-2
    and 1e-3 agree to 2e-5, their truncation)."""
    problem = rayleigh_problem
    names = ["links.coupler.damping.alpha", "links.coupler.damping.beta"]
    result = studies.sensitivity(problem, parameters=names, n_steps=N_STEPS)
    assert result.methods == {name: "analytic" for name in names}
    for name in names:
        value = result.parameters[name]
        h = 1e-3 * value
        up = studies.steady_state(problem, {name: value + h}, n_steps=N_STEPS)
        down = studies.steady_state(problem, {name: value - h}, n_steps=N_STEPS)
        for spec in result.derivative:
            for mine, field in ((result.derivative, "peak_to_peak"), (result.peak_derivative, "peak")):
                difference = (getattr(up, field)[spec] - getattr(down, field)[spec]) / (2.0 * h)
                assert mine[spec][name] == pytest.approx(difference, rel=1e-4), (name, spec, field)


# ---------------------------------------------------------------------------------------------------
# neighbours on the point's kinematics
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("scene", ["four_bar_fem4", "four_bar_controlled"])
def test_nominal_dynamics_against_a_fresh_nominal_motion(scene):
    """The inverse dynamics recomputed on another mechanism's kinematics against that mechanism's own
    nominal motion (the continuation from scratch), and the linearisation on them against ``about``'s."""
    problem = studies.MechanismProblem.from_scene(scene, parameter_paths=["links.coupler.thickness"])
    thicker = problem.mechanism({"links.coupler.thickness": 1.3 * problem.parameters["links.coupler.thickness"]})
    kinematics = mechanisms.nominal_motion(problem.mechanism(), n_steps=N_STEPS)
    reused = mechanisms.nominal_dynamics(thicker, kinematics)
    fresh = mechanisms.nominal_motion(thicker, n_steps=N_STEPS)
    assert np.abs(reused.lam - fresh.lam).max() <= 1e-8 * np.abs(fresh.lam).max()
    assert np.abs(reused.drive_torque - fresh.drive_torque).max() <= 1e-8 * np.abs(fresh.drive_torque).max()
    assert np.abs(reused.lam - kinematics.lam).max() > 1e-3 * np.abs(fresh.lam).max()   # it did change
    mine = linearize.about(thicker, n_steps=N_STEPS, observables=OBSERVABLES, kinematics=kinematics)
    theirs = linearize.about(thicker, n_steps=N_STEPS, observables=OBSERVABLES)
    for field in "MCKf":
        a, b = getattr(mine.system, field), getattr(theirs.system, field)
        assert np.abs(a - b).max() <= 1e-7 * np.abs(b).max(), field


def test_nominal_dynamics_refuses_a_moved_linkage():
    problem = studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=["links.crank.length"])
    kinematics = mechanisms.nominal_motion(problem.mechanism(), n_steps=N_STEPS)
    longer = problem.mechanism({"links.crank.length": 1.001 * problem.parameters["links.crank.length"]})
    with pytest.raises(mechanisms.ArgumentError, match="linkage moved"):
        mechanisms.nominal_dynamics(longer, kinematics)
    with pytest.raises(linearize.LinearizationError, match="kinematics"):
        linearize.about(problem.mechanism(), n_steps=2 * N_STEPS, kinematics=kinematics)


def test_forward_neighbours_off_the_scene_speed_against_fresh_steady_states():
    """At a speed that is not the scene's (a speed family's member) the forward neighbour reuses that
    member's kinematics: the derivatives against fresh steady states at the same point."""
    name = "links.coupler.thickness"
    problem = studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=[name], observables=OBSERVABLES)
    point = {"speed": 1.1 * problem.parameters["speed"]}
    result = studies.sensitivity(problem, point, parameters=[name], n_steps=N_STEPS)
    assert result.methods[name] == "forward"
    value = result.parameters[name]
    h = 1e-4 * value
    up = studies.steady_state(problem, dict(point, **{name: value + h}), n_steps=N_STEPS)
    down = studies.steady_state(problem, dict(point, **{name: value - h}), n_steps=N_STEPS)
    for spec in result.derivative:
        difference = (up.peak_to_peak[spec] - down.peak_to_peak[spec]) / (2.0 * h)
        assert result.derivative[spec][name] == pytest.approx(difference, rel=1e-4), spec


# ---------------------------------------------------------------------------------------------------
# the input term of the error budget (the V&V split)
# ---------------------------------------------------------------------------------------------------
def test_input_term_stays_outside_the_numerical_total():
    """The input term is shown beside the numerical terms and enters neither their total, nor the
    dominant term, nor the unknown terms, nor the tolerance check."""
    from studies._budget import INPUT, ErrorBudget, describe, verdict  # the budget object is internal

    numerical = {"x": {"time_step": 1e-5, "mesh": -2e-5, "linearisation": "not applicable"}}
    with_input = {"x": dict(numerical["x"], **{INPUT: 5e-3})}
    plain, banded = ErrorBudget(numerical), ErrorBudget(with_input)
    assert banded.total("x") == plain.total("x") == pytest.approx(3e-5)
    assert banded.dominant("x") == "mesh"
    assert banded.input_band("x") == 5e-3 and plain.input_band("x") == "not applicable"
    assert verdict(banded, {"x": 1e-2}, 0.02) == verdict(plain, {"x": 1e-2}, 0.02) == ("ok", "")
    assert ErrorBudget({"x": dict(numerical["x"], **{INPUT: float("nan")})}).unknown("x") == []
    words = describe(banded, "x", "m")
    assert "input band 5 mm from the tolerances (apart)" in words and words.startswith("total 0.03 mm")


def test_sensitivity_budget_carries_the_input_band(tmp_path):
    """A sensitivity with tolerances: its peak-to-peak and peak budgets hold the time step's term (the
    numerical total, ``peak_to_peak_error``) and the input term (``input_band``), through the file and
    the summary; a file written before the budgets reads them from its stored errors and band."""
    problem = studies.mathieu_problem(speed=0.7)
    result = studies.sensitivity(problem, parameters=["speed", "damping_ratio"], n_steps=64,
                                 tolerances={"damping_ratio": 0.002, "speed": 1e-3})
    for spec in result.derivative:
        band = math.hypot(result.derivative[spec]["damping_ratio"] * 0.002, result.derivative[spec]["speed"] * 1e-3)
        assert result.error_budget[spec]["input"] == pytest.approx(band, rel=1e-12)
        assert result.budget.total(spec) == result.peak_to_peak_error[spec]
        assert result.peak_error_budget[spec]["input"] == result.input_band["peak"][spec]
        assert result.error_budget[spec]["mesh"] == "not applicable"    # a periodic problem has no mesh
    kind = studies.kinds()["sensitivity"]
    assert "from the tolerances (apart)" in kind.summary(result)
    assert any(row.quantity.startswith("input band") for row in kind.headlines(result).rows)
    path = tmp_path / "sensitivity.h5"
    result.save(path)
    back = studies.load(path)["sensitivity"]
    assert back.error_budget == result.error_budget and back.error_methods == result.error_methods

    class Before:        # a group of a file written before the budgets: no error_budget attribute
        attrs: dict = {}

    filled = result._filled(Before())
    assert filled["error_budget"] == {spec: dict(terms, mesh="not estimated", linearisation="not estimated")
                                      for spec, terms in result.error_budget.items()}
    without = studies.sensitivity(problem, parameters=["speed"], n_steps=64)
    assert all("input" not in terms for terms in without.error_budget.values())
    assert "input" not in without.error_methods


def test_gains_keep_the_rigid_dynamics():
    """A controller's gain leaves the rigid inverse dynamics alone (the nominal motion's model drops
    the controllers): the kinematics come back as they are, and the linearisation on them equals a
    fresh one at the new gain."""
    name = "controllers.strain.gain"
    problem = studies.MechanismProblem.from_scene("four_bar_controlled", parameter_paths=[name],
                                                  observables=OBSERVABLES)
    point = problem.linearize({}, n_steps=N_STEPS)
    values = {name: 1.7 * problem.parameters[name]}
    assert mechanisms.nominal_dynamics(problem.mechanism(values), point.context.nominal) is point.context.nominal
    mine = problem.linearize(values, n_steps=N_STEPS, kinematics=point.context.nominal)
    theirs = problem.linearize(values, n_steps=N_STEPS)
    for field in "MCKf":
        a, b = getattr(mine.system, field), getattr(theirs.system, field)
        assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max(), field
    z = 1e-4 * np.random.default_rng(2).standard_normal(point.system.f.shape)
    z[-1] = z[0]
    np.testing.assert_allclose(mine.observe(z), theirs.observe(z), rtol=1e-9, atol=1e-12)
