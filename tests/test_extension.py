"""The extensions of ``tests/_support/extensions.py`` together, as a user would use them: a geared
four-bar (the new joint, ``Gear``, between the crank and a wheel) whose elastic coupler is a Legendre
Ritz basis (the new discretisation), reporting the coupler's midspan curvature and chord angle (the new
observables), solved with the theta-method (the new periodic scheme, by its registered name) through

* a steady state (``studies.steady_state(..., scheme=...)``),
* the HDF5 round trip (``save``, ``studies.load``: the same numbers, the scene rebuilds the model),
* the new study kind ``peak_table`` declared in a scene file, through the command's entry point
  ``studies.cli.main`` called in-process, read back with ``studies.load``,

each number held to something that does not know of it: the gear's relation on the nominal motion and
along the vibration (to round-off); the curvature recomputed from the state with numpy's Legendre
series, and against the built-in bending moment; an equivalent model (the geared wheel is a flywheel of
``ratio^2 I`` on the crank); the built-in trapezoidal scheme (within the two error estimates); and
``studies.steady_state`` itself for the study kind. Last, the definitions module imports public names
only: none of it needed an edit to a package.
"""

from __future__ import annotations

import ast
import dataclasses
import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from numpy.polynomial import legendre

import linearize
import mechanisms
import periodic
import studies
import studies.cli
from tests._support import extensions
from tests._support.extensions import Gear, Legendre

RATIO, OFFSET = 2.0, 0.3        # a whole ratio: the wheel returns after one period
WHEEL_INERTIA = 4e-5            # kg m^2 about its centroid, the pivot
N_BENDING = 3                   # Legendre bending shapes of the coupler (and one axial)
N_STEPS = 128
SCHEME = "theta-0.6"            # order 1: its answer differs visibly from the trapezoidal rule's
CURVATURE, CHORD = "coupler.curvature@0.5", "coupler.chord_angle"
SPECS = (CURVATURE, CHORD, "coupler.moment@0.5", "coupler.angle", "crank.angle")


def _four_bar(flywheel: float = 0.0) -> mechanisms.Mechanism:
    """The thesis four-bar, its coupler a Legendre basis, its crank torque-driven with PD feedback (so
    that the crank, hence the gear, vibrates) and carrying a flywheel (kg m^2)."""
    base = mechanisms.load("four_bar_ritz")
    coupler = dataclasses.replace(base.link("coupler"), discretisation=Legendre(N_BENDING, 1))
    drive = mechanisms.TorqueDrive("O", rate=100.0, kp=2.0, kd=0.02, flywheel=flywheel)
    return base.replace(links=(base.links[0], coupler, base.links[2]), drives=(drive,))


def _geared() -> mechanisms.Mechanism:
    """The four-bar with a wheel pinned to the ground at its centroid, geared to the crank."""
    base = _four_bar()
    wheel = mechanisms.RigidLink("wheel", 0.03, mass=0.05, inertia=WHEEL_INERTIA, centroid=(0.0, 0.0))
    joints = base.joints + (mechanisms.Revolute("W", "ground", (0.05, -0.08), "wheel", "start"),
                            Gear("G", "crank", "start", "wheel", "start", RATIO, OFFSET))
    return base.replace(links=base.links + (wheel,), joints=joints)


@pytest.fixture(scope="module")
def geared() -> mechanisms.Mechanism:
    return _geared()


@pytest.fixture(scope="module")
def problem(geared) -> studies.MechanismProblem:
    return studies.MechanismProblem.from_mechanism(geared, observables=SPECS)


@pytest.fixture(scope="module")
def steady(problem) -> studies.SteadyStateResult:
    return studies.steady_state(problem, n_steps=N_STEPS, scheme=SCHEME)


def _gear_residual(model, s: np.ndarray) -> np.ndarray:
    """``theta_wheel + ratio theta_crank - offset`` along the states ``s`` (N+1, n): rad."""
    crank, wheel = model.link_coordinates("crank"), model.link_coordinates("wheel")
    return s[:, wheel.start + 2] + RATIO * s[:, crank.start + 2] - OFFSET


def test_the_gear_holds_on_the_nominal_motion_and_along_the_steady_state(geared, steady):
    """The gear's row is linear in the angles: the nominal motion satisfies it to round-off, and so does
    the vibration about it (``full_state`` is nominal + V z, V spanning the constraints' null space)."""
    motion = mechanisms.nominal_motion(geared, n_steps=N_STEPS)
    assert np.ptp(motion.s[:, motion.model.link_coordinates("crank").start + 2]) > 6.0  # a full turn
    np.testing.assert_allclose(_gear_residual(motion.model, motion.s), 0.0, rtol=0, atol=1e-12)
    lin = linearize.about(geared, n_steps=N_STEPS, observables=SPECS)
    assert lin.labels == steady.labels                  # the steady state's coordinates z are lin's
    s, _ = lin.full_state(steady.x, np.zeros_like(steady.x))
    np.testing.assert_allclose(_gear_residual(lin.nominal.model, s), 0.0, rtol=0, atol=1e-12)
    # ... and the vibration is there: the crank's angle moves about its nominal motion, the wheel's
    # coordinate (an independent one) is -ratio times it
    crank = steady.response["crank.angle"]
    assert np.ptp(crank) > 1e-3
    wheel = steady.x[:, steady.labels.index("wheel.theta")]
    np.testing.assert_allclose(wheel, -RATIO * crank, rtol=0, atol=1e-12 * np.abs(crank).max())


