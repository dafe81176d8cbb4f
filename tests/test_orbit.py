"""Periodic orbits of nonlinear systems (periodic.find_orbit, periodic.continue_orbits) against
references independent of them: long transients of scipy's DOP853, harmonic balance solved by
scipy.optimize, the single-harmonic fold points and the backbone of the Duffing oscillator, finite
differences of the period map, the damped Mathieu equation's tongue from a DOP853 monodromy, and
maps whose bifurcations are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, fsolve

import periodic

# The hardening Duffing oscillator of the fold tests: x'' + c x' + x + k3 x^3 = F cos(Omega t),
# zeta = c / 2 = 0.005, peak amplitude about F / c = 0.5, backbone shift 3 k3 A^2 / 8 ~ 0.019 >> zeta.
DAMPING, CUBIC, FORCE = 0.01, 0.2, 0.005
# Omega between the folds (1.0131 and 1.0183): three orbits.
HYSTERESIS_OMEGA = 1.016


def duffing_rhs(damping, cubic, force, omega, stiffness=1.0, pump=0.0):
    def rhs(t, y):
        linear = stiffness + pump * np.cos(omega * t)
        return [y[1], force * np.cos(omega * t) - damping * y[1] - linear * y[0] - cubic * y[0] ** 3]
    return rhs


def poincare_points(rhs, state, period, n_periods):
    """The states at t = k T, k = 0..n_periods, of a DOP853 transient (tight tolerances)."""
    solution = solve_ivp(rhs, (0.0, n_periods * period), state, method="DOP853", rtol=1e-11, atol=1e-13,
                         t_eval=np.arange(n_periods + 1) * period)
    assert solution.success
    return solution.y.T


def amplitude(states, omegas):
    """``sqrt(x^2 + (v / Omega)^2)`` at t = 0: the first harmonic's amplitude up to the higher ones."""
    states = np.atleast_2d(states)
    return np.hypot(states[:, 0], states[:, 1] / omegas)


def single_harmonic_amplitudes(omega):
    """The amplitudes A of the single-harmonic balance at ``omega``: the real roots of
    ``[(1 - Omega^2 + 3/4 k3 A^2)^2 + (c Omega)^2] A^2 = F^2``, a cubic in A^2, increasing."""
    detuning = 1.0 - omega**2
    q = 0.75 * CUBIC
    # q^2 u^3 + 2 q detuning u^2 + (detuning^2 + c^2 Omega^2) u - F^2 = 0, u = A^2
    roots = np.roots([q * q, 2.0 * q * detuning, detuning**2 + (DAMPING * omega) ** 2, -FORCE**2])
    real = np.sort(roots[np.abs(roots.imag) < 1e-12].real)
    return np.sqrt(real[real > 0.0])


def single_harmonic_folds():
    """``(Omega, A)`` of the lower and upper folds of the single-harmonic response curve: the extrema of
    Omega(A) on its upper root, ``Omega^2 = [(2 K_A - c^2) + sqrt(...)] / 2`` with ``K_A = 1 + 3/4 k3 A^2``."""
    a = np.linspace(0.01, 0.5, 1_000_001)
    stiffness = 1.0 + 0.75 * CUBIC * a**2
    discriminant = (2.0 * stiffness - DAMPING**2) ** 2 - 4.0 * (stiffness**2 - FORCE**2 / a**2)
    real = discriminant >= 0.0
    omega = np.where(real, np.sqrt((2.0 * stiffness - DAMPING**2 + np.sqrt(np.where(real, discriminant, 0.0))) / 2.0),
                     np.inf)
    lower = np.argmin(omega)  # Omega(A) falls from infinity at A -> 0 to the lower fold ...
    upper = np.argmax(np.where(real & (a > a[lower]), omega, -np.inf))  # ... rises to the upper one
    return (omega[lower], a[lower]), (omega[upper], a[upper])


