"""linearize on real mechanisms: each result against an independent reference (an equivalent
formulation, a closed form, direct evaluation of the nonlinear equations, or the theory's scaling)."""

import math

import numpy as np
import pytest

import linearize
import mechanisms as mc
import periodic
from linearize import LinearizationError
from tests._support.columns import euler_column


@pytest.fixture(scope="module")
def four_bar():
    return mc.four_bar(discretisation="fem", n_elements=4)


def _dominant(multipliers, floor=1e-6):
    """Multipliers above round-off, sorted by modulus then angle (conjugate pairs are adjacent)."""
    mu = np.asarray(multipliers)
    mu = mu[np.abs(mu) > floor]
    return mu[np.lexsort((np.angle(mu), np.round(np.abs(mu), 10)))]


def test_reversed_coupler_is_an_equivalent_formulation(four_bar):
    """The same four-bar with the coupler's floating frame attached at B instead of A (other
    redundant and elastic coordinates, same physics) must linearise to an equivalent periodic
    system: the two are related by a constant change of elastic coordinates, which Newmark
    shooting preserves, so the multipliers and the midspan response agree to round-off."""
    joints = {j.name: j for j in four_bar.joints}
    reversed_frame = four_bar.replace(
        joints=(joints["O"], mc.Revolute("A", "crank", "end", "coupler", "end"),
                mc.Revolute("B", "coupler", "start", "rocker", "end"), joints["C"]),
        initial_angles={**four_bar.initial_angles,
                        "coupler": four_bar.initial_angles["coupler"] + math.pi})
    results = []
    for mechanism in (four_bar, reversed_frame):
        lin = linearize.about(mechanism, n_steps=128)
        steady = periodic.steady_state(lin.system)
        results.append((_dominant(steady.multipliers), lin.observe(steady.x)))
    (mu_a, y_a), (mu_b, y_b) = results
    assert mu_a.shape == mu_b.shape and mu_a.size >= 2
    # Eigenvalues of similar 24x24 monodromies: round-off times their condition (~1e3 here).
    np.testing.assert_allclose(mu_b, mu_a, rtol=1e-9)
    deflection_a, deflection_b = y_a["coupler.deflection@0.5"], y_b["coupler.deflection@0.5"]
    # The reversed frame's +y side is the original's -y side.
    np.testing.assert_allclose(deflection_b, -deflection_a,
                               atol=1e-9 * np.abs(deflection_a).max())


def test_speed_family_equals_direct_linearisation_at_every_speed():
    mechanism = mc.four_bar(discretisation="fem", n_elements=2, gravity=(0.0, -9.81))
    family = linearize.speed_family(mechanism, n_steps=64)
    for rate in (37.0, 100.0, 161.0):
        direct = linearize.about(mechanism.with_parameter("drive.rate", rate), n_steps=64).system
        fast = family.at_speed(rate).system
        assert fast.period == pytest.approx(direct.period, rel=1e-15)
        for name in ("M", "C", "K", "f"):
            a, b = getattr(fast, name), getattr(direct, name)
            # Round-off of the three-speed quadratic fit, amplified at most by (rate/100)^2 ~ 3.
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-11 * np.abs(b).max(), err_msg=name)


@pytest.mark.parametrize("load_ratio", [0.0, 0.3, 0.75, 0.96])
def test_geometric_stiffness_lowers_bending_frequency_as_euler_predicts(load_ratio):
    """With the exact first buckling mode sin(pi x / L) as a Ritz shape, the frequency under an end
    load P is omega_1 sqrt(1 - P / P_E) exactly. The column's own weight adds a compression
    mu g (L - x) whose work on that mode equals an end load of mu g L / 2, so the closed form is
    omega_1 sqrt(1 - (P + mu g L / 2) / P_E)."""
    mechanism, column = euler_column(load_ratio, mc.Ritz(n_bending=1, n_axial=1))
    lin = linearize.about(mechanism, n_steps=4)
    assert lin.labels == ("column.b1", "column.a1")
    M, K = lin.system.M[0], lin.system.K[0]
    bending = math.sqrt(K[0, 0] / M[0, 0])  # b1 decouples from a1 on a vertical static column
    assert abs(K[0, 1]) < 1e-12 * K[0, 0]
    euler_load = math.pi**2 * column.youngs_modulus * column.second_moment / column.length**2
    g = -mechanism.gravity[1]
    end_load = load_ratio * euler_load + column.mass * g / 2
    assert bending / column.first_bending_frequency() == pytest.approx(
        math.sqrt(1.0 - end_load / euler_load), rel=1e-10)


