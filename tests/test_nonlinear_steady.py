"""The nonlinear periodic state of a mechanism by shooting (mechanisms.PeriodMap, studies.nonlinear_steady_state)
against independent references: finite differences of the period map, a long transient, and the linear
periodic state in the limit of small loading."""

from pathlib import Path

import numpy as np
import pytest

import mechanisms
import periodic
import studies
from studies._kinds.nonlinear_steady_state import shooting_setup  # the kind's period maps: no public face
from tests._support.tangent_twin import central_differences, tight_period_map

SPEC = "coupler.deflection@0.5"


@pytest.fixture(scope="module")
def problem():
    return studies.MechanismProblem.from_scene("four_bar_fem4", parameter_paths=["links.crank.length"])


@pytest.fixture(scope="module")
def shot(problem):
    """The stiffened thesis four-bar at its nominal speed (100 rad/s, near resonance), N = 64."""
    return studies.nonlinear_steady_state(problem, n_steps=64)


@pytest.fixture(scope="module")
def trusted(problem):
    """The same orbit on N = 256 steps, where its error estimate is trusted (status ok)."""
    return studies.nonlinear_steady_state(problem, n_steps=256)


@pytest.mark.slow
def test_monodromy_matches_finite_differences_of_the_period_map(problem):
    setup = shooting_setup(problem, None, 64)
    period_map = tight_period_map(setup)
    x0 = setup.guess
    monodromy = period_map.run(x0).monodromy
    m = x0.size // 2
    # steps 1e-5 of each block's size: truncation (the stiff axial coordinates are strongly
    # nonlinear) and the integrator's Newton tolerance 1e-12 m are both far below the check
    differences = central_differences(period_map, x0, ((slice(0, m), 1e-5), (slice(m, None), 1e-5)))
    assert np.abs(monodromy - differences).max() <= 1e-4 * np.abs(monodromy).max()
    # the multipliers agree as well (the two leading ones, a lightly damped bending pair)
    leading = np.sort(np.abs(np.linalg.eigvals(monodromy)))[::-1][:2]
    leading_fd = np.sort(np.abs(np.linalg.eigvals(differences)))[::-1][:2]
    np.testing.assert_allclose(leading, leading_fd, rtol=1e-4)


def test_a_period_asked_for_again_from_the_same_state_is_not_run_again(problem, monkeypatch):
    import mechanisms._orbit as orbit_module  # patched: the period map's integration (internal)

    setup = shooting_setup(problem, None, 32)
    period_map = setup.fine
    integrations = []
    integrate = orbit_module._integrate
    monkeypatch.setattr(orbit_module, "_integrate", lambda *a, **k: integrations.append(1) or integrate(*a, **k))
    first = period_map.run(setup.guess)
    again = period_map.run(setup.guess.copy())          # the same state: no new run
    assert len(integrations) == 1
    np.testing.assert_array_equal(again.s, first.s)
    np.testing.assert_array_equal(again.monodromy, first.monodromy)
    moved = setup.guess.copy()
    moved[0] += 1e-9
    other = period_map.run(moved, tangent=False)
    assert len(integrations) == 2 and not np.array_equal(other.end_state, first.end_state)
    # a caller cannot change the cached period: the key is a copy, the returned arrays are copies
    first = period_map.run(moved)
    first.state[0] += 1e-4
    first.s[:] = 0.0
    assert len(integrations) == 2
    repeated = period_map.run(moved, tangent=False)
    assert len(integrations) == 2 and np.array_equal(repeated.s, other.s)


@pytest.mark.slow
def test_periodic_state_equals_the_end_of_a_long_transient(problem, shot):
    # N = 64 is outside the error estimate's asymptotic range (see test_untrusted_error_estimate_...):
    # the orbit is the periodic state of this discretisation all the same, stable as best estimate
    assert shot.status == "inaccurate" and shot.is_stable
    setup = shooting_setup(problem, None, 64)
    # 40 periods from the linear state: the slowest multiplier 0.70 leaves 0.7^40 ~ 1e-6 of the start
    transient = setup.fine.run(setup.guess, n_periods=40, tangent=False)
    observable = setup.fine.model.observable(SPEC)
    nominal = np.array([observable.value(s) for s in setup.linear.context.nominal.s])
    values = np.array([observable.value(s) for s in transient.s])
    last, previous = values[-65:] - nominal, values[-129:-64] - nominal
    peak_to_peak = np.ptp(last)
    assert np.abs(last - previous).max() <= 1e-5 * peak_to_peak   # settled: successive periods agree
    assert np.abs(last - shot.response[SPEC]).max() <= shot.response_error[SPEC]
    # and the near-resonance correction of the linear model the issue names: about 0.91 at N = 256
    nonlinear, linear = shot.peak_to_peak[SPEC], shot.linear_peak_to_peak[SPEC]
    assert 0.88 < nonlinear / linear < 0.95


