"""Exact section derivatives of the sensitivities (issue 20): a link's density, width and thickness
(``linearize/_section.py``: one linearisation of the link moved along the parameter's tangent, along
which coefficients and maps are linear, and the damping's closed form) against Richardson-extrapolated
central differences of the linearisation's coefficients and maps on the point's kinematics (rounding
level, where the forward difference it replaces was 5e-7 off), the headlines and the spectral radius
against central differences of fresh steady states, the damping kind's closed form against rebuilt
links, and the cases that keep the forward difference."""

from __future__ import annotations

import numpy as np
import pytest

import linearize
import mechanisms
import periodic
import studies

N_STEPS = 64
OBSERVABLES = ["coupler.deflection@0.5", "joint.B.force", "drive.O.torque", "coupler.stress_top@0.5",
               "coupler.moment@0.5"]
SECTION = ["links.coupler.thickness", "links.coupler.width", "links.coupler.density"]
EPS = np.finfo(float).eps


def _variant(**coupler):
    """``four_bar_fem4`` with the coupler's scene keys ``coupler`` changed."""
    spec = mechanisms.load("four_bar_fem4").to_spec()
    spec["links"]["coupler"].update(coupler)
    return mechanisms.build(spec, source=f"four_bar_fem4 with {coupler}")


@pytest.fixture(scope="module")
def scene():
    problem = studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=SECTION, observables=OBSERVABLES)
    return problem, problem.linearize({}, n_steps=N_STEPS)


def _richardson(problem, nominal, name, relative, read):
    """``read(linearisation)`` differentiated by Richardson's extrapolation of central differences at steps
    ``relative`` and ``relative / 2`` of the value, on the kinematics ``nominal`` (truncation (step)^4), and
    the absolute step."""
    value = problem.parameters[name]

    def central(h):
        up, down = (read(problem.linearize({name: v}, n_steps=N_STEPS, kinematics=nominal))
                    for v in (value + h, value - h))
        return {key: (up[key] - down[key]) / (2.0 * h) for key in up}

    h = relative * value
    coarse, fine = central(h), central(h / 2.0)
    return {key: (4.0 * fine[key] - coarse[key]) / 3.0 for key in fine}, h


@pytest.mark.parametrize("name", SECTION)
def test_coefficients_against_richardson_differences(scene, name):
    """dM, dC, dK, df of the exact route against Richardson-extrapolated central differences of the
    coefficients (steps 1e-2 and 5e-3 of the value: truncation 1e-8 of the fourth derivative's scale)
    within 1e-9 of the derivative, plus the reference's own rounding (its weights amplify the
    coefficients' rounding by about 6 over the step: 20 eps |coefficient| / step bounds it).  The forward
    difference of step 1e-6 that the route replaces misses the thickness's and the density's damping by
    far more (measured 5e-7 and 2.5e-7)."""
    problem, linear = scene
    mine = linearize.analytic_derivative(linear.context, name)
    assert mine is not None
    nominal = linear.context.nominal
    reference, h = _richardson(problem, nominal, name, 1e-2, lambda lin: {f: getattr(lin.system, f) for f in "MCKf"})
    value = problem.parameters[name]
    forward_step = linearize.parameter_step(value, linearize.FORWARD_STEP)
    forward = linearize.coefficient_derivative(
        problem.linearize({name: value + forward_step}, n_steps=N_STEPS, kinematics=nominal).system,
        linear.system, forward_step)
    for field in "MCKf":
        exact = getattr(mine, field)
        exact = np.zeros_like(reference[field]) if exact is None else exact
        scale = np.abs(reference[field]).max()
        floor = 20.0 * EPS * np.abs(getattr(linear.system, field)).max() / h
        assert np.abs(exact - reference[field]).max() <= 1e-9 * scale + floor, field
        if field == "C" and name != "links.coupler.width":       # the width is affine: no truncation
            assert np.abs(getattr(forward, field) - reference[field]).max() > 1e-7 * scale
    assert mine.log_period == 0.0


def _map_arrays(linearisation):
    return {(spec, key): array for spec, found in linearisation.context.observable_maps.items()
            for key, array in found.arrays().items()}