def test_bending_frequency_vanishes_at_the_euler_load_with_finite_elements():
    """Hermite elements approximate the buckling mode, so P_E is matched only as the mesh is
    refined: the lowest bending eigenvalue at P = P_E (relative to the unloaded one) must fall
    towards zero at the elements' order (h^4 for the cubic Hermite buckling load)."""
    ratios = []
    for n_elements in (2, 4, 8):
        mechanism, _ = euler_column(1.0, mc.Fem(n_elements))
        unloaded, _ = euler_column(0.0, mc.Fem(n_elements))
        lin, lin0 = linearize.about(mechanism, n_steps=4), linearize.about(unloaded, n_steps=4)
        bend = [i for i, label in enumerate(lin.labels) if not label.startswith("column.u")]
        import scipy.linalg
        lowest = scipy.linalg.eigh(lin.system.K[0][np.ix_(bend, bend)],
                                   lin.system.M[0][np.ix_(bend, bend)], eigvals_only=True)[0]
        lowest0 = scipy.linalg.eigh(lin0.system.K[0][np.ix_(bend, bend)],
                                    lin0.system.M[0][np.ix_(bend, bend)], eigvals_only=True)[0]
        ratios.append(lowest / lowest0)
    ratios = np.abs(ratios)
    orders = np.log2(ratios[:-1] / ratios[1:])
    assert ratios[-1] < 1e-3
    assert np.all(orders > 3.5), orders


def test_rigid_limit_response_falls_as_one_over_stiffness():
    """As the coupler's modulus grows, its elastic response tends to the quasi-static one, which is
    proportional to 1/EI: peak deflection times E converges (the dynamic correction falls as
    (Omega / omega_1)^2 ~ 1/E)."""
    products = []
    for factor in (10.0, 100.0, 1000.0):
        mechanism = mc.four_bar(discretisation="fem", n_elements=2, youngs_modulus=2.0e11 * factor)
        lin = linearize.about(mechanism, n_steps=128)
        y = lin.observe(periodic.steady_state(lin.system).x)["coupler.deflection@0.5"]
        products.append(np.abs(y).max() * mechanism.link("coupler").youngs_modulus)
    products = np.array(products)
    changes = np.abs(np.diff(products)) / products[1:]
    # Each tenfold stiffening shrinks the dynamic correction about tenfold.
    assert changes[1] < 0.2 * changes[0]
    assert changes[1] < 0.01


@pytest.mark.parametrize("stiffening", [False, True])
def test_perturbed_nonlinear_residual_departs_from_the_linear_prediction_at_second_order(
        stiffening):
    """R(s0 + eps x, ...) projected on V^T equals -f + eps (M z'' + C z' + K z) + O(eps^2), with
    x = V z and its exact rates. The geometric stiffness is a modelling addition, not part of the
    model's own linearisation, so it is left out here."""
    mechanism = mc.four_bar(discretisation="fem", n_elements=2, geometric_stiffening=stiffening)
    nominal = mc.nominal_motion(mechanism, n_steps=32)
    model = nominal.model
    independent = np.asarray(model.elastic_index)
    lin = linearize.linear_coefficients(model, nominal.t, nominal.s, nominal.sdot, nominal.sddot,
                                        nominal.lam, period=nominal.period,
                                        independent=independent)
    rng = np.random.default_rng(7)
    k = 11
    m = independent.size
    z, zd, zdd = (rng.standard_normal(m) * scale for scale in (1e-3, 1e-1, 1e1))
    V, Vd, Vdd = lin.V[k], lin.Vdot[k], lin.Vddot[k]
    x, xd, xdd = V @ z, V @ zd + Vd @ z, V @ zdd + 2 * Vd @ zd + Vdd @ z
    s0, sd0, sdd0, lam0, t = (nominal.s[k], nominal.sdot[k], nominal.sddot[k], nominal.lam[k],
                              nominal.t[k])

    def residual(s, sd, sdd):
        return (model.mass_matrix(s) @ sdd - model.forces(s, sd, t)
                + model.constraint_jacobian(s, t).T @ lam0)

    predicted = lin.M[k] @ zdd + lin.C[k] @ zd + lin.K[k] @ z
    eps = np.array([1e-1, 3e-2, 1e-2, 3e-3])
    errors = []
    for e in eps:
        r = V.T @ residual(s0 + e * x, sd0 + e * xd, sdd0 + e * xdd)
        errors.append(np.abs(r + lin.f[k] - e * predicted).max())
    slopes = np.diff(np.log(errors)) / np.diff(np.log(eps))
    assert np.all((slopes > 1.9) & (slopes < 2.1)), slopes


