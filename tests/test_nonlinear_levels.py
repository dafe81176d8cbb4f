"""Issue 24: the error levels (N/2, N/4) converged to ``accuracy`` of their distance from the finer
orbit (``periodic.find_orbit``'s ``accuracy``, ``Settled``) instead of to ``tol``, against the same
levels converged to ``tol`` (the shooting before): the same error estimates to about ``accuracy`` of
themselves, the same multipliers' error bars, the same verdicts, in fewer periods.

- Duffing reference maps (``periodic.duffing_period_map``): the N/2 estimate and a coarser level found
  alone against its ``finer`` orbit, each against Newton to 1e-12.
- ``studies.nonlinear_steady_state`` on the four-bar, the six-bar (8 elements per link, reduced by
  default) and the two-link arm, with ``LEVEL_ACCURACY`` against ``LEVEL_ACCURACY = None``: the orbit
  itself (its state and multipliers, the N-step level) is the same, its error estimates within 2 %.
"""

from __future__ import annotations

import numpy as np
import pytest

import periodic
import studies
from studies._kinds import nonlinear_steady_state as steady_module  # the study's level accuracy


def _duffing(n_steps):
    return periodic.duffing_period_map("omega", n_steps=n_steps, damping=0.05, cubic=0.5, force=0.3, pump=0.1)


class _Counting:
    """A period map that counts its periods (with and without their monodromy)."""

    def __init__(self, period_map):
        self.period_map, self.calls = period_map, 0

    def __call__(self, x, parameter):
        self.calls += 1
        return self.period_map(x, parameter)

    def end_state(self, x, parameter):
        self.calls += 1
        return self.period_map(x, parameter)[0]


def test_settled_judges_each_block_against_its_distance_from_the_finer_orbit():
    settled = periodic._orbit.Settled(np.zeros(4), 0.01, ((0, 2), (2, 4)))
    y = np.array([1.0, 0.0, 100.0, 0.0])
    assert settled(y, np.array([0.005, 0.0, 0.5, 0.0]))
    # the positions' correction is small against the rates' distance but not against their own
    assert not settled(y, np.array([0.05, 0.0, 0.5, 0.0]))
    # a block at zero distance settles only with a zero correction
    assert not settled(np.array([1.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.0, 1e-300, 0.0]))


def test_the_n_over_2_estimate_at_level_accuracy_against_newton_to_1e_12():
    fine = _duffing(128)
    exact = periodic.find_orbit(fine, np.zeros(2), 1.1, tol=1e-12, estimate=_duffing(64), error_factor=1 / 3)
    coarse = _Counting(_duffing(64))
    quick = periodic.find_orbit(fine, np.zeros(2), 1.1, tol=1e-12, estimate=coarse, error_factor=1 / 3,
                                accuracy=0.01)
    alone = periodic.find_orbit(_duffing(64), np.zeros(2), 1.1, tol=1e-12)
    assert quick.status == exact.status == "ok"
    np.testing.assert_array_equal(quick.state, exact.state)          # the orbit itself is unchanged
    reference = np.abs(exact.state - alone.state).max() / 3
    assert exact.state_error == pytest.approx(reference, rel=1e-6)
    assert quick.state_error == pytest.approx(reference, rel=0.02)
    # the multipliers' error bars: their moduli's N/2 differences, to the same relative accuracy
    np.testing.assert_allclose(quick.multiplier_errors, exact.multiplier_errors, rtol=0.05,
                               atol=1e-3 * np.abs(exact.multipliers).max())
    calls = _Counting(_duffing(64))
    periodic.find_orbit(fine, np.zeros(2), 1.1, tol=1e-12, estimate=calls, error_factor=1 / 3)
    assert coarse.calls < calls.calls


def test_a_coarser_level_alone_at_accuracy_of_its_distance_from_the_finer_orbit():
    finer = periodic.find_orbit(_duffing(128), np.zeros(2), 1.1, tol=1e-12)
    exact = periodic.find_orbit(_duffing(32), finer.state, 1.1, tol=1e-12)
    level = periodic.find_orbit(_duffing(32), finer.state, 1.1, tol=1e-12, monodromy=finer.monodromy,
                                finer=finer.state, accuracy=0.01)
    assert level.converged and level.status == exact.status, level.message
    distance = np.abs(exact.state - finer.state).max()
    assert np.abs(level.state - exact.state).max() <= 0.01 * distance
    assert level.residual > 1e-12 and "error level" in level.message       # said, not hidden
    np.testing.assert_allclose(np.abs(level.multipliers), np.abs(exact.multipliers), rtol=0, atol=0.01 * np.abs(
        np.abs(exact.multipliers) - np.abs(finer.multipliers)).max() + 1e-12)