@pytest.mark.slow
def test_tends_to_the_linear_state_as_the_amplitude_squared(problem):
    # the crank length scales the coupler's kinematic excitation, at nearly the same frequencies
    amplitudes, differences = [], []
    # N = 256: at 128 the N/2 error estimate is not in its asymptotic range at the two larger
    # amplitudes (ratio 2.3-2.6, not ~4; the linear steady state is inaccurate there too)
    for factor in (0.5, 0.25, 0.125):
        result = studies.nonlinear_steady_state(problem, {"links.crank.length": 0.0508 * factor}, n_steps=256)
        assert result.status == "ok"
        amplitudes.append(np.ptp(result.linear_response[SPEC]))
        differences.append(np.abs(result.response[SPEC] - result.linear_response[SPEC]).max())
    slope = np.polyfit(np.log(amplitudes), np.log(differences), 1)[0]
    # second-order terms: slope 2; the measured 2.3-2.7 (docs/studies.md) also carries the amplitude
    # dependence of the linearisation's own coefficients
    assert 1.8 < slope < 3.0
    relative = np.array(differences) / np.array(amplitudes)
    assert np.all(np.diff(relative) < 0.0) and relative[-1] < 0.005


def _against_a_long_transient(problem, n_steps):
    """({spec: max |orbit - transient| over the period}, the orbit): the nonlinear periodic state
    against the last of 40 periods of the transient route (``MechanismProblem.simulate``, the run the
    nonlinear check reads, from the linear periodic state: the slowest multiplier ~0.7 leaves
    ~1e-6 of the start)."""
    import periodic

    orbit = studies.nonlinear_steady_state(problem, n_steps=n_steps)
    linear = problem.linearize(None, n_steps=n_steps)
    steady = periodic.steady_state(linear.system, scheme="trapezoidal")  # the studies' linear state
    run = problem.simulate(linear, steady.x[0], steady.v[0], n_periods=40, steps_per_period=n_steps)
    return {spec: np.abs(run.observables[spec][-(n_steps + 1):] - orbit.response[spec]).max()
            for spec in orbit.response}, orbit


@pytest.mark.slow
def test_forces_torques_and_stresses_of_the_orbit_are_those_a_long_transient_ends_in():
    # totals as the linear steady state reports them: the joint force from the multipliers, the drive
    # torque, the bending stress with the nominal axial part. Each period of the map restarts the
    # multipliers; read over the orbit's first period they were off by about their own error bar
    # (0.8-1.2 of it at N = 64-256)
    specs = [SPEC, "coupler.stress_top@0.5", "joint.B.force", "drive.O.torque"]
    problem = studies.MechanismProblem.from_scene("four_bar_fem4", observables=specs)
    differences, orbit = _against_a_long_transient(problem, 128)
    for spec in specs:
        assert np.isfinite(orbit.response[spec]).all()
        assert differences[spec] <= 0.1 * orbit.response_error[spec], spec


@pytest.mark.slow
def test_the_torque_of_a_saturated_drive_stays_within_its_limit():
    # the torque the run applied: feedforward and feedback summed, then limited (the linear route's
    # nominal + change exceeds the limit; adding the nominal to a limited feedback did too)
    limit = 1.5
    mechanism = mechanisms.load("four_bar_controlled").with_parameter("drive.torque_limit", limit)
    problem = studies.MechanismProblem.from_mechanism(mechanism, observables=[SPEC, "drive.O.torque"])
    result = studies.nonlinear_steady_state(problem, n_steps=128)
    assert result.is_stable
    torque, linear = result.response["drive.O.torque"], result.linear_response["drive.O.torque"]
    assert np.abs(linear).max() > 1.5 * limit                       # the unlimited law asks for more
    assert np.abs(torque).max() <= limit * (1.0 + 1e-12)
    assert np.isclose(np.abs(torque).max(), limit)                 # and the drive saturates