def _legendre_curvature(x: np.ndarray, labels: tuple[str, ...], length: float) -> np.ndarray:
    """w''(L/2) of the coupler from its amplitudes in the states ``x`` (N+1, m): the bending shapes
    ``P_{k+2} - P_k`` of ``xi = 2 x / L - 1``, differentiated by numpy's Legendre class (1/m)."""
    total = np.zeros(len(x))
    for k in range(N_BENDING):
        shape = legendre.Legendre.basis(k + 2) - legendre.Legendre.basis(k)
        total += x[:, labels.index(f"coupler.b{k + 1}")] * shape.deriv(2)(0.0) * (2.0 / length) ** 2
    return total


def test_the_new_observables_along_the_steady_state_are_their_definitions(geared, steady):
    coupler = geared.link("coupler")
    curvature = steady.response[CURVATURE]
    assert steady.units[CURVATURE] == "1/m" and steady.units[CHORD] == "rad"
    assert steady.peak_to_peak[CURVATURE] > 0.1        # 1/m: the coupler bends
    scale = np.abs(curvature).max()
    expected = _legendre_curvature(steady.x, steady.labels, coupler.length)
    np.testing.assert_allclose(curvature, expected, rtol=0, atol=1e-10 * scale)
    # the built-in bending moment is E I w''
    rigidity = coupler.youngs_modulus * coupler.second_moment
    np.testing.assert_allclose(rigidity * curvature, steady.response["coupler.moment@0.5"], rtol=0,
                               atol=1e-10 * rigidity * scale)
    # a pinned-pinned link's frame is its chord: the chord angle is the built-in link angle
    np.testing.assert_allclose(steady.response[CHORD], steady.response["coupler.angle"], rtol=0,
                               atol=1e-10 * np.abs(steady.response["coupler.angle"]).max())
    assert np.ptp(steady.response[CHORD]) > 1e-4


def test_the_geared_steady_state_is_that_of_a_flywheel_of_the_reflected_inertia(steady):
    """The wheel turns at -ratio times the crank: it adds ratio^2 I to the crank's inertia. The same
    scheme on the equivalent model gives the same steady state."""
    flywheel = studies.steady_state(studies.MechanismProblem.from_mechanism(
        _four_bar(flywheel=RATIO**2 * WHEEL_INERTIA), observables=SPECS), n_steps=N_STEPS, scheme=SCHEME)
    for spec in SPECS:
        a, b = steady.response[spec], flywheel.response[spec]
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-8 * np.abs(b).max(), err_msg=spec)


def test_the_new_scheme_agrees_with_the_trapezoidal_rule_within_the_two_error_estimates(problem, steady):
    trapezoidal = studies.steady_state(problem, n_steps=N_STEPS, scheme="trapezoidal")
    for spec in SPECS:
        difference = np.abs(steady.response[spec] - trapezoidal.response[spec]).max()
        # the time step's part of each error budget (the linearisation's is the same for both)
        both = (steady.response_error_budget[spec]["time_step"]
                + trapezoidal.response_error_budget[spec]["time_step"])
        # N/2 estimates of the leading error term: at order 1 the next term adds a few per cent
        assert 0.5 * both <= difference <= 1.2 * both, (spec, difference, both)
    # the new scheme's error is the larger one (order 1 against order 2)
    assert steady.error_estimate > 3.0 * trapezoidal.error_estimate
    # theta = 1/2 is the trapezoidal rule on the first-order form: the same numbers to round-off
    same_rule = studies.steady_state(problem, n_steps=N_STEPS, scheme="theta-0.5")
    for spec in SPECS:
        expected = trapezoidal.response[spec]
        np.testing.assert_allclose(same_rule.response[spec], expected, rtol=0,
                                   atol=1e-10 * np.abs(expected).max(), err_msg=spec)


def test_the_steady_state_round_trips_through_its_hdf5_file(tmp_path, geared, steady, assert_same):
    path = tmp_path / "geared.h5"
    steady.save(path, "steady")
    loaded = studies.load(path)["steady"]
    assert_same(steady, loaded)
    np.testing.assert_array_equal(loaded.response[CURVATURE], steady.response[CURVATURE])
    # the file's scene rebuilds the model: the gear and the Legendre basis by their registered names
    rebuilt = mechanisms.loads(loaded.scene)
    assert rebuilt == geared
    assert rebuilt.joint("G") == geared.joint("G") and isinstance(rebuilt.link("coupler").discretisation,
                                                                  Legendre)


