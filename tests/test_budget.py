"""The error budget (studies._budget) and its linearisation term (linearize.linearisation_error),
each against something independent: the full nonlinear periodic state of the same scene
(``studies.nonlinear_steady_state``), the order of the residual in the amplitude, and the budget's
arithmetic by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

import linearize
import studies
from studies import _budget as budget  # the budget's rules are internal to the studies (tested here)
from studies._numerics import peak_to_peak, solve_steady  # the linear steady state the estimate corrects
from tests._support.older_files import as_format_2

N_STEPS = 256


# ---------------------------------------------------------------------------------------------------
# the budget's arithmetic
# ---------------------------------------------------------------------------------------------------
def test_total_is_the_sum_of_magnitudes_and_not_applicable_is_left_out():
    found = budget.ErrorBudget({"a": {"time_step": 1.0, "mesh": budget.NOT_APPLICABLE,
                                      "linearisation": -3.0}})
    # opposite signs must not cancel in an honest bar
    assert found.total("a") == 4.0
    assert found.dominant("a") == "linearisation"
    assert found.unknown("a") == []


def test_an_unknown_applicable_term_makes_the_estimate_untrustworthy():
    found = budget.ErrorBudget({"a": {"time_step": 1e-6, "mesh": budget.NOT_APPLICABLE,
                                      "linearisation": math.nan}})
    assert math.isnan(found.total("a"))
    status, message = budget.verdict(found, {"a": 1.0}, 0.02)
    assert status == "inaccurate" and "not trustworthy" in message and "linearisation" in message


def test_verdict_names_the_dominant_term_and_its_fix():
    found = budget.ErrorBudget({"a": {"time_step": 0.001, "mesh": 0.03, "linearisation": 0.002}})
    status, message = budget.verdict(found, {"a": 1.0}, 0.02)
    assert status == "inaccurate"
    assert "mostly mesh" in message and "add elements" in message
    assert budget.verdict(found, {"a": 1.0}, 0.05) == ("ok", "")


def test_grid_budgets_total_and_dominant_per_point():
    found = budget.ErrorBudget({"a": {"time_step": np.array([1.0, 0.1]),
                                      "linearisation": np.array([-0.5, 2.0])}})
    np.testing.assert_allclose(found.total("a"), [1.5, 2.1])
    assert list(found.dominant("a")) == ["time_step", "linearisation"]


@pytest.mark.parametrize("value", [0.0, 1.0, -0.1, "2 %", True])
def test_error_tolerance_is_checked(value):
    with pytest.raises(studies.StudiesError, match="error_tolerance"):
        budget.check_tolerance(value)


# ---------------------------------------------------------------------------------------------------
# the linearisation term
# ---------------------------------------------------------------------------------------------------
def _linear_state(scene: str, speed: float):
    problem = studies.MechanismProblem.from_scene(scene)
    linear = problem.linearize({"speed": speed}, n_steps=N_STEPS)
    return problem, linear, solve_steady(linear)


@pytest.fixture(scope="module")
def thesis():
    """four_bar_thesis at 100 rad/s: no geometric stiffening, so the linear system is exactly the
    linearisation of the full equations and their difference is of second order."""
    return _linear_state("four_bar_thesis", 100.0)


def test_the_residual_is_of_second_order_in_the_amplitude(thesis):
    _, linear, steady = thesis
    z = steady.state.x
    sizes = [np.abs(linearize.nonlinear_residual(linear.context, a * z, system=linear.system)[0]).max()
             for a in (1.0, 0.5, 0.25)]
    # N(a z) = a^2 N(z) + O(a^3)
    assert sizes[1] / sizes[0] == pytest.approx(0.25, rel=0.05)
    assert sizes[2] / sizes[0] == pytest.approx(0.0625, rel=0.05)


def test_the_estimate_falls_as_the_amplitude_squared(thesis):
    """The estimate of the linear state scaled by a (the same equations: N(a z) = a^2 N(z) where the
    linear system is the exact linearisation) falls as a^2, to the higher-order terms."""
    _, linear, steady = thesis
    sizes = []
    for a in (1.0, 0.5, 0.25):
        found = linearize.linearisation_error(linear.context, a * steady.state.x, system=linear.system,
                                              observe=linear.observe)
        assert found.trusted, found.reason
        sizes.append(np.abs(found.change).max())
    assert sizes[0] > 0.0
    assert sizes[1] / sizes[0] == pytest.approx(0.25, rel=0.05)
    assert sizes[2] / sizes[0] == pytest.approx(0.0625, rel=0.05)


# The load scaled physically: four_bar_fem4's crank speed lowered from 80 to 40 rad/s, below the 3:1
# resonance at 98 rad/s. The inertial load goes as speed^2 and the (quasi-static) response amplitude a
# with it (a falls by 4.2 here). The terms the linearisation leaves out are quadratic in the elastic
# coordinates with coefficients of the same inertia (the rigid motion's accelerations and velocities,
# the nominal axial force), so the error goes as speed^2 a^2, i.e. as a^3: the linearisation error
# is of second order in the amplitude at a fixed load (test above), and this load brings its
# coefficient down with it. Measured (N = 256, the response's max abs): estimate 1.46e-4 m -> 2.00e-6 m,
# the nonlinear state's difference 1.45e-4 m -> 1.64e-6 m (exponents 3.00 and 3.13 in a).
LOAD_SPEEDS = (80.0, 56.6, 40.0)


@pytest.fixture(scope="module")
def lowered_speeds():
    """{speed: (amplitude, estimate, true)}: the linear response's max abs, the linearisation
    estimate's change's max abs and the max abs difference of the full nonlinear state (its own
    nonlinear_steady_state, every mode) from the linear one, of the coupler's midspan deflection (m)."""
    import warnings

    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    found = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for speed in LOAD_SPEEDS:
            linear = problem.linearize({"speed": speed}, n_steps=N_STEPS)
            steady = solve_steady(linear)
            estimate = linearize.linearisation_error(linear.context, steady.state.x, system=linear.system,
                                                     observe=linear.observe, monodromy=steady.state.monodromy)
            assert estimate.trusted, estimate.reason
            nonlinear = studies.nonlinear_steady_state(problem, {"speed": speed}, n_steps=N_STEPS, modes="full")
            spec = linear.observables[0]
            response = steady.response[:, 0]
            found[speed] = (float(np.abs(response).max()), float(np.abs(estimate.change[:, 0]).max()),
                            float(np.abs(np.asarray(nonlinear.response[spec]) - response).max()))
    return found


