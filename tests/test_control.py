"""Drives and controllers (issue 11): DC motor, flywheel, torque limit, PD and observable feedback.

Each numerical test is against something independent of the code it checks: a closed-form motor
speed, finite differences of the nonlinear model, the energy balance of a nonlinear run, the
prescribed-speed model as the limit of stiff feedback, and the nonlinear run as the reference of
the closed-loop linearisation."""

from __future__ import annotations

import math

import numpy as np
import pytest

import linearize
import mechanisms as mc
import periodic


@pytest.fixture(scope="module")
def controlled():
    return mc.load("four_bar_controlled")


# ---------------------------------------------------------------------------------------------------
# Scene keys, parameters, without_feedback
# ---------------------------------------------------------------------------------------------------
def test_controlled_scene_reads_its_drive_and_controllers_and_writes_them_back(controlled):
    drive = controlled.drives[0]
    assert isinstance(drive, mc.TorqueDrive) and drive.torque_limit == 5.0
    assert drive.motor == mc.DCMotor(1.0, 1000.0, 1e-5, 4.0)
    assert drive.inertia == pytest.approx(16e-5)
    assert drive.motor.back_emf_damping == pytest.approx(16 * 1.0 / 1000.0)
    assert [type(c) for c in controlled.controllers] == [mc.PDController, mc.ObservableFeedback]
    assert mc.loads(controlled.to_toml()) == controlled
    # gains and motor constants are scene parameters
    changed = controlled.with_parameters({"controllers.strain.gain": 1.0,
                                          "controllers.crank_pd.kp": 7.0,
                                          "drive.motor.gear_ratio": 2.0})
    assert changed.controllers[1].gain == 1.0 and changed.controllers[0].kp == 7.0
    assert changed.drives[0].motor.gear_ratio == 2.0
    # a mechanism made from parts writes its drive and controllers to a scene too
    from_parts = controlled.replace()
    assert from_parts.spec is None and mc.loads(from_parts.to_toml()) == controlled


def test_motor_from_armature_constants_is_the_linear_characteristic():
    resistance, k_t, voltage = 2.0, 0.05, 24.0
    motor = mc.DCMotor.from_armature(resistance=resistance, torque_constant=k_t,
                                     supply_voltage=voltage, gear_ratio=3.0)
    assert motor.stall_torque == pytest.approx(k_t * voltage / resistance)   # locked rotor: i = V / R
    assert motor.no_load_speed == pytest.approx(voltage / k_t)               # back EMF = V
    spec = {"stall_torque": 1.0}
    with pytest.raises(mc.MechanismError, match="not both"):
        mc.loads(_crank_scene(motor={**spec, "resistance": 1.0}))


def test_without_feedback_keeps_the_feedforward_and_the_motor(controlled):
    open_loop = controlled.without_feedback()
    assert open_loop.controllers == ()
    assert (open_loop.drives[0].kp, open_loop.drives[0].kd) == (0.0, 0.0)
    assert open_loop.drives[0].motor == controlled.drives[0].motor
    assert open_loop.drives[0].torque_limit == controlled.drives[0].torque_limit
    from_parts = controlled.replace(drives=(
        controlled.drives[0].__class__(**{**controlled.drives[0].__dict__, "kp": 3.0}),))
    assert from_parts.without_feedback().drives[0].kp == 0.0
    assert from_parts.without_feedback().controllers == ()


def test_bad_controllers_are_refused_with_the_key_and_the_fix(controlled):
    spec = controlled.to_spec()
    spec["controllers"]["strain"]["joint"] = "C"
    with pytest.raises(mc.MechanismError, match="no torque drive"):
        mc.build(spec)
    spec = controlled.to_spec()
    spec["controllers"]["strain"]["gian"] = 1.0
    with pytest.raises(mc.MechanismError, match="did you mean 'gain'"):
        mc.build(spec)
    spec = controlled.to_spec()
    spec["controllers"]["strain"]["observable"] = "coupler.angle"
    with pytest.raises(mc.MechanismError, match="PD controller"):
        mc.assemble(mc.build(spec))
    spec["controllers"]["strain"]["observable"] = "coupler.nonsense@0.5"
    with pytest.raises(mc.MechanismError, match="controller 'strain'"):
        mc.assemble(mc.build(spec))


