"""Run-up and run-down through resonance (``studies.run_up``, ``[studies.run_up]``), each against an
independent reference: the ramp's angle against the quadrature of its rate; a fast ramp of an elastic
arm, whose one mode is exactly a single-degree-of-freedom oscillator in the rotating frame, against
scipy's DOP853 of that oscillator (closed-form coefficients from the clamped-free eigenfunction); a
very slow ramp of the four-bar against its nonlinear periodic states along the way."""

from __future__ import annotations

import math
import pathlib
import tomllib

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

import mechanisms
import studies
from studies.cli import main

ARM = pathlib.Path(__file__).parent / "data" / "arm_sdof.toml"
TIP = "arm.transverse@1"
#: The arm's scene numbers, which the oscillator below is computed from.
ARM_SCENE = tomllib.loads(ARM.read_text())
#: Its gravity (m/s^2), the oscillator's forcing beside the ramp's angular acceleration.
GRAVITY = -ARM_SCENE["gravity"][1]


# --- the ramp ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", ["linear", "smooth"])
def test_ramp_angle_is_the_integral_of_its_rate(shape):
    ramp = mechanisms.SpeedRamp(100.0, 30.0, 0.4, shape)
    for t in (-0.05, 0.0, 0.1, 0.25, 0.4, 0.55):
        angle, rate, acc = ramp.law(t)
        expected = quad(lambda u: ramp.law(u)[1], 0.0, t, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
        assert angle == pytest.approx(expected, rel=1e-10, abs=1e-12)
        if 0.0 < t < 0.4:   # the rate's derivative inside the ramp (a kink at its ends for linear)
            h = 1e-6
            assert acc == pytest.approx((ramp.law(t + h)[1] - ramp.law(t - h)[1]) / (2 * h), rel=1e-6)
    assert ramp.law(0.0)[1] == 100.0 and ramp.law(1.0)[1:] == (30.0, 0.0)
    times = np.linspace(-0.1, 0.6, 71)   # the array path agrees with the scalar one
    np.testing.assert_allclose(np.stack(ramp.law(times), axis=1),
                               [ramp.law(float(t)) for t in times], rtol=1e-14, atol=1e-14)


def test_ramp_refuses_bad_input():
    with pytest.raises(mechanisms.MechanismError, match="shape"):
        mechanisms.SpeedRamp(1.0, 2.0, 1.0, "cubic")
    with pytest.raises(mechanisms.MechanismError, match="duration"):
        mechanisms.SpeedRamp(1.0, 2.0, 0.0)
    drive = mechanisms.PrescribedDrive("O", rate=1.0, harmonics=((1, 0.1, 0.0),))
    import dataclasses
    with pytest.raises(mechanisms.MechanismError, match="harmonics"):
        dataclasses.replace(drive, profile=mechanisms.SpeedRamp(1.0, 2.0, 1.0))


# --- the arm: an exact single-degree-of-freedom oscillator ----------------------------------------
def _arm_oscillator():
    """(m, c, k, s, s0, tip) of the arm's one clamped-free mode ``phi`` (own normalisation):
    ``m q'' + c q' + (k - m theta'^2) q = -s theta'' - g s0 cos(theta)``, tip deflection ``tip q``;
    from the link's numbers in tests/data/arm_sdof.toml, the Lagrangian of a beam turning about its
    root (no axial deformation, no stiffening, no rotary inertia)."""
    link = ARM_SCENE["links"]["arm"]
    assert ARM_SCENE["gravity"][0] == 0.0 and link["boundary"] == "clamped-free"
    assert not (link["axial"] or link["geometric_stiffening"] or link["rotary_inertia"])
    assert link["discretisation"] == {"type": "ritz", "n_bending": 1, "n_axial": 0}
    assert link["damping"]["type"] == "rayleigh" and set(link["damping"]) == {"type", "beta"}
    length, width, thickness, density, modulus = (float(link[key]) for key in (
        "length", "width", "thickness", "density", "youngs_modulus"))
    beta = float(link["damping"]["beta"])
    rho_a, ei = density * width * thickness, modulus * width * thickness**3 / 12.0
    b = 1.8751040687119611 / length
    sigma = (math.cosh(b * length) + math.cos(b * length)) / (math.sinh(b * length) + math.sin(b * length))

    def phi(x):
        return math.cosh(b * x) - math.cos(b * x) - sigma * (math.sinh(b * x) - math.sin(b * x))

    def curvature(x):
        return b * b * (math.cosh(b * x) + math.cos(b * x) - sigma * (math.sinh(b * x) + math.sin(b * x)))

    def integral(f):
        return quad(f, 0.0, length, epsabs=0.0, epsrel=1e-13, limit=200)[0]

    m = rho_a * integral(lambda x: phi(x) ** 2)
    k = ei * integral(lambda x: curvature(x) ** 2)
    return (m, beta * k, k, rho_a * integral(lambda x: x * phi(x)), rho_a * integral(phi), phi(length))


def _steady_amplitude(speed, m, c, k, s0, g=GRAVITY):
    """The complex amplitude Q of the periodic state ``q = Re(Q e^{i speed t})`` at a constant speed."""
    return -g * s0 / (k - 2.0 * m * speed**2 + 1j * c * speed)


def _reference_per_revolution(start, stop, duration):
    """Per revolution (mean speed, tip peak-to-peak) of the oscillator under the linear ramp,
    DOP853 at rtol 1e-11 from the closed-form periodic state at ``start``."""
    m, c, k, s, s0, tip = _arm_oscillator()
    rate = (stop - start) / duration

    def theta(t):
        return start * t + 0.5 * rate * t * t, start + rate * t, rate

    def rhs(t, y):
        angle, speed, acc = theta(t)
        return [y[1], (-c * y[1] - (k - m * speed**2) * y[0] - s * acc - GRAVITY * s0 * math.cos(angle)) / m]

    q = _steady_amplitude(start, m, c, k, s0)
    solution = solve_ivp(rhs, (0.0, duration), [q.real, (1j * start * q).real], method="DOP853",
                         rtol=1e-11, atol=1e-14, dense_output=True)
    assert solution.success
    total = theta(duration)[0]
    speeds, ptps = [], []
    for n in range(int(total / (2 * math.pi))):
        # the times where theta = 2 pi n and 2 pi (n + 1): roots of the quadratic
        ends = [(-start + math.sqrt(start**2 + 2.0 * rate * 2 * math.pi * j)) / rate for j in (n, n + 1)]
        samples = tip * solution.sol(np.linspace(*ends, 4001))[0]
        speeds.append(2 * math.pi / (ends[1] - ends[0]))
        ptps.append(np.ptp(samples))
    return np.array(speeds), np.array(ptps)


def _only_the_model_form_verdict(result, speed):
    """The arm is unstiffened on purpose (an exact SDOF) and deflects many section heights, which
    linearize's model-form verdict rightly calls outside the range of such a link: the run-up's status
    is that verdict of its start, with its reason and fix, its peak deflection the closed form's at
    the start speed, and the run's own verdict (error estimates, failure) adds nothing to it."""
    assert result.status == "outside_linear_range", result.message
    verdicts, _, words = result.message.partition("; run-")
    assert verdicts.startswith("start: linear steady state outside_linear_range (outside the linear range: "
                               "model form: link 'arm' has no geometric stiffening: its peak deflection is "), verdicts
    assert "enable geometric_stiffening" in verdicts and verdicts.count("start:") == 1, verdicts
    heights = float(verdicts.split("its peak deflection is ")[1].split(" section heights")[0])
    m, c, k, _, s0, tip = _arm_oscillator()
    closed_form = abs(tip * _steady_amplitude(speed, m, c, k, s0)) / ARM_SCENE["links"]["arm"]["thickness"]
    assert heights == pytest.approx(closed_form, rel=0.01) and heights > 2.0
    return verdicts


@pytest.fixture(scope="module")
def arm():
    return studies.MechanismProblem.from_mechanism(mechanisms.load(str(ARM)), observables=[TIP])


@pytest.mark.slow
@pytest.mark.parametrize("start, stop", [(12.0, 28.0), (28.0, 12.0)])
def test_fast_ramp_through_resonance_against_the_oscillator(arm, start, stop):
    """Passage through resonance: the peak is lower than the steady one and comes after the
    resonance in the sweep's direction; each revolution's peak-to-peak matches the oscillator's."""
    duration = 4.0
    result = studies.run_up(arm, start=start, stop=stop, duration=duration, start_state="linear",
                            n_steps=128, curve_points=0)
    verdicts = _only_the_model_form_verdict(result, start)
    for reason in ("estimated error", "no error estimate", "error estimate not checked", "the run failed", "p2p"):
        assert reason not in verdicts, verdicts     # the run's own verdict: ok
    speeds, reference = _reference_per_revolution(start, stop, duration)
    ptp, error = result.peak_to_peak[TIP], result.peak_to_peak_error[TIP]
    assert ptp.size == speeds.size
    np.testing.assert_allclose(result.speed, speeds, rtol=1e-8)
    # within the run's own error estimate (3x, plus round-off of the extremes' refinement)
    assert np.all(np.abs(ptp - reference) <= 3.0 * error + 1e-3 * reference.max()), \
        np.c_[speeds, ptp, reference, error]
    assert np.all(error <= 0.02 * reference.max())
    # the steady curve of the same oscillator, closed form, and its resonance
    m, c, k, _, s0, tip = _arm_oscillator()
    grid = np.linspace(min(start, stop), max(start, stop), 20001)
    steady = 2.0 * abs(tip) * np.abs(_steady_amplitude(grid, m, c, k, s0))
    resonance = grid[np.argmax(steady)]
    largest, at = result.largest[TIP], result.speed_at_largest[TIP]
    assert largest < 0.9 * steady.max()
    assert largest == pytest.approx(reference.max(), rel=0.01)
    if stop > start:
        assert at > resonance + 0.3
    else:
        assert at < resonance - 0.3
    assert np.isclose(result.resonance_speed, resonance, rtol=0.01).any()


def test_drive_follows_the_ramp_and_run_down_to_standstill(arm):
    """A prescribed drive turns at the ramp's rate; with stop = 0 the arm is brought to rest."""
    result = studies.run_up(arm, start=20.0, stop=0.0, duration=2.0, start_state="rest", curve_points=3,
                            n_steps=64)
    # from rest the unstiffened arm swings to tens of section heights: the check along the ramp says
    # its model form (the run's own verdict adds nothing)
    assert result.status == "outside_linear_range", result.message
    assert result.message.startswith("along the ramp: outside the linear range in 3 of 3 revolutions"), \
        result.message
    assert "enable geometric_stiffening" in result.message and "estimated error" not in result.message
    ramp = mechanisms.SpeedRamp(20.0, 0.0, 2.0)
    # the rates of an index-3 scheme carry its O(h^2) velocity error (the angles are exact)
    np.testing.assert_allclose(result.drive_speed, ramp.law(result.t)[1], rtol=0.0, atol=1e-4 * 20.0)
    # theta = 20 t - 5 t^2 = 2 pi n: the revolutions' mean speeds from the exact crossing times
    crossings = np.array([(20.0 - math.sqrt(400.0 - 40.0 * math.pi * n)) / 10.0
                          for n in range(result.speed.size + 1)])
    np.testing.assert_allclose(result.speed, 2 * math.pi / np.diff(crossings), rtol=1e-6)
    assert result.speed.size == int(ramp.law(2.0)[0] / (2 * math.pi))
    assert np.all(np.diff(result.speed) < 0)       # running down
    assert result.start_state == "rest"
    # the step is bounded by the elastic period, not by revolutions: the slow end is resolved
    assert result.dt <= 2 * math.pi / 20.0 / 64 + 1e-15


# --- the four-bar: a very slow ramp follows its nonlinear periodic states -------------------------
@pytest.fixture(scope="module")
def four_bar():
    return studies.MechanismProblem.from_scene("four_bar_fem4")


@pytest.mark.slow
def test_very_slow_ramp_reproduces_the_nonlinear_periodic_states(four_bar):
    """60 -> 64 rad/s over 8 s (78 revolutions, 40 decay times of the coupler's first mode): each
    revolution's peak to peak is the nonlinear periodic state's at its mean speed, within the error
    estimates and a quasi-static lag of 0.1 %, and nearer to it than to the linear one (0.6 % apart)."""
    spec = "coupler.deflection@0.5"
    result = studies.run_up(four_bar, start=60.0, stop=64.0, duration=8.0, curve_points=0, mode_steps=24,
                            modes="full")
    assert result.status == "ok", result.message
    assert result.start_state == "nonlinear periodic state" and "full element models" in result.message
    for k in (result.speed.size // 2, result.speed.size - 2):
        # on the run's model, the full element models (the study's default reduces them)
        orbit = studies.nonlinear_steady_state(four_bar, {"speed": float(result.speed[k])}, n_steps=256,
                                               modes="full")
        assert orbit.status != "failed"
        ramped, steady, linear = (result.peak_to_peak[spec][k], orbit.peak_to_peak[spec],
                                  orbit.linear_peak_to_peak[spec])
        allowed = 3 * (result.peak_to_peak_error[spec][k] + orbit.peak_to_peak_error[spec]) + 1e-3 * steady
        assert abs(ramped - steady) <= allowed, (k, result.speed[k], ramped, steady, allowed)
        assert abs(ramped - steady) < 0.5 * abs(ramped - linear), (ramped, steady, linear)
        # the check along the ramp: the steady states' linear-range measures at that speed (the
        # deflection within the nonlinear-linear difference, the nominal compression the same formula)
        from studies._numerics import solve_steady

        check = solve_steady(four_bar.linearize({"speed": float(result.speed[k])}, n_steps=256)).linear_range
        for name, rel in (("peak_deflection_over_height", 0.02), ("peak_compression_over_euler", 1e-3)):
            assert result.range_measures[f"coupler.{name}"][k] == pytest.approx(check[f"coupler.{name}"], rel=rel)
    assert set(result.revolution_status) == {"ok"} and result.is_stable


# --- the scene study ---------------------------------------------------------------------------------
@pytest.mark.slow
def test_scene_table_runs_and_round_trips(tmp_path):
    scene = tmp_path / "arm.toml"
    scene.write_text(ARM.read_text() + "\n[studies]\nobservables = [\"arm.transverse@1\"]\n\n"
                     "[studies.run_up]\nstart = 12.0\nstop = 20.0\nduration = 1.0\nstart_state = \"linear\"\n"
                     "curve_points = 5\n")
    out = tmp_path / "out.h5"
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == 0
    loaded = studies.load(out)["run_up"]
    assert isinstance(loaded, studies.RunUp)
    assert loaded.peak_to_peak[TIP].shape == loaded.speed.shape
    assert loaded.settings["stop"] == 20.0
    # the verdicts along the ramp and the tail round-trip
    assert loaded.revolution_status.shape == (loaded.speed.size + 1,)
    assert set(loaded.range_measures) == {f"arm.{name}" for name in (
        "peak_deflection_over_length", "peak_deflection_over_height", "peak_slope",
        "peak_compression_over_euler", "peak_stress_over_yield")}
    assert loaded.tail_peak_to_peak.keys() == {TIP} and np.isfinite(loaded.tail_start)
    assert loaded.curve_is_stable.shape == (5,) and loaded.is_stable
    assert main(["plot", str(out), "--outdir", str(tmp_path / "figures")]) == 0
    assert any(p.name.startswith("run_up") for p in (tmp_path / "figures").iterdir())


def test_scene_table_refuses_bad_keys(tmp_path):
    scene = tmp_path / "arm.toml"
    scene.write_text(ARM.read_text() + "\n[studies.run_up]\nstart = 12.0\nstop = 12.0\nduration = 1.0\n")
    assert main(["run", str(scene), "--out", str(tmp_path / "o.h5"), "--quiet"]) == 2
    with pytest.raises(studies.StudiesError, match="start_state"):
        studies.run_up(studies.MechanismProblem.from_scene("four_bar_fem1"), start=10.0, stop=20.0,
                       duration=1.0, start_state="warm")
    with pytest.raises(studies.StudiesError, match="mechanism"):
        studies.run_up(studies.mathieu_problem(), start=1.0, stop=2.0, duration=1.0)


@pytest.mark.slow
def test_a_stiff_torque_drive_runs_up_as_the_prescribed_one():
    """Two formulations of one run-up: a torque drive whose ramped reference (PD 3000 N m/rad,
    30 N m s/rad, feedforward read at the reference's angle) holds the crank on the ramp gives the
    prescribed drive's per-revolution peak-to-peak, within the two error estimates."""
    prescribed = mechanisms.four_bar(n_elements=1)
    spec = prescribed.to_spec()
    spec["drive"].update(type="torque", kp=3000.0, kd=30.0)
    torque = mechanisms.build(spec, source="four-bar, stiff PD drive")
    # fine enough for the error estimate to be in its asymptotic range (the 4 dt check)
    options = dict(start=100.0, stop=120.0, duration=0.5, start_state="linear", curve_points=0, n_steps=128,
                   mode_steps=32)
    a, b = (studies.run_up(studies.MechanismProblem.from_mechanism(m), **options) for m in (prescribed, torque))
    assert a.status == b.status == "ok", (a.message, b.message)
    ramp = mechanisms.SpeedRamp(100.0, 120.0, 0.5)
    assert np.abs(b.drive_speed - ramp.law(b.t)[1]).max() < 0.1      # the PD's tracking error, rad/s
    np.testing.assert_allclose(b.speed, a.speed, rtol=1e-4)
    for spec_ in a.units:
        difference = np.abs(a.peak_to_peak[spec_] - b.peak_to_peak[spec_])
        allowed = 3 * (a.peak_to_peak_error[spec_] + b.peak_to_peak_error[spec_]) + 2e-3 * a.largest[spec_]
        assert np.all(difference <= allowed), (spec_, difference, allowed)
        assert not np.array_equal(a.drive_torque, b.drive_torque)   # the torque law, not the multiplier


def test_steady_curves_of_the_exactly_linear_arm(arm):
    """The arm's equations are linear in its mode: the nonlinear periodic states of the curve equal the
    linear ones, and both the closed form's peak to peak, within their error estimates."""
    result = studies.run_up(arm, start=14.0, stop=18.0, duration=1.0, start_state="linear", curve_points=3,
                            nonlinear_curve=True, estimate_error=False)
    m, c, k, _, s0, tip = _arm_oscillator()
    exact = 2.0 * abs(tip) * np.abs(_steady_amplitude(result.curve_speed, m, c, k, s0))
    linear, nonlinear = result.curve_peak_to_peak[TIP], result.nonlinear_curve_peak_to_peak[TIP]
    assert np.all(np.abs(linear - exact) <= 3 * result.curve_error[TIP] + 1e-9), (linear, exact)
    assert np.all(np.abs(nonlinear - exact) <= 3 * result.curve_error[TIP] + 1e-3 * exact), (nonlinear, exact)
    verdicts = _only_the_model_form_verdict(result, 14.0)
    assert "no error estimate (estimate_error = false)" in verdicts   # as asked


def test_the_prescribed_drive_s_torque_series_is_each_sample_s_drive_torque():
    """The run-up's torque series of a prescribed drive, minus its multiplier read off the run at once,
    is each sample's ``Model.drive_torques`` (the per-sample path a torque drive keeps), exactly."""
    from studies._kinds._run_up_revolutions import torques

    model = mechanisms.integrated_model(mechanisms.four_bar(n_elements=1)).with_drive_profiles(
        lambda drive: mechanisms.SpeedRamp(drive.rate, 1.2 * drive.rate, 0.05))
    run = mechanisms.simulate(model, t_end=0.02, dt=2e-4, estimate_error=False)
    joint = model.mechanism.drives[0].joint
    expected = np.array([model.drive_torques(s, v, t, lam)[0] for s, v, t, lam in zip(run.s, run.sdot, run.t, run.lam)])
    series = torques(model, run, joint)
    assert series.shape == run.t.shape and np.ptp(series) > 0.0
    np.testing.assert_array_equal(series, expected)
    np.testing.assert_array_equal(torques(model, run), expected)
