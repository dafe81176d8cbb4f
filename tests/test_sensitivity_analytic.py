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
    """A parameter that no part differentiates (a rigid link's section, a length) gets None here, and the
    study differences linearisations for it."""
    problem = studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=["links.crank.thickness"])
    linear = problem.linearize({}, n_steps=N_STEPS)
    assert linearize.analytic_derivative(linear.context, "links.crank.thickness") is None
    assert linearize.analytic_derivative(linear.context, "links.crank.length") is None
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
    member's kinematics: the derivatives against fresh steady states at the same point (the rigid
    rocker's thickness: its mass moves, the linkage does not)."""
    name = "links.rocker.thickness"
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


# ---------------------------------------------------------------------------------------------------
# controller gains and Young's modulus (the controller's law_derivative, K_ee / E)
# ---------------------------------------------------------------------------------------------------
STRESS = "coupler.stress_top@0.5"
GAINS = ["controllers.crank_pd.kp", "controllers.crank_pd.kd", "controllers.strain.gain",
         "controllers.strain.rate_gain"]
MODULUS = "links.coupler.youngs_modulus"


def _problem(mechanism_or_scene, names):
    if isinstance(mechanism_or_scene, str):
        return studies.MechanismProblem.from_scene(mechanism_or_scene, parameter_paths=names,
                                                   observables=OBSERVABLES + [STRESS])
    return studies.MechanismProblem.from_mechanism(mechanism_or_scene, parameter_paths=names,
                                                   observables=OBSERVABLES + [STRESS])


def _lagged():
    """The closed-loop four-bar with a 2 ms lag on its strain feedback (a lag state in z)."""
    return mechanisms.load("four_bar_controlled").with_parameter("controllers.strain.lag", 2e-3)


def _drive_pd():
    """The closed-loop four-bar with a PD of its torque drive's own (``drive.kp``, ``drive.kd``)."""
    return mechanisms.load("four_bar_controlled").with_parameters({"drive.kp": 5.0, "drive.kd": 0.05})


def _reduced():
    """The 4-element coupler reduced to 3 modes (its basis from K_ee and M_ee)."""
    return mechanisms.load("four_bar_fem4").with_parameter("links.coupler.discretisation.modes", 3)


CASES = ([("four_bar_controlled", name) for name in GAINS + [MODULUS]]
         + [("lagged", name) for name in GAINS[2:]] + [("drive_pd", "drive.kp"), ("drive_pd", "drive.kd")]
         + [("four_bar_fem4", MODULUS), ("reduced", MODULUS)])


