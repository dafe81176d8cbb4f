"""Joint forces, drive torques, fibre stresses and point errors of a linearised mechanism, each
against something independent of the code that computes it: a hand-written Newton-Euler solution
of the rigid four-bar (nominal forces, torque and axial force), central differences of the
nonlinear model's multipliers (their linearised change), ``N/A -+ M c/I`` from the model's own
strain and moment observables, and the model's point positions."""

import dataclasses
import math

import numpy as np
import pytest

import linearize
import mechanisms as mc
import periodic

FORCES = ("joint.O.fx", "joint.O.fy", "joint.A.fx", "joint.A.fy", "joint.B.fx", "joint.B.fy",
          "joint.C.fx", "joint.C.fy", "drive.O.torque")
N_STEPS = 64
WIDTH, THICKNESS, DENSITY = 0.02, 0.0016, 7800.0


@pytest.fixture(scope="module")
def four_bar():
    """The thesis four-bar with an elastic coupler without axial coordinates (its axial force is
    then the rigid inverse dynamics'), linearised with the force, stress and point observables."""
    mechanism = mc.four_bar(discretisation="fem", n_elements=2, axial=False,
                            geometric_stiffening=False)
    specs = FORCES + ("joint.B.force", "coupler.stress_top@0.5", "coupler.stress_bottom@0.5",
                      "coupler.moment@0.5", "coupler.point_error_x@0.5",
                      "coupler.point_error_y@0.5", "coupler.point_error@0.5",
                      "rocker.point_error_x@end", "coupler.point_error_x@1.0")
    return linearize.about(mechanism, n_steps=N_STEPS, observables=specs)


def _link_angles(lin, name):
    labels = list(lin.nominal.model.coord_labels)
    return lin.nominal.s[:, labels.index(f"{name}.theta")]


def _newton_euler(lin):
    """Pin forces (on link_b from link_a, N) and the crank torque (N m) of the rigid four-bar at
    every sample, by hand: velocity and acceleration loop closure for the rates, then F = m a and
    the moment equation of each uniform bar (mass rho b h L, inertia m L^2 / 12 about its centre)."""
    mechanism = lin.mechanism
    links = {link.name: link for link in mechanism.links}
    l1, l2, l3 = (links[n].length for n in ("crank", "coupler", "rocker"))
    m1, m2, m3 = (DENSITY * WIDTH * THICKNESS * length for length in (l1, l2, l3))
    i1, i2, i3 = (m * length**2 / 12.0 for m, length in ((m1, l1), (m2, l2), (m3, l3)))
    w1 = mechanism.drives[0].rate
    out = {spec: [] for spec in FORCES}
    axial = []
    for k in range(len(lin.nominal.t)):
        t1, t2, t3 = (_link_angles(lin, n)[k] for n in ("crank", "coupler", "rocker"))
        e1, e2, e3 = (np.array([math.cos(a), math.sin(a)]) for a in (t1, t2, t3))
        p1, p2, p3 = (np.array([-e[1], e[0]]) for e in (e1, e2, e3))
        # O + l1 e1 + l2 e2 = C + l3 e3: rates and accelerations of coupler and rocker
        jac = np.column_stack([l2 * p2, -l3 * p3])
        w2, w3 = np.linalg.solve(jac, -l1 * w1 * p1)
        rhs = l1 * w1**2 * e1 + l2 * w2**2 * e2 - l3 * w3**2 * e3
        a2, a3 = np.linalg.solve(jac, rhs)
        r_a = l1 * e1
        acc_a = -l1 * w1**2 * e1
        g1 = 0.5 * r_a
        acc1 = 0.5 * acc_a
        g2 = r_a + 0.5 * l2 * e2
        acc2 = acc_a + 0.5 * l2 * (a2 * p2 - w2**2 * e2)
        r_c = np.array([mechanism.joints[3].point_a[0], mechanism.joints[3].point_a[1]])
        g3 = r_c + 0.5 * l3 * e3
        acc3 = 0.5 * l3 * (a3 * p3 - w3**2 * e3)
        r_b = r_c + l3 * e3

        # unknowns: F_O, F_A, F_B, F_C (on link_b from link_a) and the torque tau on the crank
        rows, rhs = [], []

        def force_rows(coefficients, target):
            for axis in (0, 1):
                row = np.zeros(9)
                for slot, sign in coefficients:
                    row[2 * slot + axis] = sign
                rows.append(row)
                rhs.append(target[axis])

        force_rows([(0, 1.0), (1, -1.0)], m1 * acc1)      # crank: F_O - F_A
        force_rows([(1, 1.0), (2, -1.0)], m2 * acc2)      # coupler: F_A - F_B
        force_rows([(2, 1.0), (3, 1.0)], m3 * acc3)       # rocker: F_B + F_C
        for inertia, alpha, centre, loads, torque in (
                (i1, 0.0, g1, [(0, np.zeros(2), 1.0), (1, r_a, -1.0)], 1.0),
                (i2, a2, g2, [(1, r_a, 1.0), (2, r_b, -1.0)], 0.0),
                (i3, a3, g3, [(2, r_b, 1.0), (3, r_c, 1.0)], 0.0)):
            row = np.zeros(9)
            for slot, point, sign in loads:
                lever = point - centre
                row[2 * slot] += sign * -lever[1]        # lever x F = lx Fy - ly Fx
                row[2 * slot + 1] += sign * lever[0]
            row[8] = torque
            rows.append(row)
            rhs.append(inertia * alpha)
        solution = np.linalg.solve(np.array(rows), np.array(rhs))
        for j, joint in enumerate("OABC"):
            out[f"joint.{joint}.fx"].append(solution[2 * j])
            out[f"joint.{joint}.fy"].append(solution[2 * j + 1])
        out["drive.O.torque"].append(solution[8])
        # axial force at midspan of the coupler: the axial part of every force on its outer half
        # (the pin force -F_B and the inertia of the half, -int mu a), tension positive
        mu = m2 / l2
        half_inertia = mu * 0.5 * l2 * (acc_a + 0.75 * l2 * (a2 * p2 - w2**2 * e2))
        axial.append(e2 @ (-solution[4:6] - half_inertia))
    return {spec: np.array(v) for spec, v in out.items()}, np.array(axial)


