"""A new study kind defined outside the packages (in ``tests/_support/extensions.py``), with public API
only (``studies.StudyKind``, ``studies.register_kind``, ``studies.Result``,
``studies.steady_solves``, ``studies.Summary``): "peak_table", the steady state's peak to peak of
each observable at a few speeds. Registered, it runs through the ``flexvib`` entry point in-process
(on a scene file declaring it, and in the built-in mathieu scene through its demo table), its file
loads back with ``studies.load``, and its numbers are held to the closed form of the forced
oscillator and to ``studies.steady_state`` itself."""

from __future__ import annotations

import math

import h5py
import pytest

import mechanisms
import studies
from studies.cli import main
from tests._support.extensions import DEMO_SPEEDS, KIND, PeakTable


# ---------------------------------------------------------------------------------------------------
def _oscillator_peak_to_peak(speed: float, *, natural_frequency=1.0, damping_ratio=0.02, force=1.0) -> float:
    """Twice the amplitude of x'' + 2 zeta w0 x' + w0^2 x = F cos(W t) in its steady state."""
    w0 = natural_frequency
    return 2.0 * force / math.hypot(w0**2 - speed**2, 2.0 * damping_ratio * w0 * speed)


def test_the_kind_is_registered_with_its_pieces():
    assert studies.kinds()["peak_table"] is KIND and studies.register_kind(KIND) is KIND  # idempotent
    with pytest.raises(studies.StudiesError, match="already registered"):
        studies.register_kind(studies.StudyKind(name="peak_table", result=PeakTable, keys=(), check=KIND.check,
                                                run=KIND.run, summary=KIND.summary, cost=KIND.cost))
    estimate = studies.estimate(studies.mathieu_problem(), "peak_table", {"speeds": DEMO_SPEEDS, "n_steps": 64})
    single = studies.estimate(studies.mathieu_problem(), "steady_state", {"values": {}, "n_steps": 64})
    # three solves one after the other: more time than one, the same peak memory
    assert "3 steady states x 64 steps" in estimate.sizes
    assert estimate.time > single.time and estimate.memory == single.memory


def test_its_numbers_meet_the_closed_form_of_the_forced_oscillator(tmp_path):
    """Without the parametric term (epsilon = 0) the Mathieu problem is the forced, damped oscillator,
    whose peak to peak is known in closed form; through the HDF5 round trip."""
    problem = studies.mathieu_problem(epsilon=0.0)
    result = KIND.run(problem, KIND.check("studies.peak_table", {"speeds": [0.5, 0.9, 1.4]}, 256))
    result.save(tmp_path / "table.h5")
    back = studies.load(tmp_path / "table.h5")["peak_table"]
    assert isinstance(back, PeakTable) and studies.kind_of(back) is KIND
    for speed, value, error in zip(back.speeds, back.peak_to_peak["x"], back.peak_to_peak_error["x"]):
        exact = _oscillator_peak_to_peak(speed)
        # within the estimated error of the peak to peak (the sampled extremes and the time step)
        assert abs(value - exact) <= 3.0 * error + 1e-3 * exact, (speed, value, exact, error)


def test_it_runs_in_the_mathieu_scene_through_its_demo_table(tmp_path, capsys):
    out = tmp_path / "mathieu.h5"
    assert main(["run", "mathieu", "--out", str(out), "--only", "peak_table", "--quiet"]) == 0
    assert "peak_table" in capsys.readouterr().out
    with h5py.File(out, "r") as handle:
        assert handle["peak_table"].attrs["kind"] == "peak_table"
    table = studies.load(out)["peak_table"]
    problem = studies.mathieu_problem()
    for speed, value in zip(DEMO_SPEEDS, table.peak_to_peak["x"]):
        direct = studies.steady_state(problem, {"speed": speed}, n_steps=64)
        assert value == pytest.approx(direct.peak_to_peak["x"], rel=1e-12)


def test_it_runs_on_a_scene_file_declaring_it(tmp_path, capsys):
    mechanism = mechanisms.load("four_bar_thesis")
    speed = 2.0 * math.pi / mechanism.period
    speeds = [0.8 * speed, 1.1 * speed]
    scene = tmp_path / "scene.toml"
    scene.write_text(mechanism.to_toml() + f"\n[studies]\nn_steps = 32\n\n[studies.peak_table]\nspeeds = {speeds!r}\n")
    out = tmp_path / "scene.h5"
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "peak_table" in printed and "peak to peak at" in printed  # its line and its summary rows
    table = studies.load(out)["peak_table"]
    problem = studies.MechanismProblem.from_scene(str(scene))
    for k, value in enumerate(speeds):
        direct = studies.steady_state(problem, {"speed": value}, n_steps=32)
        for spec, values in table.peak_to_peak.items():
            assert values[k] == pytest.approx(direct.peak_to_peak[spec], rel=1e-9), spec
    # a bad table is refused with the kind's own message (exit code 2)
    scene.write_text(mechanism.to_toml() + "\n[studies.peak_table]\nspeeds = []\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "bad.h5"), "--quiet"]) == 2
    assert "[studies.peak_table] speeds: expected a list of positive speeds" in capsys.readouterr().err


@pytest.mark.parametrize("change, message", [
    ({"name": "Peak table"}, "must be an identifier"),
    ({"name": "scheme"}, "is a key of the \\[studies\\] table"),
    ({"name": "peak_table_2", "cost": None}, "declares no cost model"),
    ({"name": "peak_table_2", "result": dict}, "result must be a subclass of studies.Result"),
    ({"name": "peak_table_2"}, "result class PeakTable is already the result of kind 'peak_table'"),
    ({"name": "peak_table_2", "grid": True}, "a grid study without a point function"),
    ({"name": "peak_table_2", "demo": [1.0]}, "demo must be a table"),
    ({"name": "peak_table_2", "result": studies.Result},
     "result class Result lacks status, message, run_time, peak, peak_error, peak_to_peak, peak_to_peak_error"),
])
def test_a_kind_missing_a_piece_is_refused_at_registration(change, message):
    import dataclasses

    with pytest.raises(studies.StudiesError, match=message):
        studies.register_kind(dataclasses.replace(KIND, **change))
    assert set(studies.kinds()) >= {"peak_table"} and "peak_table_2" not in studies.kinds()