def harmonic_balance(omega, guess_amplitude, harmonics=(1, 3, 5, 7)):
    """``(x(0), v(0))`` of the periodic solution by harmonic balance with odd ``harmonics``, the
    Galerkin residual projected on 64 samples per period and solved by scipy's fsolve."""
    samples = 64
    t = np.arange(samples) * (2.0 * np.pi / omega / samples)
    k = np.asarray(harmonics, dtype=float)
    cosines, sines = np.cos(np.outer(t, k) * omega), np.sin(np.outer(t, k) * omega)

    def residual(coefficients):
        a, b = coefficients[: k.size], coefficients[k.size:]
        x = cosines @ a + sines @ b
        v = omega * (sines @ (-k * a) + cosines @ (k * b))
        acc = -(omega**2) * (cosines @ (k**2 * a) + sines @ (k**2 * b))
        r = acc + DAMPING * v + x + CUBIC * x**3 - FORCE * np.cos(omega * t)
        return np.concatenate([cosines.T @ r, sines.T @ r]) / samples

    start = np.zeros(2 * k.size)
    start[0] = guess_amplitude
    coefficients = fsolve(residual, start, xtol=1e-13)
    assert np.max(np.abs(residual(coefficients))) < 1e-13  # solved (fsolve's own flag is too strict)
    a, b = coefficients[: k.size], coefficients[k.size:]
    return np.array([a.sum(), omega * (k * b).sum()])


@pytest.fixture(scope="module")
def branches():
    """The pseudo-arclength branch over Omega in [0.9, 1.15] through both folds, at N = 128 and 256."""
    result = {}
    for n_steps in (128, 256):
        period_map = periodic.duffing_period_map("omega", n_steps=n_steps, damping=DAMPING, cubic=CUBIC,
                                                 force=FORCE)
        result[n_steps] = periodic.continue_orbits(period_map, np.zeros(2), 0.9, 1.15, method="arclength",
                                                   stop_at_instability=False)
    return result


def test_monodromy_equals_finite_differences_of_the_period_map():
    period_map = periodic.duffing_period_map("omega", n_steps=64, damping=0.05, cubic=0.5, force=0.3,
                                             pump=0.1)
    orbit = periodic.find_orbit(period_map, np.zeros(2), 1.1)
    assert orbit.converged and orbit.residual <= 1e-10
    for state in (orbit.state, np.array([0.7, -0.4])):
        _, monodromy = period_map(state, 1.1)
        if state is orbit.state:
            np.testing.assert_array_equal(monodromy, orbit.monodromy)
        central = np.empty((2, 2))
        for j in range(2):
            shift = np.zeros(2)
            shift[j] = 1e-5
            central[:, j] = (period_map(state + shift, 1.1)[0] - period_map(state - shift, 1.1)[0]) / 2e-5
        # central differences: error ~ h^2 |P'''| ~ 1e-10, rounding ~ eps / h ~ 1e-11
        np.testing.assert_allclose(monodromy, central, rtol=0, atol=1e-8)


def test_orbit_equals_the_end_of_a_long_transient_within_its_error_estimate():
    # well damped (decay e^(-c t / 2)): 80 periods take the transient from rest to ~1e-9
    damping, cubic, force, omega = 0.1, 0.2, 0.05, 1.1
    rhs = duffing_rhs(damping, cubic, force, omega)
    transient = poincare_points(rhs, [0.0, 0.0], 2.0 * np.pi / omega, 80)
    assert np.max(np.abs(transient[-1] - transient[-2])) < 1e-8  # settled
    errors = []
    for n_steps in (128, 256):
        period_map = periodic.duffing_period_map("omega", n_steps=n_steps, damping=damping, cubic=cubic,
                                                 force=force)
        orbit = periodic.find_orbit(period_map, np.zeros(2), omega, estimate=period_map.coarsened())
        assert orbit.status == "ok" and orbit.is_stable and orbit.bifurcation == "none"
        error = np.max(np.abs(orbit.state - transient[-1]))
        # the N/2 estimate is the error of this order-2 map within a factor 2 either way
        assert 0.5 * orbit.state_error < error < 2.0 * orbit.state_error
        # multipliers of a damped oscillator: |mu1 mu2| = det(Phi) = exp(-c T) up to O(h^2)
        assert abs(np.prod(orbit.multipliers).real - np.exp(-damping * 2 * np.pi / omega)) < 10 * orbit.state_error
        errors.append(error)
    assert 3.5 < errors[0] / errors[1] < 4.5  # order 2