def test_accuracy_and_finer_are_checked():
    with pytest.raises(periodic.PeriodicError, match="accuracy"):
        periodic.find_orbit(_duffing(32), np.zeros(2), 1.1, accuracy=2.0)
    with pytest.raises(periodic.PeriodicError, match="finer"):
        periodic.find_orbit(_duffing(32), np.zeros(2), 1.1, finer=np.zeros(3), accuracy=0.01)


class _Misleading(_Counting):
    """A coarse map whose first period without its monodromy (``WithinError``'s probe) comes back with
    its residual ``factor`` times too large: a distance from the coarse orbit measured wrong."""

    def __init__(self, period_map, factor):
        super().__init__(period_map)
        self.factor, self.misled = factor, False

    def end_state(self, x, parameter):
        end = super().end_state(x, parameter)
        if not self.misled:
            self.misled = True
            return x + self.factor * (end - x)
        return end


def _settling(coarse, **options):
    # started, as the study is from its linear state, near the orbit: a neighbouring parameter's
    start = periodic.find_orbit(_duffing(128), np.zeros(2), 1.09, tol=1e-12).state
    return periodic.find_orbit(_Counting(_duffing(128)), start, 1.1, tol=1e-12, estimate=coarse,
                               error_factor=1 / 3, accuracy=0.01, reuse_first=True, settle_on_iterate=True,
                               **options)


def test_an_orbit_settled_within_its_error_against_newton_to_1e_12():
    exact = _settling(_Counting(_duffing(64)))
    quick = _settling(_Counting(_duffing(64)), settle_within_error=True)
    assert exact.residual <= 1e-12 and exact.settled_fraction == 0.0
    assert quick.converged and quick.status == exact.status == "ok", quick.message
    # settled before tol, and says so: its correction a share of its distance within the accuracy
    assert quick.residual > 1e-12 and "of its distance from the N/2 orbit" in quick.message
    assert 0.0 < quick.settled_fraction <= 0.01
    assert quick.map_calls < exact.map_calls
    # the state is the tol orbit's to about that share of the N, N/2 distance, inside its widened bar
    distance = 3.0 * exact.state_error
    assert np.abs(quick.state - exact.state).max() <= 2.0 * quick.settled_fraction * distance
    assert exact.state_error < quick.state_error <= exact.state_error * (1.0 + 6.0 * quick.settled_fraction)
    # the widened bar covers the tol orbit's bar plus the distance from it (the N/2 difference measured
    # from the settled state is itself off by up to a third of that distance)
    assert quick.state_error >= exact.state_error + (2 / 3) * np.abs(quick.state - exact.state).max()
    # the multipliers' bars widened by 1 + share / factor, covering the move of the multipliers
    np.testing.assert_allclose(quick.multiplier_errors, exact.multiplier_errors * (1 + 3 * quick.settled_fraction),
                               rtol=0.05, atol=1e-3 * np.abs(exact.multipliers).max())
    assert np.all(np.abs(np.abs(quick.multipliers) - np.abs(exact.multipliers)) <= quick.multiplier_errors)


def test_a_misleading_distance_sends_the_settled_orbit_on_to_tol():
    exact = _settling(_Counting(_duffing(64)))
    misled = _settling(_Misleading(_duffing(64), 1e3), settle_within_error=True)
    assert misled.converged and misled.residual <= 1e-12 and misled.settled_fraction == 0.0, misled.message
    np.testing.assert_allclose(misled.state, exact.state, rtol=0, atol=1e-10)
    assert misled.state_error == pytest.approx(exact.state_error, rel=0.02)


def test_settle_within_error_needs_the_coarse_map_and_an_accuracy():
    with pytest.raises(periodic.PeriodicError, match="settle_within_error"):
        periodic.find_orbit(_duffing(32), np.zeros(2), 1.1, settle_within_error=True, accuracy=0.01)
    with pytest.raises(periodic.PeriodicError, match="settle_within_error"):
        periodic.find_orbit(_duffing(32), np.zeros(2), 1.1, settle_within_error=True, estimate=_duffing(16))


def _branch(**options):
    return periodic.continue_orbits(_Counting(_duffing(128)), np.zeros(2), 0.9, 1.2, step=0.02, max_step=0.02,
                                    tol=1e-12, estimate=_Counting(_duffing(64)), error_factor=1 / 3,
                                    accuracy=0.01, **options)


