"""What ``flexvib run`` shows (log lines, progress bars, warnings once, --quiet, --version) and its
conveniences (--set, --only, ``MechanismProblem.from_mechanism`` with the mechanism alone), through
``studies.cli.main`` in-process."""

from __future__ import annotations

import io
import logging
import re
import warnings

import h5py
import numpy as np
import pytest

import mechanisms
import periodic
import studies
from studies._kinds import nonlinear_check as nonlinear_check_module  # patched: the name its run calls
from studies.cli import _console, _scene, main  # _console, _scene: the command's machinery, no public face

SMALL_FOUR_BAR = """
[studies]
n_steps = 32

[studies.steady_state]

[studies.sweep]
parameter = "speed"
values = [60.0, 100.0]
"""


@pytest.fixture(scope="module")
def small_scene(tmp_path_factory):
    scene = tmp_path_factory.mktemp("scene") / "small.toml"
    scene.write_text(mechanisms.load("four_bar_thesis").to_toml() + SMALL_FOUR_BAR)
    return scene


class _Terminal(io.StringIO):
    """A captured stderr that says it is a terminal (progress bars are drawn only there)."""

    def isatty(self) -> bool:
        return True


# --- --version -------------------------------------------------------------------------------------
def test_version_names_flexvib_and_the_numerical_packages(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("flexvib ")
    for package in ("numpy", "scipy", "numba", "h5py"):
        assert re.search(rf"\b{package} \d", out), out


# --- progress bars and log lines -------------------------------------------------------------------
def test_no_progress_bar_into_redirected_output_and_one_log_line_each(tmp_path, capsys):
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--only", "sweep",
                 "--only", "steady_state"]) == 0
    err = capsys.readouterr().err
    assert "\r" not in err and "%|" not in err  # stderr is not a terminal here: no bars
    assert "running steady_state\n" in err and "running sweep\n" in err


def test_log_lines_are_never_glued_to_a_bar_on_a_terminal(tmp_path, monkeypatch, capsys):
    terminal = _Terminal()
    monkeypatch.setattr("sys.stderr", terminal)
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--only", "sweep",
                 "--only", "campbell", "--only", "steady_state"]) == 0
    err = terminal.getvalue()
    assert "%|" in err  # bars drawn
    # tqdm redraws a bar after "\r"; a log line written around the bars starts a segment of its own
    segments = re.split(r"[\r\n]", err)
    for name in ("steady_state", "sweep", "campbell"):
        holding = [s for s in segments if f"running {name}" in s]
        assert holding and all(s.startswith(f"running {name}") for s in holding), holding


@pytest.mark.slow
def test_per_point_messages_only_at_debug_level(small_scene, tmp_path, capsys):
    assert main(["run", str(small_scene), "--out", str(tmp_path / "a.h5")]) == 0
    quiet_enough = capsys.readouterr().err
    assert "running sweep" in quiet_enough and "nominal motion" not in quiet_enough
    # (another n_steps: the nominal motions of the first run are cached in this process)
    assert main(["run", str(small_scene), "--out", str(tmp_path / "b.h5"), "--verbose",
                 "--set", "studies.n_steps=48"]) == 0
    assert "nominal motion" in capsys.readouterr().err


# --- warnings, each once; --quiet --------------------------------------------------------------------
def _warning_check(monkeypatch):
    """Make the nonlinear check warn twice the same and once another, as a study may."""
    original = nonlinear_check_module.nonlinear_check

    def warning_check(problem, **options):
        for _ in range(2):
            warnings.warn("speed 0.7 rad/s is near a resonance", periodic.NearResonanceWarning, stacklevel=2)
        logging.getLogger("studies._grid").warning("a point failed")
        return original(problem, **options)

    monkeypatch.setattr(nonlinear_check_module, "nonlinear_check", warning_check)


def test_each_distinct_warning_is_shown_once_after_the_run(tmp_path, monkeypatch, capsys):
    _warning_check(monkeypatch)
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--only", "nonlinear_check"]) == 0
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    near = [line for line in lines if "near a resonance" in line]
    assert near == ["warning: NearResonanceWarning: speed 0.7 rad/s is near a resonance (2 times)"]
    assert lines.count("warning: a point failed") == 1
    # shown after the run (last lines of stderr); the summary is on stdout
    assert lines[-2:] == [near[0], "warning: a point failed"]
    assert "nonlinear_check" in captured.out
    assert [str(w) for w in _console.collected_warnings()] == lines[-2:]


def test_quiet_prints_errors_only(tmp_path, monkeypatch, capsys):
    _warning_check(monkeypatch)
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--only", "nonlinear_check",
                 "--quiet"]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert "nonlinear_check" in captured.out  # the result itself still goes to stdout
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--only", "nope", "--quiet"]) == 2
    assert "flexvib: error: --only" in capsys.readouterr().err