def test_orbit_on_the_upper_branch_equals_harmonic_balance():
    """Between the folds three orbits coexist; started from the upper one's single-harmonic amplitude,
    Newton shooting finds the upper orbit, equal to a 4-harmonic balance within its N/2 estimate."""
    upper_amplitude = single_harmonic_amplitudes(HYSTERESIS_OMEGA)[-1]
    reference = harmonic_balance(HYSTERESIS_OMEGA, upper_amplitude)
    period_map = periodic.duffing_period_map("omega", n_steps=512, damping=DAMPING, cubic=CUBIC, force=FORCE)
    orbit = periodic.find_orbit(period_map, reference, HYSTERESIS_OMEGA, estimate=period_map.coarsened())
    assert orbit.status == "ok", orbit.message
    error = np.max(np.abs(orbit.state - reference))
    assert 0.5 * orbit.state_error < error < 2.0 * orbit.state_error
    assert orbit.state_error < 1e-3 * upper_amplitude


@pytest.mark.slow  # with the branches' fixture: two continuations through both folds, ~1 s
def test_folds_against_the_single_harmonic_balance_and_the_backbone(branches):
    (lower_omega, lower_amplitude), (upper_omega, upper_amplitude) = single_harmonic_folds()
    folds = {}
    for n_steps, branch in branches.items():
        assert branch.status == "unstable", branch.message  # it reached stop, with an unstable middle part
        assert branch.parameters[-1] == 1.15
        assert [kind for _, kind in branch.bifurcations] == ["fold", "fold"]
        for index in branch.bifurcation_indices:
            orbit = branch.orbits[index]
            # located on the unit circle: marginal, the critical multiplier +1 within the tolerance
            assert orbit.status == "marginal" and orbit.bifurcation == "fold"
            assert abs(orbit.multipliers[0] - 1.0) < 1e-6
        folds[n_steps] = np.array([parameter for parameter, _ in branch.bifurcations])
        fold_amplitudes = amplitude(branch.states[list(branch.bifurcation_indices)],
                                    folds[n_steps])
        # the upper fold (jump down) first, near the peak; amplitudes within the third harmonic's share
        np.testing.assert_allclose(fold_amplitudes, [upper_amplitude, lower_amplitude], rtol=5e-3)
    # order 2 in h: the folds move by 4x less from 256 to 512 than from 128 to 256 (measured 4.0) ...
    extrapolated = folds[256] + (folds[256] - folds[128]) / 3.0
    # ... and the extrapolated folds equal the single-harmonic ones up to the neglected harmonics
    # (measured 2.3e-5 and 2.4e-6; the raw N = 256 folds are 5e-5 off)
    np.testing.assert_allclose(extrapolated, [upper_omega, lower_omega], rtol=0, atol=4e-5)
    # the upper fold sits where the forced response meets the backbone w0 + 3 k3 A^2 / (8 w0), at the
    # peak amplitude F / (2 zeta w0^2) = F / c, to first order in zeta = 0.005
    backbone = 1.0 + 3.0 * CUBIC * upper_amplitude**2 / 8.0
    assert abs(extrapolated[0] - backbone) < 0.2 * DAMPING
    assert abs(upper_amplitude - FORCE / DAMPING) < 0.05 * FORCE / DAMPING