def test_the_error_falls_with_the_load_as_speed_squared_times_amplitude_squared(lowered_speeds):
    high, low = lowered_speeds[LOAD_SPEEDS[0]], lowered_speeds[LOAD_SPEEDS[-1]]
    amplitude = high[0] / low[0]
    assert amplitude > 3.0   # the load's range spans a factor 3-4 in the amplitude
    law = (LOAD_SPEEDS[0] / LOAD_SPEEDS[-1]) ** 2 * amplitude ** 2   # speed^2 a^2
    for k, words in ((1, "estimate"), (2, "nonlinear difference")):
        # both fall as the second-order law with the load's coefficient, to the harmonic content's
        # change with the speed (the response's shape is not exactly the same at both speeds)
        assert high[k] / low[k] == pytest.approx(law, rel=0.3), (words, high[k] / low[k], law)
        # so the relative error falls with the amplitude (a linearisation error, not a fixed floor)
        assert high[k] / high[0] > 2.0 * low[k] / low[0]
    # the estimate falls as the true difference does
    exponents = [math.log(high[k] / low[k]) / math.log(amplitude) for k in (1, 2)]
    assert abs(exponents[0] - exponents[1]) < 0.3, exponents


def test_the_estimate_tracks_the_nonlinear_state_as_the_load_falls(lowered_speeds):
    for speed, (_, estimate, true) in lowered_speeds.items():
        assert 0.5 <= estimate / true <= 2.0, (speed, estimate, true)


def test_linearisation_error_refuses_a_state_of_the_wrong_shape(thesis):
    _, linear, steady = thesis
    with pytest.raises(linearize.LinearizationError, match="z must have shape"):
        linearize.linearisation_error(linear.context, steady.state.x[:-1])


# The shipped scenes at speeds where the linear-nonlinear difference of the peak-to-peak ranges from
# 0.1 % to 10 % (measured by nonlinear_steady_state): four-bars (beam elements with stiffening, Ritz),
# the six-bar and the slider-crank.
CASES = [("four_bar_fem4", 60.0), ("four_bar_fem4", 100.0), ("four_bar_ritz", 120.0),
         ("six_bar", 100.0), ("six_bar", 140.0), ("slider_crank", 200.0), ("slider_crank", 300.0)]


