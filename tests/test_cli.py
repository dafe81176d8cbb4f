"""The flexvib command end to end through ``main(argv)`` on small scenes."""

from __future__ import annotations

import re

import numpy as np
import pytest

import mechanisms
import studies
from studies import _grid  # patched: the grid's point evaluation (internal)
from studies.cli import main

SMALL_FOUR_BAR = """
[studies]
n_steps = 32

[studies.steady_state]

[studies.sweep]
parameter = "speed"
values = [60.0, 100.0, 140.0]

[studies.stability_chart]
x = { parameter = "speed", values = [80.0, 120.0] }
y = { parameter = "links.coupler.thickness", values = [1.4e-3, 1.8e-3] }
n_steps = 32

[studies.nonlinear_check]
n_periods = 2
"""


@pytest.fixture(scope="module")
def mathieu_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mathieu")
    path = folder / "m.h5"
    assert main(["run", "mathieu", "--out", str(path), "--quiet"]) == 0
    return path


def test_scenes_lists_mechanisms_and_the_mathieu_demo(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    assert "four_bar_thesis" in out and "mathieu" in out


def test_run_writes_every_declared_study_and_resumes(mathieu_run, monkeypatch, capsys):
    results = studies.load(mathieu_run)
    # the mathieu scene runs each registered kind's demo table
    demo_kinds = {name for name, kind in studies.kinds().items() if kind.demo is not None}
    assert "steady_state" in demo_kinds and set(results) == demo_kinds
    assert all(r.done.all() for r in results.values() if hasattr(r, "done"))
    evaluated = []
    monkeypatch.setattr(_grid, "evaluate", lambda *a: evaluated.append(a) or None)
    assert main(["run", "mathieu", "--out", str(mathieu_run), "--quiet"]) == 0
    assert evaluated == []  # everything was complete: nothing recomputed
    assert "sweep" in capsys.readouterr().out


def test_jobs_do_not_change_the_numbers(mathieu_run, tmp_path, assert_same):
    path = tmp_path / "pool.h5"
    assert main(["run", "mathieu", "--out", str(path), "--jobs", "2", "--quiet"]) == 0
    serial, pooled = studies.load(mathieu_run), studies.load(path)
    for kind in ("sweep", "campbell", "stability_chart"):
        assert_same(serial[kind], pooled[kind])


EXPECTED_LABELS = {
    "steady_state": ["time (s)", "x (m)"],  # the Mathieu problem has no crank
    "steady_state_multipliers": ["Re mu", "Im mu"],
    "sweep": ["speed (rad/s)", "x peak to peak (m)", "spectral radius |mu|max"],
    "campbell": ["speed (rad/s)", "frequency (rad/s)"],
    "stability_chart": ["speed (rad/s)", "epsilon", "spectral radius |mu|max"],
    "nonlinear_check": ["time (s)", "x (m)"],
    "error_cost": ["run time (s)", "relative error (1)"],
    "optimize": ["evaluation (one steady state per speed)", "rms:x (m)"],
}


@pytest.mark.slow
def test_plot_draws_every_figure_with_its_axes(mathieu_run, tmp_path, capsys):
    outdir = tmp_path / "figures"
    assert main(["plot", str(mathieu_run), "--outdir", str(outdir)]) == 0
    for stem, labels in EXPECTED_LABELS.items():
        assert (outdir / f"{stem}.png").stat().st_size > 1000
        svg = (outdir / f"{stem}.svg").read_text()
        texts = {t.replace("&#39;", "'") for t in re.findall(r">([^<>]+)</text>", svg)}
        for label in labels:
            assert label in texts, (stem, label)


def test_info_summarises(mathieu_run, capsys):
    assert main(["info", str(mathieu_run)]) == 0
    out = capsys.readouterr().out
    assert "[sweep] sweep of mathieu, complete" in out and "points done: 57 of 57" in out
    assert "numpy" in out and "error_estimate" in out
    import h5py

    with h5py.File(mathieu_run, "r") as handle:   # the run's compile time, recorded apart
        assert f"compile_time: {float(handle.attrs['compile_time']):.3g} s" in out
    # each grid study's verdicts are tallied, as the run's summary does
    sweep = studies.load(mathieu_run)["sweep"]
    names, counts = np.unique(sweep.point_status, return_counts=True)
    tally = out.split("[sweep]")[1].split("statuses: ")[1].splitlines()[0]
    assert sorted(tally.split(", ")) == sorted(f"{c} {n}" for n, c in zip(names, counts))


@pytest.mark.slow
def test_small_four_bar_scene_end_to_end(tmp_path, capsys):
    scene = tmp_path / "small.toml"
    scene.write_text(mechanisms.load("four_bar_thesis").to_toml() + SMALL_FOUR_BAR)
    path = tmp_path / "fb.h5"
    assert main(["run", str(scene), "--out", str(path), "--quiet"]) == 0
    results = studies.load(path)
    assert set(results) == {"steady_state", "sweep", "stability_chart", "nonlinear_check"}
    chart = results["stability_chart"]
    assert chart.parameters == ("speed", "links.coupler.thickness") and chart.parameter_units[1] == "m"
    assert np.isfinite(chart.spectral_radius).all()
    steady = results["steady_state"]
    # the deformed outlines keep the pins together: the crank's end is the coupler's start (the
    # coupler is pinned-pinned, so its deflection vanishes there) to the nominal motion's residual
    outlines = steady.outlines
    np.testing.assert_allclose(outlines["crank"][:, -1], outlines["coupler"][:, 0], atol=1e-9)
    np.testing.assert_allclose(outlines["coupler"][:, -1], outlines["rocker"][:, -1], atol=1e-9)
    outdir = tmp_path / "figures"
    assert main(["plot", str(path), "--outdir", str(outdir)]) == 0
    svg = (outdir / "steady_state_mechanism.svg").read_text()
    assert "x (m)" in svg and "y (m)" in svg


@pytest.mark.parametrize("argv, message", [
    (["run", "no_such_scene"], "no built-in scene 'no_such_scene'"),
    (["run", "missing.toml"], "does not exist"),
    (["run", "mathieu", "--jobs", "0"], "--jobs"),
    (["run", "mathieu", "--executor", "dask"], "--scheduler"),
    (["run", "mathieu", "--scheduler", "tcp://127.0.0.1:1"], "only used with --executor dask"),
    (["plot", "missing.h5"], "does not exist"),
    (["info", "missing.h5"], "does not exist"),
])
def test_bad_input_exits_2_with_a_clear_message(argv, message, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize(
    "table, message",
    [
        ("[studies.sweep]\nparameter = 'speed'\nstrat = 1.0\n", "unknown key 'strat'; did you mean 'start'?"),
        ("[studies]\nn_steps = 33\n[studies.steady_state]\n", "n_steps: expected an even integer"),
        (
            "[studies.sweep]\nparameter = 'links.coupler.thicknes'\nvalues = [1e-3]\n",
            "no parameter 'links.coupler.thicknes'",
        ),
        ("[studies]\nn_steps = 32\n", "declares no study"),
        (
            "[studies]\nobservables = ['coupler.deflektion@0.5']\n[studies.steady_state]\n",
            "unknown quantity 'deflektion'",
        ),
    ],
)
def test_bad_studies_table_exits_2_naming_the_key(table, message, tmp_path, capsys):
    scene = tmp_path / "bad.toml"
    scene.write_text(mechanisms.load("four_bar_thesis").to_toml() + table)
    assert main(["run", str(scene), "--out", str(tmp_path / "bad.h5"), "--quiet"]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["plot", "--help"], ["info", "--help"],
                                  ["scenes", "--help"]])
def test_help_everywhere(argv, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 0 and "usage: flexvib" in capsys.readouterr().out


def test_argparse_errors_exit_2(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["run", "--jobs", "two"])
    assert exit_.value.code == 2


@pytest.mark.slow
def test_dask_scheduler_from_the_command_line(mathieu_run, tmp_path, assert_same):
    distributed = pytest.importorskip("distributed")
    path = tmp_path / "dask.h5"
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp",
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        assert main(["run", "mathieu", "--out", str(path), "--executor", "dask", "--scheduler",
                     cluster.scheduler_address, "--quiet"]) == 0
    serial, remote = studies.load(mathieu_run), studies.load(path)
    for kind in ("sweep", "campbell", "stability_chart"):
        assert_same(serial[kind], remote[kind])


def test_a_study_that_cannot_be_computed_is_reported_and_the_rest_written(tmp_path, monkeypatch, capsys):
    from studies._kinds import nonlinear_check  # patched: the name the kind's run calls (internal)

    def fails(*args, **kwargs):
        raise RuntimeError("Newton's method did not converge")

    monkeypatch.setattr(nonlinear_check, "nonlinear_check", fails)
    path = tmp_path / "m.h5"
    assert main(["run", "mathieu", "--out", str(path), "--quiet"]) == 1
    assert "nonlinear_check  FAILED: RuntimeError: Newton's method" in capsys.readouterr().out
    assert "nonlinear_check" not in studies.load(path) and "sweep" in studies.load(path)


def test_speed_of_a_scene_with_oscillating_drives_is_its_fundamental_frequency():
    import math

    from studies import MechanismProblem

    problem = MechanismProblem.from_scene("two_link_arm")
    period = mechanisms.load("two_link_arm").period
    assert problem.parameters["speed"] == pytest.approx(2 * math.pi / period, rel=1e-15)
    linear = problem.linearize({"speed": 4 * math.pi / period}, n_steps=8, context=False)
    assert linear.system.period == pytest.approx(period / 2, rel=1e-15)


# ---------------------------------------------------------------------------------------------------
# exit codes: bad input 2, a numerical failure 1, an internal error (a bug) 1 in one line
# ---------------------------------------------------------------------------------------------------
def test_a_bad_scene_exits_2_naming_it(tmp_path, capsys):
    scene = tmp_path / "bad.toml"
    scene.write_text(mechanisms.load("four_bar_thesis").to_toml().replace("[links.coupler]",
                                                                          "[links.coupler]\nlenght = 1.0"))
    assert main(["run", str(scene), "--out", str(tmp_path / "bad.h5"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("flexvib: error: ") and "lenght" in err and "Traceback" not in err


def _raise_in_run(monkeypatch, error):
    from studies.cli import _run as _plan  # patched: the run the command starts (internal)

    def run_plan(*args, **kwargs):
        raise error

    monkeypatch.setattr(_plan, "run_plan", run_plan)


def test_a_numerical_failure_exits_1(tmp_path, monkeypatch, capsys):
    _raise_in_run(monkeypatch, np.linalg.LinAlgError("singular matrix"))
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err == "flexvib: error: LinAlgError: singular matrix\n"


@pytest.mark.parametrize("error", [TypeError("unsupported operand"), KeyError("speed")])
def test_an_internal_error_exits_1_in_one_line_without_traceback(error, tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("FLEXVIB_DEBUG", raising=False)
    _raise_in_run(monkeypatch, error)
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith(f"flexvib: internal error: {type(error).__name__}: ")
    assert "please report; set FLEXVIB_DEBUG=1 for the traceback" in err
    assert "Traceback" not in err and err.count("\n") == 1


def test_flexvib_debug_prints_the_traceback_of_an_internal_error(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("FLEXVIB_DEBUG", "1")
    _raise_in_run(monkeypatch, TypeError("unsupported operand"))
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "flexvib: internal error: TypeError: unsupported operand" in err


def test_studies_error_is_public_and_a_value_error():
    assert issubclass(studies.StudiesError, ValueError) and issubclass(studies.ComputationError, RuntimeError)
    with pytest.raises(studies.StudiesError, match="n_steps"):
        studies.steady_state(studies.mathieu_problem(), n_steps=15)


def test_demo_writes_the_periodic_example_and_rejects_an_odd_step_count(tmp_path, capsys):
    prefix = tmp_path / "demo"
    assert main(["demo", "--out", str(prefix), "--n-steps", "64"]) == 0
    assert capsys.readouterr().out.split() == [str(prefix) + ".h5", str(prefix) + ".png"]
    assert main(["demo", "--out", str(tmp_path / "odd"), "--n-steps", "63"]) == 2
    assert "n_steps: expected an even integer >= 4" in capsys.readouterr().err
    assert not list(tmp_path.glob("odd*"))


def test_a_scene_plan_holds_the_checked_studies_of_scene_set_and_only():
    from studies.cli import ScenePlan, UsageError

    plan = ScenePlan.read("mathieu", [("studies.sweep.count", 5), ("studies.n_steps", 64)], only=["sweep"])
    assert list(plan.studies) == ["sweep"] and plan.studies["sweep"]["values"].size == 5
    assert plan.common["n_steps"] == 64 and plan.common["scheme"] == "trapezoidal"
    assert plan.studies["sweep"]["scheme"] == "trapezoidal" and plan.problem.name == "mathieu"
    with pytest.raises(UsageError, match="--set epsilon=0.1: the built-in mathieu scene has no scene table"):
        ScenePlan.read("mathieu", [("epsilon", 0.1)])
    with pytest.raises(UsageError, match="--only: the scene declares no study 'campbel'"):
        ScenePlan.read("mathieu", only=["campbel"])
