"""HDF5 round trip, resume after an interrupted sweep, executors (process pool, Dask), figures."""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import h5py
import numpy as np
import pytest

import studies
from studies import _grid  # patched: the grid store's writes and point evaluation (internal)

SPEEDS = np.linspace(0.3, 2.4, 12)


@pytest.fixture(scope="module")
def results(crossing_problem):
    mathieu = studies.mathieu_problem(epsilon=0.3, damping_ratio=0.05, cubic=1e-3)
    return {
        "steady": studies.steady_state(mathieu, {"speed": 1.3}, n_steps=64),
        "sweep": studies.sweep(mathieu, "speed", SPEEDS, n_steps=32),
        "campbell": studies.campbell(crossing_problem(), SPEEDS, n_steps=32, frozen_samples=4),
        "chart": studies.stability_chart(mathieu, ("speed", SPEEDS[:5]), ("epsilon", [0.1, 0.5, 0.9]),
                                         n_steps=32),
        "nonlinear": studies.nonlinear_check(mathieu, {"speed": 1.3}, n_steps=64, n_periods=2,
                                             from_rest=True, max_periods_from_rest=3),
        "error_cost": studies.error_cost(mathieu, {"speed": 1.3}, n_steps=(16, 32)),
    }


def test_round_trip_of_every_result(results, tmp_path, assert_same):
    path = tmp_path / "run.h5"
    for name, result in results.items():
        result.save(path, name)
    loaded = studies.load(path)
    assert loaded.keys() == results.keys()
    for name, result in results.items():
        assert_same(result, loaded[name])
    with h5py.File(path, "r") as handle:
        assert "numpy" in handle.attrs["versions"] and handle.attrs["created"]
        sweep = handle["sweep"]
        assert sweep["values"].attrs["units"] == "rad/s"
        assert sweep["peak_to_peak/x"].attrs["units"] == "m"
        assert sweep["frozen_mean"].attrs["units"] == "rad/s"
        assert "epsilon = 0.3" in sweep.attrs["scene"] and sweep.attrs["complete"]
        assert handle["steady"]["response/x"].attrs["units"] == "m"


def test_resume_after_an_interrupted_sweep_equals_an_uninterrupted_one(tmp_path, monkeypatch, assert_same):
    problem = studies.mathieu_problem(epsilon=0.3, damping_ratio=0.05)
    with studies.open_file(tmp_path / "whole.h5") as out:
        whole = studies.sweep(problem, "speed", SPEEDS, n_steps=32, out=out)

    write = _grid.GridStore.write
    calls = []

    def killed_after_five(self, index, outcome):
        if len(calls) == 5:
            raise KeyboardInterrupt("simulated kill")
        calls.append(index)
        write(self, index, outcome)

    monkeypatch.setattr(_grid.GridStore, "write", killed_after_five)
    with pytest.raises(KeyboardInterrupt), studies.open_file(tmp_path / "resumed.h5") as out:
        studies.sweep(problem, "speed", SPEEDS, n_steps=32, out=out)
    monkeypatch.setattr(_grid.GridStore, "write", write)

    partial = studies.load(tmp_path / "resumed.h5")["sweep"]  # readable after the kill
    assert partial.done.sum() == 5 and np.isnan(partial.spectral_radius[~partial.done]).all()

    evaluated = []
    evaluate = _grid.evaluate
    monkeypatch.setattr(_grid, "evaluate", lambda *a: evaluated.append(a[2]) or evaluate(*a))
    with studies.open_file(tmp_path / "resumed.h5") as out:
        resumed = studies.sweep(problem, "speed", SPEEDS, n_steps=32, out=out)
    assert len(evaluated) == SPEEDS.size - 5
    assert_same(whole, resumed)
    assert_same(whole, studies.load(tmp_path / "resumed.h5")["sweep"])


def test_resume_refuses_other_settings(tmp_path):
    problem = studies.mathieu_problem()
    with studies.open_file(tmp_path / "run.h5") as out:
        studies.sweep(problem, "speed", SPEEDS[:3], n_steps=16, out=out)
        with pytest.raises(ValueError, match="other settings"):
            studies.sweep(problem, "speed", SPEEDS[:4], n_steps=16, out=out)


def test_process_pool_gives_the_same_numbers(results, crossing_problem, assert_same):
    mathieu = studies.mathieu_problem(epsilon=0.3, damping_ratio=0.05, cubic=1e-3)
    with ProcessPoolExecutor(2) as pool:
        pooled = studies.sweep(mathieu, "speed", SPEEDS, n_steps=32, executor=pool)
        campbell = studies.campbell(crossing_problem(), SPEEDS, n_steps=32, frozen_samples=4, executor=pool)
    assert_same(results["sweep"], pooled)
    assert_same(results["campbell"], campbell)


def test_dask_local_cluster_gives_the_same_numbers(results, assert_same):
    distributed = pytest.importorskip("distributed")
    mathieu = studies.mathieu_problem(epsilon=0.3, damping_ratio=0.05, cubic=1e-3)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp", host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        chart = studies.stability_chart(mathieu, ("speed", SPEEDS[:5]), ("epsilon", [0.1, 0.5, 0.9]),
                                        n_steps=32, executor=client.get_executor())
    assert_same(results["chart"], chart)


AXES = {
    "steady": [("time (s)", "x (m)"), ("Re mu", "Im mu")],  # the Mathieu problem has no crank
    "sweep": [("speed (rad/s)", "x peak to peak (m)"), ("speed (rad/s)", "spectral radius |mu|max")],
    "campbell": [("speed (rad/s)", "frequency (rad/s)")],
    "chart": [("speed (rad/s)", "epsilon"), ("", "spectral radius |mu|max")],
    "nonlinear": [("time (s)", "x (m)")],
    "error_cost": [("run time (s)", "relative error (1)")],
}


@pytest.mark.parametrize("name", sorted(AXES))
def test_each_figure_has_its_axes(results, name):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    drawing = results[name].plot()
    figure = drawing.figure
    assert drawing.artists and all(ax.figure is figure for ax in drawing.axes)
    labels = [(ax.get_xlabel(), ax.get_ylabel()) for ax in figure.axes]
    assert labels == AXES[name]
    plt.close(figure)