@pytest.mark.parametrize("scene, name", CASES)
def test_gains_and_modulus_against_coefficient_differences(scene, name):
    """dM, dC, dK, df, d ln T of the closed forms against the forward difference of the coefficients
    (on the point's kinematics, the route they replace) and the central difference of two fresh
    linearisations.  The coefficients are affine in a gain on fixed kinematics, so the forward
    difference is exact but for round-off over its step (1e-16 / 1e-6 of the coefficients' scale) and
    the central one adds the nominal motions' Newton tolerance over its step: 1e-7 of the scale bounds
    both (measured: 1e-12).  In E they are affine but for the damping a ratio sets (beta K_ee grows as
    sqrt(E)), whose forward truncation is FORWARD_STEP / 4 of its derivative: 1e-6 of the scale there.
    The reduced coupler's basis is normalised by its first sample within 1e-6 of the largest (not by
    whichever of an antisymmetric mode's equal peaks round-off makes larger, which flipped a column's
    sign at a step of 1e-6 and made the forward difference O(1) wrong).  The maps the
    parameter moves (the drive torque for a gain, the stress for E; their derivatives along ``x = V z``)
    against those of the fresh linearisation at p + h."""
    mechanism = {"lagged": _lagged, "reduced": _reduced, "drive_pd": _drive_pd}.get(scene, lambda: scene)()
    problem = _problem(mechanism, [name])
    linear = problem.linearize({}, n_steps=N_STEPS)
    closed = linearize.analytic_derivative(linear.context, name)
    assert closed is not None
    value = problem.parameters[name]
    h = linearize.parameter_step(value, linearize.FORWARD_STEP)
    forward = linearize.coefficient_derivative(
        problem.linearize({name: value + h}, n_steps=N_STEPS, kinematics=linear.context.nominal).system,
        linear.system, h)
    up, down, step = _central_coefficients(problem, name)
    for field in "MCKf":
        central = (getattr(up.system, field) - getattr(down.system, field)) / (2.0 * step)
        mine = getattr(closed, field)
        mine = np.zeros_like(central) if mine is None else mine
        theirs = getattr(forward, field)
        theirs = np.zeros_like(central) if theirs is None else theirs
        scale = max(np.abs(central).max(), np.abs(getattr(linear.system, field)).max() / abs(value))
        tol = linearize.FORWARD_STEP if name == MODULUS else 1e-7
        assert np.abs(mine - theirs).max() <= tol * scale, (field, "forward")
        assert np.abs(mine - central).max() <= 1e-7 * scale, (field, "central")
    assert max(np.abs(array).max() for array in (closed.C, closed.K) if array is not None) > 0.0
    assert closed.log_period == 0.0 == forward.log_period
    slopes = linearize.map_derivatives(linear.context, name, problem.mechanism({name: value + step}), step)
    assert slopes and linearize.moves_maps(linear.context, name)
    moved = 0
    for spec, slope in slopes.items():
        fresh, here = up.context.observable_maps[spec].arrays(), linear.context.observable_maps[spec].arrays()
        for key in fresh:
            # the map at p + h along its derivative against the fresh linearisation's, to 1e-9 of its size
            derivative = slope.arrays().get(key, 0.0)
            assert np.abs(here[key] + step * derivative - fresh[key]).max() <= 1e-9 * max(
                np.abs(fresh[key]).max(), 1e-300), (spec, key)
            if np.any(derivative):
                # and the derivative itself against the fresh difference quotient (affine: round-off)
                quotient = (fresh[key] - here[key]) / step
                assert np.abs(derivative - quotient).max() <= 1e-6 * np.abs(derivative).max(), (spec, key)
                moved += 1
    # some map does move (the drive torque for a gain, the stress for E); a lagged gain's torque is the
    # lag's state, whose row the gain moves instead
    assert (moved == 0) if scene == "lagged" else (moved > 0)


def test_gain_derivatives_decline_where_they_are_not_closed_forms():
    """A controller's lag is not a gain (None: differenced), an unknown controller neither; the
    controller kinds say so themselves."""
    problem = _problem(_lagged(), [])
    linear = problem.linearize({}, n_steps=N_STEPS)
    for path in ("controllers.strain.lag", "controllers.crank_pd.lag", "controllers.nobody.kp", "drive.rate",
                 "drive.flywheel", "drives.nowhere.kp"):
        assert linearize.analytic_derivative(linear.context, path) is None, path
    assert mechanisms.PDController("pd", "O", kp=2.0).law_derivative("kp") == mechanisms.ControllerLaw(kp=1.0)
    assert mechanisms.ObservableFeedback("fb", "O", "coupler.strain@0.5").law_derivative(
        "rate_gain") == mechanisms.ControllerLaw(observable="coupler.strain@0.5", rate_gain=1.0)


@pytest.mark.parametrize("scene, names", [("four_bar_controlled", GAINS + [MODULUS]),
                                          ("lagged", GAINS[2:]), ("drive_pd", ["drive.kp", "drive.kd"]),
                                          ("four_bar_fem4", [MODULUS])])