def test_a_branch_settled_within_its_error_against_newton_to_1e_12():
    """``continue_orbits(settle_within_error=True)``: each step's orbit (Newton from the predictor, or
    the chord) converged once its correction is within ``accuracy`` of its distance from its N/2
    orbit, against the same branch to 1e-12: the same points and verdicts, each state inside its
    widened bar, in fewer periods."""
    exact = _branch()
    quick = _branch(settle_within_error=True)
    assert quick.status == exact.status == "ok", quick.message
    np.testing.assert_array_equal(quick.parameters, exact.parameters)
    settled = [orbit for orbit in quick.orbits if orbit.settled_fraction > 0.0]
    assert len(settled) >= len(quick.orbits) // 2 and quick.orbits[0].settled_fraction == 0.0
    assert all(0.0 < orbit.settled_fraction <= 2 * 0.01 and "of its distance from the N/2 orbit" in orbit.message
               for orbit in settled)
    assert quick.map_calls < exact.map_calls
    for fast, slow in zip(quick.orbits, exact.orbits):
        assert fast.status == slow.status
        distance = 3.0 * slow.state_error
        assert np.abs(fast.state - slow.state).max() <= 2.0 * max(fast.settled_fraction, 1e-9) * distance
        assert fast.state_error >= slow.state_error * (1 - 0.03)
        assert np.all(np.abs(np.abs(fast.multipliers) - np.abs(slow.multipliers)) <= fast.multiplier_errors)


def test_settle_within_error_of_a_branch_needs_the_coarse_map_and_an_accuracy():
    with pytest.raises(periodic.PeriodicError, match="settle_within_error"):
        periodic.continue_orbits(_duffing(32), np.zeros(2), 0.9, 1.0, settle_within_error=True, accuracy=0.01)


def _six_bar():
    paths = ("links.link2.discretisation.n_elements", "links.link4.discretisation.n_elements")
    problem = studies.MechanismProblem.from_scene("six_bar", parameter_paths=paths)
    return problem, {"speed": 100.0, **{path: 8 for path in paths}}


@pytest.mark.slow
@pytest.mark.parametrize("case", ["four_bar_fem4", "six_bar", "two_link_arm"])
def test_the_study_with_its_level_accuracy_against_levels_converged_to_tol(case, monkeypatch):
    if case == "six_bar":
        problem, values = _six_bar()
    else:
        problem, values = studies.MechanismProblem.from_scene(case), None
    # the error levels alone: the N orbit converged to tol in both (its own settling: the test below)
    monkeypatch.setattr(steady_module, "SETTLE_WITHIN_ERROR", False)
    quick = studies.nonlinear_steady_state(problem, values)
    monkeypatch.setattr(steady_module, "LEVEL_ACCURACY", None)
    exact = studies.nonlinear_steady_state(problem, values)
    assert quick.status == exact.status and quick.is_stable == exact.is_stable, (quick.message, exact.message)
    assert quick.map_calls < exact.map_calls
    # the orbit (N steps) is the same one; its error estimates within 2 % of themselves
    np.testing.assert_array_equal(quick.state, exact.state)
    np.testing.assert_array_equal(quick.multipliers, exact.multipliers)
    assert quick.error_estimate == pytest.approx(exact.error_estimate, rel=0.02)
    for spec, error in exact.response_error.items():
        assert quick.response_error[spec] == pytest.approx(error, rel=0.02)
    worst = np.abs(exact.multipliers).max()
    np.testing.assert_allclose(quick.multiplier_errors, exact.multiplier_errors, rtol=0.05, atol=1e-3 * worst)


def test_the_quarter_level_measures_the_ratio_to_its_accuracy_and_the_window_narrows_by_it(monkeypatch):
    """The N/4 orbit converged to ``QUARTER_ACCURACY`` of its distance from the N/2 orbit: the ratio
    of successive differences within that fraction of the ratio of the orbit to ``tol``, and the
    trust window's lower end raised by the levels' settled shares (``order_tolerance``, with
    ``RATIO_MARGIN``)."""
    import math

    problem, values = _six_bar()
    accuracy = steady_module.QUARTER_ACCURACY
    seen = []
    verdict = periodic.error_verdict

    def spy(fine, coarse, order, **options):
        seen.append((coarse / fine, options.get("order_tolerance")))
        return verdict(fine, coarse, order, **options)

    monkeypatch.setattr(periodic, "error_verdict", spy)
    quick = studies.nonlinear_steady_state(problem, values)
    monkeypatch.setattr(steady_module, "QUARTER_ACCURACY", 1e-6)   # the N/4 orbit to ~tol
    exact = studies.nonlinear_steady_state(problem, values)
    (ratio, window), (exact_ratio, exact_window) = seen
    assert abs(ratio - exact_ratio) <= accuracy * exact_ratio
    # the window raised by every level's settled share (N/4, N/2 twice, the N orbit's), with the margin
    margin = steady_module.RATIO_MARGIN
    assert window < periodic.ORDER_TOLERANCE + math.log2(1 - margin * (accuracy + 2 * steady_module.LEVEL_ACCURACY))
    assert window >= periodic.ORDER_TOLERANCE + math.log2(1 - margin * (accuracy + 2 * steady_module.LEVEL_ACCURACY
                                                                        + 0.02))
    assert window < exact_window < periodic.ORDER_TOLERANCE
    assert quick.status == exact.status