def test_the_middle_branch_is_unstable_like_harmonic_balance_says(branches):
    """The orbits between the folds are unstable with a real multiplier past +1, and they are those of
    the middle root of the single-harmonic balance, the unstable one; the stable ones are not."""
    branch = branches[256]
    first, second = branch.bifurcation_indices
    assert np.all(branch.stable[:first + 1]) and np.all(branch.stable[second:])
    middle = np.arange(first + 1, second)
    assert middle.size >= 3 and not np.any(branch.stable[middle])
    assert all(branch.orbits[i].status == "unstable" and branch.orbits[i].bifurcation == "fold" for i in middle)
    checked = 0
    for index, (omega, state) in enumerate(zip(branch.parameters, branch.states)):
        roots = single_harmonic_amplitudes(omega)
        # near a fold two roots merge and a small shift in Omega (the map's O(h^2) error, 5e-5, where
        # dA/dOmega is infinite) can swap them: only roots 5 % apart tell which one an orbit is on
        if roots.size != 3 or np.min(np.diff(roots)) < 0.05 * roots[-1]:
            continue
        nearest = np.argmin(np.abs(roots - amplitude(state, omega)[0]))
        assert (nearest == 1) == (not branch.stable[index]), (omega, roots, state)
        checked += 1
    assert checked >= 5


@pytest.mark.slow
def test_a_transient_leaves_the_middle_orbit_for_a_stable_one(branches):
    branch = branches[256]
    candidates = np.where(branch.stable, np.inf, np.abs(branch.parameters - HYSTERESIS_OMEGA))
    period_map = periodic.duffing_period_map("omega", n_steps=256, damping=DAMPING, cubic=CUBIC, force=FORCE)
    middle = periodic.find_orbit(period_map, branch.states[np.argmin(candidates)], HYSTERESIS_OMEGA)
    assert middle.status == "unstable" and middle.bifurcation == "fold" and middle.multipliers[0].real > 1.01
    stable = [periodic.find_orbit(period_map, harmonic_balance(HYSTERESIS_OMEGA, a), HYSTERESIS_OMEGA)
              for a in single_harmonic_amplitudes(HYSTERESIS_OMEGA)[[0, 2]]]
    assert all(orbit.status == "ok" for orbit in stable)
    rhs = duffing_rhs(DAMPING, CUBIC, FORCE, HYSTERESIS_OMEGA)
    points = poincare_points(rhs, middle.state, 2.0 * np.pi / HYSTERESIS_OMEGA, 400)
    distance_from_middle = np.linalg.norm(points - middle.state, axis=1)
    assert distance_from_middle[-1] > 100 * distance_from_middle[:5].max()
    # it settles on one of the stable orbits (to the map's discretisation error near resonance, ~0.3 %)
    size = np.linalg.norm(stable[1].state)
    assert min(np.linalg.norm(points[-1] - orbit.state) for orbit in stable) < 0.01 * size


def test_natural_continuation_stops_at_the_fold_and_says_so():
    period_map = periodic.duffing_period_map("omega", n_steps=128, damping=DAMPING, cubic=CUBIC, force=FORCE)
    branch = periodic.continue_orbits(period_map, np.zeros(2), 0.9, 1.15)
    assert branch.status == "failed"
    assert "min_step" in branch.message and "method='arclength'" in branch.message
    assert 1.017 < branch.parameters[-1] < 1.0182  # just before the upper fold (1.0181 at N = 128)
    assert np.all(np.diff(branch.parameters) > 0.0) and np.all(branch.stable)


def test_arclength_continuation_stops_at_the_first_fold_when_asked():
    period_map = periodic.duffing_period_map("omega", n_steps=128, damping=DAMPING, cubic=CUBIC, force=FORCE)
    branch = periodic.continue_orbits(period_map, np.zeros(2), 0.9, 1.15, method="arclength",
                                      estimate=period_map.coarsened())
    assert branch.status == "unstable" and "fold" in branch.message
    assert len(branch.bifurcations) == 1 and branch.bifurcation_indices == (len(branch.parameters) - 1,)
    assert np.all(branch.stable) and abs(branch.bifurcations[0][0] - 1.0181) < 1e-4
    # with the N/2 map as estimate, the orbits away from the fold carry their error estimates ...
    away = branch.parameters < 1.01
    assert away.sum() > 10 and all(branch.orbits[i].status == "ok" and np.isfinite(branch.orbits[i].state_error)
                                   and np.all(np.isfinite(branch.orbits[i].multiplier_errors))
                                   for i in np.flatnonzero(away))
    # ... but at the fold the N/2 map has no orbit (its own fold is ~6e-4 lower): inaccurate, and why
    fold = branch.orbits[-1]
    assert fold.status == "inaccurate" and fold.is_stable and "coarse map" in fold.message
    assert abs(fold.multipliers[0] - 1.0) < 1e-6
    assert sum(orbit.map_calls for orbit in branch.orbits) <= branch.map_calls


