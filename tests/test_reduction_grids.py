"""The modal reduction's error in the grid studies (sweep, Campbell diagram, stability chart): one
check per study at the scene's own values, reported at study level (fields with units in HDF5,
``status``, the summary line and the headlines); nothing for a scene without a reduced
link. The check's number is compared with ``linearize.reduction_error`` run on its own, and
the 1-mode coupler against the full element model (an independent reference)."""

import numpy as np
import pytest

import linearize
import mechanisms as mc
import studies
from studies._studies import reduction_check  # the grid studies' internal check: no public face
from studies._summary import text_table  # the command's summary table: no public face
from tests._support.figure_text import text_problems

FOUR_BAR = mc.load("four_bar_fem4")
DAMPING = "links.coupler.damping.ratio"
#: Speeds (rad/s) below the scene's 100 rad/s where the sweep's points are all ``ok`` at 64 steps,
#: so that the study's status shows the reduction alone.
SPEEDS = (25.0, 50.0)
N_STEPS = 64
#: The sweeps' steps: their points judge their spectral radius too (time step + mesh against
#: error_tolerance): at 64 steps the radius at 25 rad/s reads 0.97 against 0.228 converged (its bar
#: 0.003 misses it: a wrong ok), at 128 and 256 steps it is not yet in the asymptotic range; at 512
#: steps every point is ok (0.228 +- 0.0035).
SWEEP_STEPS = 512


def _coupler(n_elements, modes=None):
    changes = {"links.coupler.discretisation.n_elements": n_elements}
    if modes is not None:
        changes["links.coupler.discretisation.modes"] = modes
    return FOUR_BAR.with_parameters(changes)


def _problem(mechanism):
    return studies.MechanismProblem.from_mechanism(mechanism, parameter_paths=(DAMPING,))


@pytest.fixture(scope="module")
def sweeps():
    """Two-point speed sweeps of the four-bar: 16-element coupler at 1 and 6 modes, and the
    unreduced 4-element coupler."""
    return {modes: studies.sweep(_problem(_coupler(16 if modes else 4, modes)), "speed", SPEEDS,
                                 n_steps=SWEEP_STEPS)
            for modes in (1, 6, None)}


def test_a_sweep_on_a_one_mode_coupler_is_inaccurate_at_study_level(sweeps):
    """One mode leaves the deflection about 0.6 % off against 3 modes: every point is ``ok`` on its
    own, the study is ``inaccurate``, and its summary line and table say why and the fix. The
    number is ``linearize.reduction_error`` at the scene's values, and it is near the actual
    difference from the full element model (within a factor 3)."""
    coarse = sweeps[1]
    assert set(coarse.point_status) == {"ok"}
    assert coarse.reduction_status == "inaccurate" and coarse.status == "inaccurate"
    assert "raise modes" in coarse.reduction_message
    assert "every point's numbers carry this reduction error" in coarse.reduction_message
    own = linearize.reduction_error(_coupler(16, 1), n_steps=SWEEP_STEPS)
    assert coarse.reduction_error == pytest.approx(own.error, rel=1e-9)
    actual = linearize.reduction_error(_coupler(16, 1), n_steps=SWEEP_STEPS, reference="full")
    assert actual.error / 3 < coarse.reduction_error < 3 * actual.error
    assert coarse.reduction_error > linearize.REDUCTION_TOL
    assert 0.0 < coarse.reduction_run_time < coarse.run_time
    line = studies.kinds()["sweep"].summary(coarse)
    assert "inaccurate: at the scene's values, modal reduction error" in line
    table = studies.kinds()["sweep"].headlines(coarse)
    assert table.status == "2 ok; modal reduction inaccurate"
    row = table.rows[-1]
    assert row.quantity.startswith("modal reduction error") and row.value == coarse.reduction_error
    assert "modal reduction inaccurate" in coarse.reduction_note()
    assert "modal reduction error" in text_table({"sweep": table})


def test_a_sweep_on_a_six_mode_coupler_is_ok_with_its_reduction_error_reported(sweeps):
    fine = sweeps[6]
    assert fine.reduction_status == "ok" and fine.status == "ok"
    assert 0.0 < fine.reduction_error < linearize.REDUCTION_TOL
    assert "6 modes against 8" in fine.reduction_message
    assert studies.kinds()["sweep"].headlines(fine).status == "2 ok"
    assert studies.kinds()["sweep"].headlines(fine).rows[-1].value == fine.reduction_error
    assert fine.reduction_note() == ""
    # the reduced sweep's numbers are the full model's to about the reduction's error
    full = studies.sweep(_problem(_coupler(16)), "speed", SPEEDS, n_steps=SWEEP_STEPS)
    spec = "coupler.deflection@0.5"
    assert np.allclose(fine.peak_to_peak[spec], full.peak_to_peak[spec], rtol=10 * fine.reduction_error)


def test_a_sweep_without_a_reduced_link_is_unchanged(sweeps):
    plain = sweeps[None]
    assert (plain.reduction_error, plain.reduction_status, plain.reduction_message,
            plain.reduction_run_time) == (0.0, "ok", "", 0.0)
    assert plain.status == "ok"
    assert "modal reduction" not in studies.kinds()["sweep"].summary(plain)
    headlines = studies.kinds()["sweep"].headlines(plain)
    assert headlines.status == "2 ok"
    assert not any("reduction" in row.quantity for row in headlines.rows)
    assert reduction_check(_problem(_coupler(4)), n_steps=N_STEPS) == {}