@pytest.mark.slow
def test_the_torque_of_a_torque_drive_is_its_total_once():
    # a motor under PD control: the torque is the feedforward (the nominal inverse dynamics) plus the
    # feedback; the period map's model applies the feedforward itself (it was counted twice: 59 % of
    # the peak to peak off)
    specs = [SPEC, "drive.O.torque"]
    problem = studies.MechanismProblem.from_scene("four_bar_controlled", observables=specs)
    differences, orbit = _against_a_long_transient(problem, 128)
    for spec in specs:
        assert differences[spec] <= 1e-3 * np.ptp(orbit.response[spec]), spec


def test_result_round_trip_plot_and_summary(shot, tmp_path):
    from studies import kinds

    with studies.open_file(tmp_path / "r.h5", "w") as handle:
        shot.to_hdf5(handle.create_group("nonlinear_steady_state"))
    back = studies.load(tmp_path / "r.h5")["nonlinear_steady_state"]
    np.testing.assert_array_equal(back.response[SPEC], shot.response[SPEC])
    np.testing.assert_array_equal(back.multipliers, shot.multipliers)
    assert back.status == shot.status and back.message == shot.message
    plot = shot.plot()
    assert SPEC in plot.artists and "multipliers" in plot.artists
    assert "peak to peak nonlinear / linear" in kinds()["nonlinear_steady_state"].summary(shot)
    # the summary table's rows: the numbers worked out here from the result's fields
    summary = kinds()["nonlinear_steady_state"].headlines(shot)
    rows = {row.quantity: row for row in summary.rows}
    nonlinear, linear = np.ptp(shot.response[SPEC]), np.ptp(shot.linear_response[SPEC])
    assert rows[f"{SPEC} peak to peak"].value == pytest.approx(nonlinear)
    assert rows[f"{SPEC} peak to peak"].error == pytest.approx(2 * shot.response_error[SPEC])
    assert rows[f"{SPEC} peak to peak, nonlinear / linear"].value == pytest.approx(nonlinear / linear)
    assert rows["spectral radius of the nonlinear orbit"].value == shot.spectral_radius
    assert summary.status == shot.headline


def test_failed_newton_is_a_status_not_an_exception(problem):
    result = studies.nonlinear_steady_state(problem, n_steps=32, max_iterations=1, tol=1e-14)
    assert result.status == "failed" and not result.is_stable
    assert "did not converge" in result.message


def test_bad_arguments_name_themselves(problem):
    with pytest.raises(studies.StudiesError, match="n_steps"):
        studies.nonlinear_steady_state(problem, n_steps=8)
    with pytest.raises(studies.StudiesError, match="tol"):
        studies.nonlinear_steady_state(problem, tol=2.0)
    with pytest.raises(mechanisms.ArgumentError, match="shooting state"):
        mechanisms.PeriodMap(mechanisms.load("four_bar_fem4"), n_steps=8).start_state(np.zeros(3))


