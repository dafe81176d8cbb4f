"""A new observable from outside the packages, with public API only: the bending curvature w'' and the
slope w' at a point of an elastic link, and the global angle of a link's chord, registered with
``mechanisms.register_observable`` (defined in ``tests/_support/extensions.py``). Each is checked
against an independent computation (central differences of its value; the built-in moment and stress
it must relate to; the built-in transverse displacement along the link; the built-in point positions
of the chord's ends), then reported by the linearisation, a nonlinear run, ``studies.steady_state``
and a sweep (in this process and in a pool's workers), through the HDF5 round trip and a resumed
run."""

import math
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

import linearize
import mechanisms
import studies
from tests._support.extensions import curvature, slope

SPECS = ("coupler.curvature@0.5", "coupler.moment@0.5", "coupler.slope@0.25", "coupler.chord_angle")


def _four_bar(rate=100.0):
    return mechanisms.four_bar(n_elements=2, axial=False, geometric_stiffening=False,
                               crank_speed=rate)


def _random_state(model, scale, seed):
    """A configuration of ``model`` near its initial one with elastic coordinates of ``scale``."""
    rng = np.random.default_rng(seed)
    s = rng.normal(0.0, 0.3, model.n_coords)
    s[np.asarray(model.elastic_index)] *= scale / 0.3
    return s


def _central_gradient(value, s, step):
    out = np.zeros_like(s)
    for i in range(s.size):
        e = np.zeros_like(s)
        e[i] = step
        out[i] = (value(s + e) - value(s - e)) / (2 * step)
    return out


@pytest.mark.parametrize("mechanism, specs", [
    (_four_bar(), ("coupler.curvature@0.3", "coupler.slope@0.7", "coupler.chord_angle")),
    (mechanisms.two_link_arm(), ("forearm.curvature@1.0", "upper.slope@0.5", "upper.chord_angle")),
])
def test_gradient_against_central_differences_of_the_value(mechanism, specs):
    model = mechanisms.assemble(mechanism)
    s = _random_state(model, 1e-2, seed=3)
    for spec in specs:
        observable = model.observable(spec)
        expected = _central_gradient(observable.value, s, 1e-6)
        np.testing.assert_allclose(observable.gradient(s), expected, rtol=1e-7,
                                   atol=1e-7 * np.abs(expected).max())


def test_curvature_against_the_built_in_moment_and_stress():
    """M = E I w'' (the built-in moment) and, axial force aside, the top fibre's stress is
    -M c / I = -E c w'': values and gradients."""
    mechanism = _four_bar()
    model = mechanisms.assemble(mechanism)
    coupler = next(link for link in mechanism.links if link.name == "coupler")
    s = _random_state(model, 1e-3, seed=5)
    for fraction in (0.0, 0.3, 0.5, 1.0):
        kappa = model.observable(f"coupler.curvature@{fraction}")
        moment = model.observable(f"coupler.moment@{fraction}")
        stress = model.observable(f"coupler.stress_top@{fraction}")
        rigidity = coupler.youngs_modulus * coupler.second_moment
        assert moment.value(s) == pytest.approx(rigidity * kappa.value(s), rel=1e-12)
        np.testing.assert_allclose(moment.gradient(s), rigidity * kappa.gradient(s), rtol=1e-12)
        top = -coupler.youngs_modulus * coupler.fibre_distance
        assert stress.value(s, axial_force=0.0) == pytest.approx(top * kappa.value(s), rel=1e-12)
        np.testing.assert_allclose(stress.gradient(s), top * kappa.gradient(s), rtol=1e-12)
        assert kappa.unit == "1/m" and model.observable(f"coupler.slope@{fraction}").unit == "1"


def test_slope_against_differences_of_the_built_in_transverse_displacement():
    """w'(x) against the central difference of the built-in w along the link (cubic elements: the
    difference's error is h^2 w''' / 6, tiny at h = 1e-4 L)."""
    model = mechanisms.assemble(_four_bar())
    s = _random_state(model, 1e-3, seed=7)
    length = model.layouts["coupler"].link.length
    h = 1e-4
    for fraction in (0.2, 0.25, 0.7):
        ahead = model.observable(f"coupler.transverse@{fraction + h}").value(s)
        behind = model.observable(f"coupler.transverse@{fraction - h}").value(s)
        expected = (ahead - behind) / (2 * h * length)
        assert model.observable(f"coupler.slope@{fraction}").value(s) == pytest.approx(expected, rel=1e-6)