def test_gains_and_modulus_headlines_against_fresh_steady_states(scene, names, monkeypatch):
    """Every headline's derivative through the closed forms against central differences of fresh steady
    states at the same N (relative step 1e-3 for the gains: truncation (1e-3)^2 and the steady states'
    rounding 1e-12 / 1e-3 of the value, well under the 1e-4 asked; 1e-4 for E, near whose value the
    response curves strongly (measured: the differences converge as the step squared, 1e-2 of the
    derivative at a step of 1e-2 and 1e-6 at 1e-4), with normalised sensitivities of 0.1 to 5, so the
    rounding is 1e-7 of the derivative), and against the
    forward coefficient route they replace (analytic_derivative switched off), tight: the forward
    route observes a force's magnitude by a one-sided step 1e-6 p in z, its truncation 1e-6 of the
    derivative and more where a peak-to-peak cancels (measured: 1e-5)."""
    mechanism = {"lagged": _lagged, "drive_pd": _drive_pd}.get(scene, lambda: scene)()
    problem = _problem(mechanism, names)
    result = studies.sensitivity(problem, parameters=names, n_steps=N_STEPS)
    assert result.methods == {name: "analytic" for name in names}
    with monkeypatch.context() as patch:
        patch.setattr(linearize, "analytic_derivative", lambda linearized, path: None)
        forward = studies.sensitivity(problem, parameters=names, n_steps=N_STEPS)
    assert set(forward.methods.values()) == {"forward"}
    for name in names:
        value = result.parameters[name]
        h = (1e-4 if name == MODULUS else 1e-3) * value
        up = studies.steady_state(problem, {name: value + h}, n_steps=N_STEPS)
        down = studies.steady_state(problem, {name: value - h}, n_steps=N_STEPS)
        for spec in result.derivative:
            for field, table in (("peak_to_peak", "derivative"), ("peak", "peak_derivative"),
                                 ("rms", "rms_derivative")):
                mine = getattr(result, table)[spec][name]
                assert mine == pytest.approx(getattr(forward, table)[spec][name], rel=1e-4), (name, spec, field)
                if field == "rms":
                    continue
                difference = (getattr(up, field)[spec] - getattr(down, field)[spec]) / (2.0 * h)
                assert mine == pytest.approx(difference, rel=1e-4), (name, spec, field)


@pytest.mark.parametrize("name", ["links.coupler.thickness", "links.coupler.width", "links.coupler.density"])
def test_reduced_link_sections_forward_against_central_coefficients(name):
    """A reduced coupler's section properties take forward differences on the point's kinematics: the
    reduction's basis, recomputed at the neighbour, must not jump (a column's sign flipped at a step of
    1e-6 of the thickness, and the derivative came out 2000 times too large).  Against central
    differences of fresh linearisations: the forward step's truncation, about FORWARD_STEP of the
    derivative for the thickness (I = b h^3 / 12) and the density (the ratio's damping), 0 for the
    width (affine), and the central one's (1e-4)^2: 1e-5 of the scale bounds both."""
    problem = _problem(_reduced(), [name])
    linear = problem.linearize({}, n_steps=N_STEPS)
    value = problem.parameters[name]
    h = linearize.parameter_step(value, linearize.FORWARD_STEP)
    forward = linearize.coefficient_derivative(
        problem.linearize({name: value + h}, n_steps=N_STEPS, kinematics=linear.context.nominal).system,
        linear.system, h)
    up, down, step = _central_coefficients(problem, name)
    for field in "MCKf":
        central = (getattr(up.system, field) - getattr(down.system, field)) / (2.0 * step)
        theirs = getattr(forward, field)
        theirs = np.zeros_like(central) if theirs is None else theirs
        scale = max(np.abs(central).max(), np.abs(getattr(linear.system, field)).max() / abs(value))
        assert np.abs(theirs - central).max() <= 1e-5 * scale, field


