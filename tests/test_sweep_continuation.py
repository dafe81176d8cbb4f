"""The continuation's corrector choices (issue 24, the 50-speed sweep): chord iterations, at a natural
step and on the N/2 error level, only where their predicted rate pays, against references
independent of them: the observed contraction of chord iterations on linear maps, closed-form orbits
of affine maps, and the error estimates of single ``find_orbit`` solves whose N/2 level is solved
by Newton to ``tol`` from the N-step orbit."""

from __future__ import annotations

import numpy as np
import pytest

import periodic
from periodic._continuation import CHORD_RATE, chord_rate

RNG = np.random.default_rng(24)


def _stable_matrix(n, radius):
    """A random (n, n) matrix with spectral radius ``radius``."""
    matrix = RNG.standard_normal((n, n))
    return matrix * (radius / np.max(np.abs(np.linalg.eigvals(matrix))))


def test_chord_rate_is_the_observed_contraction_of_chord_iterations():
    kept = _stable_matrix(6, 0.7)
    actual = kept + 0.1 * RNG.standard_normal((6, 6))
    offset = RNG.standard_normal(6)
    fixed_point = np.linalg.solve(np.eye(6) - actual, offset)
    jacobian = kept - np.eye(6)
    x = fixed_point + RNG.standard_normal(6)
    errors = [np.linalg.norm(x - fixed_point)]
    while errors[-1] > 1e-13 * np.linalg.norm(fixed_point) and len(errors) < 500:
        # chord iterations on x -> actual x + offset with the Jacobian kept - I
        x = x - np.linalg.solve(jacobian, actual @ x + offset - x)
        errors.append(np.linalg.norm(x - fixed_point))
    assert len(errors) > 30   # slow enough to show the asymptotic rate
    observed = (errors[-1] / errors[-21]) ** (1.0 / 20.0)   # the dominant mode's (mean) ratio
    assert 0.05 < observed < 0.95
    assert chord_rate(kept, actual) == pytest.approx(observed, rel=0.02)
    assert chord_rate(actual, actual) == pytest.approx(0.0, abs=1e-12)
    assert chord_rate(np.eye(3), 0.5 * np.eye(3)) == np.inf   # kept - I singular: no chord


class _AffineFamily:
    """``P(x, p) = A(p) x + b p`` (n = 4): the orbit ``(I - A(p))^-1 b p`` in closed form; counts the
    periods with a monodromy (``monodromies``) and without (``ends``)."""

    def __init__(self, base, slope):
        self.base, self.slope, self.b = base, slope, np.arange(1.0, 5.0)
        self.monodromies = self.ends = 0

    def matrix(self, p):
        return self.base + p * self.slope

    def orbit(self, p):
        return np.linalg.solve(np.eye(4) - self.matrix(p), self.b * p)

    def __call__(self, x, p):
        self.monodromies += 1
        return self.matrix(p) @ x + self.b * p, self.matrix(p)

    def end_state(self, x, p):
        self.ends += 1
        return self.matrix(p) @ x + self.b * p


@pytest.mark.parametrize("slope_size, chord", [(0.0, True), (6.0, False)])
def test_natural_steps_take_the_chord_only_where_its_rate_pays(slope_size, chord):
    base = _stable_matrix(4, 0.2)
    family = _AffineFamily(base, slope_size * _stable_matrix(4, 0.1))
    branch = periodic.continue_orbits(family, np.zeros(4), 0.1, 0.6, step=0.05, max_step=0.05, tol=1e-12)
    assert branch.status == "ok" and branch.parameters[-1] == 0.6
    for p, state in zip(branch.parameters, branch.states):
        np.testing.assert_allclose(state, family.orbit(p), rtol=0, atol=1e-10 * np.abs(family.orbit(p)).max())
    rates = [chord_rate(family.matrix(p), family.matrix(q)) for p, q in zip(branch.parameters, branch.parameters[1:])]
    assert all((rate <= CHORD_RATE) == chord for rate in rates)
    steps = branch.parameters.size - 1
    if chord:
        # the first step by Newton (no rate yet), then each a chord period at the predictor (exact for an
        # affine map with A's monodromy) and the orbit's own monodromy (the same period, not run again)
        assert family.monodromies <= 3 + steps + 2
        assert family.ends >= 2 * (steps - 1)
    else:
        # Newton at every step: a period without a monodromy only for each point's tangent (dP/dp)
        assert family.ends == branch.parameters.size
        assert family.monodromies >= 2 * steps


def _duffing(n_steps):
    return periodic.duffing_period_map("omega", n_steps=n_steps, damping=0.05, cubic=0.5, force=0.3, pump=0.1)