@pytest.mark.parametrize("coupler", [{}, {"axial": False}], ids=["axial", "axially_rigid"])
@pytest.mark.parametrize("name", SECTION)
def test_maps_against_richardson_differences(name, coupler):
    """The observables' maps (joint forces and the drive torque through the multipliers, the stress's
    fibre distance, the moment's EI, an axially rigid link's nominal N / A) per unit of the parameter,
    against Richardson-extrapolated central differences of the maps of linearisations on the point's
    kinematics (steps 3e-3 and 1.5e-3: truncation 1e-10 for N / A), within 1e-9 of each array's
    derivative plus 1e-12 of its own scale over the value (the exactly zero derivatives: a deflection's,
    the stress's gradient under the width)."""
    problem = studies.MechanismProblem.from_mechanism(_variant(**coupler), parameter_paths=SECTION,
                                                      observables=OBSERVABLES)
    linear = problem.linearize({}, n_steps=N_STEPS)
    assert linearize.moves_maps(linear.context, name)
    assert linearize.analytic_derivative(linear.context, name) is not None
    mine = {(spec, key): array for spec, found in linearize.map_derivatives(linear.context, name).items()
            for key, array in found.arrays().items()}
    reference, _ = _richardson(problem, linear.context.nominal, name, 3e-3, _map_arrays)
    point = _map_arrays(linear)
    value = problem.parameters[name]
    moved = 0
    for key, expected in reference.items():
        exact = mine.get(key, np.zeros_like(expected))
        bound = 1e-9 * np.abs(expected).max() + 1e-12 * np.abs(point[key]).max() / value
        assert np.abs(exact - expected).max() <= bound, key
        moved += bool(np.abs(expected).max() > 1e-6 * np.abs(point[key]).max() / value)
    assert moved >= 4      # forces, torque, and the stress or moment


@pytest.fixture(scope="module")
def headlines(scene):
    problem, linear = scene
    return studies.sensitivity(problem, parameters=SECTION, n_steps=N_STEPS)


@pytest.mark.parametrize("name", SECTION)
def test_headlines_and_radius_against_fresh_steady_states(scene, headlines, name):
    """Every observable's peak and peak-to-peak against central differences (step 1e-4 of the value) of
    fresh steady states, and the spectral radius against fresh multipliers.  Not where the
    study says an extreme switches instant (its derivative is one-sided there: the stress's and the
    moment's maximum and minimum are within the response's error, the torque has two maxima), nor the
    deflection's peak-to-peak under the thickness: its sampled minimum jumps between instants at this N
    (the fresh differences at steps 1e-3, 1e-4, 1e-5 are 63, 79 and 61.5 against the derivative's 61.5,
    the forward route's too)."""
    problem, _ = scene
    result = headlines
    assert result.methods[name] == "analytic"
    value = result.parameters[name]
    h = 1e-4 * value
    up = studies.steady_state(problem, {name: value + h}, n_steps=N_STEPS)
    down = studies.steady_state(problem, {name: value - h}, n_steps=N_STEPS)
    checked = 0
    for spec in result.derivative:
        checks = [(label, field, table) for label, field, table in (
            ("peak", "peak", "peak_derivative"), ("peak-to-peak", "peak_to_peak", "derivative"))
            if f"the {label} of {spec} has" not in result.message]
        if spec == "coupler.deflection@0.5" and name == "links.coupler.thickness":
            checks = [check for check in checks if check[1] == "peak"]
        for _, field, table in checks:
            checked += 1
            difference = (getattr(up, field)[spec] - getattr(down, field)[spec]) / (2.0 * h)
            assert getattr(result, table)[spec][name] == pytest.approx(difference, rel=1e-4), (spec, field)
    assert checked >= 4

    def radius(v):
        return abs(periodic.steady_state(problem.linearize({name: v}, n_steps=N_STEPS).system).critical_multiplier)

    def central(step):
        return (radius(value + step) - radius(value - step)) / (2.0 * step)

    # the radius barely moves with the width (it scales the coupler's mass and stiffness alike): steps of
    # 1e-2 and 5e-3, Richardson-extrapolated, keep the fresh multipliers' rounding out of the difference
    reference = (4.0 * central(5e-3 * value) - central(1e-2 * value)) / 3.0
    assert result.radius_derivative[name] == pytest.approx(reference, rel=1e-4)


def test_off_the_scene_speed_against_fresh_steady_states():
    """At a speed that is not the scene's (a speed family's member: its maps interpolated in the speed)
    the neighbour is linearised on the member's kinematics: the density's and the thickness's derivatives
    against fresh steady states at that speed."""
    names = ["links.coupler.density", "links.coupler.thickness"]
    problem = studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=names, observables=OBSERVABLES[:4])
    point = {"speed": 1.1 * problem.parameters["speed"]}
    result = studies.sensitivity(problem, point, parameters=names, n_steps=N_STEPS)
    assert result.methods == {name: "analytic" for name in names}
    for name in names:
        value = result.parameters[name]
        h = 1e-4 * value
        up = studies.steady_state(problem, dict(point, **{name: value + h}), n_steps=N_STEPS)
        down = studies.steady_state(problem, dict(point, **{name: value - h}), n_steps=N_STEPS)
        for spec in ("joint.B.force", "coupler.stress_top@0.5", "drive.O.torque"):
            difference = (up.peak[spec] - down.peak[spec]) / (2.0 * h)
            assert result.peak_derivative[spec][name] == pytest.approx(difference, rel=1e-4), (name, spec)


