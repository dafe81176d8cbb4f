"""Issue 24, session 9: the N-step orbit by chord iterations with the monodromy at its start
(``periodic.find_orbit``'s ``reuse_first``) and the error levels' orbits at their settled chord
iterate (``settle_on_iterate``), against the shooting before (Newton throughout, the iterate plus its
correction) and against Newton to 1e-12:

- Duffing reference maps (``periodic.duffing_period_map``): the same orbit to round-off of ``tol``,
  multipliers from the exact monodromy at the converged orbit (the same to 1e-9), fewer monodromies;
  a start where the kept monodromy does not contract still converges (Newton takes over); the N/2
  estimate and a coarser level at their settled iterate within ``accuracy`` of Newton's to 1e-12.
- ``studies.nonlinear_steady_state`` on the four-bar, the six-bar (8 elements per link, reduced by
  default) and the two-link arm, new defaults against ``REUSE_FIRST_MONODROMY = SETTLE_ON_ITERATE =
  REUSE_LINEAR_STATE = False``: the same orbit to a thousandth of its error estimate, the same
  multipliers within a hundredth of their error bars, the error estimates within 2 % of themselves,
  the same verdicts and mesh terms, fewer monodromies and no more periods.
"""

from __future__ import annotations

import numpy as np
import pytest

import periodic
import studies
from mechanisms import _orbit as period_map_module  # counts the periods and monodromies
from studies._kinds import nonlinear_steady_state as steady_module  # the study's switches


def _duffing(n_steps, **values):
    options = dict(damping=0.05, cubic=0.5, force=0.3, pump=0.1)
    options.update(values)
    return periodic.duffing_period_map("omega", n_steps=n_steps, **options)


class _Counting:
    """A period map that counts its periods with their monodromy and without, and keeps the states
    of the periods without (``ran``)."""

    def __init__(self, period_map):
        self.period_map, self.monodromies, self.plain, self.ran, self.last_monodromy_at = period_map, 0, 0, [], None

    def __call__(self, x, parameter):
        self.monodromies += 1
        self.last_monodromy_at = np.array(x)
        return self.period_map(x, parameter)

    def end_state(self, x, parameter):
        self.plain += 1
        self.ran.append(np.array(x))
        return self.period_map(x, parameter)[0]


def _linear_start(omega):
    """The orbit of the same oscillator without its cubic term (the study's linear start)."""
    return periodic.find_orbit(_duffing(128, cubic=0.0), np.zeros(2), omega, tol=1e-12).state


@pytest.mark.parametrize("omega", [0.8, 1.4])
def test_the_chord_with_the_first_monodromy_finds_newtons_orbit_with_fewer_monodromies(omega):
    newton_map, chord_map = _Counting(_duffing(128, cubic=0.2)), _Counting(_duffing(128, cubic=0.2))
    exact = periodic.find_orbit(newton_map, _linear_start(omega), omega, tol=1e-12)
    chord = periodic.find_orbit(chord_map, _linear_start(omega), omega, tol=1e-12, reuse_first=True)
    assert chord.converged and chord.status == exact.status, chord.message
    scale = np.abs(exact.state).max()
    np.testing.assert_allclose(chord.state, exact.state, rtol=0, atol=1e-11 * scale)
    # the multipliers from the exact monodromy at the converged orbit: Newton's, to round-off
    np.testing.assert_allclose(chord.multipliers, exact.multipliers, rtol=0, atol=1e-10)
    np.testing.assert_allclose(chord.monodromy, _duffing(128, cubic=0.2)(chord.state, omega)[1],
                               rtol=1e-12, atol=1e-12)
    # one monodromy at the start, one at the orbit, the periods between without; Newton one a step
    assert chord_map.monodromies == 2 and chord_map.plain >= 2
    assert newton_map.monodromies >= 4


@pytest.mark.parametrize("cubic", [0.2, 0.5])
def test_a_start_where_the_kept_monodromy_does_not_contract_is_left_to_newton(cubic):
    # near the resonance the orbit's monodromy is far from the start's: the chord's first step does
    # not contract, and Newton goes on from the start with the monodromy already computed there
    newton_map, chord_map = _Counting(_duffing(128, cubic=cubic)), _Counting(_duffing(128, cubic=cubic))
    exact = periodic.find_orbit(newton_map, _linear_start(1.1), 1.1, tol=1e-12)
    chord = periodic.find_orbit(chord_map, _linear_start(1.1), 1.1, tol=1e-12, reuse_first=True)
    assert exact.converged and chord.converged, chord.message
    np.testing.assert_array_equal(chord.state, exact.state)       # Newton's own iterates
    np.testing.assert_array_equal(chord.multipliers, exact.multipliers)
    assert chord_map.plain == 1 and chord_map.monodromies == newton_map.monodromies


def test_an_orbit_given_as_the_guess_costs_one_period_with_its_monodromy():
    orbit = periodic.find_orbit(_duffing(64), np.zeros(2), 1.1, tol=1e-13)
    period_map = _Counting(_duffing(64))
    again = periodic.find_orbit(period_map, orbit.state, 1.1, tol=1e-10, reuse_first=True)
    assert again.converged and again.iterations == 0
    assert (period_map.monodromies, period_map.plain) == (1, 0)
    np.testing.assert_array_equal(again.multipliers, orbit.multipliers)