# ---------------------------------------------------------------------------------------------------
# A crank alone: closed-form motor and torque-limit responses
# ---------------------------------------------------------------------------------------------------
def _crank_scene(*, motor=None, torque_limit=None, rate=400.0, kd=10.0) -> str:
    """A uniform rigid crank pinned to the ground, torque-driven, no gravity: no load, so the
    feedforward is zero and the motor's command is its back EMF plus the PD on the speed."""
    lines = ['name = "crank"', "[links.crank]", 'type = "rigid"', "length = 0.1", "mass = 0.3",
             "inertia = 2.5e-4", "[joints.O]", 'link_a = "ground"', "point_a = [0.0, 0.0]",
             'link_b = "crank"', 'point_b = "start"', "[drive]", 'type = "torque"', 'joint = "O"',
             f"rate = {rate}", f"kd = {kd}"]
    if torque_limit is not None:
        lines.append(f"torque_limit = {torque_limit}")
    if motor is not None:
        lines.append("[drive.motor]")
        lines += [f"{key} = {value}" for key, value in motor.items()]
    return "\n".join(lines) + "\n"


def _crank_rate_from_rest(mechanism, n_periods, steps_per_period=200):
    nominal = mc.nominal_motion(mechanism, n_steps=16)
    run = mc.simulate(mechanism, n_periods=n_periods, steps_per_period=steps_per_period,
                      s0=nominal.s[0], sdot0=np.zeros_like(nominal.s[0]), estimate_error=False)
    assert run.success, run.message
    h = mc.assemble(mechanism).drive_gradient("O")
    return run, run.sdot @ h


@pytest.mark.slow
def test_dc_motor_at_full_voltage_follows_its_closed_form_speed():
    """Commanded beyond the supply voltage (nominal speed above the no-load speed at the crank),
    the motor gives ``G T_s - c theta'``: from rest ``theta' = (w0 / G) (1 - exp(-c t / J))`` with
    ``J`` the crank's inertia about O plus the reflected rotor ``G^2 J_r``."""
    motor = {"stall_torque": 2.0, "no_load_speed": 600.0, "rotor_inertia": 2e-6, "gear_ratio": 3.0}
    mechanism = mc.loads(_crank_scene(motor=motor, rate=400.0))   # 400 > 600 / 3 rad/s
    gear, stall, w0 = motor["gear_ratio"], motor["stall_torque"], motor["no_load_speed"]
    inertia = 2.5e-4 + 0.3 * 0.05**2 + gear**2 * motor["rotor_inertia"]
    damping = gear**2 * stall / w0
    run, rate = _crank_rate_from_rest(mechanism, n_periods=8)
    exact = w0 / gear * (1.0 - np.exp(-damping * run.t / inertia))
    assert damping * run.t[-1] / inertia > 3.0          # the speed has nearly settled
    np.testing.assert_allclose(rate, exact, rtol=0, atol=2e-6 * w0 / gear)  # measured 1.6e-7
    # the motor's torque is the characteristic at the crank
    torques = np.array([mc.assemble(mechanism).drive_torques(s, v, t)[0]
                        for s, v, t in zip(run.s[::50], run.sdot[::50], run.t[::50])])
    np.testing.assert_allclose(torques, gear * stall - damping * rate[::50], rtol=1e-12, atol=1e-12)


def test_torque_limit_saturates_the_demanded_torque():
    """An ideal source held at its torque limit accelerates the crank uniformly: theta' = L t / J."""
    limit = 0.05
    mechanism = mc.loads(_crank_scene(torque_limit=limit, rate=400.0, kd=10.0))
    inertia = 2.5e-4 + 0.3 * 0.05**2
    run, rate = _crank_rate_from_rest(mechanism, n_periods=0.5)
    assert rate[-1] < 400.0                      # demanded kd (400 - theta') > L throughout
    np.testing.assert_allclose(rate, limit * run.t / inertia, rtol=1e-9, atol=1e-9)


