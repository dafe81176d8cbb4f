"""Every study kind declares its cost model for the resource guard (``StudyKind.cost``), and the
nonlinear kinds' estimates follow their sizes; their table keys have upper limits."""

import dataclasses

import pytest

import studies
from studies import kinds


def test_every_kind_has_a_cost_model():
    # a kind without one could only be sized as something else: far too cheap for a nonlinear or grid study
    assert kinds() and all(callable(kind.cost) for kind in kinds().values())


def test_a_kind_without_a_cost_model_is_refused_at_registration():
    class Unsized(studies.Result):
        pass

    steady = kinds()["steady_state"]
    unsized = dataclasses.replace(steady, name="unsized_steady_state", result=Unsized, cost=None, aliases=())
    with pytest.raises(studies.StudiesError, match="unsized_steady_state.*no cost model"):
        studies.register_kind(unsized)
    assert "unsized_steady_state" not in kinds()
    with pytest.raises(studies.StudiesError, match="unknown study kind 'unsized_steady_state'"):
        studies.estimate(None, "unsized_steady_state", {})


@pytest.fixture(scope="module")
def problem():
    return studies.MechanismProblem.from_scene("four_bar_fem4")


def test_nonlinear_estimates_grow_with_their_sizes(problem):
    steady = kinds()["nonlinear_steady_state"]
    small = studies.estimate(problem, "nonlinear_steady_state", steady.check("s", {}, 128))
    large = studies.estimate(problem, "nonlinear_steady_state", steady.check("s", {"n_steps": 1024}, 128))
    # a shooting costs more than a linear steady state of the same size, and scales with the steps
    linear = studies.estimate(problem, "steady_state", {"values": {}, "n_steps": 128})
    assert small.time > 2.0 * linear.time and large.time > 6.0 * small.time
    sweep = kinds()["nonlinear_sweep"]
    short = studies.estimate(problem, "nonlinear_sweep", sweep.check("s", {"start": 90.0, "stop": 100.0,
                                                                          "max_points": 10}, 128))
    long = studies.estimate(problem, "nonlinear_sweep", sweep.check("s", {"start": 90.0, "stop": 100.0,
                                                                         "max_points": 1000, "step": 0.01}, 128))
    # 1000 orbits against 10 (the transient and the linear curve are the same)
    assert long.time > 3.0 * short.time and short.time > small.time
    assert "orbits" in long.sizes
    # an empty range (refused by the table check) costs one orbit, not a ZeroDivisionError
    empty = dict(sweep.check("s", {"start": 90.0, "stop": 100.0}, 128), stop=90.0)
    assert studies.estimate(problem, "nonlinear_sweep", empty).sizes.startswith("1 orbits")


@pytest.mark.parametrize("kind, table, key", [
    ("nonlinear_steady_state", {"max_iterations": 10**6}, "max_iterations"),
    ("nonlinear_sweep", {"start": 1.0, "stop": 2.0, "max_points": 10**7}, "max_points"),
    ("nonlinear_sweep", {"start": 1.0, "stop": 2.0, "transient_periods": 10**7}, "transient_periods"),
    ("nonlinear_sweep", {"start": 1.0, "stop": 2.0, "n_steps": 2**20}, "n_steps"),
])
def test_size_keys_have_upper_limits(kind, table, key):
    with pytest.raises(studies.StudiesError, match=f"{key}: at most"):
        kinds()[kind].check("studies." + kind, table, 128)
