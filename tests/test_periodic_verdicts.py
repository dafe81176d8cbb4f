"""periodic: the verdicts (stability with its error bar, trust of the error estimate), each status
reached by a system built to reach it, checked against independent references (scipy.special's
Mathieu characteristic values, scipy.linalg.expm, solve_ivp, Richardson at large N)."""

import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
import scipy.special

import periodic
from periodic import PeriodicError, PeriodicSystem

sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
import bench_periodic  # noqa: E402  (its smooth and stiff cases)

TWO_PI = 2.0 * np.pi


def test_statuses_and_worst_status():
    assert periodic.STATUSES == ("failed", "unstable", "outside_linear_range", "inaccurate", "near_resonance",
                                 "marginal", "unresolved_stiff_mode", "ok")
    assert periodic.worst_status() == "ok"
    assert periodic.worst_status("ok", "marginal", "inaccurate", "unresolved_stiff_mode") == "inaccurate"
    assert periodic.worst_status("near_resonance", "failed") == "failed"
    with pytest.raises(PeriodicError, match="status: expected one of .*got 'stable'"):
        periodic.worst_status("ok", "stable")


def mathieu(a, q, n_steps, damping=0.0):
    """y'' + c y' + (a - 2q cos 2t) y = 0, T = pi."""
    t = np.arange(n_steps + 1) * np.pi / n_steps
    ones = np.ones((n_steps + 1, 1, 1))
    return PeriodicSystem(np.pi, ones, damping * ones, (a - 2.0 * q * np.cos(2.0 * t))[:, None, None])


@pytest.mark.parametrize("order, kind", [(1, "period_doubling"), (2, "fold")])
def test_mathieu_tongues_are_unstable_with_their_kind(order, kind):
    """Inside the tongue of order r (b_r(q) < a < a_r(q), scipy) the multipliers are real: near -1 for
    the principal tongue (r = 1: response at half the pulsation frequency), near +1 for r = 2."""
    q = 1.0
    a = 0.5 * (scipy.special.mathieu_a(order, q) + scipy.special.mathieu_b(order, q))
    system = mathieu(a, q, 256)
    result = periodic.floquet(system, estimate_error=True)
    assert (result.status, result.instability_kind, result.is_stable) == ("unstable", kind, False)
    assert result.spectral_radius - 1.0 > result.spectral_radius_error > 0.0
    assert np.sign(result.critical_multiplier.real) == (-1 if order == 1 else 1)
    assert result.message.startswith("unstable: ") and kind.replace("_", " ") in result.message.replace(
        "fold or", "fold"
    )
    # Same verdict from the steady state (unforced: x = 0, the error check agrees to round-off).
    steady = periodic.steady_state(system)
    assert (steady.status, steady.instability_kind, steady.is_stable) == ("unstable", kind, False)
    assert steady.error_trusted


def test_combination_resonance_is_a_secondary_hopf():
    """Two modes (1 and 1.7 rad/s) coupled by a stiffness pulsating at their sum 2.7 rad/s: the
    multipliers exp(i w1 T) and exp(i w2 T) collide off the real axis and leave the circle as a
    complex quadruplet.  Checked against an independent monodromy (DOP853)."""
    omega = 2.7
    K0, K1 = np.diag([1.0, 1.7**2]), np.array([[0.0, 1.0], [1.0, 0.0]])

    def stiffness(t):
        return K0 + 0.3 * np.cos(omega * t) * K1

    system = PeriodicSystem.from_functions(TWO_PI / omega, lambda t: np.eye(2), lambda t: np.zeros((2, 2)),
                                           stiffness, n_steps=256)
    result = periodic.floquet(system, estimate_error=True)
    assert (result.status, result.instability_kind) == ("unstable", "secondary_hopf")

    def rhs(t, y):
        Y = y.reshape(4, 4)
        return np.vstack((Y[2:], -stiffness(t) @ Y[:2])).ravel()

    end = scipy.integrate.solve_ivp(rhs, (0.0, TWO_PI / omega), np.eye(4).ravel(), method="DOP853",
                                    rtol=1e-12, atol=1e-12).y[:, -1]
    exact = np.linalg.eigvals(end.reshape(4, 4))
    critical = exact[np.argmax(np.abs(exact))]
    assert abs(critical.imag) > 0.1 and abs(critical) > 1.1
    assert abs(abs(result.critical_multiplier) - abs(critical)) < result.spectral_radius_error


