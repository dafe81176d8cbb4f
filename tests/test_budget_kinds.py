"""The error budget on the stability chart, the Campbell diagram, the control comparison and the
optimisation optimum (studies._budget), and the guard's cost of the budget: each against something
independent (a converged radius, the steady state the optimum's budget comes from, the comparison's
own N-against-N/2 errors, the cost model's parts)."""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

import mechanisms
import studies
from studies import _budget as budget  # the budget's words are internal to the studies (tested here)
from studies import _cost as cost  # the guard's cost model's parts (tested here)
from tests._support.older_files import as_format_2

TOLERANCE = 0.02


# ---------------------------------------------------------------------------------------------------
# the spectral radius: stability chart and Campbell diagram
# ---------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def charts():
    problem = studies.mathieu_problem(damping_ratio=0.02, force=0.0)
    axes = (("speed", np.linspace(0.15, 0.6, 6)), ("epsilon", [0.1, 0.5]))  # slow: the step matters
    coarse = studies.stability_chart(problem, *axes, n_steps=32)
    converged = studies.stability_chart(problem, *axes, n_steps=512)
    return coarse, converged


def test_the_chart_says_which_terms_of_its_radius_apply(charts):
    coarse, _ = charts
    terms = coarse.error_budget["spectral_radius"]
    np.testing.assert_array_equal(terms["time_step"], coarse.spectral_radius_error)
    # a periodic problem has no mesh: not applicable, not a zero error
    assert terms["mesh"] == budget.NOT_APPLICABLE and terms["linearisation"] == budget.NOT_APPLICABLE
    assert "not applicable" in coarse.error_methods["linearisation"]
    assert coarse.error_methods["mesh"].startswith("not applicable") and coarse.spectral_radius_mesh_error is None
    assert coarse.settings["error_tolerance"] == TOLERANCE


def test_a_cell_whose_radius_is_off_by_more_than_the_tolerance_is_not_ok(charts):
    coarse, converged = charts
    true_error = np.abs(coarse.spectral_radius - converged.spectral_radius)
    off = true_error > 2.0 * TOLERANCE * converged.spectral_radius
    assert off.any(), "the coarse chart should have cells off by more than the tolerance"
    assert not (coarse.point_status[off] == "ok").any()
    # the rule itself: a time-step error above the tolerance of the radius is inaccurate
    over = coarse.spectral_radius_error > TOLERANCE * coarse.spectral_radius
    assert (coarse.point_status[over] != "ok").all()
    assert "spectral radius error" in " ".join(coarse.point_message[over])


def test_a_looser_tolerance_keeps_the_cells_the_rule_flagged(charts):
    coarse, _ = charts
    problem = studies.mathieu_problem(damping_ratio=0.02, force=0.0)
    loose = studies.stability_chart(problem, ("speed", coarse.first), ("epsilon", coarse.second), n_steps=32,
                                    error_tolerance=0.9)
    flagged = (coarse.point_status == "inaccurate") & (loose.point_status != "inaccurate")
    assert flagged.any()
    assert not any("spectral radius error" in m for m in loose.point_message.ravel())


def test_campbell_carries_the_budget_of_its_radius_and_frequencies():
    problem = studies.mathieu_problem(damping_ratio=0.02, force=0.0)
    result = studies.campbell(problem, [0.2, 0.4, 0.8], n_steps=32)
    found = result.error_budget
    np.testing.assert_array_equal(found["characteristic"]["time_step"], result.characteristic_error)
    np.testing.assert_array_equal(found["spectral_radius"]["time_step"], result.spectral_radius_error)
    for terms in found.values():
        assert terms["linearisation"] == budget.NOT_APPLICABLE and terms["mesh"] == budget.NOT_APPLICABLE
    over = result.spectral_radius_error > TOLERANCE * result.spectral_radius
    assert over.any() and (result.point_status[over] != "ok").all()


def test_chart_methods_round_trip(charts, tmp_path):
    coarse, _ = charts
    path = tmp_path / "chart.h5"
    coarse.save(path)
    back = studies.load(path)["stability_chart"]
    assert dict(back.error_methods) == dict(coarse.error_methods)
    np.testing.assert_array_equal(back.error_budget["spectral_radius"]["time_step"], coarse.spectral_radius_error)
    assert back.error_budget["spectral_radius"]["mesh"] == budget.NOT_APPLICABLE


# ---------------------------------------------------------------------------------------------------
# the mesh term of the radius on a mechanism: against a converged mesh (32 coupler elements)
# ---------------------------------------------------------------------------------------------------
RADIUS_SPEEDS = (100.0, 185.0)   # stable, and inside the instability tongue (radius 1.116 at N = 64)
CHART_TOLERANCE = 2e-4