@pytest.mark.slow
def test_continuation_over_speed_against_single_orbits(problem, monkeypatch):
    from studies import kinds
    from studies._kinds import nonlinear_steady_state as steady_module  # the levels' accuracy

    sweep = studies.nonlinear_sweep(problem, start=96.0, stop=100.0, n_steps=128, step=2.0)
    assert sweep.status == "ok" and sweep.values[0] == 96.0 and sweep.values[-1] == 100.0
    assert sweep.stable.all() and sweep.after_instability == ""
    single = studies.nonlinear_steady_state(problem, {"speed": 100.0}, n_steps=128, tol=1e-8)
    np.testing.assert_allclose(sweep.linear_at_branch[SPEC][-1], single.linear_peak_to_peak[SPEC], rtol=1e-9)
    # the peak-to-peak error of each orbit: N against N/2, here against two separate shootings from the
    # linear start (N = 128 and 64); the N/2 orbit also gave each orbit's multipliers their error bars
    half = studies.nonlinear_steady_state(problem, {"speed": 100.0}, n_steps=64, tol=1e-8)
    difference = abs(single.peak_to_peak[SPEC] - half.peak_to_peak[SPEC])
    # with every orbit converged to tol (the N/2 orbits too), the branch's end point is the orbit a
    # single shooting finds there (independent start: the linear state), and its error the shootings'
    with monkeypatch.context() as patch:
        patch.setattr(steady_module, "LEVEL_ACCURACY", None)
        patch.setattr("studies._kinds.nonlinear_sweep.LEVEL_ACCURACY", None)
        exact = studies.nonlinear_sweep(problem, start=96.0, stop=100.0, n_steps=128, step=2.0)
    np.testing.assert_allclose(exact.peak_to_peak[SPEC][-1], single.peak_to_peak[SPEC], rtol=1e-6)
    np.testing.assert_allclose(exact.peak_to_peak_error[SPEC][-1], difference / 3.0, rtol=1e-4)
    # by default each orbit settled within LEVEL_ACCURACY of its distance from its N/2 orbit (and
    # each N/2 orbit to it of its distance from the N orbit): the end point within a few of those
    # shares of that distance from the orbit to tol, and its error bar widened by that share
    # and the sweep says so (the exact one does not)
    assert "orbits settled within their error" in sweep.message
    assert "settled within" not in exact.message
    accuracy, slack = steady_module.LEVEL_ACCURACY, periodic.SETTLE_SLACK
    assert abs(sweep.peak_to_peak[SPEC][-1] - single.peak_to_peak[SPEC]) <= 3 * slack * accuracy * difference
    np.testing.assert_allclose(sweep.peak_to_peak_error[SPEC], exact.peak_to_peak_error[SPEC],
                               rtol=(2 + 3 * slack) * accuracy)
    assert np.all(sweep.peak_to_peak_error[SPEC] > 0.0) and sweep.peak_to_peak_error[SPEC].size == sweep.values.size
    assert sweep.linear_values[0] == 96.0 and sweep.linear_peak_to_peak[SPEC].size == sweep.linear_values.size
    plot = sweep.plot()
    assert SPEC in plot.artists
    rows = {row.quantity: row for row in kinds()["nonlinear_sweep"].headlines(sweep).rows}
    largest = rows[f"{SPEC} largest peak to peak (nonlinear orbit)"]
    assert largest.value == pytest.approx(sweep.peak_to_peak[SPEC].max())
    assert rows["loss of stability"].value == "none on the branch"


@pytest.mark.slow
def test_the_sweep_judges_its_orbits_with_the_n_over_2_error_bars(problem, monkeypatch):
    # issue: continue_orbits was called without estimate=, so ok / unstable rested on a bare tolerance
    import periodic

    seen = {}
    follow = periodic.continue_orbits

    def spy(period_map, *args, **options):
        seen.update(options)
        return follow(period_map, *args, **dict(options, max_points=2))

    monkeypatch.setattr(periodic, "continue_orbits", spy)
    sweep = studies.nonlinear_sweep(problem, start=99.0, stop=100.0, n_steps=32, transient_periods=4,
                                    max_points=2)
    assert seen["estimate"].period_map.n_steps == 16 and seen["error_factor"] == pytest.approx(1 / 3)
    assert sweep.peak_to_peak_error[SPEC].shape == sweep.values.shape


def test_transient_classification_names_the_period():
    from studies._kinds.nonlinear_sweep import _settles  # the sweep's internal verdict: no public face

    k = np.arange(40)[:, None]
    period_one = np.ones((40, 4)) + 0.5 ** k                          # converges to one state
    period_two = np.ones((40, 4)) + 0.3 * (-1.0) ** k + 0.5 ** k       # alternates: period 2T
    drifting = np.ones((40, 4)) + np.sin(0.7 * k)                      # quasi-periodic
    assert "period T " in _settles(period_one)
    assert "period 2T" in _settles(period_two)
    assert "does not settle" in _settles(drifting)