def test_reduced_link_sections_against_fresh_steady_states():
    """The reduced coupler's section properties (forward) and Young's modulus (closed form) through to
    the headlines, against central differences of fresh steady states (step 1e-4 of the value): every
    observable's peak and the pin force's peak-to-peak.  Not the deflection's peak-to-peak: its sampled
    minimum jumps between instants at this N (the fresh differences at steps 1e-3, 1e-4, 1e-5 of the
    thickness are 63, 79 and 61.5 against the derivative's 61.5)."""
    names = ["links.coupler.thickness", "links.coupler.width", "links.coupler.density", MODULUS]
    problem = _problem(_reduced(), names)
    result = studies.sensitivity(problem, parameters=names, n_steps=N_STEPS)
    assert result.methods == {**{name: "forward" for name in names[:3]}, MODULUS: "analytic"}
    for name in names:
        value = result.parameters[name]
        h = 1e-4 * value
        up = studies.steady_state(problem, {name: value + h}, n_steps=N_STEPS)
        down = studies.steady_state(problem, {name: value - h}, n_steps=N_STEPS)
        for spec in result.derivative:
            checks = [("peak", "peak_derivative")]
            if spec == "joint.B.force":
                checks.append(("peak_to_peak", "derivative"))
            for field, table in checks:
                difference = (getattr(up, field)[spec] - getattr(down, field)[spec]) / (2.0 * h)
                assert getattr(result, table)[spec][name] == pytest.approx(difference, rel=1e-4), (name, spec, field)


def test_modulus_off_the_scene_speed_against_fresh_steady_states():
    """At a speed that is not the scene's the point is a speed family's member, whose coefficients keep
    the base speed's multiplier maps (its own maps are interpolated in the speed): the maps E moves are
    rebuilt as changes on the member's motion, so the forces and torques come out right (they were
    wrong by a factor 100 when rebuilt whole).  Against fresh steady states, step 1e-4 of E."""
    problem = _problem("four_bar_fem4", [MODULUS])
    point = {"speed": 1.1 * problem.parameters["speed"]}
    result = studies.sensitivity(problem, point, parameters=[MODULUS], n_steps=N_STEPS)
    assert result.methods == {MODULUS: "analytic"}
    value = result.parameters[MODULUS]
    h = 1e-4 * value
    up = studies.steady_state(problem, dict(point, **{MODULUS: value + h}), n_steps=N_STEPS)
    down = studies.steady_state(problem, dict(point, **{MODULUS: value - h}), n_steps=N_STEPS)
    for spec in result.derivative:
        for field, table in (("peak_to_peak", "derivative"), ("peak", "peak_derivative")):
            difference = (getattr(up, field)[spec] - getattr(down, field)[spec]) / (2.0 * h)
            assert getattr(result, table)[spec][MODULUS] == pytest.approx(difference, rel=1e-4), (spec, field)


def test_ratio_made_rayleigh_follows_e_when_rebuilt_from_its_parts():
    """A Rayleigh damping made from a ratio records it and writes it back, so that a mechanism written
    from its parts (no scene spec) and rebuilt at another E gets beta from its own first frequency
    (beta ~ E^-1/2), which ``modulus_derivative`` (beta K_ee / (2 E)) assumes; its closed form against
    the central difference of beta K_ee over rebuilt links."""
    scene = mechanisms.load("four_bar_fem4")
    bare = scene.replace(links=scene.links)
    assert bare.spec is None
    coupler = next(link for link in bare.links if link.name == "coupler")
    assert coupler.damping.ratio == 0.02 and coupler.damping.to_table() == {"type": "rayleigh", "ratio": 0.02}
    k_ee = np.diag([1.0, 2.0])
    value = coupler.youngs_modulus
    h = 1e-4 * value

    def beta_k(e):
        link = next(item for item in bare.with_parameter(MODULUS, e).links if item.name == "coupler")
        return link.damping.beta * k_ee * (e / value)     # K_ee grows with E

    central = (beta_k(value + h) - beta_k(value - h)) / (2.0 * h)
    closed = coupler.damping.modulus_derivative(coupler, np.eye(2), k_ee)
    np.testing.assert_allclose(closed, central, rtol=1e-7)
    assert mechanisms.Rayleigh(0.0, 1e-4).modulus_derivative(coupler, np.eye(2), k_ee)[1, 1] == pytest.approx(
        1e-4 * 2.0 / value, rel=1e-15)
