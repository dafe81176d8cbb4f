"""periodic: bad input is rejected with a message naming the argument."""

import dataclasses

import numpy as np
import pytest

import periodic
from periodic import PeriodicError, PeriodicSystem

N, n = 8, 2


def arrays():
    M = np.tile(np.eye(n), (N + 1, 1, 1))
    C = 0.1 * M
    K = np.tile(np.array([[2.0, -1.0], [-1.0, 2.0]]), (N + 1, 1, 1))
    f = np.zeros((N + 1, n))
    return M, C, K, f


def test_valid_arrays_build_a_system():
    system = PeriodicSystem(2.0, *arrays())
    assert (system.n_steps, system.n_dof, system.step) == (N, n, 0.25)
    assert not system.M.flags.writeable


@pytest.mark.parametrize("period", [0.0, -1.0, np.nan, np.inf])
def test_period_must_be_positive_and_finite(period):
    with pytest.raises(ValueError, match="period"):
        PeriodicSystem(period, *arrays())


def test_period_must_be_a_number():
    with pytest.raises(TypeError, match="period"):
        PeriodicSystem("1.0", *arrays())


@pytest.mark.parametrize("index, name", [(0, "mass"), (1, "damping"), (2, "stiffness"), (3, "force")])
def test_wrong_shape_names_the_argument(index, name):
    args = list(arrays())
    args[index] = args[index][:, :1]
    with pytest.raises(ValueError, match=f"^{name}: expected shape"):
        PeriodicSystem(1.0, *args)


@pytest.mark.parametrize("index, name", [(0, "mass"), (1, "damping"), (2, "stiffness"), (3, "force")])
def test_non_finite_names_the_argument(index, name):
    args = list(arrays())
    args[index][3].flat[0] = np.nan
    with pytest.raises(ValueError, match=f"^{name}: expected finite"):
        PeriodicSystem(1.0, *args)


def test_too_few_samples():
    M, C, K, f = arrays()
    with pytest.raises(ValueError, match="n_steps >= 2"):
        PeriodicSystem(1.0, M[:2], C[:2], K[:2], f[:2])


def test_singular_mass_names_the_sample_time():
    M, C, K, f = arrays()
    M[3] = np.array([[1.0, 1.0], [1.0, 1.0]])  # singular at t_3 = 3 * 2 / 8 = 0.75 s
    with pytest.raises(PeriodicError, match=r"mass: .*singular at sample 3 \(t = 0\.75 s"):
        PeriodicSystem(2.0, M, C, K, f)


def test_samples_must_be_periodic():
    M, C, K, f = arrays()
    K[-1] *= 1.1
    with pytest.raises(PeriodicError, match="stiffness: the last sample"):
        PeriodicSystem(1.0, M, C, K, f)


def test_nearly_periodic_samples_warn():
    M, C, K, f = arrays()
    K[-1] *= 1.0 + 1e-8
    with pytest.warns(RuntimeWarning, match="stiffness: samples at t = 0 and t = T differ"):
        PeriodicSystem(1.0, M, C, K, f)


def constant(value):
    return lambda t: value


@pytest.mark.parametrize("n_steps, error", [(1, ValueError), (0, ValueError), (2.0, TypeError), (True, TypeError)])
def test_from_functions_n_steps(n_steps, error):
    with pytest.raises(error, match="n_steps"):
        PeriodicSystem.from_functions(
            1.0, constant(np.eye(n)), constant(np.eye(n)), constant(np.eye(n)), n_steps=n_steps
        )


def test_from_functions_reports_a_raising_callable_and_time():
    def stiffness(t):
        if t > 0.4:
            raise ZeroDivisionError("boom")
        return np.eye(n)

    with pytest.raises(ValueError, match=r"stiffness: the callable raised ZeroDivisionError at t = 0\.5 s"):
        PeriodicSystem.from_functions(1.0, constant(np.eye(n)), constant(np.eye(n)), stiffness, n_steps=4)


def test_from_functions_rejects_non_callables():
    with pytest.raises(TypeError, match="damping: expected a callable"):
        PeriodicSystem.from_functions(1.0, constant(np.eye(n)), np.eye(n), constant(np.eye(n)), n_steps=4)


def test_from_functions_wrong_force_shape():
    with pytest.raises(ValueError, match="force: expected shape"):
        PeriodicSystem.from_functions(
            1.0, constant(np.eye(n)), constant(np.eye(n)), constant(np.eye(n)), constant(np.ones(3)), n_steps=4
        )


def test_steady_state_options():
    system = PeriodicSystem(1.0, *arrays())
    with pytest.raises(TypeError):
        periodic.steady_state(system, n_steps=4)  # unknown option
    with pytest.raises(TypeError, match="system: expected a periodic.PeriodicSystem"):
        periodic.steady_state(arrays())
    with pytest.raises(PeriodicError, match="extrapolate: .*gamma = 1/2"):
        periodic.steady_state(system, extrapolate=True, scheme=periodic.Newmark(beta=0.36, gamma=0.7))
    with pytest.raises(PeriodicError, match="beta, gamma"):
        periodic.floquet(system, scheme=periodic.Newmark(beta=-0.1))
    with pytest.raises(TypeError):
        periodic.floquet(system, beta=0.3)  # the scheme is one object: scheme=periodic.Newmark(...)
    with pytest.raises(PeriodicError, match="resonance_tol"):
        periodic.steady_state(system, resonance_tol=-1.0)
    with pytest.raises(PeriodicError, match=r"stability_tol: expected a tolerance in \[0, 1e-06\]"):
        periodic.floquet(system, stability_tol=1e-3)