def test_nominal_joint_forces_and_torque_match_newton_euler(four_bar):
    reference, _ = _newton_euler(four_bar)
    for spec in FORCES:
        nominal = four_bar.observable_maps[spec].nominal
        scale = np.abs(reference[spec]).max()
        np.testing.assert_allclose(nominal, reference[spec], atol=1e-9 * scale, err_msg=spec)


def test_nominal_axial_stress_of_an_axially_rigid_link_matches_newton_euler(four_bar):
    """Without axial coordinates N is the rigid inverse dynamics' axial force: at midspan the
    axial part of the pin force at B and of the outer half's inertia."""
    _, axial = _newton_euler(four_bar)
    area = WIDTH * THICKNESS
    for spec in ("coupler.stress_top@0.5", "coupler.stress_bottom@0.5"):
        np.testing.assert_allclose(four_bar.observable_maps[spec].nominal, axial / area,
                                   atol=1e-9 * np.abs(axial / area).max())


def _multipliers_from_equations(model, t, s, sdot, sddot, dependent):
    """The multipliers solved from the dependent rows of the nonlinear equations of motion,
    ``Phi_d^T lam = [Q - M s'']_d``."""
    residual = model.forces(s, sdot, t) - model.mass_matrix(s) @ sddot
    jacobian = model.constraint_jacobian(s, t)
    return np.linalg.solve(jacobian[:, dependent].T, residual[dependent])