def oscillator(damping_ratio, n_steps, omega_n=2.3):
    """x'' + 2 zeta w x' + w^2 x = cos t, T = 2 pi (forced off resonance: exp(i w T) is far from +1)."""
    ones = np.ones((n_steps + 1, 1, 1))
    t = np.arange(n_steps + 1) * TWO_PI / n_steps
    return PeriodicSystem(TWO_PI, ones, 2.0 * damping_ratio * omega_n * ones, omega_n**2 * ones, np.cos(t)[:, None])


@pytest.mark.parametrize("n_steps", [64, 256, 1024])
def test_undamped_oscillator_is_marginal_and_lightly_damped_is_ok(n_steps):
    undamped = periodic.steady_state(oscillator(0.0, n_steps))
    assert (undamped.status, undamped.is_stable, undamped.instability_kind) == ("marginal", True, "secondary_hopf")
    assert undamped.message.startswith("marginal: ")
    damped = periodic.steady_state(oscillator(0.01, n_steps))
    # expm of the constant-coefficient state matrix
    exact_radius = np.abs(np.linalg.eigvals(scipy.linalg.expm(np.array([[0, 1], [-2.3**2, -0.046]]) * TWO_PI))).max()
    assert (damped.status, damped.is_stable, damped.instability_kind) == ("ok", True, "")
    assert abs(damped.spectral_radius - exact_radius) <= damped.spectral_radius_error


def test_spurious_growth_within_the_error_bar_is_marginal():
    """A multiplier moved off the unit circle by the scheme converges like c h^2: with mu_N = 1 + c h^2
    and mu_{N/2} = 1 + 4 c h^2, the N/2 estimate is c h^2, as large as the excess (the issue's undamped
    four-bar: |mu| - 1 = 1.2e-3 at N = 256).  Marginal, not unstable; twice as far out is unstable."""
    excess = 1.2e-3
    estimate = abs((1.0 + excess) - (1.0 + 4.0 * excess)) / 3.0
    rates = np.array([0.05, 0.05])
    verdict = periodic.stability_verdict(np.array([-1.0 - excess, 0.5]), np.array([estimate, 1e-9]), rates)
    assert (verdict.status, verdict.is_stable, verdict.kind) == ("marginal", True, "period_doubling")
    assert verdict.spectral_radius_error == pytest.approx(2.0 * estimate)
    verdict = periodic.stability_verdict(np.array([1.0 + 3.0 * excess, 0.5]), np.array([estimate, 1e-9]), rates)
    assert (verdict.status, verdict.is_stable, verdict.kind) == ("unstable", False, "fold")
    assert verdict.spectral_radius - 1.0 > verdict.spectral_radius_error + periodic.STABILITY_TOL


def test_unresolved_modes_are_never_the_critical_multiplier():
    """An unresolved decaying mode (step rate > 1) near the unit circle does not decide stability. An
    unresolved mode outside the circle cannot be told from a discretisation artefact (with
    time-varying coefficients an undamped stiff mode can leave the circle at a coarse step): the
    verdict is inaccurate, refine n_steps; a resolved growing mode is unstable."""
    multipliers = np.array([0.9999995, -0.6 + 0.2j, -0.6 - 0.2j])
    verdict = periodic.stability_verdict(multipliers, None, np.array([40.0, 0.3, 0.3]))
    assert verdict.status == "ok" and verdict.critical_multiplier == -0.6 + 0.2j
    unresolved = periodic.stability_verdict(np.array([3.0, 0.5]), None, np.array([40.0, 0.3]))
    assert unresolved.status == "inaccurate" and unresolved.critical_multiplier == 3.0
    assert unresolved.message.startswith("inaccurate: refine n_steps") and unresolved.is_stable
    resolved = periodic.stability_verdict(np.array([3.0, 0.5]), None, np.array([0.5, 0.3]))
    assert resolved.status == "unstable" and not resolved.is_stable
    # a resolved instability is unstable whatever an unresolved mode does
    both = periodic.stability_verdict(np.array([5.0, 1.5]), None, np.array([40.0, 0.3]))
    assert both.status == "unstable" and both.critical_multiplier == 1.5


