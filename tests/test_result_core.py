"""One result core: every registered study kind's result has ``status`` (a word of
``periodic.STATUSES``), ``message``, ``run_time`` (s), the observables' ``peak``, ``peak_to_peak`` and
their errors in the documented shapes ({spec: float} for one point, {spec: array of the grid's
shape} for a grid; {} for a study without observables), ``point_*`` arrays where it has grid points,
``plot()`` and ``to_hdf5``; read back from HDF5 it has the same fields. Small real results: the
built-in Mathieu problem and the one-element four-bar at few steps.

``tests/data/results_before_core.h5`` was written by the code before the result core (commit
56570dd) with :func:`write_small_results`; it must still load, with the shared fields filled:
``PYTHONPATH=<a checkout of 56570dd>:. python -c "from tests.test_result_core import
write_small_results; write_small_results('tests/data/results_before_core.h5')"``.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib
import numpy as np
import pytest

import mechanisms
import periodic
import studies

matplotlib.use("Agg")

OLD_FILE = Path(__file__).parent / "data" / "results_before_core.h5"
PEAK_FIELDS = ("peak", "peak_error", "peak_to_peak", "peak_to_peak_error")


def _registry():
    """The study kinds by name, through the public face where there is one."""
    for name in ("kinds", "KINDS"):
        face = getattr(studies, name, None)
        if face is not None:
            return face() if callable(face) else face
    from studies._kinds import KINDS  # the face of a checkout without studies.kinds() (56570dd)

    return KINDS


def _four_bar():
    return studies.MechanismProblem.from_scene("four_bar_fem1")


def _controlled_four_bar():
    spec = mechanisms.four_bar(n_elements=1).to_spec()
    spec["drive"].update(type="torque", kp=20.0, kd=0.5)
    return studies.MechanismProblem.from_mechanism(mechanisms.build(spec, source="test four-bar, PD drive"))


#: kind -> (the study on a small problem, the grid's shape of its observable summaries from the result:
#: None for a single point, "none" for a study without observables)
BUILDERS = {
    "steady_state": (lambda: studies.steady_state(studies.mathieu_problem(), n_steps=32), None),
    "sweep": (lambda: studies.sweep(studies.mathieu_problem(), "speed", [0.8, 1.9], n_steps=32),
              lambda result: result.values.shape),
    "campbell": (lambda: studies.campbell(studies.mathieu_problem(), [0.8, 1.9], n_steps=32), "none"),
    "stability_chart": (lambda: studies.stability_chart(studies.mathieu_problem(), ("speed", [1.8, 2.0]),
                                                        ("epsilon", [0.1, 0.3]), n_steps=32), "none"),
    "nonlinear_check": (lambda: studies.nonlinear_check(_four_bar(), n_steps=32, n_periods=2), None),
    "nonlinear_steady_state": (lambda: studies.nonlinear_steady_state(_four_bar(), n_steps=32), None),
    "nonlinear_sweep": (lambda: studies.nonlinear_sweep(_four_bar(), start=95.0, stop=100.0, step=5.0,
                                                        n_steps=32, transient_periods=4),
                        lambda result: result.values.shape),
    "error_cost": (lambda: studies.error_cost(studies.mathieu_problem(), n_steps=(16, 32)),
                   lambda result: (result.resolutions.size, result.n_steps.size)),
    "control_comparison": (lambda: studies.control_comparison(_controlled_four_bar(), n_periods=3, n_steps=64),
                           None),
    "optimize": (lambda: studies.optimize(studies.mathieu_problem(), {"damping_ratio": (0.02, 0.1)},
                                          objective="peak_to_peak:x", speeds=[0.9, 1.1], n_steps=16,
                                          max_evaluations=4, check=False),
                 lambda result: result.speeds.shape),
    "run_up": (lambda: studies.run_up(_four_bar(), start=90.0, stop=100.0, duration=0.4, n_steps=32,
                                      start_state="linear", curve_points=3, curve_steps=32),
               lambda result: result.speed.shape),

    "sensitivity": (lambda: studies.sensitivity(studies.mathieu_problem(), parameters=["speed", "epsilon"],
                                                n_steps=32), None),
}
#: kinds added after tests/data/results_before_core.h5 was written (the file has no group of theirs)
NEWER_KINDS = {"run_up", "sensitivity"}


def write_small_results(path) -> None:
    """Write one small result of every kind in :data:`BUILDERS` to ``path`` (public API only, so that
    the code of any version can write it)."""
    for name, (build, _) in BUILDERS.items():
        build().save(path, name)


@pytest.fixture(scope="module")
def results():
    return {name: build() for name, (build, _) in BUILDERS.items()}


def test_every_built_in_kind_is_covered():
    built_in = {name for name, kind in _registry().items() if kind.result.__module__.startswith("studies.")}
    assert built_in <= set(BUILDERS), sorted(built_in - set(BUILDERS))


def _assert_core(result, shape) -> None:
    """The shared fields of ``result`` in their documented types and shapes."""
    assert isinstance(result.status, str) and result.status in periodic.STATUSES, result.status
    assert isinstance(result.message, str)
    assert isinstance(result.run_time, float) and math.isfinite(result.run_time) and result.run_time > 0
    summaries = [getattr(result, name) for name in PEAK_FIELDS]
    if shape == "none":
        assert all(summary == {} for summary in summaries)
        return
    specs = list(result.units) if hasattr(result, "units") else list(summaries[2])
    assert specs and all(list(summary) == list(summaries[0]) for summary in summaries)
    assert set(summaries[0]) <= set(specs)
    for summary in summaries:
        for spec, value in summary.items():
            if shape is None:
                assert isinstance(value, float), (spec, value)
            else:
                assert isinstance(value, np.ndarray) and value.shape == shape(result), (spec, np.shape(value))
    if shape is not None and hasattr(result, "point_status"):
        grid = shape(result) if not getattr(result, "is_grid", False) else np.shape(result.done)
        assert np.shape(result.point_status) == grid


@pytest.mark.slow
@pytest.mark.parametrize("name", list(BUILDERS))
def test_shared_fields_figure_and_round_trip(results, name, tmp_path, assert_same):
    import matplotlib.pyplot as plt

    result, shape = results[name], BUILDERS[name][1]
    _assert_core(result, shape)
    if getattr(result, "is_grid", False):   # a grid's own verdicts, per point
        for field in ("point_status", "point_message", "point_run_time"):
            assert np.shape(getattr(result, field)) == np.shape(result.done), field
        assert result.run_time >= np.nansum(result.point_run_time)
    drawing = result.plot()
    assert isinstance(drawing, studies.Plot) and drawing.artists
    plt.close(drawing.figure)
    result.save(tmp_path / "r.h5", name)
    back = studies.load(tmp_path / "r.h5")[name]
    assert_same(result, back)
    assert (back.status, back.message, back.run_time) == (result.status, result.message, result.run_time)
    for field in PEAK_FIELDS:
        np.testing.assert_equal(getattr(back, field), getattr(result, field), err_msg=field)


def test_peaks_are_those_of_the_response():
    """A single point's summaries are the refined extremes of its own response (peak_summary's), the
    same numbers in every kind that reports a periodic response."""
    result = studies.steady_state(studies.mathieu_problem(), n_steps=32)
    response = result.response["x"]
    assert result.peak_to_peak["x"] == pytest.approx(np.ptp(response), rel=0.02)
    assert result.peak_to_peak["x"] >= np.ptp(response[:-1]) - 1e-15   # refined: never below the samples
    assert result.peak_to_peak_error["x"] >= 2 * result.response_error["x"]
    assert result.peak["x"] >= np.abs(response).max() - 1e-15


@pytest.mark.slow
def test_a_file_written_before_the_core_still_loads():
    found = studies.load(OLD_FILE)
    assert set(found) == set(BUILDERS) - NEWER_KINDS
    for name, result in found.items():
        _assert_core(result, BUILDERS[name][1])
    cost = found["error_cost"]   # no status then: "ok", and the message says it was not judged
    assert cost.status == "ok" and "not judged" in cost.message
    assert cost.point_run_time.shape == (1, 2) and cost.run_time == pytest.approx(
        cost.reference_run_time + cost.point_run_time.sum())
    assert all(np.isnan(values).all() for values in cost.peak_to_peak.values())
    orbit = found["nonlinear_steady_state"]   # run_time was the shooting's alone
    assert orbit.shooting_run_time < orbit.run_time == pytest.approx(orbit.shooting_run_time + orbit.linear_run_time)
    comparison = found["control_comparison"]   # run_time was {case: s}
    assert set(comparison.case_run_time) == {"with", "without"}
    assert comparison.run_time == pytest.approx(sum(comparison.case_run_time.values()))
    branch = found["nonlinear_sweep"]   # "statuses" then
    assert branch.point_status.shape == branch.values.shape and branch.point_status.dtype.kind == "U"