def _fem4_radius(n_elements: int, speed: float) -> float:
    """The spectral radius of four_bar_fem4 with ``n_elements`` coupler elements at ``speed`` on 64
    steps, assembled apart from the studies (linearize.about, periodic.floquet)."""
    import dataclasses

    import linearize
    import periodic

    mechanism = mechanisms.load("four_bar_fem4").with_parameters({"drive.rate": speed})
    links = tuple(dataclasses.replace(link, discretisation=mechanisms.Fem(n_elements))
                  if getattr(link, "discretisation", None) is not None else link for link in mechanism.links)
    mechanism = mechanism.replace(links=links)
    return float(periodic.floquet(linearize.about(mechanism, n_steps=64).system).spectral_radius)


@pytest.fixture(scope="module")
def fem4_radii():
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        problem = studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=("links.coupler.thickness",))
        thickness = problem.parameters["links.coupler.thickness"]
        # a time step fine enough that the mesh term dominates, and a tolerance the time step alone passes
        chart = studies.stability_chart(problem, ("speed", [150.0]), ("links.coupler.thickness", [thickness]),
                                        n_steps=512, error_tolerance=CHART_TOLERANCE)
        campbell = studies.campbell(problem, list(RADIUS_SPEEDS), n_steps=64)
        truth = {speed: {n: _fem4_radius(n, speed) for n in (4, 8, 16, 32)} for speed in RADIUS_SPEEDS}
    return chart, campbell, truth


def test_the_radius_mesh_term_covers_the_32_element_error_and_is_not_loose(fem4_radii):
    from studies._mesh_error import radius_mesh_error

    _, campbell, truth = fem4_radii
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    shares = []
    for k, speed in enumerate(RADIUS_SPEEDS):
        radii = truth[speed]
        assert campbell.spectral_radius[k] == pytest.approx(radii[4], rel=1e-9)
        true = abs(radii[4] - radii[32])
        found = radius_mesh_error(problem, {"speed": speed}, n_steps=64)
        assert found.applicable and "known order 4" in found.method
        assert true <= found.error <= 3.0 * true, (speed, found.error, true)
        # the declared order against the observed one: successive differences fall by 2^4
        ratio = abs(radii[4] - radii[8]) / abs(radii[8] - radii[16])
        assert 12.0 <= ratio <= 20.0, (speed, ratio)
        shares.append(found.error / found.radius)
        # the grid's term (the largest relative error of its headline speeds, applied to each) covers it
        assert campbell.spectral_radius_mesh_error[k] >= true
    np.testing.assert_allclose(campbell.spectral_radius_mesh_error, max(shares) * campbell.spectral_radius,
                               rtol=1e-9)
    assert campbell.spectral_radius[1] > 1.0 and not campbell.is_stable[1]


def test_the_grid_term_is_in_the_budget_and_the_verdict(fem4_radii):
    _, campbell, _ = fem4_radii
    terms = campbell.error_budget["spectral_radius"]
    np.testing.assert_array_equal(terms["mesh"], campbell.spectral_radius_mesh_error)
    # the frequencies' term (tests/test_mesh_terms_grids.py against the 32-element frequencies)
    np.testing.assert_array_equal(campbell.error_budget["characteristic"]["mesh"],
                                  campbell.characteristic_mesh_error)
    methods = campbell.error_methods["mesh"]
    assert "headline points" in methods and "the largest radius" in methods
    # the rule with the mesh term: a total above the tolerance is inaccurate, naming the mesh where it dominates
    status, message = budget.radius_verdict(1.0, 1e-4, TOLERANCE, mesh=0.05)
    assert status == "inaccurate" and "mostly mesh" in message and "add elements" in message
    assert budget.radius_verdict(1.0, 1e-4, TOLERANCE, mesh=1e-3) == ("ok", "")


# ---------------------------------------------------------------------------------------------------
# the control comparison
# ---------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def comparison():
    spec = mechanisms.four_bar(n_elements=1).to_spec()
    spec["drive"].update(type="torque", kp=20.0, kd=0.5)
    problem = studies.MechanismProblem.from_mechanism(mechanisms.build(spec, source="torque four-bar"))
    return studies.control_comparison(problem, n_periods=8, n_steps=64)


def test_the_comparison_budget_is_its_time_step_and_mesh_without_linearisation(comparison):
    for name in comparison.quantities:
        terms = comparison.error_budget[name]
        assert terms["time_step"] == comparison.steady_peak_error["with"][name]
        assert terms["linearisation"] == budget.NOT_APPLICABLE   # the runs are of the full equations
        if comparison.roles[name] != "elastic" and terms["mesh"] != budget.NOT_APPLICABLE:
            assert terms["mesh"] == budget.NOT_ESTIMATED
        total = budget.ErrorBudget(comparison.error_budget).total(name)
        value = comparison.steady_peak["with"][name]
        if not total <= TOLERANCE * abs(value):
            assert comparison.status != "ok" and name in comparison.message


