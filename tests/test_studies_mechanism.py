"""Studies on the thesis four-bar: parameter plumbing against a direct computation, frozen frequencies
against the pinned-pinned beam, the linear steady state against the full nonlinear model."""

from __future__ import annotations

import numpy as np
import pytest

import linearize
import mechanisms
import periodic
import studies
from studies import MechanismProblem


@pytest.fixture(scope="module")
def four_bar():
    return MechanismProblem.from_scene("four_bar_thesis", parameter_paths=("links.coupler.thickness",))


def test_scene_parameter_reaches_the_mechanism(four_bar):
    thickness = [1.2e-3, 2.0e-3]
    chart = studies.stability_chart(four_bar, ("speed", [150.0]), ("links.coupler.thickness", thickness),
                                    n_steps=32)
    for j, h in enumerate(thickness):
        mechanism = mechanisms.load("four_bar_thesis").with_parameters(
            {"links.coupler.thickness": h, "drive.rate": 150.0})
        direct = periodic.floquet(linearize.about(mechanism, n_steps=32).system).spectral_radius
        # same equations, assembled once through the speed family and once directly: the two differ
        # by the rounding of the polynomial split of the coefficients in the speed
        assert chart.spectral_radius[0, j] == pytest.approx(direct, rel=1e-9)
    assert chart.parameter_units == ("rad/s", "m")


def test_frozen_frequency_at_low_speed_is_the_pinned_pinned_coupler(four_bar):
    sweep = studies.sweep(four_bar, "speed", [1.0, 2.0], n_steps=32)
    omega_1 = mechanisms.load("four_bar_thesis").link("coupler").first_bending_frequency()
    # With the crank held (speed -> 0) the coupler is a beam between fixed pins: its first frozen
    # frequency is (pi/L)^2 sqrt(EI / rho A) (the Ritz mode sin(pi x / L) is exact); the speed
    # terms are O(speed^2 / omega_1^2) ~ 1e-5 and so is the inertia coupling with the axial mode.
    np.testing.assert_allclose(sweep.frozen_mean[:, 0], omega_1, rtol=1e-4)
    np.testing.assert_allclose(sweep.frozen_mean[:, 1], 4 * omega_1, rtol=1e-4)


def test_linear_steady_state_agrees_with_the_nonlinear_model(four_bar):
    coarse = studies.nonlinear_check(four_bar, n_steps=128, n_periods=3)
    fine = studies.nonlinear_check(four_bar, n_steps=256, n_periods=3)
    spec = "coupler.deflection@0.5"
    # Both routes are second-order integrators (Newmark and generalized-alpha): if the linear model
    # is the nonlinear one's first-order part and the deflection is small, their difference is
    # dominated by discretisation errors and falls by 4 when the step halves (3.5..4.5 allows the
    # next-order terms); a wrong linearisation would leave a floor.
    assert 3.5 <= coarse.difference[spec] / fine.difference[spec] <= 4.5
    assert fine.relative_difference[spec] < 1e-3
    assert fine.nonlinear_run_time > 0 and fine.linear_run_time > 0
    # away from the scene's speed (linearised through the speed family) the start must be consistent
    # with the drive at that speed, and the routes still agree to the discretisation level
    other = studies.nonlinear_check(four_bar, {"speed": 120.0}, n_steps=256, n_periods=3)
    assert other.relative_difference[spec] < 1e-3


def test_slow_four_bar_deflects_like_a_beam_under_its_inertia_load():
    problem = MechanismProblem.from_scene("four_bar_fem4")
    result = studies.steady_state(problem, {"speed": 20.0}, n_steps=256)
    mechanism = mechanisms.load("four_bar_fem4").with_parameter("drive.rate", 20.0)
    nominal = mechanisms.nominal_motion(mechanism, n_steps=256)
    labels = list(nominal.model.coord_labels)
    i = labels.index("coupler.x")
    theta, rate = nominal.s[:, i + 2], nominal.sdot[:, i + 2]
    coupler = mechanism.link("coupler")
    half = coupler.length / 2
    along = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    normal = np.stack([-np.sin(theta), np.cos(theta)], axis=1)
    # rigid-body acceleration of the coupler's midpoint, across the chord
    middle = (nominal.sddot[:, i:i + 2] + nominal.sddot[:, i + 2, None] * half * normal
              - rate[:, None] ** 2 * half * along)
    across = np.sum(middle * normal, axis=1)
    # Quasi-statically the coupler is a pinned-pinned beam under the inertia load -rho A a(x), linear
    # in x, whose mid-span deflection is 5 q_mid L^4 / (384 EI). The dynamic amplification of the
    # harmonics k Omega (k <= 3 carry the load) is 1 / (1 - (k Omega / omega_1)^2) - 1 <= 4.3 %.
    quasi_static = (-5 * coupler.density * coupler.area * coupler.length**4
                    / (384 * coupler.youngs_modulus * coupler.second_moment) * across)
    response = result.response["coupler.deflection@0.5"]
    assert np.abs(response - quasi_static).max() <= 0.05 * np.abs(quasi_static).max()