def test_multiplier_change_matches_central_differences_of_the_nonlinear_model(four_bar):
    """``mu = A_x z + A_v z' + A_a z''`` against d/d(eps) of the multipliers of the full equations
    at ``s0 + eps x`` (x, x', x'' from z, z', z'' through V, V', V'') at several samples."""
    lin = four_bar
    model = lin.nominal.model
    c = lin.coefficients
    dependent = np.setdiff1d(np.arange(model.n_coords), c.independent)
    rng = np.random.default_rng(3)
    m = len(lin.labels)
    for k in (0, 13, 40):
        z, zdot, zddot = rng.normal(size=(3, m)) * np.array([[1e-3], [1e-1], [1e1]])
        x = c.V[k] @ z
        xdot = c.V[k] @ zdot + c.Vdot[k] @ z
        xddot = c.V[k] @ zddot + 2.0 * c.Vdot[k] @ zdot + c.Vddot[k] @ z
        t = lin.nominal.t[k]

        def lam(eps):
            return _multipliers_from_equations(
                model, t, lin.nominal.s[k] + eps * x, lin.nominal.sdot[k] + eps * xdot,
                lin.nominal.sddot[k] + eps * xddot, dependent)

        np.testing.assert_allclose(lam(0.0), lin.nominal.lam[k],
                                   atol=1e-9 * np.abs(lin.nominal.lam[k]).max())
        eps = 1e-4
        difference = (lam(eps) - lam(-eps)) / (2 * eps)
        a_x, a_v, a_a = (a[k] for a in c.multiplier_maps)
        predicted = a_x @ z + a_v @ zdot + a_a @ zddot
        np.testing.assert_allclose(predicted, difference, atol=1e-6 * np.abs(difference).max())


def test_force_observables_are_nominal_plus_weighted_multiplier_change(four_bar):
    """joint.<J>.fx/fy is lam of the joint's rows (force on link_b); drive.<J>.torque is -lam of
    the drive row; joint.<J>.force is the magnitude of (fx, fy) along the response."""
    lin = four_bar
    steady = periodic.steady_state(lin.system)
    observed = lin.observe(steady.x, steady.v, steady.a)
    labels = list(lin.nominal.model.constraint_labels)
    mu = sum(np.einsum("kri,ki->kr", a, v) for a, v in
             zip(lin.coefficients.multiplier_maps, (steady.x, steady.v, steady.a)))
    lam = lin.nominal.lam + mu
    np.testing.assert_allclose(observed["joint.B.fx"], lam[:, labels.index("B.x")], rtol=1e-12)
    np.testing.assert_allclose(observed["joint.B.fy"], lam[:, labels.index("B.y")], rtol=1e-12)
    np.testing.assert_allclose(observed["drive.O.torque"], -lam[:, labels.index("drive:O")],
                               rtol=1e-12)
    np.testing.assert_allclose(observed["joint.B.force"],
                               np.hypot(observed["joint.B.fx"], observed["joint.B.fy"]))
    # without rates given, observe differentiates the periodic z spectrally: the same to O(h^2)
    spectral = lin.observe(steady.x)["joint.B.fx"]
    assert np.abs(spectral - observed["joint.B.fx"]).max() < 0.05 * np.ptp(observed["joint.B.fx"])


def test_stress_is_axial_over_area_minus_moment_times_fibre_over_inertia(four_bar):
    lin = four_bar
    steady = periodic.steady_state(lin.system)
    observed = lin.observe(steady.x)
    coupler = next(link for link in lin.mechanism.links if link.name == "coupler")
    c = THICKNESS / 2
    assert coupler.fibre_distance == pytest.approx(c)
    axial = lin.observable_maps["coupler.stress_top@0.5"].nominal * coupler.area
    moment = observed["coupler.moment@0.5"]
    inertia = WIDTH * THICKNESS**3 / 12
    np.testing.assert_allclose(observed["coupler.stress_top@0.5"],
                               axial / coupler.area - moment * c / inertia, rtol=1e-10)
    np.testing.assert_allclose(observed["coupler.stress_bottom@0.5"],
                               axial / coupler.area + moment * c / inertia, rtol=1e-10)


def test_stress_of_a_link_with_axial_coordinates_uses_its_strain():
    """With axial coordinates N = EA eps (their response carries the axial load); the stress is
    E eps -+ M c / I by hand from the strain and moment observables, and the outer_fibre key
    replaces h / 2."""
    base = mc.four_bar(discretisation="fem", n_elements=2)
    coupler = next(link for link in base.links if link.name == "coupler")
    fibre = 0.9 * coupler.section_height / 2
    mechanism = base.replace(links=tuple(dataclasses.replace(link, outer_fibre=fibre)
                                         if link.name == "coupler" else link
                                         for link in base.links))
    specs = ("coupler.stress_top@0.25", "coupler.strain@0.25", "coupler.moment@0.25")
    lin = linearize.about(mechanism, n_steps=N_STEPS, observables=specs)
    observed = lin.observe(periodic.steady_state(lin.system).x)
    e = coupler.youngs_modulus
    expected = (e * observed["coupler.strain@0.25"]
                - observed["coupler.moment@0.25"] * fibre / coupler.second_moment)
    np.testing.assert_allclose(observed["coupler.stress_top@0.25"], expected,
                               atol=1e-10 * np.abs(expected).max())
    assert lin.observable_maps["coupler.stress_top@0.25"].nominal is None