def test_full_state_at_zero_deviation_is_the_nominal_motion(four_bar):
    lin = linearize.about(four_bar, n_steps=16)
    zero = np.zeros(lin.system.f.shape)
    s, sdot = lin.full_state(zero, zero)
    np.testing.assert_array_equal(s, lin.nominal.s)
    np.testing.assert_array_equal(sdot, lin.nominal.sdot)
    assert set(lin.observe(zero)) == {"coupler.deflection@0.5"}


def test_bad_input_is_named(four_bar):
    with pytest.raises(TypeError, match="mechanism must be a mechanisms.Mechanism"):
        linearize.about("four_bar", n_steps=16)
    family = linearize.speed_family(mc.four_bar(discretisation="fem", n_elements=1), n_steps=16)
    with pytest.raises(ValueError, match="same sign"):
        family.at_speed(-50.0)
    lin = linearize.about(four_bar, n_steps=16)
    with pytest.raises(ValueError, match="z must have shape"):
        lin.observe(np.zeros((3, 3)))
    torque_driven = four_bar.replace(drives=(mc.TorqueDrive("O", rate=100.0, kp=10.0, kd=1.0),))
    with pytest.raises(LinearizationError, match="PrescribedDrive"):
        linearize.speed_family(torque_driven, n_steps=16)


@pytest.mark.parametrize("scene", ["four_bar_fem4", "six_bar", "slider_crank", "two_link_arm"])
def test_spectrally_interpolated_nominal_motion_equals_the_direct_one(scene):
    """about() computes the nominal motion on a coarse grid and interpolates it when the coarse
    samples resolve it to round-off; it must then equal the direct computation on the fine grid."""
    from linearize._about import _nominal_motion  # about()'s interpolated motion: no public face

    mechanism = mc.load(scene)
    fast, direct = _nominal_motion(mechanism, 512), mc.nominal_motion(mechanism, n_steps=512)
    for name in ("s", "sdot", "sddot", "lam", "drive_torque"):
        a, b = getattr(fast, name), getattr(direct, name)
        # Newton's and the interpolation's round-off, amplified by the conditioning (~10).
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max(), err_msg=name)
    assert fast.constraint_residual < 1e-12


def test_coefficients_from_coarse_samples_equal_those_evaluated_everywhere(four_bar):
    from linearize._about import _coefficients  # about()'s sampled coefficients: no public face

    lin = linearize.about(four_bar, n_steps=512)
    assert lin.coefficients.stride > 1 and lin.coefficients.interpolation_error < 1e-12
    nominal = lin.nominal
    everywhere = _coefficients(nominal.model, nominal.t, nominal.s, nominal.sdot, nominal.sddot,
                               nominal.lam, period=nominal.period,
                               independent=lin.coefficients.independent, label=str, stride=1)
    for name in ("M", "C", "K", "f"):
        a, b = getattr(lin.system, name), getattr(everywhere, name)
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max(), err_msg=name)


