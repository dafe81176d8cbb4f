"""periodic: the LAPACK paths of the Newmark kernel (large n) against its hand-written LU (small n).

The same shooting on both paths must agree to rounding on random periodic systems of several
sizes, well conditioned and stiff.  The exact-reference tests (orders, closed-form monodromies)
run on both paths in ``tests/test_periodic_numerics.py``; ``tests/test_periodic_kernel.py`` checks
every solver of the kernel against a numpy twin.
"""

import numpy as np
import pytest

import periodic
from periodic import _newmark  # internal kernels and their solver choice: no public face
from tests._support.newmark_twin import newmark_numpy
from tests._support.paths import kernel_path

RELATIVE = 1e-12


def random_periodic_system(n, n_steps, *, stiffness_spread=1.0, seed=0):
    """n DOF with periodic, non-symmetric M, C, K and forcing, well damped, stable and away from
    resonance (a unique, well-conditioned steady state).  ``stiffness_spread``: ratio of the highest
    to the lowest stiffness (stiff modes the step does not resolve)."""
    rng = np.random.default_rng(seed)
    A, B = rng.normal(size=(n, n)), rng.normal(size=(n, n))
    root = np.diag(np.geomspace(1.0, stiffness_spread, n) ** 0.5)
    mass = A @ A.T / n + np.eye(n)
    stiffness = 40.0 * root @ (B @ B.T / n + np.eye(n)) @ root
    damping = 2e-3 * stiffness + 0.5 * mass
    mass_variation = 0.05 * rng.normal(size=(n, n)) / np.sqrt(n)
    stiffness_variation = 0.1 * rng.normal(size=(n, n)) / np.sqrt(n)  # relative, non-symmetric
    force = rng.normal(size=n)
    omega = 2.0 * np.pi
    return periodic.PeriodicSystem.from_functions(
        1.0,
        lambda t: mass @ (np.eye(n) + np.sin(omega * t) * mass_variation),
        lambda t: damping,
        lambda t: stiffness @ (np.eye(n) + np.cos(omega * t) * stiffness_variation),
        lambda t: force * np.cos(omega * t) + 0.3 * force[::-1] * np.sin(2 * omega * t),
        n_steps=n_steps,
    )


def assert_close(new, old, what):
    scale = np.abs(old).max()
    assert np.abs(new - old).max() <= RELATIVE * scale, what


def assert_same_multipliers(new, old):
    """Each multiplier has a partner within rounding (the modulus sort may swap conjugate pairs)."""
    distance = np.abs(new[:, None] - old[None, :]).min(axis=1)
    assert distance.max() <= RELATIVE * np.abs(old).max()


def shoot(system, path):
    with kernel_path(path):
        return periodic.steady_state(system), periodic.floquet(system, estimate_error=True)


@pytest.mark.parametrize("n", [3, 21, 45])
def test_lapack_path_equals_the_loops_to_rounding(n):
    """Steady state (N, N/2, N/4 runs), monodromy and multipliers: the LAPACK path (dgetri + dgemm for
    the 2n+1 columns, dgetrs for the forced run) against the hand-written LU, to 1e-12 relative."""
    system = random_periodic_system(n, 16)
    new_state, new_floquet = shoot(system, "lapack")
    old_state, old_floquet = shoot(system, "loops")
    for name in ("x", "v", "a", "monodromy", "x_coarse", "x_quarter"):
        assert_close(getattr(new_state, name), getattr(old_state, name), name)
    assert_close(new_floquet.monodromy, old_floquet.monodromy, "floquet monodromy")
    assert_same_multipliers(new_state.multipliers, old_state.multipliers)
    assert_same_multipliers(new_floquet.multipliers_coarse, old_floquet.multipliers_coarse)
    assert new_state.status == old_state.status
    assert new_state.error_estimate == pytest.approx(old_state.error_estimate, rel=1e-9)


@pytest.mark.parametrize("stiffness_spread", [1e4, 1e6])
@pytest.mark.parametrize("scheme", ["trapezoidal", "damped"])
def test_every_solver_is_as_accurate_as_a_backward_stable_solve_on_stiff_systems(stiffness_spread, scheme):
    """Unresolved stiff modes (step rates 20-200) make the effective matrices S ill-conditioned, and the
    paths then differ by more than 1e-12.  Each solver, the inverse's product included, must stay
    within the rounding bound N cond(S) eps (times 10) of a march by numpy's backward-stable solve
    (LAPACK dgesv at every step) on the monodromy's 2n+1 columns."""
    n, n_steps = 24, 16
    system = random_periodic_system(n, n_steps, stiffness_spread=stiffness_spread)
    beta, gamma, h = periodic.SCHEMES[scheme].beta, periodic.SCHEMES[scheme].gamma, system.step
    x0, v0 = np.zeros((n, 2 * n + 1)), np.zeros((n, 2 * n + 1))
    x0[:, :n], v0[:, n : 2 * n] = np.eye(n), np.eye(n)
    forced = np.zeros(2 * n + 1)
    forced[-1] = 1.0
    twin = newmark_numpy(system.M, system.C, system.K, system.f, h, beta, gamma, forced, x0, v0)
    reference = np.vstack((twin[0][-1], twin[1][-1]))
    condition = np.linalg.cond(system.M + gamma * h * system.C + beta * h * h * system.K).max()
    bound = 10.0 * n_steps * condition * np.finfo(float).eps
    assert condition > 100.0  # the case is ill-conditioned, as meant
    empty = np.empty((0, n, 2 * n + 1))
    for solver in (_newmark.SOLVE_LOOPS, _newmark.SOLVE_LAPACK, _newmark.SOLVE_INVERSE):
        x, v = x0.copy(), v0.copy()
        status = _newmark.march(system.M, system.C, system.K, system.f, h, beta, gamma, forced, x, v,
                                np.empty_like(x), empty, empty, empty, solver)
        assert status == -1
        error = np.abs(np.vstack((x, v)) - reference).max() / np.abs(reference).max()
        assert error <= bound, solver


def test_solver_choice_by_size_density_and_columns():
    """Hand-written LU below the crossover and for sparse matrices; above it the inverse for the
    monodromy's many columns and dgetrs for the forced run's one; a path can be forced."""
    small, large = _newmark.LAPACK_FROM_N_DOF - 1, _newmark.LAPACK_FROM_N_DOF
    assert _newmark.choose_solver(small, 2 * small + 1) == _newmark.SOLVE_LOOPS
    assert _newmark.choose_solver(small, 1) == _newmark.SOLVE_LOOPS
    assert _newmark.choose_solver(large, 2 * large + 1) == _newmark.SOLVE_INVERSE
    assert _newmark.choose_solver(large, 1) == _newmark.SOLVE_LAPACK
    assert _newmark.choose_solver(10 * large, 1, density=0.1) == _newmark.SOLVE_LOOPS
    banded = np.zeros((3, 30, 30))
    banded[:, np.arange(30), np.arange(30)] = 1.0
    assert _newmark.nonzero_fraction(banded, 0.0 * banded, banded) == pytest.approx(1.0 / 30.0)
    with kernel_path("lapack"):
        assert _newmark.choose_solver(2, 5) == _newmark.SOLVE_INVERSE
    with kernel_path("loops"):
        assert _newmark.choose_solver(500, 1001) == _newmark.SOLVE_LOOPS