def test_chord_angle_against_the_built_in_point_positions():
    """A clamped-free link: its chord's global angle from the global positions of its start and
    tip, the built-in point observables."""
    model = mechanisms.assemble(mechanisms.two_link_arm())
    s = _random_state(model, 2e-2, seed=11)
    for link in ("upper", "forearm"):
        def position(fraction, link=link):
            return np.array([model.observable(f"{link}.point_error_{axis}@{fraction}").value(s)
                             for axis in "xy"])

        dx, dy = position(1.0) - position(0.0)
        assert model.observable(f"{link}.chord_angle").value(s) == pytest.approx(
            math.atan2(dy, dx), abs=1e-13)


def test_unknown_names_and_bad_registrations_are_refused():
    model = mechanisms.assemble(_four_bar())
    with pytest.raises(mechanisms.ArgumentError, match="unknown quantity 'curvatur'.*did you mean 'curvature'"):
        model.observable("coupler.curvatur@0.5")
    with pytest.raises(ValueError, match="'crank.curvature@0.5'.*rigid"):
        model.observable("crank.curvature@0.5")
    with pytest.raises(ValueError, match="fraction must be in"):
        model.observable("coupler.curvature@1.5")
    with pytest.raises(ValueError, match="takes no '@fraction'"):
        model.observable("coupler.chord_angle@0.5")
    with pytest.raises(ValueError, match="built-in"):
        mechanisms.register_observable("deflection", curvature, unit="m")
    with pytest.raises(ValueError, match="registered already"):
        mechanisms.register_observable("curvature", slope, unit="1")
    mechanisms.register_observable("curvature", curvature, unit="1/m", elastic_only=True)  # the same again
    with pytest.raises(ValueError, match="identifier"):
        mechanisms.register_observable("bad name", curvature, unit="1/m")
    with pytest.raises(ValueError, match="unit"):
        mechanisms.register_observable("other", curvature, unit="")


def test_linearisation_maps_it_through_its_gradient_and_a_run_reports_it():
    """The linear map of the curvature is that of its value along ``full_state`` (linear in the
    elastic coordinates, zero on the rigid nominal motion); along a nonlinear run the curvature is
    the run's moment over E I, as the built-in moment's."""
    mechanism = _four_bar()
    lin = linearize.about(mechanism, n_steps=64, observables=SPECS)
    n, m = lin.system.f.shape
    phase = 2 * np.pi * np.arange(n) / (n - 1)
    rng = np.random.default_rng(2)
    z = 1e-4 * (np.outer(np.sin(phase), rng.normal(size=m)) + np.outer(np.cos(2 * phase), rng.normal(size=m)))
    observed = lin.observe(z)
    s_full, _ = lin.full_state(z, np.zeros_like(z))
    kappa = lin.nominal.model.observable("coupler.curvature@0.5")
    np.testing.assert_allclose(observed["coupler.curvature@0.5"], [kappa.value(sk) for sk in s_full],
                               rtol=1e-10, atol=1e-14)
    coupler = next(link for link in mechanism.links if link.name == "coupler")
    rigidity = coupler.youngs_modulus * coupler.second_moment
    np.testing.assert_allclose(rigidity * observed["coupler.curvature@0.5"], observed["coupler.moment@0.5"],
                               rtol=1e-10, atol=1e-12 * np.abs(observed["coupler.moment@0.5"]).max())
    run = mechanisms.simulate(mechanism, n_periods=1, steps_per_period=64,
                              observables=["coupler.curvature@0.5", "coupler.moment@0.5"])
    assert run.success
    np.testing.assert_allclose(rigidity * run.observables["coupler.curvature@0.5"],
                               run.observables["coupler.moment@0.5"], rtol=1e-10,
                               atol=1e-12 * np.abs(run.observables["coupler.moment@0.5"]).max())


