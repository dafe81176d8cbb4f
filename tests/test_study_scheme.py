"""The ``scheme`` of the studies: a keyword of the study functions that shoot and a key of the
``[studies]`` table, checked against the registry of periodic schemes, recorded in the result file
and part of a study's request (a run with another scheme is another study, not a resume)."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

import periodic
import studies
from studies.cli import main
from studies.cli._scene import plan  # the command's [studies] check: no public face


@pytest.fixture(scope="module")
def mathieu():
    return studies.mathieu_problem()


def test_an_unknown_scheme_is_refused_naming_the_registered_ones(mathieu):
    with pytest.raises(studies.StudiesError, match="scheme: .*trapezoidal.*got 'leapfrog'"):
        studies.steady_state(mathieu, n_steps=32, scheme="leapfrog")
    with pytest.raises(studies.StudiesError, match=r"\[studies\] scheme: .*damped.*trapezoidal"):
        plan({"scheme": "leapfrog", "steady_state": {}})


def test_the_scheme_changes_the_numbers_within_their_error_estimates(mathieu):
    """Both schemes converge to the same steady state: at N steps each differs from a fine
    trapezoidal reference by about its own error estimate (order 1 against order 2)."""
    n_steps = 256
    reference = studies.steady_state(mathieu, {"speed": 0.7}, n_steps=4096)
    for name in ("trapezoidal", "damped"):
        found = studies.steady_state(mathieu, {"speed": 0.7}, n_steps=n_steps, scheme=name)
        error = np.abs(found.response["x"] - reference.response["x"][:: 4096 // n_steps]).max()
        estimate = found.response_error["x"]
        assert 0.3 * estimate < error < 3.0 * estimate + 1e-9, (name, error, estimate)
    trapezoidal = studies.steady_state(mathieu, {"speed": 0.7}, n_steps=n_steps)
    damped = studies.steady_state(mathieu, {"speed": 0.7}, n_steps=n_steps, scheme="damped")
    # first order against second: the damped scheme's error is the larger one
    assert damped.response_error["x"] > 3.0 * trapezoidal.response_error["x"]
    assert (trapezoidal.scheme, damped.scheme) == ("trapezoidal", "damped")


def test_an_error_cost_study_records_its_scheme_and_refuses_one_it_cannot_extrapolate(mathieu):
    found = studies.error_cost(mathieu, {"speed": 0.7}, n_steps=(16, 32), scheme="trapezoidal")
    assert found.settings["scheme"] == "trapezoidal"
    with pytest.raises(studies.StudiesError, match="scheme 'damped' is not symmetric.*Richardson"):
        studies.error_cost(mathieu, {"speed": 0.7}, n_steps=(16, 32), scheme="damped")


def test_a_steady_state_records_its_scheme_in_its_file(mathieu, tmp_path):
    damped = studies.steady_state(mathieu, {"speed": 0.7}, n_steps=64, scheme="damped")
    damped.save(tmp_path / "s.h5")
    (back,) = studies.load(tmp_path / "s.h5").values()
    assert back.scheme == "damped"
    np.testing.assert_array_equal(back.response["x"], damped.response["x"])


def test_a_grid_point_uses_the_scheme(mathieu):
    speeds = [0.6, 0.8]
    default = studies.sweep(mathieu, "speed", speeds, n_steps=64)
    damped = studies.sweep(mathieu, "speed", speeds, n_steps=64, scheme="damped")
    assert default.settings["scheme"] == "trapezoidal" and damped.settings["scheme"] == "damped"
    # each point as its own steady state with that scheme
    for index, speed in enumerate(speeds):
        alone = studies.steady_state(mathieu, {"speed": speed}, n_steps=64, scheme="damped")
        assert damped.spectral_radius[index] == pytest.approx(alone.spectral_radius, rel=1e-12)
    assert not np.allclose(default.spectral_radius, damped.spectral_radius, rtol=1e-6)


def test_the_scheme_is_recorded_and_part_of_the_request(tmp_path, capsys):
    out = tmp_path / "m.h5"
    run = ["run", "mathieu", "--out", str(out), "--only", "steady_state", "--only", "sweep", "--quiet",
           "--set", "studies.sweep.count=3"]
    assert main(run) == 0
    with h5py.File(out, "r") as handle:
        asked = json.loads(handle["steady_state"].attrs["request"])
        first_hash = handle["steady_state"].attrs["request_hash"]
        assert asked["scheme"] == "trapezoidal"
        assert json.loads(handle["sweep"].attrs["settings"])["scheme"] == "trapezoidal"
    # the same file with another scheme: the steady state is recomputed, the grid is refused (its
    # points were computed with the other scheme and cannot be resumed)
    assert main(run + ["--set", "studies.scheme=damped"]) == 2
    assert "sweep (scheme)" in capsys.readouterr().err
    assert main(["run", "mathieu", "--out", str(out), "--only", "steady_state", "--quiet",
                 "--set", "studies.scheme=damped"]) == 0
    with h5py.File(out, "r") as handle:
        assert json.loads(handle["steady_state"].attrs["request"])["scheme"] == "damped"
        assert handle["steady_state"].attrs["request_hash"] != first_hash
    damped = studies.load(out)["steady_state"]
    fresh = studies.steady_state(studies.mathieu_problem(), {"speed": 0.7}, n_steps=128, scheme="damped")
    np.testing.assert_allclose(damped.response["x"], fresh.response["x"], rtol=1e-12)


def test_every_registered_scheme_is_accepted():
    for name in periodic.SCHEMES:
        common, declared = plan({"scheme": name, "steady_state": {}})
        assert common["scheme"] == name and declared["steady_state"]["scheme"] == name


@pytest.mark.slow
def test_the_reduction_check_compares_models_with_the_same_scheme():
    """A steady state's modal-reduction error is the difference of two models integrated with its own
    scheme: with the first-order "damped" scheme it equals ``linearize.reduction_error`` solving both
    models afresh with that scheme, and stays near the trapezoidal rule's (mixing the schemes gave
    4e-3 here, the schemes' difference, and the status ``inaccurate``)."""
    import linearize
    import mechanisms

    mechanism = mechanisms.load("four_bar_fem4").with_parameters(
        {"links.coupler.discretisation.n_elements": 16, "links.coupler.discretisation.modes": 6})
    problem = studies.MechanismProblem.from_mechanism(mechanism)
    found = {name: studies.steady_state(problem, {"speed": 50.0}, n_steps=64, scheme=name)
             for name in ("trapezoidal", "damped")}
    alone = linearize.reduction_error(problem.mechanism({"speed": 50.0}), n_steps=64,
                                      observables=problem.observable_specs, scheme="damped")
    assert found["damped"].reduction_error == pytest.approx(alone.error, rel=1e-9)
    assert found["damped"].reduction_error < 3.0 * found["trapezoidal"].reduction_error