def test_the_branchs_n_over_2_levels_give_single_solves_error_estimates():
    fine, coarse = _duffing(64), _duffing(32)
    branch = periodic.continue_orbits(fine, np.zeros(2), 1.0, 1.3, step=0.05, max_step=0.05, estimate=coarse,
                                      accuracy=0.01, tol=1e-12)
    assert branch.status == "ok" and branch.parameters.size == 7
    for orbit in branch.orbits:
        # the N/2 orbit by Newton to tol from the N-step orbit, nothing continued
        single = periodic.find_orbit(fine, orbit.state, orbit.parameter, estimate=coarse, tol=1e-12)
        assert orbit.status == single.status == "ok"
        np.testing.assert_allclose(orbit.state, single.state, rtol=0, atol=1e-10)
        # the branch's level to 1 % of its distance from the N orbit: the estimates to about 1 %
        assert orbit.state_error == pytest.approx(single.state_error, rel=0.02)
        np.testing.assert_allclose(orbit.multiplier_errors, single.multiplier_errors, rtol=0.05,
                                   atol=1e-3 * np.abs(single.multiplier_errors).max())
        assert single.state_error > 1e-4   # a level difference the test can see


def test_the_branch_is_the_same_whichever_corrector_solves_it(monkeypatch):
    # always the chord (with Newton where it does not contract: the old rule) against never the chord
    # (Newton throughout)
    fine, coarse = _duffing(64), _duffing(32)
    branches = {}
    for rate in (np.inf, 0.0):
        monkeypatch.setattr("periodic._continuation.CHORD_RATE", rate)
        branches[rate] = periodic.continue_orbits(fine, np.zeros(2), 1.0, 1.3, step=0.05, max_step=0.05,
                                                  estimate=coarse, accuracy=0.01)
    chord, newton = branches[np.inf], branches[0.0]
    assert chord.map_calls != newton.map_calls   # two correctors did run
    assert chord.status == newton.status == "ok" and chord.statuses == newton.statuses
    np.testing.assert_array_equal(chord.parameters, newton.parameters)
    np.testing.assert_allclose(chord.states, newton.states, rtol=0, atol=1e-8 * np.abs(newton.states).max())
    np.testing.assert_allclose(chord.multipliers, newton.multipliers, rtol=0, atol=1e-7)
    for a, b in zip(chord.orbits, newton.orbits):
        assert a.state_error == pytest.approx(b.state_error, rel=0.02)


class _CountedPeriods:
    """A period map with ``end_state`` (a period without its monodromy), counting both kinds."""

    def __init__(self, period_map):
        self.period_map, self.monodromies, self.ends = period_map, 0, 0

    def __call__(self, x, p):
        self.monodromies += 1
        return self.period_map(x, p)

    def end_state(self, x, p):
        self.ends += 1
        return self.period_map(x, p)[0]


def test_the_early_turn_check_rejects_the_same_steps_for_fewer_periods(monkeypatch):
    # natural steps up a lightly damped Duffing's resonance into its fold: near it steps turn too far
    # and are halved until min_step; the turn checked at each Newton iterate (and at a full step's point
    # before its period) against only at the converged point
    branches, maps = {}, {}
    for early in (True, False):
        monkeypatch.setattr("periodic._continuation.EARLY_TURN_CHECK", early)
        maps[early] = _CountedPeriods(periodic.duffing_period_map("omega", n_steps=64, damping=0.01, cubic=0.2,
                                                                  force=0.005))
        branches[early] = periodic.continue_orbits(maps[early], np.zeros(2), 0.9, 1.15, stop_at_instability=False)
    early, late = branches[True], branches[False]
    assert late.status == early.status == "failed" and "method='arclength'" in early.message
    # (the last step's reason may differ: the late check's Newton diverged there before converging)
    assert "turned by more than" in early.message
    np.testing.assert_array_equal(early.parameters, late.parameters)
    np.testing.assert_array_equal(early.states, late.states)
    assert early.statuses == late.statuses
    assert maps[True].monodromies < 0.5 * maps[False].monodromies
    exact = periodic.duffing_period_map("omega", n_steps=64, damping=0.01, cubic=0.2, force=0.005)
    for orbit in early.orbits[-3:]:    # the last orbits, nearest the fold: on the branch
        single = periodic.find_orbit(exact, orbit.state, orbit.parameter, tol=1e-13)
        # within the residual's error bound |(M - I)^-1| |r| (a multiplier near +1 amplifies it ~1e4 here)
        bound = np.linalg.norm(np.linalg.inv(single.monodromy - np.eye(2)), 2) * orbit.residual * np.linalg.norm(
            orbit.state)
        assert np.linalg.norm(orbit.state - single.state) <= 2.0 * bound