def test_a_problem_without_a_mechanism_has_no_reduction_check(crossing_problem):
    assert reduction_check(crossing_problem(), n_steps=N_STEPS) == {}


def test_reduction_fields_round_trip_through_hdf5_with_units(sweeps, tmp_path):
    import h5py

    for modes in (1, None):
        path = tmp_path / f"sweep_{modes}.h5"
        sweeps[modes].save(path, "sweep")
        with h5py.File(path, "r") as handle:
            group = handle["sweep"]
            assert group["reduction_error"].attrs["units"] == "1"
            assert group["reduction_run_time"].attrs["units"] == "s"
            assert "reduction_error" not in group.attrs
        stored = studies.load(path)["sweep"]
        for name in ("reduction_error", "reduction_status", "reduction_message", "reduction_run_time"):
            assert getattr(stored, name) == getattr(sweeps[modes], name), name
        assert stored.status == sweeps[modes].status
        # written again from what was read, the numbers keep their units
        stored.save(path, "again")
        with h5py.File(path, "r") as handle:
            assert handle["again/reduction_error"].attrs["units"] == "1"


def test_a_grid_file_without_reduction_fields_reads_back_with_none(sweeps, tmp_path):
    """Files written before the check read back as 'no reduced link'."""
    import h5py

    path = tmp_path / "old.h5"
    sweeps[None].save(path, "sweep")
    with h5py.File(path, "a") as handle:
        for name in ("reduction_error", "reduction_run_time"):
            del handle["sweep"][name]
        for name in ("reduction_status", "reduction_message"):
            del handle["sweep"].attrs[name]
        # and as such a file is: result format 2, without the checksums of format 3
        for item in (handle, handle["sweep"]):
            item.attrs["format_version"] = 2
            del item.attrs["digest"]
    stored = studies.load(path)["sweep"]
    assert (stored.reduction_error, stored.reduction_status, stored.reduction_message) == (0.0, "ok", "")


@pytest.fixture(scope="module")
def coarse_grids():
    """A Campbell diagram and a stability chart of the four-bar with the 1-mode coupler."""
    problem = _problem(_coupler(16, 1))
    return (studies.campbell(problem, SPEEDS, n_steps=SWEEP_STEPS, frozen_samples=4),
            studies.stability_chart(problem, ("speed", SPEEDS), (DAMPING, (0.02,)), n_steps=SWEEP_STEPS))


def test_campbell_and_stability_chart_report_the_reduction_at_study_level(sweeps, coarse_grids):
    """The same check, once per study, in a Campbell diagram and a stability chart on the 1-mode
    coupler: the same error as the sweep's at the same steps."""
    for result, kind in zip(coarse_grids, (studies.kinds()["campbell"], studies.kinds()["stability_chart"])):
        assert result.reduction_status == "inaccurate" and result.status == "inaccurate"
        assert result.reduction_error == pytest.approx(sweeps[1].reduction_error, rel=1e-9)
        assert "modal reduction inaccurate" in kind.headlines(result).status
        assert "raise modes" in kind.summary(result)
        assert kind.headlines(result).rows[-1].quantity.startswith("modal reduction error")


@pytest.mark.slow
def test_figures_of_a_reduced_grid_name_the_inaccurate_reduction_in_clean_text(sweeps, coarse_grids):
    """The figures' titles carry the study-level verdict (the points' markers cannot show it)."""
    import matplotlib.pyplot as plt

    for result in (sweeps[1], *coarse_grids):
        plot = result.plot()
        titles = " ".join(ax.get_title() for ax in plot.figure.axes)
        assert "modal reduction inaccurate" in titles, type(result).__name__
        assert text_problems(plot.figure) == [], type(result).__name__
        plt.close(plot.figure)
    assert "modal reduction" not in " ".join(ax.get_title() for ax in sweeps[6].plot().figure.axes)
    plt.close("all")


def test_a_failed_reduction_check_is_reported_and_keeps_the_grid(monkeypatch):
    """A numerical failure of the check (either steady state) is the study's ``failed`` reduction
    status, with the cause; the points are computed as usual."""
    import periodic

    def fail(*args, **kwargs):
        raise periodic.ShootingError("no periodic solution (test)")

    monkeypatch.setattr(linearize, "reduction_error", fail)
    result = studies.sweep(_problem(_coupler(16, 1)), "speed", SPEEDS[:1], n_steps=N_STEPS)
    assert result.reduction_status == "failed" and result.status == "failed"
    assert "no periodic solution (test)" in result.reduction_message
    assert np.isnan(result.reduction_error) and result.done.all()


def test_the_guard_counts_a_grid_studys_reduction_check():
    """A sweep on a reduced link is estimated with its reduction check (a linearisation and a solve at
    modes + 2, and one reduced solve at the scene's values); without a reduced link, nothing is added."""
    options = {"parameter": "speed", "values": [25.0, 50.0], "n_steps": 64}
    reduced = studies.estimate(_problem(_coupler(16, modes=2)), "sweep", options)
    full = studies.estimate(_problem(_coupler(16)), "sweep", options)
    assert "reduction check at" in reduced.sizes and "reduction check" not in full.sizes