# The damped Mathieu-Duffing equation x'' + c x' + (d + e cos t) x + k3 x^3 = 0 (T = 2 pi): its trivial
# orbit loses stability by period doubling on the principal tongue around d = 1/4.
MATHIEU_DAMPING, MATHIEU_PUMP, MATHIEU_CUBIC = 0.05, 0.2, 1.0


def mathieu_map(n_steps):
    return periodic.duffing_period_map("stiffness", n_steps=n_steps, damping=MATHIEU_DAMPING,
                                       pump=MATHIEU_PUMP, cubic=MATHIEU_CUBIC, force=0.0, omega=1.0)


def mathieu_tongue():
    """The tongue's edges in d: where ``det(I + Phi) = 0`` for the linear damped Mathieu equation, its
    monodromy by DOP853 (rtol 1e-12), the roots by Brent."""
    def det_plus(d):
        def rhs(t, y):
            stiffness = d + MATHIEU_PUMP * np.cos(t)
            return [y[1], -MATHIEU_DAMPING * y[1] - stiffness * y[0], y[3], -MATHIEU_DAMPING * y[3] - stiffness * y[2]]
        solution = solve_ivp(rhs, (0.0, 2.0 * np.pi), [1.0, 0.0, 0.0, 1.0], method="DOP853", rtol=1e-12,
                             atol=1e-14)
        return np.linalg.det(np.eye(2) + solution.y[:, -1].reshape(2, 2).T)
    return brentq(det_plus, 0.1, 0.25, xtol=1e-12), brentq(det_plus, 0.25, 0.4, xtol=1e-12)


@pytest.mark.slow
def test_period_doubling_on_the_mathieu_tongue_and_the_transient_that_doubles_the_period():
    lower, upper = mathieu_tongue()
    edges = {}
    for n_steps in (128, 256):
        branch = periodic.continue_orbits(mathieu_map(n_steps), np.zeros(2), 0.1, 0.4, stop_at_instability=False)
        assert [kind for _, kind in branch.bifurcations] == ["period_doubling", "period_doubling"]
        assert branch.parameters[-1] == 0.4 and np.all(np.diff(branch.parameters) > 0.0)
        edges[n_steps] = np.array([parameter for parameter, _ in branch.bifurcations])
        inside = (branch.parameters > edges[n_steps][0] + 1e-3) & (branch.parameters < edges[n_steps][1] - 1e-3)
        outside = (branch.parameters < edges[n_steps][0] - 1e-3) | (branch.parameters > edges[n_steps][1] + 1e-3)
        assert inside.any() and not np.any(branch.stable[inside]) and np.all(branch.stable[outside])
        assert all(orbit.bifurcation == "period_doubling" for orbit in np.array(branch.orbits)[inside])
    # the edges converge at order 2 to the DOP853 tongue
    error_coarse, error_fine = np.abs(edges[128] - [lower, upper]), np.abs(edges[256] - [lower, upper])
    assert np.all(error_fine < 1e-4) and np.all(3.0 < error_coarse / error_fine)
    # stop_at_instability: the branch ends at the first edge, where the orbit loses stability
    stopped = periodic.continue_orbits(mathieu_map(256), np.zeros(2), 0.1, 0.4)
    assert stopped.status == "unstable" and "period doubling" in stopped.message
    assert stopped.statuses[-1] == "marginal" and abs(stopped.multipliers[-1, 0] + 1.0) < 1e-6
    # inside the tongue a transient from near the trivial orbit settles on a 2T orbit: its Poincare
    # section alternates between two points (x(t + T) = -x(t) by the symmetry x -> -x, t -> t + T)
    d = 0.25
    rhs = duffing_rhs(MATHIEU_DAMPING, MATHIEU_CUBIC, 0.0, 1.0, stiffness=d, pump=MATHIEU_PUMP)
    points = poincare_points(rhs, [1e-3, 0.0], 2.0 * np.pi, 600)
    last, before = points[-1], points[-2]
    assert np.linalg.norm(last) > 0.1  # grown from 1e-3
    np.testing.assert_allclose(points[-3], last, atol=1e-7)  # period 2T ...
    np.testing.assert_allclose(before, -last, atol=1e-7)  # ... and not T
    # the twice-iterated map's orbit through the transient's point (N = 256: O(h^2) off the DOP853 one)
    single = mathieu_map(256)

    def doubled(state, parameter):
        middle, first = single(state, parameter)
        end, second = single(middle, parameter)
        return end, second @ first

    orbit = periodic.find_orbit(doubled, last, d, estimate=None)
    assert orbit.status == "ok" and orbit.is_stable
    assert np.max(np.abs(orbit.state - last)) < 1e-3 * np.linalg.norm(last)