def test_the_new_study_kind_runs_the_scene_through_the_command(tmp_path, geared, steady, capsys):
    """A scene file that names the gear, the Legendre basis, the observables and the scheme, and
    declares ``[studies.peak_table]``: ``flexvib run`` in-process writes the table, whose numbers are
    the steady states ``studies.steady_state`` computes at those speeds with that scheme."""
    speeds = [90.0, 100.0]
    declared = {"n_steps": N_STEPS, "scheme": SCHEME, "observables": list(SPECS),
                "peak_table": {"speeds": speeds}}
    scene = tmp_path / "geared.toml"
    scene.write_text(geared.replace(studies=declared).to_toml())
    for name in ('type = "gear"', 'type = "legendre"', f'scheme = "{SCHEME}"', CURVATURE, CHORD):
        assert name in scene.read_text(), name
    out = tmp_path / "geared.h5"
    assert studies.cli.main(["run", str(scene), "--out", str(out), "--quiet"]) == 0
    assert "peak_table" in capsys.readouterr().out
    with h5py.File(out, "r") as handle:   # the scheme is part of the request (another scheme, another study)
        assert json.loads(handle["peak_table"].attrs["request"])["scheme"] == SCHEME
    table = studies.load(out)["peak_table"]
    assert isinstance(table, extensions.PeakTable) and table.scheme == SCHEME
    assert table.n_steps == N_STEPS and table.units == steady.units
    np.testing.assert_array_equal(table.speeds, speeds)
    from_scene = studies.MechanismProblem.from_scene(str(scene), observables=SPECS)
    for k, speed in enumerate(speeds):
        direct = studies.steady_state(from_scene, {"speed": speed}, n_steps=N_STEPS, scheme=SCHEME)
        for spec in SPECS:
            assert table.peak_to_peak[spec][k] == pytest.approx(direct.peak_to_peak[spec], rel=1e-12), spec
            assert table.peak_to_peak_error[spec][k] == pytest.approx(direct.peak_to_peak_error[spec],
                                                                      rel=1e-12), spec
    # at the scene's own speed: the steady state of the mechanism built in Python
    for spec in SPECS:
        assert table.peak_to_peak[spec][1] == pytest.approx(steady.peak_to_peak[spec], rel=1e-9), spec


# ---------------------------------------------------------------------------------------------------
# no edit to any package: the definitions use public names only
# ---------------------------------------------------------------------------------------------------
PACKAGES = ("periodic", "mechanisms", "linearize", "studies")


def _private_uses(source: str) -> list[str]:
    """Private names of the packages a module's ``source`` reaches: a ``_``-prefixed module or name
    imported from them, or a ``_``-prefixed attribute of a name bound to one of them."""
    found, bound = [], set()        # bound: the names the module binds to the packages' objects
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] in PACKAGES:
                    if any(part.startswith("_") for part in parts):
                        found.append(alias.name)
                    bound.add(alias.asname or parts[0])
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            parts = (node.module or "").split(".")
            if parts[0] in PACKAGES:
                if any(part.startswith("_") for part in parts):
                    found.append(node.module)
                for alias in node.names:
                    if alias.name.startswith("_") or alias.name == "*":
                        found.append(f"{node.module}.{alias.name}")
                    bound.add(alias.asname or alias.name)
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Attribute) and node.attr.startswith("_"):
            base = node.value
            while isinstance(base, ast.Attribute):
                base = base.value
            if isinstance(base, ast.Name) and base.id in bound:
                found.append(f"{ast.unparse(node.value)}.{node.attr}")
    return found


def _imported_packages(source: str) -> set[str]:
    modules = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            modules |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            modules.add(node.module)
    return {m for m in modules if m.split(".")[0] in PACKAGES}


def test_the_definitions_use_only_the_public_faces_of_the_packages():
    source = Path(extensions.__file__).read_text()
    assert _private_uses(source) == []
    assert _imported_packages(source) == {"periodic", "mechanisms", "studies"}
    assert _private_uses(Path(__file__).read_text()) == []
    # and what they registered is what the packages' registries hold
    assert mechanisms.JOINT_TYPES["gear"] is Gear
    assert mechanisms.DISCRETISATION_TYPES["legendre"] is Legendre
    assert periodic.SCHEMES[SCHEME] is extensions.THETA_SCHEMES[SCHEME]
    assert studies.kinds()["peak_table"] is extensions.KIND


@pytest.mark.parametrize("source, expected", [
    ("import mechanisms._parts", ["mechanisms._parts"]),
    ("import studies._store as store", ["studies._store"]),
    ("from studies._kind import StudyKind", ["studies._kind"]),
    ("from studies import _kind", ["studies._kind"]),
    ("from periodic.lapack import _solve", ["periodic.lapack._solve"]),
    ("from linearize import *", ["linearize.*"]),
    ("import mechanisms\nmechanisms._assemble.assemble(m)", ["mechanisms._assemble"]),
    ("import studies.cli as cli\ncli._main.main()", ["cli._main"]),
    ("from studies import Result\nResult._units", ["Result._units"]),
    ("import numpy as np\nnp._core\nimport mechanisms\nmechanisms.load('x')", []),
    ("import studies.cli\nstudies.cli.main([])", []),
])
def test_the_check_of_private_names_finds_them(source, expected):
    assert _private_uses(source) == expected