@pytest.mark.slow
@pytest.mark.parametrize("scene, speed", CASES)
def test_linearisation_estimate_against_the_nonlinear_periodic_state(scene, speed):
    problem, linear, steady = _linear_state(scene, speed)
    found = linearize.linearisation_error(linear.context, steady.state.x, system=linear.system,
                                          observe=linear.observe, monodromy=steady.state.monodromy)
    assert found.trusted, found.reason
    nonlinear = studies.nonlinear_steady_state(problem, {"speed": speed}, n_steps=N_STEPS)
    for k, spec in enumerate(linear.observables):
        linear_ptp = peak_to_peak(steady.response[:, k])[0]
        true = nonlinear.peak_to_peak[spec] - linear_ptp
        estimate = peak_to_peak(steady.response[:, k] + found.change[:, k])[0] - linear_ptp
        if abs(true) > 0.005 * linear_ptp:
            assert 0.5 <= estimate / true <= 2.0, (spec, estimate, true)
        else:  # a small difference (0.1-0.5 %) is not reported as a large one
            assert abs(estimate) <= 0.01 * linear_ptp, (spec, estimate, true)


# ---------------------------------------------------------------------------------------------------
# the budget on results
# ---------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def fem4_steady():
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    return studies.steady_state(problem, {"speed": 100.0}, n_steps=N_STEPS)


def test_steady_state_carries_its_budget_and_reports_the_total(fem4_steady):
    result = fem4_steady
    spec = "coupler.deflection@0.5"
    terms = result.error_budget[spec]
    assert set(terms) >= {"time_step", "mesh", "linearisation"}
    # the linear figure is high (the machine's is about 9 % lower): a negative linearisation term
    assert terms["linearisation"] < -0.05 * result.peak_to_peak[spec]
    assert result.peak_to_peak_error[spec] == pytest.approx(result.budget.total(spec))
    assert result.status == "inaccurate" and "mostly linearisation" in result.message
    assert "nonlinear" in result.message


def test_a_looser_tolerance_accepts_it():
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    result = studies.steady_state(problem, {"speed": 100.0}, n_steps=N_STEPS, error_tolerance=0.2)
    assert result.status == "ok", result.message


def test_budget_round_trips_and_format_2_files_read_as_time_step_only(fem4_steady, tmp_path):
    path = tmp_path / "budget.h5"
    fem4_steady.save(path)
    back = studies.load(path)["steady_state"]
    assert back.error_budget == fem4_steady.error_budget or all(
        back.error_budget[s][k] == v or (v != v)
        for s, terms in fem4_steady.error_budget.items() for k, v in terms.items())
    import h5py

    with h5py.File(path, "a") as handle:
        group = handle["steady_state"]
        for name in ("error_budget", "peak_error_budget", "response_error_budget", "error_methods"):
            del group.attrs[name]
        as_format_2(handle, "steady_state")   # as flexvib wrote it before the budget: no checksums either
    old = studies.load(path)["steady_state"]
    spec = "coupler.deflection@0.5"
    assert old.error_budget[spec]["time_step"] == old.peak_to_peak_error[spec]
    assert math.isnan(old.error_budget[spec]["linearisation"])
    assert "format 2" in old.error_methods["linearisation"]


def test_periodic_problem_has_no_linearisation_term():
    result = studies.steady_state(studies.mathieu_problem(), n_steps=64)
    for terms in result.error_budget.values():
        assert terms["linearisation"] == budget.NOT_APPLICABLE
        assert terms["mesh"] == budget.NOT_APPLICABLE


def test_sweep_points_carry_their_budget():
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    speeds = [60.0, 100.0, 107.0]
    result = studies.sweep(problem, "speed", speeds, n_steps=N_STEPS)
    spec = "coupler.deflection@0.5"
    terms = result.error_budget[spec]
    np.testing.assert_allclose(result.peak_to_peak_error[spec], result.budget.total(spec))
    # each point has its own linearisation term (one linearisation shared by the speeds)
    assert len(set(np.round(terms["linearisation"], 12))) == 3
    plain = studies.sweep(problem, "speed", speeds, n_steps=N_STEPS, budget=False)
    np.testing.assert_allclose(plain.peak_to_peak_error[spec], terms["time_step"])


