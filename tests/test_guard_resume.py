"""The resource guard on a resumed run: studies complete in the result file are not estimated (a run
started with --force resumes without it), a grid study partly saved is estimated for its missing
points only, and anything changed is estimated (and refused) as before."""

from __future__ import annotations

import shutil

import h5py
import numpy as np
import pytest

import mechanisms
from studies import (  # _cost: STUDY_SECONDS
    MechanismProblem,
    ResourceError,
    _cost,
    _guard,  # its TIME_LIMIT, patched (no public face)
    estimate,
    guard,
    kinds,
)
from studies.cli import load_scene, main

STUDIES = ("\n[studies]\nn_steps = 32\n[studies.steady_state]\n"
           "[studies.sweep]\nstart = 50.0\nstop = 150.0\ncount = 6\n")
#: A time limit every study is above (s): what the guard sees as a huge run, computed in seconds.
TINY = 1e-6


@pytest.fixture(scope="module")
def forced(tmp_path_factory):
    """``(scene path, result file)``: a scene whose studies are all above the tiny time limit, run to
    the end with --force."""
    folder = tmp_path_factory.mktemp("forced")
    scene, out = folder / "scene.toml", folder / "out.h5"
    scene.write_text(mechanisms.load("four_bar_fem4").to_toml() + STUDIES)
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_guard, "TIME_LIMIT", TINY)
        assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 2  # refused: over the limit
        assert not out.exists()
        assert main(["run", str(scene), "--out", str(out), "--quiet", "--force"]) == 0
    return scene, out


def _copy(forced, tmp_path):
    scene, out = forced
    shutil.copyfile(out, tmp_path / "out.h5")
    return str(scene), tmp_path / "out.h5"


def _run_times(path) -> tuple:
    """The steady state's run time and the sweep's point run times (s) in the file ``path``."""
    with h5py.File(path, "r") as handle:
        return handle["steady_state"].attrs["run_time"], tuple(handle["sweep/point_run_time"][()])


def test_a_run_started_with_force_resumes_without_it(forced, tmp_path, monkeypatch, capsys):
    scene, out = _copy(forced, tmp_path)
    monkeypatch.setattr(_guard, "TIME_LIMIT", TINY)
    before = _run_times(out)
    assert main(["run", scene, "--out", str(out), "--quiet"]) == 0
    # the studies were skipped or read back, not computed again
    assert _run_times(out) == before
    capsys.readouterr()
    # a changed study is not complete in the file: estimated, and refused, as before (exit 2)
    for changed, study in (("studies.sweep.count=7", "sweep"), ("studies.steady_state.n_steps=64", "steady_state")):
        assert main(["run", scene, "--out", str(out), "--quiet", "--set", changed]) == 2
        assert capsys.readouterr().err.startswith(f"flexvib: error: {study}: about ")
    # --overwrite starts the file afresh: nothing in it counts
    assert main(["run", scene, "--out", str(out), "--quiet", "--overwrite"]) == 2
    assert "--force" in capsys.readouterr().err


def test_a_file_of_another_scene_or_none_counts_for_nothing(forced, tmp_path, monkeypatch):
    scene, out = _copy(forced, tmp_path)
    monkeypatch.setattr(_guard, "TIME_LIMIT", TINY)
    problem, declared = load_scene(scene, force=True)
    assert guard(problem, declared, result_file=out) == []  # all complete: nothing to estimate
    other, _ = load_scene(scene, [("links.coupler.thickness", 2.0e-3)], force=True)
    for result_file in (out, tmp_path / "missing.h5", None):
        with pytest.raises(ResourceError, match="^steady_state: about"):
            guard(other if result_file == out else problem, declared, result_file=result_file)


def test_a_partly_saved_grid_is_estimated_for_its_missing_points(forced, tmp_path, monkeypatch, capsys):
    scene, out = _copy(forced, tmp_path)
    with h5py.File(out, "a") as handle:  # as a run killed after the first three points leaves it
        handle["sweep/done"][3:] = False
        handle["sweep"].attrs["complete"] = False
        saved = handle["sweep/done"][()]
    problem, declared = load_scene(scene, force=True)
    options = declared["sweep"]
    whole = estimate(problem, "sweep", options)
    left = estimate(problem, "sweep", options, done=saved)
    # independent: a speed sweep over the three missing speeds alone (one speed family either way);
    # the memory keeps the six points' results, which the resumed run reads back
    alone = estimate(problem, "sweep", dict(options, values=options["values"][3:]))
    assert left.time == pytest.approx(alone.time, rel=1e-12) and left.time < whole.time
    assert alone.memory < left.memory <= whole.memory
    assert left.sizes.endswith("(3 of 6 points left)")
    # the complete steady state is not estimated: the limit between the missing points and the whole
    # sweep lets the run resume; below the missing points' estimate it is refused
    monkeypatch.setattr(_guard, "TIME_LIMIT", 0.5 * left.time)
    assert main(["run", scene, "--out", str(out), "--quiet"]) == 2
    assert "(3 of 6 points left)" in capsys.readouterr().err
    monkeypatch.setattr(_guard, "TIME_LIMIT", 0.5 * (left.time + whole.time))
    assert main(["run", scene, "--out", str(out), "--quiet"]) == 0
    with h5py.File(out, "r") as handle:
        assert handle["sweep/done"][()].all() and handle["sweep"].attrs["complete"]


ELEMENTS = "links.coupler.discretisation.n_elements"
THICKNESS = "links.coupler.thickness"


def test_a_chart_with_rows_saved_needs_only_the_linearisations_of_the_others():
    problem = MechanismProblem.from_mechanism(mechanisms.load("four_bar_fem4"), parameter_paths=(THICKNESS,))
    chart = kinds()["stability_chart"]

    def options(thicknesses):
        return chart.check("s", {"x": {"parameter": "speed", "values": [50.0, 100.0]},
                                 "y": {"parameter": THICKNESS, "values": thicknesses}}, 32)

    whole = options([1.0e-3, 1.5e-3, 2.0e-3])
    done = np.zeros((2, 3), dtype=bool)
    done[:, 0] = True  # every speed at the first thickness saved
    left = estimate(problem, "stability_chart", whole, done=done)
    alone = estimate(problem, "stability_chart", options([1.5e-3, 2.0e-3]))
    assert left.time == pytest.approx(alone.time, rel=1e-12)
    # a grid whose points are all saved (killed before the study was marked complete) costs its
    # overhead only; a mask of another shape (not this grid) is ignored
    assert estimate(problem, "stability_chart", whole, done=np.ones((2, 3), bool)).time == _cost.STUDY_SECONDS
    assert estimate(problem, "stability_chart", whole, done=np.ones((3, 2), bool)).time == \
        estimate(problem, "stability_chart", whole).time
