"""Issue 24 (nonlinear periodic states faster) and issue 22's nonlinear-state bullet: the cheaper
routes of the shooting against the Newton shooting they replace, and the default reduction against
the full element models.

- Chord iterations (a nearby orbit's monodromy kept, periods without their own) find the orbit Newton
  finds, to the tolerance, with the same multipliers (Duffing reference map).
- The N/2 error level solved by chord from the N orbit gives the same state error and multiplier
  errors as a Newton solve of the N/2 map (Duffing; ``four_bar_fem4``'s mechanism).
- ``monodromy - I`` is judged singular by its equilibrated condition number: a Duffing map whose
  state is expressed in units 1e6 apart is solved as the unscaled one (the raw condition number was
  1e12 there, the old refusal), and ``two_link_arm``'s N/4 level, whose raw condition number 1.96e12
  made its estimate fail although its multipliers are all below 0.92, is found.
- A residual stalled at the period map's round-off is converged: a Duffing map with a declared round-off
  (and without the declaration, failed as before), ``two_link_arm`` at N = 512.
- ``modes="auto"`` against ``modes="full"`` on the six-bar with 5 elements per link: the same
  orbit within the stated reduction error plus both time-step errors.
"""

from __future__ import annotations

import numpy as np
import pytest

import periodic
import studies


class _Scaled:
    """A period map in units: state ``y = D x`` of a map of ``x`` (D diagonal)."""

    def __init__(self, period_map, scale):
        self.period_map, self.scale = period_map, np.asarray(scale, dtype=float)

    def __call__(self, y, parameter):
        end, monodromy = self.period_map(y / self.scale, parameter)
        return end * self.scale, monodromy * self.scale[:, None] / self.scale[None, :]


def _duffing(n_steps=128):
    return periodic.duffing_period_map("omega", n_steps=n_steps, damping=0.05, cubic=0.5, force=0.3, pump=0.1)


class _EndCounting:
    """A period map that offers ``end_state`` and counts the monodromies it computed."""

    def __init__(self, period_map):
        self.period_map, self.monodromies, self.ends = period_map, 0, 0

    def __call__(self, x, parameter):
        self.monodromies += 1
        return self.period_map(x, parameter)

    def end_state(self, x, parameter):
        self.ends += 1
        return self.period_map(x, parameter)[0]


def test_chord_from_a_neighbouring_orbit_finds_newtons_orbit_and_multipliers():
    period_map = _duffing()
    newton = periodic.find_orbit(period_map, np.zeros(2), 1.1, tol=1e-12)
    # the neighbour: the orbit of a coarser grid (as the error levels use it) at a nearby frequency
    neighbour = periodic.find_orbit(_duffing(64), newton.state, 1.099, tol=1e-12)
    counted = _EndCounting(period_map)
    chord = periodic.find_orbit(counted, neighbour.state, 1.1, tol=1e-12, monodromy=neighbour.monodromy)
    assert newton.converged and chord.converged and chord.status == newton.status
    np.testing.assert_allclose(chord.state, newton.state, rtol=0, atol=1e-10 * np.abs(newton.state).max())
    # the multipliers from the one exact monodromy at the converged orbit
    np.testing.assert_allclose(chord.multipliers, newton.multipliers, rtol=0, atol=1e-9)
    assert counted.monodromies == 1 and counted.ends >= 2


def test_the_n_over_2_level_by_chord_gives_the_error_bars_of_a_newton_solve():
    fine, coarse = _duffing(128), _duffing(64)
    orbit = periodic.find_orbit(fine, np.zeros(2), 1.1, tol=1e-12, estimate=coarse, error_factor=1 / 3)
    alone = periodic.find_orbit(coarse, np.zeros(2), 1.1, tol=1e-12)      # Newton from scratch
    assert orbit.status == "ok" and alone.converged
    expected = np.abs(orbit.state - alone.state).max() / 3
    assert orbit.state_error == pytest.approx(expected, rel=1e-6)
    moduli = np.abs(orbit.multipliers) - np.abs(alone.multipliers)
    np.testing.assert_allclose(orbit.multiplier_errors, np.abs(moduli) / 3, rtol=1e-6, atol=1e-14)


def test_a_state_in_units_1e6_apart_is_solved_as_the_unscaled_one():
    period_map = _duffing()
    plain = periodic.find_orbit(period_map, np.zeros(2), 1.1, tol=1e-12)
    scale = np.array([1e-6, 1e6])
    scaled = periodic.find_orbit(_Scaled(period_map, scale), np.zeros(2), 1.1, tol=1e-12)
    assert np.linalg.cond(scaled.monodromy - np.eye(2)) > 1e11      # the raw test refused this
    assert scaled.converged, scaled.message
    np.testing.assert_allclose(scaled.state / scale, plain.state, rtol=1e-8)
    np.testing.assert_allclose(np.abs(scaled.multipliers), np.abs(plain.multipliers), rtol=1e-8)


@pytest.fixture(scope="module")
def arm():
    return studies.MechanismProblem.from_scene("two_link_arm")


def test_two_link_arm_nonlinear_state_is_ok_with_defaults(arm):
    result = studies.nonlinear_steady_state(arm)
    assert result.status == "ok", result.message
    assert result.spectral_radius == pytest.approx(0.908, abs=2e-3)
    assert all(np.isfinite(v) for v in result.response_error.values())
    # the N/4 level was found (its check is part of an ok verdict) and the linear state agrees
    for spec, values in result.response.items():
        assert np.ptp(values) == pytest.approx(np.ptp(result.linear_response[spec]), rel=1e-2)