@pytest.mark.parametrize("scene", ["four_bar_fem4", "two_link_arm"])
def test_start_state_is_consistent_and_departs_from_the_linear_state_at_second_order(scene):
    """start_state meets the nonlinear position and velocity constraints to round-off and differs
    from the first-order full_state by O(|z|^2) (the axial shortening and the constraint
    curvature): halving z quarters the difference."""
    lin = linearize.about(mc.load(scene), n_steps=128)
    model = lin.nominal.model
    rng = np.random.default_rng(2)
    m = len(lin.labels)
    z_unit, zdot_unit = rng.standard_normal(m) * 1e-4, rng.standard_normal(m) * 1e-2
    differences = []
    for scale in (1.0, 0.5, 0.25):
        z, zdot = scale * z_unit, scale * zdot_unit
        s, sdot = lin.start_state(z, zdot)
        assert np.abs(model.constraints(s, 0.0)).max() < 1e-13
        assert np.abs(model.constraint_jacobian(s, 0.0) @ sdot
                      + model.constraint_rate(s, 0.0)).max() < 1e-11 * np.abs(sdot).max()
        grid = np.zeros((lin.system.n_steps + 1, m))
        grid_dot = grid.copy()
        grid[0], grid_dot[0] = z, zdot
        first_order = lin.full_state(grid, grid_dot)[0][0]
        differences.append(np.abs(s - first_order).max())
    ratios = np.array(differences[:-1]) / np.array(differences[1:])
    assert np.all((ratios > 3.6) & (ratios < 4.4)), ratios


def test_geometric_stiffness_refuses_a_joint_whose_load_it_does_not_know(four_bar):
    """The axial force of a stiffened link needs each joint's load on it: a joint that does not act
    at one point of the link (``JointRows.point_force`` false) raises instead of being treated as
    a point load, and a new kind that does act at one point needs nothing new (same stiffness)."""
    import dataclasses

    model = mc.assemble(four_bar)

    class NewJointKind:
        def __init__(self, model, point_force):
            self._model, self._point_force = model, point_force

        def __getattr__(self, name):
            return getattr(self._model, name)

        def joint_rows(self, name):
            rows = self._model.joint_rows(name)
            return (dataclasses.replace(rows, kind="cam", point_force=self._point_force)
                    if name == "B" else rows)

    nominal = mc.nominal_motion(four_bar, n_steps=16)
    args = (nominal.t, nominal.s, nominal.sdot, nominal.sddot, nominal.lam)
    stiffness = linearize.geometric_stiffness(model, *args)
    assert np.abs(stiffness).max() > 0
    np.testing.assert_array_equal(linearize.geometric_stiffness(NewJointKind(model, True), *args),
                                  stiffness)
    with pytest.raises(LinearizationError, match=r"joint 'B' \(kind 'cam'\), which does not act"):
        linearize.geometric_stiffness(NewJointKind(model, False), *args)

    class GroundJointNotAPointForce(NewJointKind):
        def joint_rows(self, name):  # the crank's ground pin O touches no stiffened link
            rows = self._model.joint_rows(name)
            return dataclasses.replace(rows, kind="cam", point_force=False) if name == "O" else rows

    np.testing.assert_array_equal(
        linearize.geometric_stiffness(GroundJointNotAPointForce(model, True), *args), stiffness)


def test_one_default_observable_rule_for_simulate_and_linearize():
    arm, four_bar = mc.load("two_link_arm"), mc.load("four_bar_fem4")
    assert mc.default_observables(arm) == ("upper.transverse@1.0", "forearm.transverse@1.0")
    assert mc.default_observables(four_bar) == ("coupler.deflection@0.5",)
    assert linearize.default_observables(arm) == mc.default_observables(arm)
    run = mc.simulate(arm, n_periods=0.02, steps_per_period=200, estimate_error=False)
    assert tuple(run.observables) == mc.default_observables(arm)
    assert linearize.about(arm, n_steps=64).observables == mc.default_observables(arm)


def test_error_classes_say_whose_fault_it_is():
    """Bad input (the scene, the arguments) raises ValueError subclasses; a numerical failure on a
    valid mechanism raises RuntimeError subclasses (the studies CLI maps them to exit 2 and 1)."""
    for bad_input in (mc.MechanismError, LinearizationError):
        assert issubclass(bad_input, ValueError) and not issubclass(bad_input, RuntimeError)
    for failure in (mc.ConvergenceError, mc.SimulationError):
        assert issubclass(failure, RuntimeError) and not issubclass(failure, ValueError)
    assert issubclass(mc.SimulationError, mc.ConvergenceError)
    lin = linearize.about(mc.load("four_bar_fem4"), n_steps=64)
    m = len(lin.labels)
    with pytest.raises(mc.ConvergenceError, match="no consistent state near the linear one"):
        lin.start_state(np.full(m, 1.0), np.zeros(m))     # 1 m deflections of a 0.28 m coupler