@pytest.mark.slow
def test_nonlinear_check_against_the_periodic_state(problem):
    # N = 128: at 64 the two error estimates (near resonance) already cover the 7.6 % difference
    near_resonance = studies.nonlinear_check(problem, n_steps=128, periodic_state=True)
    assert near_resonance.verdict == "differs" and near_resonance.settings["periodic_state"]
    assert 0.07 < near_resonance.relative_difference[SPEC] < 0.10
    # the transient route (20 periods from the linear state; the slowest multiplier 0.69 leaves
    # 0.69^20 ~ 6e-4 of the start) sees the same difference
    transient = studies.nonlinear_check(problem, n_steps=128, n_periods=20)
    assert transient.relative_difference[SPEC] == pytest.approx(near_resonance.relative_difference[SPEC], rel=0.02)
    weak = studies.nonlinear_check(problem, {"links.crank.length": 0.0508 / 8}, n_steps=128, periodic_state=True)
    assert weak.verdict == "agrees"


def test_scene_tables_are_checked():
    from studies import kinds

    steady = kinds()["nonlinear_steady_state"].check("studies.nonlinear_steady_state", {"speed": 90.0}, 128)
    assert steady == {"values": {"speed": 90.0}, "n_steps": 128, "tol": None, "max_iterations": 12,
                      "modes": "auto"}
    sweep = kinds()["nonlinear_sweep"]
    options = sweep.check("studies.nonlinear_sweep", {"parameter": "links.crank.length", "start": 0.05,
                                                      "stop": 0.04, "method": "arclength"}, 256)
    assert options["n_steps"] == 128 and options["method"] == "arclength"
    assert sweep.varies(options) == ("links.crank.length",)
    with pytest.raises(studies.StudiesError, match="missing stop"):
        sweep.check("studies.nonlinear_sweep", {"start": 1.0}, 128)
    with pytest.raises(studies.StudiesError, match="method"):
        sweep.check("studies.nonlinear_sweep", {"start": 1.0, "stop": 2.0, "method": "secant"}, 128)
    # was ZeroDivisionError (exit 1) in the guard's cost model: an empty range is bad input, exit 2
    with pytest.raises(studies.StudiesError, match="stop: expected a value different from start"):
        sweep.check("studies.nonlinear_sweep", {"start": 90.0, "stop": 90.0}, 128)


def test_an_empty_sweep_range_from_the_command_line_is_exit_2(tmp_path, capsys):
    from studies.cli import main

    scene = tmp_path / "sweep.toml"
    scene.write_text((Path(mechanisms.__file__).parent / "scenes" / "four_bar_fem4.toml").read_text()
                     + "\n[studies.nonlinear_sweep]\nstart = 90.0\nstop = 100.0\n")
    out = tmp_path / "sweep.h5"
    assert main(["run", str(scene), "--only", "nonlinear_sweep", "--set", "studies.nonlinear_sweep.stop=90",
                 "--quiet", "--out", str(out)]) == 2
    assert not out.exists()
    err = capsys.readouterr().err
    assert "stop: expected a value different from start" in err and len(err.splitlines()) == 1


@pytest.mark.slow
def test_period_doubling_of_the_nonlinear_orbit_confirmed_by_a_transient():
    # four_bar_ritz, the stiffened thesis four-bar: the linear model doubles its period at 183 rad/s
    # (README); the nonlinear orbit loses stability the same way, a little earlier
    # with a joint force as well: the transient past the instability reports it as the orbits do
    ritz = studies.MechanismProblem.from_scene("four_bar_ritz", observables=[SPEC, "joint.B.force"])
    sweep = studies.nonlinear_sweep(ritz, start=170.0, stop=180.0, n_steps=128, step=4.0, transient_periods=60)
    assert np.isfinite(sweep.transient["joint.B.force"]).all()
    assert sweep.status == "unstable"
    (where,), (kind,) = sweep.bifurcation_values, sweep.bifurcation_kinds
    assert kind == "period_doubling" and 170.0 < where < 180.0
    assert "period 2T" in sweep.after_instability
    # independently of the states the words come from: the transient's observable over its last
    # periods repeats every 2T, not every T
    spec = next(iter(sweep.transient))
    values, n = sweep.transient[spec], 128
    last, one_before, two_before = values[-n:], values[-2 * n:-n], values[-3 * n:-2 * n]
    assert np.abs(last - two_before).max() < 0.01 * np.abs(last - one_before).max()