# ---------------------------------------------------------------------------------------------------
# the property of the bar: random stable scenes from the shipped ones
# ---------------------------------------------------------------------------------------------------
# Until the mesh term lands (studies._mesh_error is a stub saying "not applicable"), the reference is
# the converged (N = 512) nonlinear state on the scene's own mesh, which the time-step and
# linearisation terms must cover. With the mesh term: take the nonlinear state on the mesh refined
# to 16-32 elements as the reference (the "converged nonlinear response"), and add
# six_bar (2 elements per link as shipped) to PROPERTY_SCENES.
PROPERTY_SCENES = ("four_bar_fem4", "four_bar_ritz", "slider_crank")
THICKNESS = "links.{}.thickness"
DAMPING = "links.{}.damping.ratio"
ELASTIC = {"four_bar_fem4": "coupler", "four_bar_ritz": "coupler", "slider_crank": "rod"}


def _random_case(rng):
    scene = PROPERTY_SCENES[rng.integers(len(PROPERTY_SCENES))]
    link = ELASTIC[scene]
    paths = (THICKNESS.format(link), DAMPING.format(link))
    problem = studies.MechanismProblem.from_scene(scene, parameter_paths=paths)
    values = {"speed": float(rng.uniform(0.5, 1.3) * problem.parameters["speed"]),
              paths[0]: float(rng.uniform(0.9, 1.2) * problem.parameters[paths[0]]),
              paths[1]: float(rng.uniform(0.01, 0.05))}
    return scene, problem, values


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6))
def test_the_nonlinear_state_lies_inside_the_bar_and_the_bar_is_not_loose(seed):
    scene, problem, values = _random_case(np.random.default_rng(seed))
    linear = studies.steady_state(problem, values, n_steps=N_STEPS, error_tolerance=0.5)
    if not linear.is_stable or any(math.isnan(e) for e in linear.peak_to_peak_error.values()):
        pytest.skip(f"{scene} at {values}: {linear.status} (the bar is for stable, estimable points)")
    reference = studies.nonlinear_steady_state(problem, values, n_steps=2 * N_STEPS)
    assert reference.status != "failed", reference.message
    for spec, value in linear.peak_to_peak.items():
        true = abs(reference.peak_to_peak[spec] - value)
        bar = linear.peak_to_peak_error[spec]
        # the reference's own (time-step) error, where it has an estimate, is allowed for
        slack = np.nan_to_num(reference.peak_to_peak_error[spec])
        assert true <= bar + slack, (scene, values, spec, true, linear.error_budget[spec])
        assert bar <= max(3.0 * true, 0.05 * value), (scene, values, spec, true, linear.error_budget[spec])


def test_files_written_before_the_budget_read_as_time_step_only():
    """tests/data/results_before_core.h5 (format 1): the errors were the time step's alone."""
    from pathlib import Path

    results = studies.load(Path(__file__).parent / "data" / "results_before_core.h5")
    for name in ("steady_state", "sweep", "nonlinear_steady_state"):
        for spec, terms in results[name].error_budget.items():
            np.testing.assert_array_equal(terms["time_step"], results[name].peak_to_peak_error[spec])
            assert np.isnan(np.asarray(terms["mesh"], dtype=float)).all()
            if name != "nonlinear_steady_state":
                assert np.isnan(np.asarray(terms["linearisation"], dtype=float)).all()


def test_the_studies_table_takes_error_tolerance():
    from studies.cli import _scene  # the [studies] table's reading is the command's machinery

    sweep = {"parameter": "speed", "start": 50.0, "stop": 150.0, "count": 3}
    _, declared = _scene.plan({"error_tolerance": 0.05, "steady_state": {}, "sweep": sweep})
    assert declared["steady_state"]["error_tolerance"] == 0.05
    assert declared["sweep"]["error_tolerance"] == 0.05
    _, plain = _scene.plan({"steady_state": {}})
    assert "error_tolerance" not in plain["steady_state"]   # the request of older files is unchanged
    with pytest.raises(studies.StudiesError, match=r"\[studies\] error_tolerance"):
        _scene.plan({"error_tolerance": 5, "steady_state": {}})