def test_console_restores_the_loggers_and_warning_hooks():
    logger = logging.getLogger("mechanisms")
    level, handlers, show = logger.level, list(logger.handlers), warnings.showwarning
    with _console.console():
        assert logger.handlers != handlers and warnings.showwarning is not show
    assert (logger.level, logger.handlers, warnings.showwarning) == (level, handlers, show)


# --- --set and --only --------------------------------------------------------------------------------
def test_set_overrides_studies_and_scene_values(small_scene, tmp_path):
    path = tmp_path / "set.h5"
    assert main(["run", "mathieu", "--out", str(path), "--only", "sweep", "--quiet",
                 "--set", "studies.sweep.count=5", "--set", "studies.n_steps=64"]) == 0
    (sweep,) = studies.load(path).values()
    assert sweep.done.size == 5
    path = tmp_path / "scene.h5"
    assert main(["run", str(small_scene), "--out", str(path), "--only", "steady_state", "--quiet",
                 "--set", "links.coupler.thickness=2.5e-3"]) == 0
    steady = studies.load(path)["steady_state"]
    assert mechanisms.loads(steady.scene).spec["links"]["coupler"]["thickness"] == 2.5e-3
    with h5py.File(path) as handle:  # the compile time is recorded apart from the run times
        assert handle.attrs["compile_time"] >= 0.0


@pytest.mark.parametrize("argument, named", [
    ("studies.swep.count=5", "'studies.swep'"),  # a table that is not there
    ("links.coupler.thicknes=2e-3", "thicknes"),  # a key the scene does not take
    ("links.coupler.thickness=-1", "links.coupler.thickness"),  # a value the scene refuses
    ("links.coupler.thickness.x=1", "'links.coupler.thickness'"),  # a value, not a table
])
def test_a_bad_set_is_exit_2_naming_the_path(small_scene, tmp_path, capsys, argument, named):
    out = tmp_path / "bad.h5"
    assert main(["run", str(small_scene), "--out", str(out), "--quiet", "--set", argument]) == 2
    err = capsys.readouterr().err
    assert err.startswith("flexvib: error:") and named in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_a_malformed_set_is_refused_by_the_parser(capsys):
    for argument in ("links.coupler.thickness", "=3", "a..b=1", "x=[1,"):
        with pytest.raises(SystemExit) as exit_:
            main(["run", "mathieu", "--set", argument])
        assert exit_.value.code == 2
        err = capsys.readouterr().err
        # argparse prints the reason, not its generic "invalid parse_set value"
        assert "argument --set: " in err and "invalid parse_set value" not in err
        assert "links.coupler.thickness=2e-3" in err or "expected a TOML value" in err


def test_set_values_are_toml_values_or_bare_words():
    assert _scene.parse_set("a.b=2e-3") == ("a.b", 2e-3)
    assert _scene.parse_set("a.b = 3") == ("a.b", 3)
    assert _scene.parse_set("a.b=true") == ("a.b", True)
    assert _scene.parse_set('a.b="speed"') == ("a.b", "speed")
    assert _scene.parse_set("a.b=speed") == ("a.b", "speed")
    assert _scene.parse_set("a.b=[60.0, 185]") == ("a.b", [60.0, 185])
    table = {"links": {"coupler": {"thickness": 1e-3}}, "name": "x"}
    changed = _scene.apply_overrides(table, [("links.coupler.thickness", 2e-3)])
    assert changed["links"]["coupler"]["thickness"] == 2e-3
    assert table["links"]["coupler"]["thickness"] == 1e-3  # the original is untouched


def test_only_an_undeclared_study_lists_the_declared_ones(small_scene, tmp_path, capsys):
    assert main(["run", str(small_scene), "--out", str(tmp_path / "o.h5"), "--only", "campbell"]) == 2
    err = capsys.readouterr().err
    assert "'campbell'" in err and "steady_state, sweep" in err


# --- MechanismProblem.from_mechanism with the mechanism alone -----------------------------------------
def test_from_mechanism_alone_and_the_unknown_parameter_advice():
    mechanism = mechanisms.four_bar()
    problem = studies.MechanismProblem.from_mechanism(mechanism)
    assert set(problem.parameters) == {"speed"}
    result = studies.steady_state(problem, n_steps=32)
    assert np.isfinite(result.spectral_radius)
    assert result.response.keys() == set(problem.describe().observables)
    with pytest.raises(studies.StudiesError, match=r"parameter_paths=\['links.coupler.thickness'\]"):
        studies.sweep(problem, "links.coupler.thickness", [1e-3, 2e-3], n_steps=32)
    with pytest.raises(studies.StudiesError, match="did you mean 'links.coupler.thickness'"):
        problem.resolve({"links.coupler.thicknes": 1e-3})
    one = studies.MechanismProblem.from_mechanism(mechanism, parameter_paths="links.coupler.thickness")
    assert one.parameters["links.coupler.thickness"] == one.mechanism().spec["links"]["coupler"]["thickness"]
    with pytest.raises(TypeError, match="from_scene"):
        studies.MechanismProblem.from_mechanism("four_bar_thesis")