def test_point_error_is_the_change_of_the_models_point_position(four_bar):
    """The linear map of a point's position against central differences of the model's own
    positions along x = V z; pins: the end of the coupler is the end of the rocker."""
    lin = four_bar
    model = lin.nominal.model
    rng = np.random.default_rng(5)
    z = rng.normal(size=len(lin.labels)) * 1e-3
    for k in (0, 21):
        x = lin.coefficients.V[k] @ z
        for spec in ("coupler.point_error_x@0.5", "coupler.point_error_y@0.5",
                     "rocker.point_error_x@end"):
            observable = model.observable(spec)
            eps = 1e-3
            difference = (observable.value(lin.nominal.s[k] + eps * x)
                          - observable.value(lin.nominal.s[k] - eps * x)) / (2 * eps)
            predicted = lin.observable_maps[spec].position[k] @ z
            assert predicted == pytest.approx(difference, rel=1e-6, abs=1e-15)
    # the pin at B: both links' points move together (to first order), and their rigid nominal
    # positions coincide
    history = np.tile(z, (N_STEPS + 1, 1))
    observed = lin.observe(history)
    np.testing.assert_allclose(observed["rocker.point_error_x@end"],
                               observed["coupler.point_error_x@1.0"], atol=1e-12)
    s0 = lin.nominal.s[7]
    assert (model.observable("rocker.point_error_x@end").value(s0)
            == pytest.approx(model.observable("coupler.point_error_x@1.0").value(s0), abs=1e-12))
    np.testing.assert_allclose(observed["coupler.point_error@0.5"],
                               np.hypot(observed["coupler.point_error_x@0.5"],
                                        observed["coupler.point_error_y@0.5"]))


def test_speed_family_maps_equal_direct_linearisation():
    """A speed family's force, torque and stress maps (quadratic in the speed) against a direct
    linearisation at other speeds, with gravity (a static part)."""
    mechanism = mc.four_bar(discretisation="fem", n_elements=2, axial=False,
                            geometric_stiffening=False, gravity=(0.0, -9.81))
    specs = ("joint.A.fy", "drive.O.torque", "coupler.stress_top@0.5", "coupler.deflection@0.5")
    family = linearize.speed_family(mechanism, n_steps=N_STEPS, observables=specs)
    for rate in (41.0, 170.0):
        direct = linearize.about(mechanism.with_parameter("drive.rate", rate), n_steps=N_STEPS,
                                 observables=specs).observable_maps
        fast = family.observable_maps_at(rate)
        for spec in specs:
            for name, array in direct[spec].arrays().items():
                expected = array
                np.testing.assert_allclose(fast[spec].arrays()[name], expected,
                                           atol=1e-9 * np.abs(expected).max(),
                                           err_msg=f"{spec} {name} at {rate}")


def test_bad_specs_name_what_is_wrong():
    model = mc.assemble(mc.four_bar(discretisation="fem", n_elements=2))
    for spec, words in (("joint.Z.fx", "unknown joint 'Z'"), ("joint.A.fz", "'fz'"),
                        ("drive.A.torque", "no drive at joint 'A'"),
                        ("crank.stress_top@0.5", "rigid"),
                        ("coupler.point_error_x@tip", "no point 'tip'"),
                        ("joint.A.fx@0.5", "takes no '@'")):
        with pytest.raises(mc.ArgumentError, match=words):
            model.observable(spec)