def test_bifurcations_of_maps_known_in_closed_form():
    """Linear maps with the fixed point 0 whose multipliers cross the unit circle at parameter 1:
    a real one through +1 (fold), through -1 (period doubling), a complex pair (secondary Hopf)."""
    angle = 0.7
    rotation = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    cases = {
        "fold": lambda p: np.diag([p, 0.5]),
        "period_doubling": lambda p: np.diag([-p, 0.5]),
        "secondary_hopf": lambda p: p * rotation,
    }
    for kind, matrix in cases.items():
        def period_map(state, parameter, matrix=matrix):
            return matrix(parameter) @ state, matrix(parameter)
        branch = periodic.continue_orbits(period_map, np.zeros(2), 0.5, 1.5, method="natural", state_scale=1.0)
        assert branch.status == "unstable", (kind, branch.message)
        (parameter, found), = branch.bifurcations
        assert found == kind and abs(parameter - 1.0) < 1e-8, (kind, parameter)
        assert branch.orbits[-1].bifurcation == kind and branch.statuses[-1] == "marginal"


def test_a_multiplier_within_its_error_bar_of_the_circle_is_marginal():
    # undamped linear oscillator off resonance: the trapezoidal rule keeps |mu| = 1 to rounding
    period_map = periodic.duffing_period_map("omega", n_steps=64, damping=0.0, cubic=0.0, force=0.1)
    orbit = periodic.find_orbit(period_map, np.zeros(2), 0.5)
    assert orbit.status == "marginal" and orbit.is_stable and orbit.bifurcation in ("fold", "secondary_hopf")
    # a damped one, |mu| - 1 = -3e-3: ok with a small error bar, marginal with one that covers it
    damped = periodic.duffing_period_map("omega", n_steps=64, damping=1e-3, cubic=0.0, force=0.1)
    assert periodic.find_orbit(damped, np.zeros(2), 2.0).status == "ok"
    covered = periodic.find_orbit(damped, np.zeros(2), 2.0, estimate=2e-3)
    assert covered.status == "marginal" and "error bar" in covered.message
    np.testing.assert_array_equal(covered.multiplier_errors, [2e-3, 2e-3])


def test_newton_failures_are_failed_with_the_reason():
    period_map = periodic.duffing_period_map("omega", n_steps=64, damping=DAMPING, cubic=CUBIC, force=FORCE)
    capped = periodic.find_orbit(period_map, [0.3, 0.0], 1.016, max_iterations=1, tol=1e-14)
    assert capped.status == "failed" and not capped.converged and not capped.is_stable
    assert "max iterations" in capped.message and capped.iterations == 1
    singular = periodic.find_orbit(lambda state, p: (state + 1.0, np.eye(2)), [0.0, 0.0], 0.0)
    assert singular.status == "failed" and "singular Jacobian" in singular.message

    def fails_away_from_the_guess(state, parameter):
        if np.any(state != 0.0):
            raise periodic.ShootingError("Newton of a step did not converge")
        return state + 1.0, 0.5 * np.eye(2)

    diverging = periodic.find_orbit(fails_away_from_the_guess, [0.0, 0.0], 0.0)
    assert diverging.status == "failed" and "diverging residual" in diverging.message
    assert "did not converge" in diverging.message and diverging.map_calls == 12  # the guess + 11 trials (1 .. 1/1024)
    branch = periodic.continue_orbits(fails_away_from_the_guess, [0.0, 0.0], 0.0, 1.0)
    assert branch.status == "failed" and branch.parameters.shape == (0,) and branch.states.shape == (0, 2)