@pytest.mark.slow
def test_two_link_arm_at_512_steps_converges_at_round_off(arm):
    coarse = studies.nonlinear_steady_state(arm)
    fine = studies.nonlinear_steady_state(arm, n_steps=512)
    assert fine.status == "ok", fine.message
    # the N = 512 orbit against the N = 256 one: within the latter's error estimate (order 2: the
    # N = 256 error is 4/3 of the difference, the bar 1/3 of its N/2 difference)
    for spec in fine.response:
        difference = np.abs(fine.response[spec][::2] - coarse.response[spec]).max()
        assert difference <= 2.0 * coarse.response_error[spec] + 1e-12


@pytest.mark.slow
def test_default_reduction_against_the_full_model_within_its_stated_error():
    paths = ["links.link2.discretisation.n_elements", "links.link4.discretisation.n_elements"]
    problem = studies.MechanismProblem.from_scene("six_bar", parameter_paths=paths)
    values = {"speed": 100.0, paths[0]: 5, paths[1]: 5}   # 4 elements: a degenerate reduced basis (full)
    reduced = studies.nonlinear_steady_state(problem, values, n_steps=128)
    full = studies.nonlinear_steady_state(problem, values, n_steps=128, modes="full")
    assert reduced.reduced_modes == {"link2": 4, "link4": 4} and full.reduced_modes == {}
    assert reduced.status == full.status == "ok", (reduced.message, full.message)
    assert "modal reduction error" in reduced.message
    for spec in full.response:
        bar = reduced.reduction_error[spec] + reduced.response_error[spec] + full.response_error[spec]
        assert np.abs(reduced.response[spec] - full.response[spec]).max() <= bar
        np.testing.assert_allclose(reduced.multipliers[:4], full.multipliers[:4], atol=5e-3)


def test_modes_option_is_checked(arm):
    with pytest.raises(studies.StudiesError, match="modes"):
        studies.nonlinear_steady_state(arm, modes="some")
    with pytest.raises(studies.StudiesError, match="modes"):
        studies.nonlinear_steady_state(arm, modes=0)


def test_modes_key_of_the_scene_tables():
    from studies import kinds

    for kind, table in (("nonlinear_steady_state", {}), ("nonlinear_sweep", {"start": 90.0, "stop": 100.0})):
        check = kinds()[kind].check
        assert check(f"studies.{kind}", table, 128)["modes"] == "auto"
        assert check(f"studies.{kind}", dict(table, modes="full"), 128)["modes"] == "full"
        assert check(f"studies.{kind}", dict(table, modes=6), 128)["modes"] == 6
        with pytest.raises(studies.StudiesError, match=f"studies.{kind}: modes"):
            check(f"studies.{kind}", dict(table, modes="some"), 128)


class _Noisy:
    """A period map whose end state carries a deterministic round-off of about ``noise`` (a stand-in for
    an integrator's Newton tolerance), declaring ``resolution`` when given."""

    def __init__(self, period_map, noise, resolution=None):
        self.period_map, self.noise = period_map, noise
        if resolution is not None:
            self.resolution = resolution

    def __call__(self, x, parameter):
        end, monodromy = self.period_map(x, parameter)
        return end + self.noise * np.sin(1e9 * x + np.arange(x.size)), monodromy


def test_a_residual_stalled_at_the_declared_round_off_is_converged_not_failed():
    clean = periodic.find_orbit(_duffing(), np.zeros(2), 1.1, tol=1e-13)
    declared = periodic.find_orbit(_Noisy(_duffing(), 1e-9, resolution=1e-8), np.zeros(2), 1.1, tol=1e-14)
    assert declared.converged and declared.status == "ok", declared.message
    assert "round-off" in declared.message
    # the orbit to the noise's level (the monodromy - I here is of order 1)
    np.testing.assert_allclose(declared.state, clean.state, rtol=0, atol=1e-7)
    # without the declaration the same stall is a failure, as before
    undeclared = periodic.find_orbit(_Noisy(_duffing(), 1e-9), np.zeros(2), 1.1, tol=1e-14)
    assert not undeclared.converged and undeclared.status == "failed"


def test_the_n_over_2_chord_level_on_the_four_bar_equals_a_newton_solve():
    import mechanisms

    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    linear = problem.linearize(None, n_steps=64)
    lin = linear.context
    fine = mechanisms.PeriodMap(lin.mechanism, n_steps=64, independent=lin.coefficients.independent,
                                nominal=lin.nominal)
    coarse = mechanisms.PeriodMap(lin.mechanism, n_steps=32, independent=fine.independent, nominal=lin.nominal)
    orbit = periodic.find_orbit(fine, np.zeros(fine.n_state), 100.0, tol=1e-9, estimate=coarse, error_factor=1 / 3)
    alone = periodic.find_orbit(coarse, orbit.state, 100.0, tol=1e-9)     # Newton, every step its monodromy
    assert orbit.converged and alone.converged, (orbit.message, alone.message)
    expected = np.abs(orbit.state - alone.state).max() / 3
    assert orbit.state_error == pytest.approx(expected, rel=1e-3)
    # each multiplier against the nearest of the N/2 orbit's (the estimate's pairing)
    nearest = alone.multipliers[np.abs(orbit.multipliers[:, None] - alone.multipliers[None, :]).argmin(axis=1)]
    np.testing.assert_allclose(orbit.multiplier_errors, np.abs(np.abs(orbit.multipliers) - np.abs(nearest)) / 3,
                               rtol=0, atol=1e-6)
