"""Generated bad scene files through the loader and ``flexvib run``: never a traceback, exit code 2
with one line naming the problem, no result file written.

Each example mutates a shipped scene (mechanisms/scenes/*.toml, with a small [studies] table
declaring every kind) so that it is invalid by construction: malformed TOML, a value of the wrong
type, a negative, zero or non-finite number where a positive one is required, an unknown or
misspelt key, a required key removed, an absurd size (elements, modes, steps, points, harmonics,
periods, a drive turning a million times per period), or bytes that are not UTF-8; and the input
classes of issue 23: TOML nested 50000 deep, a link or a period below physical sense (relative to the
mechanism), a drive harmonic of absurd amplitude, free text past its limit, empty observables, and a
later study whose option the problem cannot take (refused before the first study is written). The command's
``run_plan`` is replaced by one that fails the test: an invalid scene must be refused before any
study starts (by the loader, the table checks or the resource guard). Hypothesis runs derandomized
(the same examples on every run) with a deadline per example.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import os
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path
from unittest import mock

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import mechanisms
from mechanisms._parts.checks import MAX_TEXT  # the free-text limit itself: not exported
from studies.cli import _run as _plan  # patched: the run the command starts (internal)
from studies.cli import main

ROOT = Path(__file__).resolve().parents[1]
SCENES = sorted((ROOT / "mechanisms" / "scenes").glob("*.toml"))

#: Tables whose keys are names (of links, joints, drives, masses, points, links again), not keys of
#: the format: a misspelt name there may be a valid scene.
NAMED = ("links", "joints", "drives", "point_masses", "points", "initial_angles")
#: Keys that must be positive where they appear (a zero or negative value is refused).
POSITIVE = ("length", "density", "youngs_modulus", "width", "thickness", "area", "second_moment",
            "mass", "period", "n_elements", "n_bending", "n_steps", "count", "n_periods",
            "frozen_samples", "max_harmonic", "max_periods_from_rest", "yield_strength")
#: Keys without a default in the tables where the shipped scenes use them.
REQUIRED = ("name", "length", "density", "youngs_modulus", "link_a", "point_a", "link_b", "point_b",
            "start", "stop", "count", "x", "y")
#: Size keys and the tables they belong in (an absurd value is set or added there).
SIZES = {("links", "*", "discretisation"): ("n_elements", "n_bending", "n_axial"),
         ("studies",): ("n_steps",),
         ("studies", "sweep"): ("count", "max_harmonic", "n_steps"),
         ("studies", "campbell"): ("count", "frozen_samples", "max_harmonic", "n_steps"),
         ("studies", "nonlinear_check"): ("n_periods", "max_periods_from_rest", "n_steps"),
         ("studies", "stability_chart", "x"): ("count",)}
MALFORMED = ("[links", "x = ", "= 1", "a = 'unterminated", "[[", "name = 'twice'", "k = [1, 2",
             "k = 1 2", "[studies]\n[studies]")


def _studies(mechanism: mechanisms.Mechanism) -> dict:
    """A small [studies] table declaring every kind, around the scene's own speed."""
    speed = 2.0 * math.pi / mechanism.period
    link = mechanism.links[0].name
    length = mechanism.links[0].length
    return {
        "n_steps": 32,
        "steady_state": {},
        "sweep": {"parameter": "speed", "start": 0.5 * speed, "stop": 1.5 * speed, "count": 3},
        "campbell": {"start": 0.5 * speed, "stop": 1.5 * speed, "count": 3, "frozen_samples": 8},
        "stability_chart": {"x": {"parameter": "speed", "start": 0.9 * speed, "stop": 1.1 * speed,
                                  "count": 2},
                            "y": {"parameter": f"links.{link}.length", "values": [length, 1.0001 * length]}},
        "nonlinear_check": {"n_periods": 2},
        "error_cost": {"n_steps": [16, 32]},
    }


def _base_specs() -> list[dict]:
    specs = []
    for path in SCENES:
        spec = tomllib.loads(path.read_text())
        spec["studies"] = _studies(mechanisms.build(spec))
        specs.append(spec)
    return specs


BASES = _base_specs()


# ---------------------------------------------------------------------------------------------------
# TOML text of a spec (non-finite numbers included, which mechanisms' writer refuses)
# ---------------------------------------------------------------------------------------------------
def _key(key: str) -> str:
    return key if key.replace("_", "").replace("-", "").isalnum() and key.isascii() else f'"{key}"'