def test_process_pool_sweep_of_a_mechanism_gives_the_same_numbers(four_bar, assert_same):
    from concurrent.futures import ProcessPoolExecutor

    speeds = [60.0, 90.0, 130.0, 170.0]
    serial = studies.sweep(four_bar, "speed", speeds, n_steps=32)
    with ProcessPoolExecutor(2) as pool:
        pooled = studies.sweep(four_bar, "speed", speeds, n_steps=32, executor=pool)
    assert_same(serial, pooled)


@pytest.mark.parametrize("scene", mechanisms.scenes())
def test_describe_names_what_the_linearisation_gives(scene):
    """Labels, observables and units without linearising are those of the linear system."""
    problem = MechanismProblem.from_scene(scene)
    names = problem.describe()
    linear = problem.linearize(None, n_steps=16)
    assert names == studies.Description(labels=linear.labels, observables=linear.observables,
                                        units=linear.units)
    assert names.observables == linearize.default_observables(mechanisms.load(scene))


def test_a_sweep_builds_the_scene_once_and_never_rewrites_it(monkeypatch):
    """Scene -> Mechanism once per process: per-point work neither writes nor parses scene text; a
    parameter sweep builds each variant from the scene dict."""
    from studies import _mechanism  # its private caches: no public face

    calls = []
    for name in ("to_spec", "to_toml", "with_parameters"):
        original = getattr(mechanisms.Mechanism, name)
        monkeypatch.setattr(mechanisms.Mechanism, name,
                            lambda self, *a, _name=name, _original=original, **k:
                            calls.append(_name) or _original(self, *a, **k))
    for name in ("build", "loads"):
        original = getattr(mechanisms, name)
        monkeypatch.setattr(mechanisms, name,
                            lambda *a, _name=name, _original=original, **k: calls.append(_name) or _original(*a, **k))
    _mechanism._mechanisms.clear()
    _mechanism._families.clear()
    problem = MechanismProblem.from_scene("four_bar_thesis", parameter_paths=("links.coupler.thickness",))
    # the text that travels to worker processes, written once (to_toml writes the scene dict)
    assert [c for c in calls if c != "to_spec"] == ["to_toml"] and calls.count("to_spec") <= 1
    calls.clear()
    studies.sweep(problem, "speed", np.linspace(60.0, 150.0, 10), n_steps=16)
    # the error budget's mesh term refines the coupler at the scene's point, once a process (the Ritz
    # coupler declares no order: three levels, two refined scenes), kept for the process
    assert "loads" not in calls and calls.count("build") == 2, calls
    calls.clear()
    studies.sweep(problem, "speed", np.linspace(60.0, 150.0, 20), n_steps=16)
    assert calls == []
    thickness = np.linspace(1.2e-3, 2.0e-3, 5)
    sweep = studies.sweep(problem, "links.coupler.thickness", thickness, n_steps=16)
    # the radius's mesh term refines the coupler at its headline variants too (the largest radius,
    # the radius nearest 1; the scene's own is kept from the speed sweeps): two refined scenes each,
    # built once (as the scene's point's above)
    radius = sweep.spectral_radius
    headline = {float(thickness[int(np.argmax(radius))]), float(thickness[int(np.argmin(np.abs(radius - 1.0)))])}
    headline.discard(problem.parameters["links.coupler.thickness"])
    assert calls[:5] == ["build"] * 5 and "loads" not in calls, calls
    assert calls.count("build") == 5 + 2 * len(headline), (calls, headline)
    # the variants are the scene's: the same numbers as changing the Mechanism itself
    variant = mechanisms.load("four_bar_thesis").with_parameter("links.coupler.thickness", float(thickness[2]))
    direct = periodic.floquet(linearize.about(variant, n_steps=16).system).spectral_radius
    assert sweep.spectral_radius[2] == pytest.approx(direct, rel=1e-12)