@pytest.mark.slow
def test_continuation_through_the_sharp_bend_near_73_rad_s():
    # four_bar_fem4's branch bends sharply at 72.5 rad/s: the secant of the step that arrives there
    # differs from the branch's direction just past it by more than the 30 degree turn limit, and a
    # turn check against that secant refused every step down to min_step (issue 12); against the
    # local tangent the branch goes on
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    # (every orbit to tol: the end point compared with a single shooting's to 1e-6)
    sweep = studies.nonlinear_sweep(problem, start=68.0, stop=76.0, n_steps=64, step=2.25, tol=1e-8)
    assert sweep.status == "ok", sweep.message
    assert 72.5 in sweep.values and sweep.values[-1] == 76.0
    assert np.all(np.diff(sweep.values) > 0.0)
    # the end point is the orbit a single shooting from the linear state finds there
    single = studies.nonlinear_steady_state(problem, {"speed": 76.0}, n_steps=64, tol=1e-8)
    np.testing.assert_allclose(sweep.peak_to_peak[SPEC][-1], single.peak_to_peak[SPEC], rtol=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("split_steps", [256, 128], ids=["N", "N/2"])
def test_split_integrator_steps_make_the_orbit_inaccurate_not_ok(problem, trusted, monkeypatch, split_steps):
    # the monodromy is exact only for a period run in its N uniform steps (PeriodRun.n_substeps == 0);
    # an orbit the integrator reached only by splitting steps (on N, or on the N/2 run of the error
    # estimate) must not be reported ok, and the words must not call it stable without saying so
    import dataclasses

    assert trusted.status == "ok" and trusted.message.startswith("stable")
    run = mechanisms.PeriodMap.run

    def split_run(self, x, **options):
        result = run(self, x, **options)
        return dataclasses.replace(result, n_substeps=2) if self.n_steps == split_steps else result

    monkeypatch.setattr(mechanisms.PeriodMap, "run", split_run)
    split = studies.nonlinear_steady_state(problem, n_steps=256)
    assert split.status == "inaccurate" and "substeps" in split.message and "n_steps" in split.message
    assert split.message.startswith("inaccurate: ") and "not trusted: stable" in split.message
    assert ("N/2 run" in split.message) == (split_steps == 128)
    np.testing.assert_array_equal(split.state, trusted.state)


def test_untrusted_error_estimate_makes_the_orbit_inaccurate(problem, shot, trusted):
    # issue: at N = 64 the linear steady state is inaccurate (successive-difference ratio 0.955, not ~4)
    # while the nonlinear one said ok. The N/4 orbit's check must refuse the estimate as the linear one
    # does, and the refusal is warranted: against the N = 256 orbit (error estimate trusted, ~16x
    # smaller error) the N = 64 response is off by more than its own estimate
    linear = studies.steady_state(problem, n_steps=64)
    assert linear.status == "inaccurate"
    assert shot.status == "inaccurate" and shot.is_stable
    assert "N/4" in shot.message and shot.message.startswith("inaccurate: refine n_steps")
    assert "not trusted: stable" in shot.message
    true_error = np.abs(shot.response[SPEC] - trusted.response[SPEC][::4]).max()
    assert true_error > shot.response_error[SPEC]
    assert trusted.status == "ok" and trusted.response_error[SPEC] < 0.2 * shot.response_error[SPEC]


@pytest.mark.slow
def test_nonlinear_check_carries_the_orbits_verdict_and_no_agreement_without_its_error(problem, monkeypatch):
    # issue: with periodic_state only a failed orbit was set aside: an inaccurate one still gave
    # agrees / differs under the linear state's ok, and a NaN error estimate counted as zero
    import dataclasses

    from studies._kinds import nonlinear_steady_state as module  # patched: the name the check calls

    shoot = module.nonlinear_steady_state

    def untrusted(*args, **options):
        orbit = shoot(*args, **options)
        return dataclasses.replace(orbit, status="inaccurate", message="inaccurate: the orbit's own reason",
                                   response_error={spec: float("nan") for spec in orbit.response_error})

    values = {"links.crank.length": 0.0508 / 8}
    trusted = studies.nonlinear_check(problem, values, n_steps=256, periodic_state=True)
    assert trusted.status == "ok" and trusted.verdict == "agrees"
    monkeypatch.setattr(module, "nonlinear_steady_state", untrusted)
    check = studies.nonlinear_check(problem, values, n_steps=256, periodic_state=True)
    assert check.status == "inaccurate" and "the orbit's own reason" in check.message
    assert check.verdict != "agrees" and "unknown" in check.message