def _value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value == math.inf else
                                                "-inf" if value == -math.inf else repr(value))
    if isinstance(value, int):
        return str(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    return "{" + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + "}"


def to_toml(spec: dict) -> str:
    lines: list[str] = []

    def emit(table: dict, prefix: str) -> None:
        scalars = {k: v for k, v in table.items() if not isinstance(v, dict)}
        if prefix:
            lines.append(f"\n[{prefix}]")
        lines.extend(f"{_key(k)} = {_value(v)}" for k, v in scalars.items())
        for key, sub in table.items():
            if isinstance(sub, dict):
                emit(sub, f"{prefix}.{_key(key)}" if prefix else _key(key))

    emit(spec, "")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------------
# mutations: each returns the bytes of a scene file that is invalid by construction
# ---------------------------------------------------------------------------------------------------
def _leaves(table: dict, path: tuple = ()) -> list[tuple]:
    found = []
    for key, value in table.items():
        if isinstance(value, dict):
            found += _leaves(value, path + (key,))
        else:
            found.append(path + (key,))
    return found


def _tables(table: dict, path: tuple = ()) -> list[tuple]:
    found = [path]
    for key, value in table.items():
        if isinstance(value, dict):
            found += _tables(value, path + (key,))
    return found


def _get(spec: dict, path: tuple):
    for key in path:
        spec = spec[key]
    return spec


def _is_name(path: tuple) -> bool:
    """Whether the last key of ``path`` is a name (of a link, point ...) rather than a format key."""
    return len(path) >= 2 and path[-2] in NAMED


def _matches(path: tuple, pattern: tuple) -> bool:
    return len(path) == len(pattern) and all(p == "*" or p == k for k, p in zip(path, pattern))


def wrong_type(data, spec):
    path = data.draw(st.sampled_from(_leaves(spec)))
    value = _get(spec, path)
    if isinstance(value, list) and value and data.draw(st.booleans()):
        # one entry of a list (a value of an axis, a coordinate of a point, a harmonic)
        value[data.draw(st.integers(0, len(value) - 1))] = data.draw(st.sampled_from([True, {"a": 1}, "oops"]))
        return
    _get(spec, path[:-1])[path[-1]] = data.draw(st.sampled_from(
        ["oops", 1.5, {"a": 1}] if isinstance(value, bool) else [True, False, {"a": 1}, []]))


def bad_number(data, spec):
    numbers = [p for p in _leaves(spec) if type(_get(spec, p)) in (int, float) and not _is_name(p)]
    path = data.draw(st.sampled_from(numbers))
    choices = [math.nan, math.inf, -math.inf]
    if path[-1] in POSITIVE:
        choices += [0, 0.0, -1, -1.0e-3, -1.0e300]
    _get(spec, path[:-1])[path[-1]] = data.draw(st.sampled_from(choices))


def unknown_key(data, spec):
    path = data.draw(st.sampled_from(_tables(spec)))
    _get(spec, path)[data.draw(st.sampled_from(["bogus", "lenght_x", "n_step", "Type"]))] = 1


def misspelt_key(data, spec):
    paths = [p for p in _leaves(spec) + _tables(spec)[1:] if not _is_name(p) and len(p[-1]) > 3]
    path = data.draw(st.sampled_from(paths))
    key = path[-1]
    i = data.draw(st.integers(0, len(key) - 2))
    typo = data.draw(st.sampled_from([key[:i] + key[i + 1:], key[:i] + key[i + 1] + key[i] + key[i + 2:],
                                      key.upper(), key + "s"]))
    table = _get(spec, path[:-1])
    if typo == key or typo in table:
        typo = key + "_x"
    table[typo] = table.pop(key)


def missing_key(data, spec):
    paths = [p for p in _leaves(spec) + _tables(spec)[1:]
             if (p[-1] in REQUIRED and not _is_name(p)) or p in (("links",), ("drive",), ("drives",))]
    path = data.draw(st.sampled_from(paths))
    del _get(spec, path[:-1])[path[-1]]


def absurd_size(data, spec):
    tables = [(p, keys) for p in _tables(spec) for pattern, keys in SIZES.items() if _matches(p, pattern)]
    path, keys = data.draw(st.sampled_from(tables))
    table = _get(spec, path)
    key = data.draw(st.sampled_from([k for k in keys if k != "n_bending" or table.get("type") == "ritz"]))
    if key == "count":
        table.pop("values", None)
        table.setdefault("start", 1.0)
        table.setdefault("stop", 2.0)
    if path[0] == "links" and key != "n_elements":
        table["type"] = "ritz"
    elif path[0] == "links":
        table["type"] = "fem"
    table[key] = data.draw(st.sampled_from([10**6, 10**9, 2**31, 10**15]))


def fast_drive(data, spec):
    drives = [spec["drive"]] if "drive" in spec else list(spec["drives"].values())
    spec["period"] = 2.0 * math.pi
    for drive in drives:
        drive["rate"] = data.draw(st.sampled_from([1.0e6, 1.0e9, 1.0e300]))


def costly_study(data, spec):
    """Sizes each within its limit whose product the resource guard refuses."""
    studies = spec["studies"]
    choice = data.draw(st.sampled_from(["sweep", "campbell", "nonlinear_check", "stability_chart"]))
    if choice == "nonlinear_check":
        studies[choice].update(n_periods=10_000, n_steps=65536)
    elif choice == "stability_chart":
        # a million cells, each a valid value close to the base's
        for key in ("x", "y"):
            axis = studies[choice][key]
            first = axis["values"][0] if "values" in axis else axis["start"]
            studies[choice][key] = {"parameter": axis["parameter"],
                                    "values": [first * (1.0 + 1e-7 * k) for k in range(1000)]}
        studies[choice]["n_steps"] = 1024
    else:
        studies[choice].update(count=100_000, n_steps=65536)
        studies[choice].pop("frozen_samples", None)


def _drives(spec) -> list[dict]:
    return [spec["drive"]] if "drive" in spec else list(spec["drives"].values())


def tiny_length(data, spec):
    """A link far shorter than the mechanism's longest (issue 23: a 1e-12 m crank ran ``ok``)."""
    link = data.draw(st.sampled_from(sorted(spec["links"])))
    spec["links"][link]["length"] = data.draw(st.sampled_from([1e-9, 1e-12, 1e-15]))


def tiny_period(data, spec):
    """A period far below the elastic links' natural periods (issue 23: 1e-12 s was accepted)."""
    period = data.draw(st.sampled_from([1e-9, 1e-12]))
    spec["period"] = period
    for drive in _drives(spec):
        if drive.get("rate", 0.0):
            drive["rate"] = 2.0 * math.pi / period


def huge_harmonic(data, spec):
    """A drive harmonic of absurd amplitude (issue 23: 1e6 rad passed and hung)."""
    drive = data.draw(st.sampled_from(_drives(spec)))
    drive["harmonics"] = [[data.draw(st.sampled_from([1, 3, 1000])), data.draw(st.sampled_from([1e4, 1e6, 1e300])),
                           0.0]]


def long_text(data, spec):
    """Free text past its limit (issue 23: a 50 MB description made a run take 48 s)."""
    spec[data.draw(st.sampled_from(["description", "name"]))] = "x" * (MAX_TEXT + 1)


def empty_observables(data, spec):
    spec["studies"]["observables"] = []


def bad_later_study(data, spec):
    """A study whose option the problem cannot take, declared after valid ones: refused before the
    first study is written (an optimisation bound on a count)."""
    link = data.draw(st.sampled_from(sorted(spec["links"])))
    spec["studies"]["optimize"] = {"objective": f"peak_to_peak:{link}.angle",
                                   "bounds": {f"links.{link}.discretisation.n_elements": [1.0, 4.0]}}


MUTATIONS = (wrong_type, bad_number, unknown_key, misspelt_key, missing_key, absurd_size, fast_drive,
             costly_study, tiny_length, tiny_period, huge_harmonic, long_text, empty_observables,
             bad_later_study)


@st.composite
def bad_scenes(draw) -> tuple[str, bytes]:
    """``(what was done, file bytes)`` of an invalid scene."""
    spec = copy.deepcopy(draw(st.sampled_from(BASES)))
    kind = draw(st.sampled_from(("malformed", "not_utf8", "nested") + tuple(m.__name__ for m in MUTATIONS)))
    if kind == "not_utf8":
        return kind, b"\xff\xfe" + to_toml(spec).encode()
    if kind == "nested":   # arrays within arrays deeper than the parser follows (issue 23)
        depth = draw(st.sampled_from([5000, 50000]))
        return kind, (to_toml(spec) + "\nzz = " + "[" * depth + "]" * depth + "\n").encode()
    if kind == "malformed":
        lines = to_toml(spec).splitlines()
        at = draw(st.integers(0, len(lines)))
        lines.insert(at, draw(st.sampled_from(MALFORMED)))
        return kind, "\n".join(lines).encode()
    mutation = next(m for m in MUTATIONS if m.__name__ == kind)
    mutation(_Draw(draw), spec)
    return kind, to_toml(spec).encode()


class _Draw:
    """``data.draw`` for the mutations, over a composite strategy's ``draw``."""

    def __init__(self, draw):
        self.draw = draw


FUZZ = settings(max_examples=500, deadline=5000, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _run(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(argv)
    return code, err.getvalue()


def _refuse_to_run(*args, **kwargs):
    raise AssertionError("an invalid scene reached run_plan")


# ---------------------------------------------------------------------------------------------------
def test_every_base_scene_is_valid_and_passes_the_guard():
    from studies.cli import load_scene

    for base, path in zip(BASES, SCENES):
        with tempfile.TemporaryDirectory() as folder:
            scene = Path(folder) / path.name
            scene.write_text(to_toml(base))
            problem, declared = load_scene(str(scene))
            assert set(declared) == {"steady_state", "sweep", "campbell", "stability_chart",
                                     "nonlinear_check", "error_cost"}


@pytest.mark.slow
@FUZZ
@given(bad_scenes())
def test_the_loader_refuses_every_bad_scene_with_a_mechanism_error(scene):
    kind, data = scene
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        return  # the CLI test covers bytes that are not text
    try:
        mechanism = mechanisms.loads(text)
    except mechanisms.MechanismError as error:
        assert str(error) and "\n" not in str(error)[:200]
        return
    # the mechanism is fine: the mutation is in the [studies] table, which the loader keeps raw
    assert "studies" in mechanism.spec


@pytest.mark.slow
@FUZZ
@given(bad_scenes())
def test_flexvib_run_refuses_every_bad_scene_in_one_line_with_exit_2(scene):
    kind, data = scene
    event(kind)
    with tempfile.TemporaryDirectory() as folder, mock.patch.object(_plan, "run_plan", _refuse_to_run):
        path, out = Path(folder) / "scene.toml", Path(folder) / "out.h5"
        path.write_bytes(data)
        code, err = _run(["run", str(path), "--out", str(out), "--quiet"])
        assert code == 2, (kind, err)
        assert err.startswith("flexvib: error: ") and err.count("\n") == 1, (kind, err)
        assert "Traceback" not in err and "internal error" not in err
        assert len(err) < 1000, err  # one line, not a dump of the scene
        assert not out.exists()


@pytest.mark.slow
def _four_bar(change) -> str:
    spec = copy.deepcopy(BASES[SCENES.index(ROOT / "mechanisms" / "scenes" / "four_bar_fem1.toml")])
    change(spec)
    return to_toml(spec)


@pytest.mark.slow
@pytest.mark.parametrize("text", [
    _four_bar(lambda spec: spec["links"]["coupler"].update(discretisation={"type": "fem", "n_elements": 1000})),
    _four_bar(lambda spec: spec["studies"]["sweep"].update(max_harmonic=10**9)),
    _four_bar(lambda spec: spec.update(period=2.0 * math.pi, drive=dict(spec["drive"], rate=1.0e6))),
    "[[\n" + _four_bar(lambda spec: None),
], ids=["n_elements", "max_harmonic", "rate", "malformed"])
def test_flexvib_as_a_process_refuses_bad_scenes(tmp_path, text):
    scene, out = tmp_path / "scene.toml", tmp_path / "out.h5"
    scene.write_text(text)
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-m", "studies.cli", "run", str(scene), "--out", str(out), "--quiet"],
                          capture_output=True, text=True, env=env, timeout=120, cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("flexvib: error: ") and "Traceback" not in done.stderr
    assert done.stderr.count("\n") == 1
    assert not out.exists()