def test_ratio_damping_follows_the_section_when_rebuilt():
    """``Rayleigh.section_derivative`` with a ratio (``beta = 2 ratio / omega_1``, rebuilt with each link)
    against Richardson-extrapolated central differences of ``beta K_ee`` over links rebuilt from the scene
    at the thickness, width and density +- h (``K_ee = E (A Gu + I Gw)``, with made-up Gram matrices)."""
    base = mechanisms.load("four_bar_fem4")
    gu, gw = np.diag([1.0, 0.0, 2.0]), np.diag([0.0, 3.0, 1.0])

    def parts(mechanism):
        link = next(item for item in mechanism.links if item.name == "coupler")
        e = link.youngs_modulus
        return link, e * link.area * gu, e * link.second_moment * gw

    link, axial, bending = parts(base)
    for key in ("thickness", "width", "density"):
        value = base.spec["links"]["coupler"][key]

        def damping(v, key=key):
            rebuilt, a, b = parts(base.with_parameter(f"links.coupler.{key}", v))
            return rebuilt.damping.beta * (a + b)

        def central(h):
            return (damping(value + h) - damping(value - h)) / (2.0 * h)

        # Richardson's extrapolation (truncation 1e-8); beta K's parts cancel (beta ~ 1 / h against
        # E A ~ h), so its rounding, 6 eps |beta K| / step = 1e-13 |beta K| / value, is the floor
        reference = (4.0 * central(5e-3 * value) - central(1e-2 * value)) / 3.0
        rates = link.section_rates(key)
        d_stiffness = rates["area"] * axial + rates["second_moment"] * bending
        closed = link.damping.section_derivative(
            link, np.eye(3), axial + bending, (rates["density"] + rates["area"]) * np.eye(3), d_stiffness,
            0.5 * (rates["second_moment"] - rates["density"] - rates["area"]))
        atol = 1e-12 * np.abs(damping(value)).max() / value
        np.testing.assert_allclose(closed, reference, rtol=1e-7, atol=atol)
        if key != "width":   # beta's own change (omega_1 does not move with the width) is not negligible
            assert np.abs(closed - link.damping.beta * d_stiffness).max() > 1e3 * atol
    assert np.all(mechanisms.DampingMatrix(((1.0,),)).section_derivative(link, np.eye(1), np.eye(1), np.eye(1),
                                                                          np.eye(1), 0.5) == 0.0)


def test_section_rates_of_a_rectangle():
    """d ln(rho, A, I) / dp of the scene keys: A = b h, I = b h^3 / 12."""
    link = mechanisms.ElasticLink.rectangular("bar", 0.3, width=0.02, thickness=0.0016, density=7800.0,
                                               youngs_modulus=2e11)
    assert link.section_rates("thickness") == pytest.approx(
        {"density": 0.0, "area": 1 / 0.0016, "second_moment": 3 / 0.0016})
    assert link.section_rates("width") == pytest.approx({"density": 0.0, "area": 1 / 0.02,
                                                         "second_moment": 1 / 0.02})
    assert link.section_rates("density") == {"density": 1 / 7800.0, "area": 0.0, "second_moment": 0.0}
    assert link.section_rates("length") is None


@pytest.mark.parametrize(("scene_or_coupler", "name"), [
    ("four_bar_controlled", "links.coupler.thickness"),                          # a torque drive
    ({"damping": {"type": "modal", "ratios": [0.02]}}, "links.coupler.density"),   # not affine in M_ee
    ({"rotary_inertia": True}, "links.coupler.thickness"),                     # rho I apart from rho A
    ({"discretisation": {"type": "fem", "n_elements": 4, "modes": 2}}, "links.coupler.width"),   # reduced
])
def test_cases_that_keep_the_forward_difference(scene_or_coupler, name):
    """Where the route is not exact it declines and the study differences linearisations (and says which
    route it took); the rigid crank's section is not covered either."""
    if isinstance(scene_or_coupler, str):
        problem = studies.MechanismProblem.from_scene(scene_or_coupler, parameter_paths=[name])
    else:
        problem = studies.MechanismProblem.from_mechanism(_variant(**scene_or_coupler), parameter_paths=[name])
    linear = problem.linearize({}, n_steps=N_STEPS)
    assert linearize.analytic_derivative(linear.context, name) is None
    assert linearize.analytic_derivative(linear.context, "links.crank.thickness") is None
    if scene_or_coupler == {"rotary_inertia": True}:
        # the width moves rho A and rho I alike: still exact
        assert linearize.analytic_derivative(linear.context, "links.coupler.width") is not None