def test_error_verdict_rules():
    # Asymptotic ratio: trusted.
    check = periodic.error_verdict(1e-4, 4.1e-4, 2, scale=1.0, n_steps=256)
    assert (check.trusted, check.status) == (True, "ok") and check.ratio == pytest.approx(4.1)
    # Ratio off 2^order: refine, with the ratio in the message.
    check = periodic.error_verdict(1e-4, 1.2e-4, 2, scale=1.0, n_steps=256)
    assert (check.trusted, check.status) == (False, "inaccurate")
    assert check.message.startswith("refine n_steps: ") and "1.2," in check.message
    # First-order scheme: the ideal ratio is 2.
    assert periodic.error_verdict(1e-4, 2.1e-4, 1, scale=1.0).trusted
    # N/4 grid of 2 steps: nothing is resolved, whatever the ratio.
    assert periodic.error_verdict(1e-4, 4e-4, 2, scale=1.0, n_steps=8).status == "inaccurate"
    # Trusted but too large.
    check = periodic.error_verdict(0.6, 2.4, 2, scale=1.0, n_steps=256)
    assert (check.trusted, check.status) == (True, "inaccurate") and "estimated error is 0.2" in check.message
    # Round-off: nothing left to estimate (also the zero solution of an unforced system).
    assert periodic.error_verdict(1e-17, 3e-17, 2, scale=1.0, n_steps=256).status == "ok"
    assert periodic.error_verdict(0.0, 0.0, 2, scale=0.0, n_steps=256).status == "ok"


def test_coarse_grid_is_inaccurate_and_fine_grid_ok():
    coarse = periodic.steady_state(periodic.demo_system(16))
    assert coarse.status == "inaccurate" and not coarse.error_trusted
    assert coarse.message.startswith("refine n_steps: ") and f"{coarse.error_ratio:.3g}" in coarse.message
    fine = periodic.steady_state(periodic.demo_system(512))
    assert fine.status == "ok" and fine.error_trusted and fine.error_ratio == pytest.approx(4.0, abs=0.1)
    assert fine.x_quarter.shape == (129, 2)
    np.testing.assert_array_equal(
        fine.x_quarter, periodic.steady_state(periodic.demo_system(128), estimate_error=False).x
    )
    skipped = periodic.steady_state(periodic.demo_system(512), estimate_error=False)
    assert skipped.x_quarter is None and not skipped.error_trusted and np.isnan(skipped.error_ratio)
    assert np.isnan(skipped.spectral_radius_error) and skipped.status == "ok"


@pytest.fixture(scope="module", params=["smooth", "stiff"])
def convergence_runs(request):
    """steady_state at N = 8 .. 4096 and its true error against Richardson at N = 2^15 (order 4: its own
    error is below 1e-3 of the N = 4096 error)."""
    case = bench_periodic.smooth_case() if request.param == "smooth" else bench_periodic.stiff_case()
    reference = periodic.steady_state(case.system(2**15), extrapolate=True, estimate_error=False).x
    runs = []
    for n_steps in 2 ** np.arange(3, 13):
        result = periodic.steady_state(case.system(int(n_steps)))
        true_error = np.abs(result.x - reference[:: 2**15 // n_steps]).max()
        runs.append((int(n_steps), result, true_error))
    return request.param, runs


def test_error_estimate_is_honest_wherever_it_is_ok(convergence_runs):
    """Every "ok" has an estimate within 0.5x-20x of the true error; every estimate outside that band
    is "inaccurate"; the coarsest grid is inaccurate and the finest ok (the check is not vacuous)."""
    name, runs = convergence_runs
    for n_steps, result, true_error in runs:
        quality = result.error_estimate / true_error
        within = 0.5 <= quality <= 20.0
        assert result.status in ("ok", "inaccurate"), (name, n_steps, result.message)
        if result.status == "ok":
            assert within, (name, n_steps, quality)
        if not within:
            assert result.status == "inaccurate", (name, n_steps, quality)
    assert runs[0][1].status == "inaccurate" and all(r.status == "ok" for _, r, _ in runs[-4:]), name


def test_floquet_error_bar_covers_the_true_radius_error():
    """Constant coefficients: the exact multipliers are the eigenvalues of expm(A T)."""
    M, K = np.array([[2.0, 0.3], [0.3, 1.0]]), np.array([[5.0, -1.5], [-1.5, 3.0]])
    C = 0.05 * K + 0.1 * M
    A = np.block([[np.zeros((2, 2)), np.eye(2)], [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    exact_radius = np.abs(np.linalg.eigvals(scipy.linalg.expm(A * TWO_PI))).max()
    for n_steps in (32, 128, 512):
        system = PeriodicSystem(TWO_PI, np.tile(M, (n_steps + 1, 1, 1)), np.tile(C, (n_steps + 1, 1, 1)),
                                np.tile(K, (n_steps + 1, 1, 1)))
        plain, checked = periodic.floquet(system), periodic.floquet(system, estimate_error=True)
        assert np.isnan(plain.spectral_radius_error) and plain.multiplier_errors is None
        true_error = abs(checked.spectral_radius - exact_radius)
        assert true_error <= checked.spectral_radius_error <= 20.0 * max(true_error, 1e-12)
        assert checked.status == plain.status == "ok" and checked.is_stable