def test_torque_drive_torque_is_the_inverse_dynamics_torque_plus_its_pd_change():
    """A torque drive's nominal torque is the prescribed version's (-lam of its drive row, the
    inverse dynamics); its change is the PD law's: central differences of the model's torque at
    ``s0 + eps x``, ``s0' + eps x'``."""
    arm = mc.load("two_link_arm")
    elbow = next(d for d in arm.drives if d.joint == "elbow")
    torque_driven = arm.replace(drives=tuple(
        mc.TorqueDrive("elbow", elbow.rate, elbow.offset, elbow.harmonics, kp=40.0, kd=0.5)
        if d.joint == "elbow" else d for d in arm.drives))
    specs = ("drive.elbow.torque", "drive.shoulder.torque")
    prescribed = linearize.about(arm, n_steps=N_STEPS, observables=specs)
    driven = linearize.about(torque_driven, n_steps=N_STEPS, observables=specs)
    for spec in specs:
        expected = prescribed.observable_maps[spec].nominal
        np.testing.assert_allclose(driven.observable_maps[spec].nominal, expected,
                                   atol=1e-8 * np.abs(expected).max(), err_msg=spec)
    model = mc.assemble(torque_driven)   # no feedforward: the PD part alone
    index = [d.joint for d in torque_driven.drives].index("elbow")
    c = driven.coefficients
    rng = np.random.default_rng(11)
    m = len(driven.labels)
    torque_map = driven.observable_maps["drive.elbow.torque"]
    for k in (0, 29):
        z, zdot = rng.normal(size=(2, m)) * 1e-3
        x = c.V[k] @ z
        xdot = c.V[k] @ zdot + c.Vdot[k] @ z
        nominal = driven.nominal
        lam = np.zeros(model.n_constraints)

        def torque(eps):
            return model.drive_torques(nominal.s[k] + eps * x, nominal.sdot[k] + eps * xdot,
                                       nominal.t[k], lam)[index]

        difference = (torque(1e-3) - torque(-1e-3)) / 2e-3
        predicted = torque_map.position[k] @ z + torque_map.rate[k] @ zdot
        assert predicted == pytest.approx(difference, rel=1e-7)


def test_slider_force_is_normal_to_its_rail_and_agrees_with_the_nonlinear_model():
    """A slider on the x-axis pushes its link along y only; the crank pin's force and the slider's
    agree with the full nonlinear model's multipliers (a nonlinear check)."""
    import studies

    specs = ("joint.B.fx", "joint.B.fy", "joint.A.force", "drive.O.torque")
    problem = studies.MechanismProblem.from_scene("slider_crank", observables=specs)
    check = studies.nonlinear_check(problem, n_steps=128, n_periods=2)
    assert np.abs(check.linear["joint.B.fx"]).max() < 1e-9 * np.abs(check.linear["joint.B.fy"]).max()
    for spec in specs[1:]:
        assert check.relative_difference[spec] < 0.01, (spec, check.relative_difference[spec])


def test_simulate_refuses_observables_that_are_not_functions_of_the_coordinates():
    """mechanisms.simulate evaluates observables of s alone: a force says where to read it."""
    model = mc.assemble(mc.four_bar(discretisation="fem", n_elements=2, axial=False))
    s = np.zeros(model.n_coords)
    for spec, words in (("joint.A.fx", "value_from"), ("joint.A.force", "magnitude"),
                        ("coupler.stress_top@0.5", "axial_force")):
        with pytest.raises(mc.ArgumentError, match=words):
            model.observable(spec).value(s)
    assert model.observable("coupler.stress_top@0.5").value(s, axial_force=0.0) == 0.0


def test_a_named_point_of_a_plate_is_where_its_pin_is():
    """The six-bar plate's named point C carries joint C: its position is link4's start, and its
    linear displacement is that of link4's start (the pin keeps them together to first order)."""
    specs = ("plate.point_error_x@C", "plate.point_error_y@C", "link4.point_error_x@start",
             "link4.point_error_y@start", "plate.point_error@C")
    lin = linearize.about(mc.load("six_bar"), n_steps=N_STEPS, observables=specs)
    model = lin.nominal.model
    s0 = lin.nominal.s[5]
    for axis in "xy":
        assert (model.observable(f"plate.point_error_{axis}@C").value(s0)
                == pytest.approx(model.observable(f"link4.point_error_{axis}@start").value(s0),
                                 abs=1e-12))
    observed = lin.observe(periodic.steady_state(lin.system).x)
    for axis in "xy":
        plate, link4 = observed[f"plate.point_error_{axis}@C"], observed[f"link4.point_error_{axis}@start"]
        np.testing.assert_allclose(plate, link4, atol=1e-9 * np.abs(plate).max())
    assert np.abs(observed["plate.point_error@C"]).max() > 0.0