def test_bad_input_names_the_argument():
    period_map = periodic.duffing_period_map("omega", n_steps=16)
    with pytest.raises(periodic.PeriodicError, match="guess"):
        periodic.find_orbit(period_map, [[0.0, 0.0]], 1.0)
    with pytest.raises(periodic.PeriodicError, match="period_map: expected to return"):
        periodic.find_orbit(lambda state, p: (state[:1], np.eye(1)), [0.0, 0.0], 1.0)
    with pytest.raises(TypeError, match="period_map"):
        periodic.find_orbit("not a map", [0.0, 0.0], 1.0)
    with pytest.raises(periodic.PeriodicError, match="method"):
        periodic.continue_orbits(period_map, [0.0, 0.0], 1.0, 1.1, method="secant")
    with pytest.raises(periodic.PeriodicError, match="stop"):
        periodic.continue_orbits(period_map, [0.0, 0.0], 1.0, 1.0)
    with pytest.raises(periodic.PeriodicError, match="step"):
        periodic.continue_orbits(period_map, [0.0, 0.0], 1.0, 1.1, step=-0.1)
    with pytest.raises(periodic.PeriodicError, match="parameter"):
        periodic.duffing_period_map("mass")
    with pytest.raises(TypeError, match="unknown"):
        periodic.duffing_period_map("omega", mass=2.0)
    with pytest.raises(TypeError):
        periodic.find_orbit(period_map, [0.0, 0.0], 1.0, tolerance=1e-8)
    with pytest.raises(periodic.PeriodicError, match="estimate"):
        periodic.find_orbit(period_map, [0.0, 0.0], 1.0, estimate=-1e-3)
    with pytest.raises(periodic.PeriodicError, match="estimate"):
        periodic.continue_orbits(period_map, [0.0, 0.0], 1.0, 1.1, estimate=[1e-3, 1e-3, 1e-3])


def _cornered_branch(p, corner, slope=50.0, width=1e-3):
    """Fixed points (2,) of ``_cornered_map`` at ``p``: a line along e1 that turns by 150 degrees to e2
    within ``width`` of ``corner`` (softplus), steep (``slope`` per unit of p) as an orbit near a
    resonance, whose phase turns within a fraction of a speed step."""
    e1, e2 = np.array([1.0, 0.0]), np.array([np.cos(np.radians(150.0)), np.sin(np.radians(150.0))])
    u = (p - corner) / width
    soft = width * (np.logaddexp(0.0, u))
    return slope * ((p - corner) * e1 + soft * (e2 - e1))


@pytest.mark.parametrize("corner", [0.505, 0.54, 0.58])
def test_natural_continuation_follows_a_branch_that_bends_within_a_step(corner):
    # a step across the corner makes less than 30 degrees with the tangent where it starts and more
    # than 90 with the tangent where it ends: the continuation oriented that tangent along the step,
    # backwards, and rejected every later step (six_bar at 106.283 rad/s, issue 24)
    A = np.array([[0.5, 0.2], [-0.1, 0.4]])

    def period_map(x, p):
        return A @ x + (np.eye(2) - A) @ _cornered_branch(p, corner), A

    branch = periodic.continue_orbits(period_map, _cornered_branch(0.0, corner), 0.0, 1.0, step=0.1, max_step=0.1)
    assert branch.status == "ok", branch.message
    assert branch.parameters[-1] == 1.0 and np.all(np.diff(branch.parameters) > 0.0)
    for state, p in zip(branch.states, branch.parameters):   # on the closed-form branch
        assert np.abs(state - _cornered_branch(p, corner)).max() <= 1e-7 * 50.0