def test_steady_state_reports_it_and_the_hdf5_round_trip_keeps_it(tmp_path, assert_same):
    problem = studies.MechanismProblem.from_mechanism(_four_bar(), observables=SPECS)
    result = studies.steady_state(problem, n_steps=32)
    assert result.units["coupler.curvature@0.5"] == "1/m"
    assert result.units["coupler.chord_angle"] == "rad"
    coupler = next(link for link in problem.mechanism().links if link.name == "coupler")
    rigidity = coupler.youngs_modulus * coupler.second_moment
    # the same linear map scaled: peaks and their time-step errors scale with E I
    for name in ("peak_to_peak", "peak"):
        assert rigidity * getattr(result, name)["coupler.curvature@0.5"] == pytest.approx(
            getattr(result, name)["coupler.moment@0.5"], rel=1e-9)
    curvature, moment = result.error_budget["coupler.curvature@0.5"], result.error_budget["coupler.moment@0.5"]
    assert rigidity * curvature["time_step"] == pytest.approx(moment["time_step"], rel=1e-9)
    # the mesh term: the built-in moment's known order, the registered curvature's observed from three
    # levels (it declares none), so the two differ a little but are both estimated
    assert curvature["mesh"] > 0.0 and moment["mesh"] > 0.0
    assert rigidity * curvature["mesh"] == pytest.approx(moment["mesh"], rel=0.2)
    assert result.peak_to_peak["coupler.curvature@0.5"] > 0.0
    result.save(tmp_path / "run.h5", "steady")
    loaded = studies.load(tmp_path / "run.h5")["steady"]
    assert_same(result, loaded)


def test_a_sweep_reports_it_resumes_by_its_spec_and_refuses_other_observables(tmp_path, assert_same):
    speeds = np.array([80.0, 100.0, 120.0])
    problem = studies.MechanismProblem.from_mechanism(_four_bar(), observables=SPECS)
    path = tmp_path / "sweep.h5"
    with studies.open_file(path) as out:
        swept = studies.sweep(problem, "speed", speeds, n_steps=32, out=out)
    # the point at the scene's speed is the steady state's
    at_scene = studies.steady_state(problem, n_steps=32)
    assert swept.peak_to_peak["coupler.curvature@0.5"][1] == pytest.approx(
        at_scene.peak_to_peak["coupler.curvature@0.5"], rel=1e-9)
    # every point done: a second run into the file reads them back, run times included
    with studies.open_file(path) as out:
        again = studies.sweep(problem, "speed", speeds, n_steps=32, out=out)
    assert_same(swept, again)
    np.testing.assert_array_equal(again.point_run_time, swept.point_run_time)  # read, not rerun
    assert_same(swept, studies.load(path)["sweep"])
    # worker processes (forked) know the registered quantity
    with ProcessPoolExecutor(2) as pool:
        pooled = studies.sweep(problem, "speed", speeds, n_steps=32, executor=pool)
    assert_same(swept, pooled)
    other = studies.MechanismProblem.from_mechanism(_four_bar(), observables=("coupler.curvature@0.25",))
    with studies.open_file(path) as out, pytest.raises(ValueError, match="other settings"):
        studies.sweep(other, "speed", speeds, n_steps=32, out=out)


def test_the_command_reports_it_from_a_scenes_observables(tmp_path, capsys):
    """``flexvib run`` called in-process on a scene whose ``[studies] observables`` name it: the
    file holds what ``studies.steady_state`` gives; a misspelt name exits with code 2 and the
    nearest name."""
    from studies.cli import main

    scene = _four_bar().to_toml() + ('\n[studies]\nobservables = ["coupler.curvature@0.5", "coupler.chord_angle"]'
                                     '\n[studies.steady_state]\nn_steps = 32\n')
    (tmp_path / "scene.toml").write_text(scene)
    assert main(["run", str(tmp_path / "scene.toml"), "--out", str(tmp_path / "run.h5"), "--quiet"]) == 0
    stored = studies.load(tmp_path / "run.h5")["steady_state"]
    problem = studies.MechanismProblem.from_mechanism(
        _four_bar(), observables=("coupler.curvature@0.5", "coupler.chord_angle"))
    direct = studies.steady_state(problem, n_steps=32)
    assert stored.units == direct.units
    for spec in direct.units:
        assert stored.peak_to_peak[spec] == pytest.approx(direct.peak_to_peak[spec], rel=1e-12)
    (tmp_path / "typo.toml").write_text(scene.replace('"coupler.chord_angle"', '"coupler.chord_angel"'))
    capsys.readouterr()
    assert main(["run", str(tmp_path / "typo.toml"), "--out", str(tmp_path / "typo.h5"), "--quiet"]) == 2
    assert "did you mean 'chord_angle'" in capsys.readouterr().err
