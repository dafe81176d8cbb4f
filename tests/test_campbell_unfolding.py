"""Unfolding of Floquet characteristic frequencies: each multiplier belongs to one natural mode, told by
its Floquet mode (``studies._numerics.multiplier_modes``), and is unfolded to that mode's frequency.

A multiplier fixes a frequency only modulo the speed ``Omega = 2 pi / T``; unfolding each multiplier
to the nearest of all the modes' frequencies picks a wrong mode as soon as ``Omega`` is small against
their spacing (every multiplier then has a candidate within ``Omega / 2`` of every mode). References:
the trapezoidal rule's exact per-step phase of a constant-coefficient mode, and a four-bar's frozen bands.
"""

from __future__ import annotations

import numpy as np
import pytest

import periodic
import studies
from studies import MechanismProblem
from studies._numerics import characteristic_frequencies, frozen_modes, multiplier_modes, pooled_frequencies

#: Natural frequencies (rad/s) of the constant-coefficient test system, and its speed (rad/s).
FREQUENCIES = np.array([11.3, 152.9, 401.7])
SPEED = 7.0
N_STEPS = 2048
DAMPING = 0.1   # C = DAMPING M, 1/s


def constant_system() -> tuple[periodic.PeriodicSystem, np.ndarray]:
    """A 3-mode system with coupled (non-diagonal) mass and stiffness, and its modal shapes."""
    rotation, _ = np.linalg.qr(np.array([[1.0, 0.4, -0.3], [0.2, 1.0, 0.5], [-0.6, 0.3, 1.0]]))
    mass = np.diag([1.0, 2.5, 0.7])
    root = np.sqrt(mass)
    stiffness = root @ rotation @ np.diag(FREQUENCIES ** 2) @ rotation.T @ root
    period = 2.0 * np.pi / SPEED

    def repeat(matrix):
        return np.repeat(matrix[None], N_STEPS + 1, axis=0)

    return periodic.PeriodicSystem(period, repeat(mass), repeat(DAMPING * mass), repeat(stiffness)), rotation


def trapezoidal_frequency(omega: float, h: float) -> float:
    """The unfolded frequency (rad/s) the trapezoidal rule gives a mode ``x'' + c x' + omega^2 x = 0``:
    the argument of its per-step amplification (the root of ``(1 + c h/2 + w^2 h^2/4) z^2 - 2 (1 - w^2
    h^2/4) z + (1 - c h/2 + w^2 h^2/4) = 0``) divided by ``h``; below pi per step, so N steps add it up
    without wrapping."""
    a = omega ** 2 * h ** 2 / 4.0
    roots = np.roots([1.0 + DAMPING * h / 2.0 + a, -2.0 * (1.0 - a), 1.0 - DAMPING * h / 2.0 + a])
    return float(np.abs(np.angle(roots[0])) / h)


def test_each_multiplier_is_unfolded_to_its_own_mode_against_the_exact_discrete_phase():
    system, _ = constant_system()
    result = periodic.floquet(system)
    _, frozen, shapes = frozen_modes(system, 4)
    np.testing.assert_allclose(frozen[0], FREQUENCIES, rtol=1e-12)
    modes, shares = multiplier_modes(result.eigenvectors, shapes)
    assert sorted(modes.tolist()) == [0, 0, 1, 1, 2, 2]
    np.testing.assert_allclose(shares, 1.0, atol=1e-9)   # constant coefficients: pure modes
    found = characteristic_frequencies(result.multipliers, system.period, frozen.mean(axis=0)[modes])
    expected = np.array([trapezoidal_frequency(FREQUENCIES[j], system.step) for j in modes])
    np.testing.assert_allclose(found, expected, rtol=1e-9)
    # the pooled unfolding of before gets at least one wrong here: the check can fail
    pooled = pooled_frequencies(result.multipliers, system.period, frozen.mean(axis=0))
    assert np.max(np.abs(pooled - expected)) > 0.5 * SPEED


def test_a_repeated_mode_takes_two_multipliers_and_a_missing_target_gives_nan():
    system, _ = constant_system()
    result = periodic.floquet(system)
    _, frozen, shapes = frozen_modes(system, 4)
    targets = frozen.mean(axis=0)[multiplier_modes(result.eigenvectors, shapes)[0]]
    targets[0] = np.nan
    found = characteristic_frequencies(result.multipliers, system.period, targets)
    assert np.isnan(found[0]) and np.isfinite(found[1:]).all()


@pytest.mark.slow
def test_a_four_bar_at_low_speed_draws_each_mode_inside_its_frozen_band():
    """four_bar_fem4 at 60 rad/s (modes at about 296, 1190, 2710 rad/s, 20 to 45 speeds apart): the
    pooled unfolding drew mode 1 at 2710 rad/s; each mode's two characteristic frequencies now lie in
    its frozen band widened by the half speed (a Floquet frequency of a slowly modulated mode is
    within its frozen band, modulo the speed)."""
    result = studies.campbell(MechanismProblem.from_scene("four_bar_fem4"), [60.0], n_steps=256,
                              frozen_samples=16)
    omega = 60.0
    columns = result.order[0]
    for j in range(3):   # the three lowest tracked modes
        mine = result.characteristic[0][result.multiplier_modes[0] == columns[j]]
        assert mine.size == 2, (j, result.multiplier_modes[0])
        assert np.all(mine >= result.band_min[0, j] - 0.5 * omega), (j, mine, result.band_min[0, j])
        assert np.all(mine <= result.band_max[0, j] + 0.5 * omega), (j, mine, result.band_max[0, j])
        assert np.all(result.characteristic_error[0][result.multiplier_modes[0] == columns[j]] < 0.5 * omega)
