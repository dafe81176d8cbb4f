"""Nominal rigid motion against closed forms, finite differences and energy balances."""

import math
import re

import numpy as np
import pytest

import mechanisms
from mechanisms import MechanismError, RigidLink

N_STEPS = 256


@pytest.fixture(scope="module")
def four_bar():
    return mechanisms.nominal_motion(mechanisms.load("four_bar_fem4"), n_steps=N_STEPS)


@pytest.fixture(scope="module")
def slider_crank():
    return mechanisms.nominal_motion(mechanisms.load("slider_crank"), n_steps=N_STEPS)


def column(motion, label):
    return list(motion.model.coord_labels).index(label)


def series(motion, label):
    i = column(motion, label)
    return motion.s[:, i], motion.sdot[:, i], motion.sddot[:, i]


def spectral_derivative(values, period):
    """d/dt of a smooth periodic signal sampled at t_k = k T / N, k = 0..N-1 (exact for it up to
    the decay of its Fourier coefficients, here below 1e-13 relative)."""
    n = len(values)
    k = np.fft.fftfreq(n, d=1.0 / n)
    k[n // 2] = 0.0  # the Nyquist mode has no odd derivative on a real grid
    return np.real(np.fft.ifft(1j * k * (2 * math.pi / period) * np.fft.fft(values)))


def four_bar_closed_form(t, *, l0=0.254, l1=0.0508, l2=0.2794, l3=0.2794, omega=100.0):
    """Loop closure l1 e1 + l2 e2 - l3 e3 - l0 ex = 0 (seed eq. 2.11 with u_B = 0), open branch:
    B from the circles about A and C; rates from its first and second time derivatives projected
    on e3 and e2 (n_i . e_j = sin(phi_j - phi_i), e_i . e_j = cos(phi_i - phi_j))."""
    p1 = omega * t
    ax, ay = l1 * np.cos(p1), l1 * np.sin(p1)
    dx, dy = l0 - ax, -ay
    d = np.hypot(dx, dy)
    a = (l2**2 - l3**2 + d**2) / (2 * d)
    h = np.sqrt(l2**2 - a**2)
    bx, by = ax + (a * dx - h * dy) / d, ay + (a * dy + h * dx) / d
    p2, p3 = np.arctan2(by - ay, bx - ax), np.arctan2(by, bx - l0)
    w1 = omega
    w2 = -l1 * w1 * np.sin(p3 - p1) / (l2 * np.sin(p3 - p2))
    w3 = l1 * w1 * np.sin(p2 - p1) / (l3 * np.sin(p2 - p3))
    a2 = ((l1 * w1**2 * np.cos(p1 - p3) + l2 * w2**2 * np.cos(p2 - p3) - l3 * w3**2)
          / (l2 * np.sin(p3 - p2)))
    a3 = ((-l1 * w1**2 * np.cos(p1 - p2) - l2 * w2**2 + l3 * w3**2 * np.cos(p2 - p3))
          / (l3 * np.sin(p2 - p3)))
    return dict(p1=p1, p2=p2, p3=p3, w2=w2, w3=w3, a2=a2, a3=a3, ax=ax, ay=ay)


def unwrap_like(angle, reference):
    return reference + np.angle(np.exp(1j * (angle - reference)))


def test_four_bar_against_loop_closure(four_bar):
    ref = four_bar_closed_form(four_bar.t)
    crank, _, _ = series(four_bar, "crank.theta")
    coupler, coupler_rate, coupler_acc = series(four_bar, "coupler.theta")
    rocker, rocker_rate, rocker_acc = series(four_bar, "rocker.theta")
    # Newton stops at |Phi| < 1e-14 m and the scaled Jacobian's condition number is below 10, so
    # positions agree to ~1e-13 (relative to 0.28 m links); velocities and accelerations come from
    # linear solves with the same matrix, rounding ~1e-14 relative to their scale (w l, w^2 l).
    assert four_bar.jacobian_condition.max() < 10
    np.testing.assert_allclose(crank, ref["p1"], rtol=0, atol=1e-13)
    np.testing.assert_allclose(unwrap_like(ref["p2"], coupler), coupler, rtol=0, atol=1e-12)
    np.testing.assert_allclose(unwrap_like(ref["p3"], rocker), rocker, rtol=0, atol=1e-12)
    np.testing.assert_allclose(coupler_rate, ref["w2"], rtol=0, atol=1e-11 * 100)
    np.testing.assert_allclose(rocker_rate, ref["w3"], rtol=0, atol=1e-11 * 100)
    np.testing.assert_allclose(coupler_acc, ref["a2"], rtol=0, atol=1e-11 * 100**2)
    np.testing.assert_allclose(rocker_acc, ref["a3"], rtol=0, atol=1e-11 * 100**2)
    # Frame origins: the coupler starts at A, the rocker at C; elastic coordinates stay zero.
    np.testing.assert_allclose(series(four_bar, "coupler.x")[0], ref["ax"], atol=1e-13)
    np.testing.assert_allclose(series(four_bar, "coupler.y")[0], ref["ay"], atol=1e-13)
    np.testing.assert_allclose(series(four_bar, "rocker.x")[0], 0.254, atol=1e-13)
    elastic = four_bar.model.elastic_index
    assert not four_bar.s[:, elastic].any() and not four_bar.sddot[:, elastic].any()
    assert four_bar.constraint_residual < 1e-12 and four_bar.closure_error < 1e-12
    assert four_bar.s.shape == (N_STEPS + 1, four_bar.model.n_coords)
    assert four_bar.lam.shape == (N_STEPS + 1, 9) and four_bar.drive_torque.shape == (N_STEPS + 1, 1)
    assert four_bar.t[-1] == pytest.approx(2 * math.pi / 100, rel=1e-15)


def test_rates_against_finite_differences_of_positions():
    """Central differences of the grid positions converge to the solver's rates at order 2: the
    error ratio between h and h/2 is 4 (to within the next term, a few percent)."""
    errors = []
    for n_steps in (64, 128):
        motion = mechanisms.nominal_motion(mechanisms.load("four_bar_fem4"), n_steps=n_steps)
        h = motion.period / n_steps
        angle, rate, acc = series(motion, "rocker.theta")
        fd_rate = (angle[2:] - angle[:-2]) / (2 * h)
        fd_acc = (angle[2:] - 2 * angle[1:-1] + angle[:-2]) / h**2
        errors.append((np.abs(fd_rate - rate[1:-1]).max(), np.abs(fd_acc - acc[1:-1]).max()))
    for coarse, fine in zip(*errors):
        assert 3.8 < coarse / fine < 4.2


def test_drive_torque_against_kinetic_energy_rate(four_bar):
    """No gravity, rigid links: d(kinetic energy)/dt = torque * crank rate. The kinetic energy is
    written here by hand from the closed-form motion (crank and rocker about their pivots, coupler:
    centre of mass plus spin), and differentiated spectrally."""
    ref = four_bar_closed_form(four_bar.t[:-1])
    mu = 7800.0 * 0.02 * 0.0016  # kg/m of every link
    m1, m2, m3 = mu * 0.0508, mu * 0.2794, mu * 0.2794
    e2 = np.array([np.cos(ref["p2"]), np.sin(ref["p2"])])
    n1 = np.array([-np.sin(ref["p1"]), np.cos(ref["p1"])])
    n2 = np.array([-e2[1], e2[0]])
    v_centre = 0.0508 * 100.0 * n1 + 0.5 * 0.2794 * ref["w2"] * n2
    kinetic = (0.5 * m1 * 0.0508**2 / 3 * 100.0**2 + 0.5 * m3 * 0.2794**2 / 3 * ref["w3"] ** 2
               + 0.5 * m2 * (v_centre**2).sum(axis=0) + 0.5 * m2 * 0.2794**2 / 12 * ref["w2"] ** 2)
    power = spectral_derivative(kinetic, four_bar.period)
    torque = four_bar.drive_torque[:-1, 0]
    assert np.abs(power).max() > 10.0  # the check is not trivially zero
    # Spectral differentiation of this analytic signal with 256 samples is exact to rounding
    # (~1e-13 of the power scale); the torque comes from solves with condition number < 10.
    np.testing.assert_allclose(torque * 100.0, power, rtol=0, atol=1e-9 * np.abs(power).max())
    # And the model's own kinetic energy agrees with the hand-written one.
    own = [four_bar.model.kinetic_energy(s, v) for s, v in zip(four_bar.s[:-1], four_bar.sdot[:-1])]
    np.testing.assert_allclose(own, kinetic, rtol=1e-12)


def test_feedforward_torque_makes_the_nominal_motion_solve_the_torque_driven_model():
    """With the nominal inverse-dynamics torque as feedforward (``feedforward_torques``, the drive
    law of simulate and linearize), the nominal motion of a torque-driven four-bar solves the rigid
    rows of the full equations of the model without a drive row, ``M s'' - Q + Phi_s^T lam = 0``
    with the nominal multipliers of the joint rows: the spline passes through the tabulated torque
    at the grid samples, and the PD part vanishes on the nominal law."""
    mechanism = mechanisms.four_bar(discretisation="fem", n_elements=2,
                                    gravity=(0.0, -9.81)).replace(
        drives=(mechanisms.TorqueDrive("O", rate=100.0, kp=3.0, kd=0.1),))
    nominal = mechanisms.nominal_motion(mechanism, n_steps=128)
    feedforward = mechanisms.feedforward_torques(mechanism, nominal)
    assert list(feedforward) == ["O"]
    torque = np.array([feedforward["O"](t) for t in nominal.t])
    scale = np.abs(nominal.drive_torque).max()
    np.testing.assert_allclose(torque, nominal.drive_torque[:, 0], rtol=0, atol=1e-12 * scale)
    assert feedforward["O"](nominal.t[5] + 3 * nominal.period) == pytest.approx(torque[5],
                                                                               abs=1e-12 * scale)
    model = mechanisms.assemble(mechanism, feedforward=feedforward)
    assert model.n_constraints == nominal.model.n_constraints - 1
    lam = np.zeros((len(nominal.t), model.n_constraints))
    for joint in mechanism.joints:
        lam[:, model.joint_rows(joint.name).rows] = nominal.lam[
            :, nominal.model.joint_rows(joint.name).rows]
    residual = mechanisms.linear_terms_along(model, nominal.t, nominal.s, nominal.sdot,
                                             nominal.sddot, lam).residual[:, model.rigid_index]
    inertia = mechanisms.inertia_residual_along(nominal.model, nominal.t, nominal.s, nominal.sdot,
                                                nominal.sddot)
    assert np.abs(residual).max() < 1e-11 * np.abs(inertia).max()


def test_rigid_limit_elastic_coupler_equals_rigid_coupler(four_bar):
    """Held at zero deformation, the elastic coupler must move and load the drive exactly like a
    rigid uniform bar of the same mass (line mass: inertia m l^2 / 12)."""
    mech = mechanisms.load("four_bar_fem4")
    rigid = mech.replace(links=(mech.links[0],
                                RigidLink.uniform("coupler", 0.2794, width=0.02,
                                                  thickness=0.0016, density=7800.0),
                                mech.links[2]))
    other = mechanisms.nominal_motion(rigid, n_steps=N_STEPS)
    for label in ("crank.theta", "coupler.theta", "rocker.theta", "coupler.x", "rocker.y"):
        np.testing.assert_allclose(series(other, label)[0], series(four_bar, label)[0], atol=1e-13)
    scale = np.abs(four_bar.drive_torque).max()
    np.testing.assert_allclose(other.drive_torque, four_bar.drive_torque, rtol=0,
                               atol=1e-11 * scale)
    # A 1e6 times stiffer coupler has the same nominal motion: it does not depend on stiffness.
    stiff = mechanisms.nominal_motion(mech.with_parameter("links.coupler.youngs_modulus", 2e17),
                                      n_steps=N_STEPS)
    np.testing.assert_allclose(stiff.drive_torque, four_bar.drive_torque, rtol=0,
                               atol=1e-11 * scale)


def test_slider_crank_against_closed_form(slider_crank):
    """In-line slider-crank: r sin(phi) + l sin(beta) = 0, x_B = r cos(phi) + l cos(beta)."""
    r, l, w = 0.15, 0.30, 150.0
    phi = w * slider_crank.t
    beta = -np.arcsin(r * np.sin(phi) / l)
    beta_rate = -r * w * np.cos(phi) / (l * np.cos(beta))
    beta_acc = (r * w**2 * np.sin(phi) + l * np.sin(beta) * beta_rate**2) / (l * np.cos(beta))
    angle, rate, acc = series(slider_crank, "rod.theta")
    np.testing.assert_allclose(angle, beta, rtol=0, atol=1e-13)
    np.testing.assert_allclose(rate, beta_rate, rtol=0, atol=1e-11 * w)
    np.testing.assert_allclose(acc, beta_acc, rtol=0, atol=1e-11 * w**2)
    x, y = series(slider_crank, "rod.x")[0], series(slider_crank, "rod.y")[0]
    np.testing.assert_allclose(x + l * np.cos(angle), r * np.cos(phi) + l * np.cos(beta), atol=1e-13)
    np.testing.assert_allclose(y + l * np.sin(angle), 0.0, atol=1e-13)


def test_slider_crank_torque_against_energy_rate(slider_crank):
    """d/dt of the hand-written kinetic energy (crank about O, rod, 0.5 kg slider) = torque * w."""
    r, l, w = 0.15, 0.30, 150.0
    t = slider_crank.t[:-1]
    phi = w * t
    beta = -np.arcsin(r * np.sin(phi) / l)
    beta_rate = -r * w * np.cos(phi) / (l * np.cos(beta))
    m_crank, m_rod = 7800 * 0.03 * 0.01 * r, 7800 * 0.025 * 0.008 * l
    v_a = r * w * np.array([-np.sin(phi), np.cos(phi)])
    v_g = v_a + 0.5 * l * beta_rate * np.array([-np.sin(beta), np.cos(beta)])
    v_b = v_a[0] - l * beta_rate * np.sin(beta)
    kinetic = (0.5 * m_crank * r**2 / 3 * w**2 + 0.5 * m_rod * (v_g**2).sum(axis=0)
               + 0.5 * m_rod * l**2 / 12 * beta_rate**2 + 0.5 * 0.5 * v_b**2)
    power = spectral_derivative(kinetic, slider_crank.period)
    np.testing.assert_allclose(slider_crank.drive_torque[:-1, 0] * w, power, rtol=0,
                               atol=1e-9 * np.abs(power).max())


def test_two_link_arm_with_gravity_against_energy_balance():
    """Two prescribed joints and gravity: d(T + V)/dt = tau_shoulder q1' + tau_elbow q2', with the
    arm's forward kinematics and energies written here by hand (uniform rods, tip payload)."""
    # the former shipped arm (2 mm links, period 0.5 s, amplitudes 0.5 and 0.4 rad), vertical
    mech = mechanisms.two_link_arm(thickness=0.002, period=0.5, shoulder_amplitude=0.5,
                                   elbow_amplitude=0.4, gravity=(0.0, -9.81))
    motion = mechanisms.nominal_motion(mech, n_steps=N_STEPS)
    period, w = 0.5, 2 * math.pi / 0.5
    t = motion.t[:-1]
    q1, q1_rate = 0.5 * np.sin(w * t), 0.5 * w * np.cos(w * t)
    q2, q2_rate = 1.0 + 0.4 * np.sin(w * t), 0.4 * w * np.cos(w * t)
    th1, th2 = q1, q1 + q2
    th1_rate, th2_rate = q1_rate, q1_rate + q2_rate
    l1, l2, mu, g = 0.4, 0.3, 2700 * 0.025 * 0.002, 9.81
    m1, m2, payload = mu * l1, mu * l2, 0.2
    np.testing.assert_allclose(series(motion, "upper.theta")[0][:-1], th1, atol=1e-13)
    np.testing.assert_allclose(series(motion, "forearm.theta")[0][:-1], th2, atol=1e-13)
    np.testing.assert_allclose(series(motion, "forearm.x")[0][:-1], l1 * np.cos(th1), atol=1e-13)
    e1, n1 = np.array([np.cos(th1), np.sin(th1)]), np.array([-np.sin(th1), np.cos(th1)])
    e2, n2 = np.array([np.cos(th2), np.sin(th2)]), np.array([-np.sin(th2), np.cos(th2)])
    v_elbow = l1 * th1_rate * n1
    v_g2 = v_elbow + 0.5 * l2 * th2_rate * n2
    v_tip = v_elbow + l2 * th2_rate * n2
    kinetic = (0.5 * m1 * l1**2 / 3 * th1_rate**2 + 0.5 * m2 * (v_g2**2).sum(axis=0)
               + 0.5 * m2 * l2**2 / 12 * th2_rate**2 + 0.5 * payload * (v_tip**2).sum(axis=0))
    potential = g * (m1 * 0.5 * l1 * e1[1] + m2 * (l1 * e1[1] + 0.5 * l2 * e2[1])
                     + payload * (l1 * e1[1] + l2 * e2[1]))
    power = spectral_derivative(kinetic + potential, period)
    drive_power = motion.drive_torque[:-1, 0] * q1_rate + motion.drive_torque[:-1, 1] * q2_rate
    np.testing.assert_allclose(drive_power, power, rtol=0, atol=1e-9 * np.abs(power).max())


@pytest.mark.parametrize("name", mechanisms.scenes())
def test_every_scene_has_a_closed_nominal_motion(name):
    motion = mechanisms.nominal_motion(mechanisms.load(name), n_steps=64)
    assert motion.constraint_residual < 1e-12
    assert motion.velocity_residual < 1e-10 and motion.acceleration_residual < 1e-8
    assert motion.closure_error < 1e-10
    assert np.isfinite(motion.drive_torque).all() and motion.run_time > 0


def test_bare_model_path_matches_the_mechanism_path(four_bar):
    """Through the protocol only (no mechanism, no drive_torques helper): same motion, torque from
    the drive row's multiplier."""

    class Bare:
        def __init__(self, model):
            self._model = model
            for name in ("n_coords", "n_constraints", "coord_labels", "constraint_labels",
                         "rigid_index", "elastic_index"):
                setattr(self, name, getattr(model, name))

        def __getattr__(self, name):
            if name in ("mechanism", "drive_torques", "period"):
                raise AttributeError(name)
            return getattr(self._model, name)

    bare = Bare(four_bar.model)
    with pytest.raises(ValueError, match="s0"):
        mechanisms.nominal_motion(bare, n_steps=8, period=four_bar.period)
    with pytest.raises(ValueError, match="period"):
        mechanisms.nominal_motion(bare, n_steps=8, s0=four_bar.s[0])
    guess = four_bar.s[0] + 0.01
    motion = mechanisms.nominal_motion(bare, n_steps=N_STEPS, period=four_bar.period, s0=guess)
    np.testing.assert_allclose(motion.s, four_bar.s, atol=1e-13)
    np.testing.assert_allclose(motion.drive_torque, four_bar.drive_torque, rtol=1e-12)


# --- bad input --------------------------------------------------------------------------------------
def _slider_crank(crank, rod, origin=(0.0, 0.0), n_steps=64, offset=0.0):
    spec = mechanisms.load("slider_crank").to_spec()
    spec["links"]["crank"]["length"] = crank
    spec["links"]["rod"]["length"] = rod
    spec["joints"]["B"]["origin"] = list(origin)
    spec["drive"]["offset"] = offset
    return mechanisms.build(spec)


def _crank_angle(message):
    return float(re.search(r"crank angle (-?[0-9.]+) deg", message).group(1))


def test_crank_longer_than_rod_stops_where_the_rod_stands_vertical():
    """Crank 0.3 m, rod 0.15 m: the rod's end reaches the slider line only while
    r sin(phi) <= l, so the crank stops at asin(0.5) = 30 deg, where the Jacobian is singular."""
    with pytest.raises(MechanismError, match="crank cannot turn") as info:
        mechanisms.nominal_motion(_slider_crank(0.3, 0.15), n_steps=64)
    assert _crank_angle(str(info.value)) == pytest.approx(30.0, abs=0.05)
    assert "'B'" in str(info.value)


@pytest.mark.parametrize("n_steps", [4, 64])
def test_toggle_on_the_grid_names_joints_and_angle(n_steps):
    """Crank = rod: at phi = 90 deg the rod stands vertical over the crank pin (a change point);
    with 4 or 64 steps the grid lands exactly on it (at 64 inside the numba continuation)."""
    with pytest.raises(MechanismError, match=r"singular constraint Jacobian \(toggle position\) "
                                             r"at crank angle 90.00 deg.*joints \[.*'B'"):
        mechanisms.nominal_motion(_slider_crank(0.2, 0.2), n_steps=n_steps)


def test_linkage_that_cannot_be_assembled():
    with pytest.raises(MechanismError, match=r"cannot be assembled at crank angle 0.00 deg"):
        mechanisms.nominal_motion(_slider_crank(0.15, 0.3, origin=(0.0, 0.6)), n_steps=8)


def test_bad_arguments():
    mech = mechanisms.load("slider_crank")
    for bad in (1, 2.5, "10", True):
        with pytest.raises(ValueError, match="n_steps must be an integer >= 2"):
            mechanisms.nominal_motion(mech, n_steps=bad)
    with pytest.raises(TypeError, match="lacks 'n_coords'"):
        mechanisms.nominal_motion(object(), n_steps=8)


def test_torque_drive_follows_its_nominal_law(four_bar):
    """A torque drive's nominal motion is its law, its torque the inverse-dynamics one; a model
    assembled with it (no drive row) is refused with the fix."""
    mech = mechanisms.load("four_bar_fem4")
    torque_driven = mech.replace(drives=(mechanisms.TorqueDrive("O", rate=100.0, kp=10.0),))
    motion = mechanisms.nominal_motion(torque_driven, n_steps=N_STEPS)
    np.testing.assert_array_equal(motion.drive_torque, four_bar.drive_torque)
    with pytest.raises(MechanismError, match="pass the Mechanism"):
        mechanisms.nominal_motion(mechanisms.assemble(torque_driven), n_steps=8)


@pytest.mark.parametrize("name", mechanisms.scenes())
def test_every_scene_balances_drive_power_and_energy_rate(name):
    """d(T + V)/dt along the motion (the model's energy functions, differentiated spectrally) equals
    the drive power sum tau_i * (relative angle rate)_i from the multipliers: two independent routes
    through the model (energies vs. mass matrix, forces and constraint Jacobian)."""
    mech = mechanisms.load(name).with_parameter("gravity", [0.0, -9.81])
    motion = mechanisms.nominal_motion(mech, n_steps=N_STEPS)
    model = motion.model
    energy = np.array([model.kinetic_energy(s, v) + model.potential_energy(s)
                       for s, v in zip(motion.s[:-1], motion.sdot[:-1])])
    power = spectral_derivative(energy, motion.period)
    rates = np.array([[drive.angle(t, motion.period)[1] for drive in mech.drives]
                      for t in motion.t[:-1]])
    drive_power = (motion.drive_torque[:-1] * rates).sum(axis=1)
    # The energies' Fourier coefficients fall below rounding well before the 128th harmonic, so
    # spectral differentiation is limited by rounding in T + V (1e-16 of it) amplified by the
    # highest wavenumber (N/2 = 128): ~1e-12 of the power scale; 1e-10 leaves a margin.
    np.testing.assert_allclose(drive_power, power, rtol=0, atol=1e-10 * np.abs(power).max())


def test_six_bar_against_two_loop_closures():
    """The six-bar as two four-bars in series: B from circles about A and O2, the plate angle from
    O2B, C on the plate at -60 deg from O2B, D from circles about C and O3 (upper branches)."""
    motion = mechanisms.nominal_motion(mechanisms.load("six_bar"), n_steps=N_STEPS)

    def upper(p, r_p, q, r_q):
        d = np.hypot(q[0] - p[0], q[1] - p[1])
        a = (r_p**2 - r_q**2 + d**2) / (2 * d)
        h = np.sqrt(r_p**2 - a**2)
        ex, ey = (q[0] - p[0]) / d, (q[1] - p[1]) / d
        return p[0] + a * ex - h * ey, p[1] + a * ey + h * ex

    phi = 100.0 * motion.t
    a = (0.06 * np.cos(phi), 0.06 * np.sin(phi))
    b = upper(a, 0.28, (0.30, 0.0), 0.15)
    plate = np.arctan2(b[1], b[0] - 0.30)
    c = (0.30 + 0.10 * np.cos(plate - math.pi / 3), 0.10 * np.sin(plate - math.pi / 3))
    d = upper(c, 0.30, (0.60, 0.0), 0.20)
    np.testing.assert_allclose(unwrap_like(plate, series(motion, "plate.theta")[0]),
                               series(motion, "plate.theta")[0], atol=1e-12)
    np.testing.assert_allclose(series(motion, "link4.x")[0], c[0], atol=1e-13)
    np.testing.assert_allclose(series(motion, "link4.y")[0], c[1], atol=1e-13)
    output = np.arctan2(d[1], d[0] - 0.60)
    np.testing.assert_allclose(unwrap_like(output, series(motion, "output.theta")[0]),
                               series(motion, "output.theta")[0], atol=1e-12)


def test_rigid_limit_stiff_coupler_reproduces_kinematics_and_torque():
    """Full nonlinear runs (mechanisms.simulate) of the four-bar with a 1e3 and 1e4 times stiffer
    coupler, started on the nominal motion: in the last period the rocker angle differs from the
    rigid one by the elastic deformation, which scales as 1/E; the crank torque (drive multiplier)
    differs from the rigid inverse-dynamics torque by the integrator's error, which falls at
    second order in the step (the 1/E part is below it)."""
    base = mechanisms.load("four_bar_fem1")

    def last_period_deviation(factor, steps):
        mech = base.with_parameter("links.coupler.youngs_modulus", 2e11 * factor)
        nominal = mechanisms.nominal_motion(mech, n_steps=steps)
        run = mechanisms.simulate(mech, n_periods=2, steps_per_period=steps, rho_inf=0.5)
        last = slice(-steps - 1, None)
        np.testing.assert_allclose(run.t[last] - nominal.period, nominal.t, atol=1e-15)
        row = nominal.model.constraint_labels.index("drive:O")
        rocker = column(nominal, "rocker.theta")
        torque_error = np.abs(-run.lam[last, row] - nominal.drive_torque[:, 0]).max()
        return (torque_error / np.abs(nominal.drive_torque).max(),
                np.abs(run.s[last, rocker] - nominal.s[:, rocker]).max())

    torque_128, angle_stiff = last_period_deviation(1e4, 128)
    torque_256, _ = last_period_deviation(1e4, 256)
    _, angle_soft = last_period_deviation(1e3, 256)
    assert torque_256 < 1e-3 and 3.5 < torque_128 / torque_256 < 4.5
    assert angle_stiff < 1e-8 and 8.0 < angle_soft / angle_stiff < 12.0


@pytest.mark.parametrize("scene", ["six_bar", "two_link_arm"])
def test_the_motion_at_another_speed_from_the_same_phases_equals_its_continuation(scene):
    """``nominal_at_period`` (a speed sweep's nominal motions): the first speed's positions at the same
    phases, rates and accelerations scaled, the inverse dynamics recomputed, against the continuation
    at the new speed."""
    import studies

    problem = studies.MechanismProblem.from_scene(scene)
    speed = problem.parameters["speed"]
    first = mechanisms.nominal_motion(problem.mechanism({"speed": 0.8 * speed}), n_steps=64)
    faster = problem.mechanism({"speed": 1.3 * speed})
    carried, computed = mechanisms.nominal_at_period(faster, first), mechanisms.nominal_motion(faster, n_steps=64)
    assert carried.period == pytest.approx(computed.period, rel=1e-14)
    for name in ("t", "s", "sdot", "sddot", "lam", "drive_torque"):
        expected = getattr(computed, name)
        assert np.abs(getattr(carried, name) - expected).max() <= 1e-12 * np.abs(expected).max(), name


def test_the_motion_of_another_linkage_is_refused_at_another_speed():
    import studies

    problem = studies.MechanismProblem.from_scene("six_bar", parameter_paths=["links.crank.length"])
    length = problem.parameters["links.crank.length"]
    first = mechanisms.nominal_motion(problem.mechanism(), n_steps=64)
    with pytest.raises(mechanisms.ArgumentError, match="the linkage moved"):
        mechanisms.nominal_at_period(problem.mechanism({"links.crank.length": 1.05 * length, "speed": 90.0}),
                                     first)


def test_rates_that_do_not_meet_the_velocity_constraints_are_refused():
    """Positions that meet the constraints are not enough: rates 1 % off (a law that differs between
    the samples) are refused too."""
    import dataclasses

    import studies

    problem = studies.MechanismProblem.from_scene("six_bar")
    first = mechanisms.nominal_motion(problem.mechanism(), n_steps=64)
    wrong = dataclasses.replace(first, sdot=1.01 * first.sdot)
    with pytest.raises(mechanisms.ArgumentError, match="velocity constraint residual"):
        mechanisms.nominal_at_period(problem.mechanism({"speed": 90.0}), wrong)