def test_the_n_over_2_estimate_at_its_settled_iterate_against_newton_to_1e_12():
    fine = _duffing(128)
    exact = periodic.find_orbit(fine, np.zeros(2), 1.1, tol=1e-12, estimate=_duffing(64), error_factor=1 / 3)
    before, after = _Counting(_duffing(64)), _Counting(_duffing(64))
    plus = periodic.find_orbit(fine, np.zeros(2), 1.1, tol=1e-12, estimate=before, error_factor=1 / 3,
                               accuracy=0.01)
    settled = periodic.find_orbit(fine, np.zeros(2), 1.1, tol=1e-12, estimate=after, error_factor=1 / 3,
                                  accuracy=0.01, settle_on_iterate=True)
    assert settled.status == exact.status == "ok"
    np.testing.assert_array_equal(settled.state, exact.state)          # the N orbit itself is unchanged
    # the iterate's error is about its correction: within accuracy of the distance, not a fraction of it
    assert settled.state_error == pytest.approx(exact.state_error, rel=0.02)
    assert plus.state_error == pytest.approx(exact.state_error, rel=0.02)
    np.testing.assert_allclose(settled.multiplier_errors, exact.multiplier_errors, rtol=0.05,
                               atol=1e-3 * np.abs(exact.multipliers).max())
    # the N/2 monodromy at a state whose period was just run (a mechanisms.PeriodMap keeps it: the
    # monodromy costs its tangent alone), not at the iterate plus its correction (a period more)
    assert any(np.array_equal(after.last_monodromy_at, x) for x in after.ran)
    assert not any(np.array_equal(before.last_monodromy_at, x) for x in before.ran)


def test_a_coarser_level_alone_at_its_settled_iterate():
    finer = periodic.find_orbit(_duffing(128), np.zeros(2), 1.1, tol=1e-12)
    exact = periodic.find_orbit(_duffing(32), finer.state, 1.1, tol=1e-12)
    level = periodic.find_orbit(_duffing(32), finer.state, 1.1, tol=1e-12, monodromy=finer.monodromy,
                                finer=finer.state, accuracy=0.01, settle_on_iterate=True)
    assert level.converged and level.status == exact.status, level.message
    distance = np.abs(exact.state - finer.state).max()
    assert np.abs(level.state - exact.state).max() <= 0.02 * distance
    # its monodromy is the exact one at the state it returns
    np.testing.assert_allclose(level.monodromy, _duffing(32)(level.state, 1.1)[1], rtol=1e-12, atol=1e-12)


def _six_bar():
    paths = ("links.link2.discretisation.n_elements", "links.link4.discretisation.n_elements")
    problem = studies.MechanismProblem.from_scene("six_bar", parameter_paths=paths)
    return problem, {"speed": 100.0, **{path: 8 for path in paths}}


class _Periods:
    """Counts the period maps' runs and monodromies (``mechanisms.PeriodMap``)."""

    def __init__(self, monkeypatch):
        self.runs, self.monodromies = 0, 0
        integrate, monodromy = period_map_module._integrate, period_map_module.PeriodMap._monodromy_of

        def counted_integrate(*args, **kwargs):
            self.runs += 1
            return integrate(*args, **kwargs)

        def counted_monodromy(map_, *args):
            self.monodromies += 1
            return monodromy(map_, *args)

        monkeypatch.setattr(period_map_module, "_integrate", counted_integrate)
        monkeypatch.setattr(period_map_module.PeriodMap, "_monodromy_of", counted_monodromy)


@pytest.mark.slow
@pytest.mark.parametrize("case", ["four_bar_fem4", "six_bar", "two_link_arm"])
def test_the_study_against_the_shooting_before(case, monkeypatch):
    if case == "six_bar":
        problem, values = _six_bar()
    else:
        problem, values = studies.MechanismProblem.from_scene(case), None
    now_periods = _Periods(monkeypatch)
    now = studies.nonlinear_steady_state(problem, values)
    monkeypatch.undo()
    before_periods = _Periods(monkeypatch)
    monkeypatch.setattr(steady_module, "REUSE_FIRST_MONODROMY", False)
    monkeypatch.setattr(steady_module, "SETTLE_ON_ITERATE", False)
    monkeypatch.setattr(steady_module, "REUSE_LINEAR_STATE", False)
    monkeypatch.setattr(steady_module, "SETTLE_WITHIN_ERROR", False)
    before = studies.nonlinear_steady_state(problem, values)
    assert now.status == before.status and now.is_stable == before.is_stable, (now.message, before.message)
    assert now.instability_kind == before.instability_kind
    # the same orbit, far inside its own error estimate: before converged to tol, now settled within
    # its error (at most SETTLE_SLACK * LEVEL_ACCURACY of its N, N/2 distance, 3 error estimates)
    share = steady_module.LEVEL_ACCURACY * periodic.SETTLE_SLACK * 3.0
    np.testing.assert_allclose(now.state, before.state, rtol=0, atol=(1e-3 + share) * before.error_estimate)
    for spec, response in before.response.items():
        np.testing.assert_allclose(now.response[spec], response, rtol=0,
                                   atol=(1e-3 + share) * before.response_error[spec])
    # the multipliers: exact monodromies of (nearly) the same orbit, each well within its error bar
    nearest = np.abs(now.multipliers[:, None] - before.multipliers[None, :]).min(axis=1)
    assert np.all(nearest <= (1e-2 + share) * before.multiplier_errors + 1e-10), (nearest, before.multiplier_errors)
    # the error estimates (the levels at their settled iterate, widened by the settled share) within
    # 2 % of themselves plus that widening
    assert now.error_estimate == pytest.approx(before.error_estimate, rel=0.02 + share)
    for spec, error in before.response_error.items():
        assert now.response_error[spec] == pytest.approx(error, rel=0.02 + share)
    assert "settled within" in now.error_methods["time_step"]
    worst = np.abs(before.multipliers).max()
    np.testing.assert_allclose(now.multiplier_errors, before.multiplier_errors, rtol=0.05, atol=1e-3 * worst)
    assert now.mesh_error == before.mesh_error
    assert now_periods.monodromies < before_periods.monodromies
    assert now_periods.runs <= before_periods.runs
