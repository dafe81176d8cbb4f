"""The fused generalized-alpha step (``mechanisms/_alpha_kernel.py``: the Newton iteration of a step in one
numba call) against the Python iteration it replaces (``_Stepper._newton``, the model's methods), run for
run: the four-bar, the six-bar, the arm, a torque drive with a motor, a PD, a linear feedback and its
limits, the same with a lagged controller, a ramped drive, coarse steps that need substeps.

Both iterations evaluate the same kernels in the same order; they differ only in the summation order of a
few dot products (the drive rows' ``h_lin s`` by BLAS against a loop, a torque law's ``P.s + D.s'`` by
numpy against a loop, a lag's constant part associated differently): round-off, some 1e-16 of each term.
Newton stops at the same iterations unless an increment lies within round-off of the tolerance, so the runs
report the same counts and agree to round-off: bitwise without torque drives; with them the positions to
1e-16 and the velocities to 3e-13 of their largest values (measured), and the accelerations and multipliers
to about 1e-10: they are ``(q - qhat) / beta'`` with ``beta' ~ h^2 / 4`` (7e-8 s^2 at 128 steps a period),
so a round-off of q reaches them divided by beta', and Newton's tolerance itself holds them only to
``tol / beta'`` (1e-10 m / 7e-8 s^2 = 1.4e-3 m/s^2, 2e-7 of their largest). The assertion allows 1e-12 of
the largest value for positions, velocities and lag states and 1e-9 for accelerations and multipliers; a
wrong term in the kernel (a missed torque, Jacobian or lag term, a wrong clip) exceeds that by orders of
magnitude (a torque term's Jacobian alone changes the counts; its value moves the motion by its size).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import mechanisms
from mechanisms import _alpha_step  # the switch between the two iterations: no public face

#: each compared quantity with its allowed difference, relative to its largest value (module docstring)
QUANTITIES = {"s": 1e-12, "sdot": 1e-12, "lag_states": 1e-12, "sddot": 1e-9, "lam": 1e-9}
COUNTS = ("n_steps", "n_newton", "n_jacobian", "n_factorizations", "n_rejected", "n_substeps")


def both(monkeypatch, system, **options):
    """The run of ``mechanisms.simulate`` with the fused step and with the Python iteration."""
    runs = []
    for fused in (True, False):
        monkeypatch.setattr(_alpha_step, "FUSED_STEP", fused)
        runs.append(mechanisms.simulate(system, estimate_error=False, **options))
    return runs


def assert_same_run(fused, python):
    assert fused.success and python.success, (fused.message, python.message)
    for name, rtol in QUANTITIES.items():
        a, b = getattr(fused, name), getattr(python, name)
        scale = max(float(np.abs(b).max(initial=0.0)), 1e-300)
        assert np.abs(a - b).max(initial=0.0) <= rtol * scale, name
    assert {k: getattr(fused, k) for k in COUNTS} == {k: getattr(python, k) for k in COUNTS}
    assert fused.message == python.message


def controlled(lag=0.0, torque_limit=None):
    """``four_bar_controlled`` with its strain feedback on the midspan deflection (linear in s, so the
    fused step evaluates it), optionally lagged and with a lower torque limit (clipped near its peaks)."""
    mechanism = mechanisms.load("four_bar_controlled")
    mechanism = mechanism.with_parameter("controllers.strain.observable", "coupler.deflection@0.5")
    mechanism = mechanism.with_parameter("controllers.strain.gain", 20.0)
    mechanism = mechanism.with_parameter("controllers.strain.rate_gain", 0.05)
    if lag:
        mechanism = mechanism.with_parameter("controllers.strain.lag", lag)
    if torque_limit is not None:
        mechanism = mechanism.with_parameter("drive.torque_limit", torque_limit)
    return mechanism


def kernel_of(mechanism):
    return mechanisms.integrated_model(mechanism).step_kernel()


@pytest.mark.parametrize("scene", ["four_bar_fem4", "six_bar", "two_link_arm"])
def test_fused_step_repeats_the_python_iteration(monkeypatch, scene):
    mechanism = mechanisms.load(scene)
    assert kernel_of(mechanism) is not None
    assert_same_run(*both(monkeypatch, mechanism, n_periods=1.5, steps_per_period=128))


def test_fused_step_with_a_torque_drive_its_motor_and_limits(monkeypatch):
    mechanism = controlled(torque_limit=1.8)
    kernel = kernel_of(mechanism)
    assert kernel is not None and kernel.grad.shape[0] == 1
    assert np.isfinite(kernel.command_limit).all() and kernel.torque_limit[0] == 1.8
    fused, python = both(monkeypatch, mechanism, n_periods=2, steps_per_period=128)
    assert_same_run(fused, python)
    # the limit is reached: the clipped branch of the law was taken
    model = mechanisms.integrated_model(mechanism)
    torque = [model.drive_torques(s, v, t)[0] for s, v, t in zip(fused.s, fused.sdot, fused.t)]
    assert np.isclose(np.abs(torque).max(), 1.8)


def test_fused_step_with_a_lagged_controller(monkeypatch):
    mechanism = controlled(lag=2e-3)
    kernel = kernel_of(mechanism)
    assert kernel is not None and len(kernel.lags) == 1
    fused, python = both(monkeypatch, mechanism, n_periods=2, steps_per_period=128)
    assert_same_run(fused, python)
    assert np.abs(fused.lag_states).max() > 0.0


def test_fused_step_with_a_ramped_drive(monkeypatch):
    mechanism = mechanisms.load("four_bar_fem4")
    nominal = mechanisms.nominal_motion(mechanism)
    model = mechanisms.integrated_model(mechanism).with_drive_profiles(
        lambda drive: mechanisms.SpeedRamp(drive.rate, 1.5 * drive.rate, 0.1))
    s0, sdot0 = nominal.s[0], nominal.sdot[0]
    assert_same_run(*both(monkeypatch, model, t_end=0.1, dt=0.1 / 300, s0=s0, sdot0=sdot0))


@pytest.mark.parametrize("scene", ["four_bar_fem4", "six_bar"])
def test_fused_step_retries_in_substeps_as_the_python_iteration(monkeypatch, scene):
    """With 3 Newton iterations allowed at 64 steps a period, some steps fail and are retried in
    substeps (and modified Newton's attempts fall back to full Newton): the same retries, the same run."""
    fused, python = both(monkeypatch, mechanisms.load(scene), n_periods=0.5, steps_per_period=64,
                         max_iterations=3)
    assert fused.n_rejected > 0 and fused.n_substeps > 0
    assert_same_run(fused, python)


def test_a_nonlinear_feedback_keeps_the_python_iteration():
    """The shipped strain feedback is nonlinear in s: no kernel, the Python iteration evaluates it."""
    assert kernel_of(mechanisms.load("four_bar_controlled")) is None


def test_fused_failure_is_worded_as_the_python_iteration(monkeypatch):
    """A step that cannot converge (one Newton iteration allowed) fails with the same message."""
    runs = both(monkeypatch, mechanisms.load("six_bar"), n_periods=0.05, steps_per_period=128,
                max_iterations=1, max_step_halvings=1, throw=False)
    assert not runs[0].success
    assert runs[0].message == runs[1].message
    assert dataclasses.asdict(runs[0]).keys() == dataclasses.asdict(runs[1]).keys()


def test_auto_takes_the_fused_step_when_compiled_or_for_a_long_run(monkeypatch):
    """Under "auto" a run takes the fused kernel when it is compiled (here or in the disk cache) or
    the run is long enough to repay the compile; a short run on a cold cache keeps the Python
    iteration, so the main job's first compile does not grow by the kernel."""
    from mechanisms import _alpha_kernel  # the compiled-or-saved probe: no public face

    monkeypatch.setattr(_alpha_step, "FUSED_STEP", "auto")
    monkeypatch.setattr(_alpha_kernel, "compiled", lambda: False)
    long_run = _alpha_step.FUSED_COMPILE_STEPS
    assert not _alpha_step.fused_step_wanted(long_run - 1) and _alpha_step.fused_step_wanted(long_run)
    monkeypatch.setattr(_alpha_kernel, "compiled", lambda: True)
    assert _alpha_step.fused_step_wanted(8)
    with mechanisms.fused_step(False):
        assert not _alpha_step.fused_step_wanted(10 * long_run)
    assert _alpha_step.FUSED_STEP == "auto"   # restored
    with pytest.raises(mechanisms.ArgumentError, match="fused_step"):
        with mechanisms.fused_step("yes"):
            pass


def test_runs_that_add_up_to_a_long_run_take_the_fused_step(monkeypatch):
    """``fused_step_for(total)``: under "auto", short runs that together step ``FUSED_COMPILE_STEPS``
    times or more take the fused kernel on a cold cache (a nonlinear sweep); fewer keep "auto"'s rule;
    a setting of False or True is kept."""
    from mechanisms import _alpha_kernel

    monkeypatch.setattr(_alpha_step, "FUSED_STEP", "auto")
    monkeypatch.setattr(_alpha_kernel, "compiled", lambda: False)
    total = _alpha_step.FUSED_COMPILE_STEPS
    with mechanisms.fused_step_for(total):
        assert _alpha_step.fused_step_wanted(128)
    with mechanisms.fused_step_for(total - 1):
        assert not _alpha_step.fused_step_wanted(128)
    with mechanisms.fused_step(False), mechanisms.fused_step_for(10 * total):
        assert not _alpha_step.fused_step_wanted(128)
    assert _alpha_step.FUSED_STEP == "auto"


def test_a_long_nonlinear_sweep_takes_the_fused_step_on_a_cold_cache(monkeypatch):
    """The sweep's periods together decide (``PERIODS_PER_ORBIT`` per point): on a cold cache a sweep
    whose points add up to a long run steps by the fused kernel, a short one by the Python iteration."""
    import studies
    from mechanisms import _alpha_kernel
    from studies._kinds import nonlinear_sweep as sweep_kind

    monkeypatch.setattr(_alpha_step, "FUSED_STEP", "auto")
    monkeypatch.setattr(_alpha_kernel, "compiled", lambda: False)
    seen = []
    wanted = _alpha_step.fused_step_wanted
    monkeypatch.setattr(_alpha_step, "fused_step_wanted", lambda n: seen.append(wanted(n)) or seen[-1])
    from mechanisms import _alpha_run  # the runs' own reference to it

    monkeypatch.setattr(_alpha_run, "fused_step_wanted", _alpha_step.fused_step_wanted)
    problem = studies.MechanismProblem.from_scene("four_bar_fem4")
    options = dict(start=96.0, stop=100.0, step=2.0, n_steps=32, modes="full")
    # 2 points x PERIODS_PER_ORBIT x 32 steps: below the threshold, then above it
    monkeypatch.setattr(_alpha_step, "FUSED_COMPILE_STEPS", 2 * sweep_kind.PERIODS_PER_ORBIT * 32 + 1)
    studies.nonlinear_sweep(problem, **options)
    assert seen and not any(seen)
    seen.clear()
    monkeypatch.setattr(_alpha_step, "FUSED_COMPILE_STEPS", 2 * sweep_kind.PERIODS_PER_ORBIT * 32)
    studies.nonlinear_sweep(problem, **options)
    assert seen and all(seen)


def test_the_probe_sees_a_compiled_kernel():
    """``compiled()`` is True once the kernel has run in this process (the tests above ran it)."""
    from mechanisms import _alpha_kernel

    system = mechanisms.load("four_bar_fem1")
    with mechanisms.fused_step(True):
        mechanisms.simulate(system, t_end=system.period / 8, dt=system.period / 64, estimate_error=False)
    assert _alpha_kernel.compiled()


def test_the_main_job_does_not_compile_the_fused_step():
    """The default scene's studies (the main job) run short nonlinear runs: its kernel list (what a
    cold cache compiles, studies/cli/kernel_list.json) leaves the fused step out."""
    import json
    from pathlib import Path

    listed = json.loads((Path(__file__).resolve().parents[1] / "studies" / "cli" / "kernel_list.json").read_text())
    assert listed and not any(entry["kernel"] == "mechanisms._alpha_kernel._newton" for entry in listed)