# ---------------------------------------------------------------------------------------------------
# The closed loop's derivatives against finite differences of the nonlinear model
# ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("scene", ["four_bar_controlled", "four_bar_thesis"])
def test_feedback_jacobians_equal_finite_differences_of_the_nonlinear_forces(scene):
    """The strain feedback (nonlinear in s on the stiffened coupler of four_bar_controlled, linear on
    four_bar_thesis's) and its rate, the PD and the motor enter ``force_jacobians`` and
    ``linear_terms_along``: both equal central differences of ``forces``."""
    base = mc.load("four_bar_controlled")
    mechanism = base if scene == "four_bar_controlled" else mc.build({
        **mc.load(scene).to_spec(), "drive": base.to_spec()["drive"],
        "controllers": base.to_spec()["controllers"]})
    nominal = mc.nominal_motion(mechanism, n_steps=64)
    model = mc.assemble(mechanism, feedforward=mc.feedforward_torques(mechanism, nominal))
    rng = np.random.default_rng(1)
    k = 13
    # small deviations (the feedback's rate gain is large): the drive stays below its limits, as
    # checked below, so the derivatives are those of the feedback law
    s = nominal.s[k] + 1e-6 * rng.normal(size=model.n_coords)
    sdot = nominal.sdot[k] + 1e-4 * rng.normal(size=model.n_coords)
    t = float(nominal.t[k])
    saturated, unsaturated = (model.drive_torque_terms("O", [t], s[None], sdot[None],
                                                       saturate=flag)[0] for flag in (True, False))
    assert saturated[0] == pytest.approx(unsaturated[0], rel=1e-14)
    d_s, d_v = model.force_jacobians(s, sdot, t)
    eps = 1e-6
    for analytic, which in ((d_s, 0), (d_v, 1)):
        numeric = np.zeros_like(analytic)
        for j in range(model.n_coords):
            step = np.zeros(model.n_coords)
            step[j] = eps
            args_plus = (s + step, sdot) if which == 0 else (s, sdot + step)
            args_minus = (s - step, sdot) if which == 0 else (s, sdot - step)
            numeric[:, j] = (model.forces(*args_plus, t) - model.forces(*args_minus, t)) / (2 * eps)
        np.testing.assert_allclose(analytic, numeric, rtol=0, atol=1e-6 * np.abs(numeric).max())
    # the feedback makes the closed loop's stiffness unsymmetric: it is there
    h = model.drive_gradient("O")
    feedback = model.drive_torque_terms("O", [t], s[None], sdot[None])[1][0]
    assert np.abs(feedback[model.elastic_index]).max() > 0.0
    assert h @ feedback < 0.0                      # the PD pulls the crank back
    terms = mc.linear_terms_along(model, np.array([t]), s[None], sdot[None],
                                  np.zeros((1, model.n_coords)), np.zeros((1, model.n_constraints)))
    np.testing.assert_allclose(terms.damping[0], -d_v, rtol=0, atol=1e-12 * np.abs(d_v).max())


# ---------------------------------------------------------------------------------------------------
# Stiff feedback: the prescribed-speed limit
# ---------------------------------------------------------------------------------------------------
def _deflection(mechanism):
    lin = linearize.about(mechanism, n_steps=256, observables=["coupler.deflection@0.5"])
    return lin.observe(periodic.steady_state(lin.system, estimate_error=False).x)[
        "coupler.deflection@0.5"]


def test_stiff_crank_feedback_reproduces_the_prescribed_speed_steady_state(controlled):
    """PD controllers of growing stiffness (no motor: an ideal source) approach the steady state of
    the crank driven at prescribed speed (four_bar_ritz, the same machine), the difference falling
    as the gains grow."""
    spec = controlled.to_spec()
    del spec["drive"]["motor"], spec["controllers"]["strain"]
    prescribed = _deflection(mc.load("four_bar_ritz"))
    differences = []
    for kp in (1e2, 1e3, 1e4):
        spec["controllers"]["crank_pd"].update(kp=kp, kd=2.0 * math.sqrt(kp * 1e-4))
        differences.append(np.abs(_deflection(mc.build(spec)) - prescribed).max())
    assert differences[0] > differences[1] > differences[2]
    assert differences[2] < 0.01 * np.ptp(prescribed)


