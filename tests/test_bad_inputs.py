"""Issue 23: the bad inputs that were still accepted or mishandled, each through ``flexvib run``: exit
code 2, one line naming the key (or argument) and the fix, no traceback, no result file written; and
the physical-sense limits judged relative to the mechanism, so a millimetre-scale machine stays valid."""

import contextlib
import io
import math
from pathlib import Path

import pytest

import mechanisms
from mechanisms._parts.checks import MAX_TEXT  # the free-text limit itself: not exported
from studies.cli import main

BASE = mechanisms.load("four_bar_fem1")
STUDIES = """
[studies]
n_steps = 32
[studies.steady_state]
[studies.sweep]
parameter = "speed"
start = 80.0
stop = 120.0
count = 3
"""


def _run(argv) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            code = main([str(a) for a in argv])
        except SystemExit as stop:   # argparse's own refusals (exit 2 with its usage line)
            code = stop.code
    return code, err.getvalue()


def _refused(argv, out: Path, *words: str) -> str:
    code, err = _run(argv)
    assert code == 2, err
    assert err.startswith("flexvib: error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err and "internal error" not in err, err
    assert len(err) < 1200, err
    for word in words:
        assert word in err, (word, err)
    assert not out.exists() and not list(out.parent.glob(out.name + ".*")), "a file was written"
    return err


def _scene(tmp_path: Path, change=None, studies: str = STUDIES) -> Path:
    spec = BASE.to_spec()
    if change is not None:
        change(spec)
    path = tmp_path / "scene.toml"
    path.write_text(mechanisms.build(spec).to_toml() + studies if change is None or _valid(spec)
                    else _toml(spec) + studies)
    return path


def _valid(spec) -> bool:
    try:
        mechanisms.build(spec)
    except mechanisms.MechanismError:
        return False
    return True


def _toml(spec) -> str:
    """TOML of a spec the loader refuses (mechanisms' writer takes valid mechanisms only)."""
    from tests.test_fuzz_scenes import to_toml

    return to_toml(spec)


# ---------------------------------------------------------------------------------------------------
# the command line
# ---------------------------------------------------------------------------------------------------
def test_set_of_an_unknown_key_on_the_mathieu_scene_is_refused(tmp_path):
    out = tmp_path / "out.h5"
    _refused(["run", "mathieu", "--set", "nosuch=1", "--out", out], out, "nosuch", "studies.")
    _refused(["run", "mathieu", "--set", "studies.nosuch=1", "--out", out], out, "nosuch", "keys:")


def test_an_empty_out_is_refused(tmp_path):
    out = tmp_path / "out.h5"
    _refused(["run", "mathieu", "--only", "steady_state", "--out", ""], out, "--out", "run.h5")


def test_quiet_and_verbose_together_are_refused(tmp_path):
    out = tmp_path / "out.h5"
    code, err = _run(["run", "mathieu", "--quiet", "--verbose", "--out", out])
    assert code == 2 and "not allowed with argument" in err and "Traceback" not in err
    assert not out.exists()


@pytest.mark.parametrize("scene, words", [
    ("{folder}", ("is a folder",)),
    ("/dev/null", ("not a regular file",)),
    ("/dev/zero", ("not a regular file",)),
])
def test_a_folder_or_a_device_as_the_scene_is_named_as_such(tmp_path, scene, words):
    out = tmp_path / "out.h5"
    err = _refused(["run", scene.format(folder=tmp_path), "--out", out], out, *words)
    assert "does not exist" not in err


def test_a_scene_nested_50000_deep_is_refused(tmp_path):
    out = tmp_path / "out.h5"
    scene = tmp_path / "nested.toml"
    scene.write_text("a = " + "[" * 50000 + "]" * 50000 + "\n")
    _refused(["run", scene, "--out", out], out, "nested")


def test_a_50_mb_description_is_refused_at_once(tmp_path):
    import time

    out = tmp_path / "out.h5"
    scene = tmp_path / "long.toml"
    scene.write_text(f'description = "{"x" * 50_000_000}"\n' + BASE.to_toml().split("\n", 2)[2] + STUDIES)
    start = time.perf_counter()
    _refused(["run", scene, "--out", out], out, "bytes", "at most")
    assert time.perf_counter() - start < 5.0


def test_a_description_longer_than_the_text_limit_is_refused_by_the_loader(tmp_path):
    spec = BASE.to_spec()
    spec["description"] = "x" * (MAX_TEXT + 1)
    with pytest.raises(mechanisms.MechanismError, match="description must be at most"):
        mechanisms.build(spec)
    spec["description"] = "x" * MAX_TEXT
    mechanisms.build(spec)


def test_empty_observables_are_refused(tmp_path):
    out = tmp_path / "out.h5"
    scene = _scene(tmp_path, studies=STUDIES.replace("n_steps = 32", "n_steps = 32\nobservables = []"))
    _refused(["run", scene, "--out", out], out, "observables", "non-empty")


# ---------------------------------------------------------------------------------------------------
# a later study's bad argument: refused before the first study is written
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("later, words", [
    ("[studies.control_comparison]\n", ("feedback", "torque")),
    ('[studies.optimize]\nobjective = "peak_to_peak:coupler.deflection@0.5"\n'
     'bounds = { "links.coupler.discretisation.n_elements" = [1.0, 4.0] }\n', ("n_elements", "count")),
])
def test_a_bad_later_study_is_refused_before_anything_is_written(tmp_path, later, words):
    out = tmp_path / "out.h5"
    scene = _scene(tmp_path, studies=STUDIES + later)
    _refused(["run", scene, "--out", out], out, *words)


# ---------------------------------------------------------------------------------------------------
# physical sense, relative to the mechanism
# ---------------------------------------------------------------------------------------------------
def _harmonic(spec):
    spec["drive"]["harmonics"] = [[1, 1.0e6, 0.0]]


def _short_period(spec):
    spec["period"] = 1e-12
    spec["drive"]["rate"] = 2.0 * math.pi / 1e-12


def _tiny_crank(spec):
    spec["links"]["crank"]["length"] = 1e-12


@pytest.mark.parametrize("change, words", [
    (_harmonic, ("harmonics", "rad per period", "at most")),
    (_short_period, ("period", "natural period", "limit")),
    (_tiny_crank, ("links.crank.length", "longest link", "limit")),
], ids=["harmonic_1e6_rad", "period_1e-12_s", "crank_1e-12_m"])
def test_absurd_drives_and_sizes_are_refused_with_the_limit(tmp_path, change, words):
    out = tmp_path / "out.h5"
    spec = BASE.to_spec()
    change(spec)
    with pytest.raises(mechanisms.MechanismError):
        mechanisms.build(spec)
    _refused(["run", _scene(tmp_path, change), "--out", out], out, *words)


def test_a_millimetre_scale_four_bar_is_as_valid_as_the_metre_scale_one():
    """Every length divided by 1000 and the period by 1000 (the elastic periods scale so: omega_1 =
    (pi / L)^2 sqrt(E I / (rho A)) with I ~ h^3 b, A ~ h b scales as 1 / L): the same checks pass."""
    spec = BASE.to_spec()
    for link in spec["links"].values():
        for key in ("length", "width", "thickness"):
            if key in link:
                link[key] = link[key] / 1000.0
    for joint in spec["joints"].values():
        for key in ("point_a", "point_b"):
            if isinstance(joint.get(key), list):
                joint[key] = [v / 1000.0 for v in joint[key]]
    spec["drive"]["rate"] = spec["drive"]["rate"] * 1000.0
    small = mechanisms.build(spec)
    assert small.period == pytest.approx(BASE.period / 1000.0)
    # a harmonic of a few radians, and a crank a thousandth of the coupler, stay valid
    spec["drive"]["harmonics"] = [[2, 0.5, 0.1]]
    mechanisms.build(spec)