def test_the_comparison_budget_round_trips(comparison, tmp_path):
    path = tmp_path / "comparison.h5"
    comparison.save(path)
    back = studies.load(path)["control_comparison"]
    assert {k: dict(v) for k, v in back.error_budget.items()} == \
        {k: dict(v) for k, v in comparison.error_budget.items()}
    with h5py.File(path, "a") as handle:   # as a file written before the budget: format 2, no checksums
        for name in ("error_budget", "error_methods"):
            del handle["control_comparison"].attrs[name]
        as_format_2(handle, "control_comparison")
    old = studies.load(path)["control_comparison"]
    assert old.error_budget == {}


# ---------------------------------------------------------------------------------------------------
# the optimisation optimum
# ---------------------------------------------------------------------------------------------------
def test_the_optimum_carries_the_budget_of_the_steady_state_at_its_worst_speed():
    problem = studies.MechanismProblem.from_scene("four_bar_thesis", parameter_paths=("links.coupler.thickness",))
    objective = "peak_to_peak:coupler.deflection@0.5"
    found = studies.optimize(problem, {"links.coupler.thickness": (4e-3, 6e-3)}, objective=objective,
                             n_steps=64, max_evaluations=3, check=False)
    spec = "coupler.deflection@0.5"
    # independent: the steady state at the optimum, run apart
    steady = studies.steady_state(problem, found.values, n_steps=64)
    assert found.objective_value == pytest.approx(steady.peak_to_peak[spec], rel=1e-9)
    for term, value in steady.error_budget[spec].items():
        stored = found.error_budget[spec][term]
        assert stored == value or (isinstance(value, float) and math.isnan(value) and math.isnan(stored))
    assert found.objective_error == pytest.approx(steady.budget.total(spec), rel=1e-12)
    assert isinstance(found.error_budget[spec]["linearisation"], float)
    if not found.objective_error <= TOLERANCE * found.objective_value:
        assert found.status != "ok" and "peak-to-peak error" in found.message


def test_a_periodic_problem_optimum_has_the_time_step_alone(tmp_path):
    problem = studies.mathieu_problem(damping_ratio=0.05)
    found = studies.optimize(problem, {"damping_ratio": (0.05, 0.2)}, objective="rms:x", n_steps=64,
                             max_evaluations=3, check=False)
    terms = found.error_budget["x"]
    assert terms["mesh"] == budget.NOT_APPLICABLE and terms["linearisation"] == budget.NOT_APPLICABLE
    # independent: the response error of the steady state at the optimum, run apart
    steady = studies.steady_state(problem, found.values, n_steps=64)
    assert found.objective_error == pytest.approx(steady.response_error["x"], rel=1e-12)
    path = tmp_path / "optimum.h5"
    found.save(path)
    back = studies.load(path)["optimize"]
    assert dict(back.error_budget["x"]) == dict(terms) and back.objective_error == found.objective_error
    with h5py.File(path, "a") as handle:   # as a file written before the budget: format 2, no checksums
        for name in ("error_budget", "error_methods"):
            del handle["optimize"].attrs[name]
        as_format_2(handle, "optimize")
    old = studies.load(path)["optimize"]
    assert old.error_budget["x"]["time_step"] == found.objective_error
    assert math.isnan(old.error_budget["x"]["linearisation"]) and "format 2" in old.error_methods["mesh"]


# ---------------------------------------------------------------------------------------------------
# the guard's cost of the budget
# ---------------------------------------------------------------------------------------------------
def test_the_steady_state_estimate_includes_the_budget_terms():
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    sizes = cost.sizes_at(problem, {})
    plain = cost.steady_solves("s", problem, [{}], 128)
    with_budget = cost.steady_solves("s", problem, [{}], 128, budget=True)
    refined = cost.Sizes(n=cost.MESH_REFINEMENT * sizes.n, m=cost.MESH_REFINEMENT * sizes.m)
    mesh = cost.linearisation(128, refined)[1] + cost.solve_seconds(128, refined)
    assert with_budget.time == pytest.approx(plain.time + cost.budget_seconds(problem, 128, sizes) + mesh)
    # a periodic problem has neither term
    mathieu = studies.mathieu_problem()
    assert cost.steady_solves("s", mathieu, [{}], 128, budget=True).time == \
        cost.steady_solves("s", mathieu, [{}], 128).time


def test_a_chart_cell_judged_on_its_total_with_the_mesh_term(fem4_radii):
    chart, _, _ = fem4_radii
    radius, step, mesh = (float(np.ravel(a)[0]) for a in (chart.spectral_radius, chart.spectral_radius_error,
                                                           chart.spectral_radius_mesh_error))
    assert mesh > 0.0 and chart.error_budget["spectral_radius"]["mesh"].shape == (1, 1)
    assert step <= CHART_TOLERANCE * radius < step + mesh and mesh > step, (radius, step, mesh)
    # the time step alone passes: the mesh term makes the cell inaccurate, and the message says so
    assert chart.point_status[0, 0] == "inaccurate"
    assert "mostly mesh" in chart.point_message[0, 0] and "add elements" in chart.point_message[0, 0]