# ---------------------------------------------------------------------------------------------------
# Energy balance of a controlled nonlinear run
# ---------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_motor_work_equals_the_change_of_mechanical_energy_plus_dissipation(controlled):
    """Over a nonlinear run of the controlled four-bar (motor with its rotor, PD, feedback of the
    coupler's midspan bending moment and its rate), the work of the drive torque equals the change
    of kinetic (rotor included) and strain energy plus the energy the coupler's damping dissipates.
    The coupler has no axial coordinates, so every mode is resolved and the generalized-alpha
    run's numerical dissipation vanishes as h^2: with the trapezoid rule on both sides the
    balance's defect falls at order 2."""
    spec = controlled.to_spec()
    spec["links"]["coupler"].update(axial=False, geometric_stiffening=False)
    spec["controllers"]["strain"].update(observable="coupler.moment@0.5", gain=2.0, rate_gain=0.01)
    mechanism = mc.build(spec)
    model = mc.assemble(mechanism, feedforward=mc.feedforward_torques(
        mechanism, mc.nominal_motion(mechanism)))
    defects = []
    for steps in (200, 400, 800):
        run = mc.simulate(mechanism, n_periods=1, steps_per_period=steps, estimate_error=False,
                          tol=1e-12)
        assert run.success, run.message
        power = [model.drive_power(s, v, t) for s, v, t in zip(run.s, run.sdot, run.t)]
        loss = [model.damping_power(v, s) for s, v in zip(run.s, run.sdot)]
        energy = [model.kinetic_energy(s, v) + model.potential_energy(s)
                  for s, v in zip(run.s, run.sdot)]
        scale = np.trapezoid(np.abs(power), run.t)
        dissipated = np.trapezoid(loss, run.t)
        assert dissipated > 1e-3 * scale            # the damping term matters in the balance
        defects.append(abs(np.trapezoid(power, run.t) - (energy[-1] - energy[0] + dissipated))
                       / scale)
    orders = np.log2(np.array(defects[:-1]) / np.array(defects[1:]))
    assert np.all(np.abs(orders - 2.0) < 0.25), defects
    assert defects[-1] < 1e-5


# ---------------------------------------------------------------------------------------------------
# Saturation flagged in the periodic analysis
# ---------------------------------------------------------------------------------------------------
def test_linear_range_reports_the_peak_demanded_torque_against_the_limits(controlled):
    specs = ["drive.O.torque"]
    lin = linearize.about(controlled, n_steps=128, observables=specs)
    steady = periodic.steady_state(lin.system, estimate_error=False)
    found = lin.linear_range(steady.x)
    (drive,) = found.drives
    torque = lin.observe(steady.x)["drive.O.torque"]
    assert found.status == "ok"
    assert drive.peak_demanded_torque == pytest.approx(np.abs(torque).max(), rel=1e-9)
    assert drive.peak_demanded_torque < drive.torque_limit
    assert drive.peak_demanded_torque < drive.peak_command < drive.command_limit
    limited = controlled.with_parameter("drive.torque_limit", 0.5 * drive.peak_demanded_torque)
    lin = linearize.about(limited, n_steps=128)
    found = lin.linear_range(periodic.steady_state(lin.system, estimate_error=False).x)
    assert found.status == "outside_linear_range" and "peak demanded torque" in found.message


# ---------------------------------------------------------------------------------------------------
# The closed-loop linear steady state against the closed-loop nonlinear run
# ---------------------------------------------------------------------------------------------------
def test_closed_loop_linear_steady_state_agrees_with_the_nonlinear_run_as_open_loop_does():
    """At small amplitude (crank 1/8 as long) the closed loop's linear steady state agrees with the
    nonlinear run's (studies.nonlinear_check) as well as the prescribed-speed machine's does."""
    import studies

    relative = {}
    for scene in ("four_bar_ritz", "four_bar_controlled"):
        problem = studies.MechanismProblem.from_scene(scene, observables=["coupler.deflection@0.5"],
                                                      parameter_paths=["links.crank.length"])
        check = studies.nonlinear_check(problem, {"links.crank.length": 0.0508 / 8}, n_steps=128,
                                        n_periods=3)
        assert check.verdict == "agrees", check.message
        relative[scene] = check.relative_difference["coupler.deflection@0.5"]
    assert relative["four_bar_controlled"] < 0.01
    assert relative["four_bar_controlled"] < 1.5 * relative["four_bar_ritz"]