def test_scheme_validates_itself():
    with pytest.raises(TypeError, match="beta: expected a real number, got str"):
        periodic.Newmark(beta="0.25")
    with pytest.raises(PeriodicError, match="gamma: expected a finite number, got nan"):
        periodic.Newmark(gamma=np.nan)
    with pytest.warns(RuntimeWarning, match=r"beta=0\.16.*unconditionally stable only for 2 beta >= gamma >= 1/2"):
        scheme = periodic.Newmark(beta=0.16, gamma=0.5)  # linear acceleration-like, conditionally stable
    assert (scheme.order, scheme.error_factor, scheme.symmetric, scheme.unconditionally_stable) == (
        2,
        1 / 3,
        True,
        False,
    )
    damped = periodic.Newmark(beta=0.3025, gamma=0.6)
    assert (damped.order, damped.error_factor, damped.symmetric) == (1, 1.0, False)
    assert damped == periodic.SCHEMES["damped"] and periodic.Newmark() == periodic.SCHEMES["trapezoidal"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        damped.beta = 0.3  # frozen


def test_scheme_by_name_or_object():
    system = PeriodicSystem(1.0, *arrays())
    by_name = periodic.floquet(system, scheme="damped")
    assert by_name.scheme == periodic.Newmark(beta=0.3025, gamma=0.6)
    with pytest.raises(  # registered schemes (tests/_support/extensions.py) may follow the built-in ones
        PeriodicError,
        match=r"scheme: expected a name in periodic.SCHEMES \('trapezoidal', 'damped'.*\) or a periodic.Scheme, "
        r"got 'trapezium'",
    ):
        periodic.steady_state(system, scheme="trapezium")
    with pytest.raises(TypeError, match=r"scheme: expected a periodic.Scheme .*got tuple"):
        periodic.steady_state(system, scheme=(0.25, 0.5))


def test_a_scheme_of_another_family_is_any_object_with_order_error_factor_symmetric_and_march():
    """The shooting asks a scheme only for its order, error factor, symmetry and march: a class that
    is not a Newmark (here one that counts its marches and delegates the step to the trapezoidal
    rule) runs, and gives the trapezoidal result."""
    class CountingTrapezoidal:
        order, error_factor, symmetric = 2, 1.0 / 3.0, True

        def __init__(self):
            self.marches = 0

        def march(self, system, forced, x, v, a, x_hist, v_hist, a_hist):
            self.marches += 1
            return periodic.SCHEMES["trapezoidal"].march(system, forced, x, v, a, x_hist, v_hist, a_hist)

    system = PeriodicSystem(1.0, *arrays())
    scheme = CountingTrapezoidal()
    result = periodic.steady_state(system, scheme=scheme)
    reference = periodic.steady_state(system)
    assert scheme.marches == 6  # N, N/2 and N/4: the 2n+1 columns and the stored periodic run each
    np.testing.assert_array_equal(result.x, reference.x)
    assert result.status == reference.status and result.scheme is scheme

    class NoMarch:
        order, error_factor, symmetric = 2, 1.0 / 3.0, True

    with pytest.raises(TypeError, match="or another object with order, error_factor, symmetric and march"):
        periodic.steady_state(system, scheme=NoMarch())


def test_complex_samples_are_refused():
    M, C, K, f = arrays()
    with pytest.raises(TypeError, match="force: expected real values"):
        PeriodicSystem(1.0, M, C, K, f + 1j)


def test_odd_n_steps_needs_estimate_error_false():
    M, C, K, f = (a[:8] for a in arrays())  # N = 7
    system = PeriodicSystem(1.0, M, C, K, f)
    with pytest.raises(PeriodicError, match="n_steps: .*N/4.*multiple of 4 >= 8, got 7.*estimate_error=False"):
        periodic.steady_state(system)
    result = periodic.steady_state(system, estimate_error=False)
    assert np.isnan(result.error_estimate) and result.multiplier_errors is None
    two_steps = PeriodicSystem(1.0, *(a[:3] for a in arrays()))  # N = 2: no N/2 grid of 2 steps
    with pytest.raises(PeriodicError, match="n_steps: .*multiple of 4 >= 8, got 2.*estimate_error=False"):
        periodic.steady_state(two_steps)
    with pytest.raises(PeriodicError, match="n_steps: .*multiple of 4 >= 8, got 6.*estimate_error=False"):
        periodic.steady_state(PeriodicSystem(1.0, *(a[:7] for a in arrays())))  # even, but N/4 is no grid
    # Richardson alone needs only the N/2 grid; floquet's error estimate checks N/4 like steady_state.
    assert periodic.steady_state(PeriodicSystem(1.0, *(a[:7] for a in arrays())), extrapolate=True,
                                 estimate_error=False).extrapolated
    with pytest.raises(PeriodicError, match="n_steps: .*multiple of 4 >= 8, got 7.*estimate_error=False"):
        periodic.floquet(system, estimate_error=True)
    with pytest.raises(PeriodicError, match="n_steps: .*even n_steps >= 4, got 7.*extrapolate=False"):
        periodic.steady_state(system, extrapolate=True, estimate_error=False)


def test_from_functions_refuses_complex_values():
    with pytest.raises(TypeError, match=r"stiffness: the callable returned a non-real value at t = 0\.25 s"):
        PeriodicSystem.from_functions(
            1.0, constant(np.eye(n)), constant(np.eye(n)), lambda t: np.eye(n) + (1j if t > 0.2 else 0.0), n_steps=4
        )
