"""Every result as a table: ``to_dataframe()`` / ``to_xarray()`` against the arrays of the HDF5 file the
same result was written to (read with h5py, not through the result), and ``flexvib export --csv``."""

from __future__ import annotations

import csv
import sys

import h5py
import numpy as np
import pytest

import studies
from studies._integrity import BOOKKEEPING_DATASETS  # the file's checksums: no public face
from studies.cli import main

pandas = pytest.importorskip("pandas")
xarray = pytest.importorskip("xarray")


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A sweep, a stability chart (two axes), a Campbell diagram and a steady state of the Mathieu
    problem in one result file, and the results as loaded back."""
    path = tmp_path_factory.mktemp("tables") / "mathieu.h5"
    problem = studies.mathieu_problem(epsilon=0.3, damping_ratio=0.05)
    with studies.open_file(path, "w") as handle:
        studies.sweep(problem, "speed", np.linspace(1.5, 2.5, 7), n_steps=32, out=handle)
        studies.stability_chart(problem, ("speed", np.linspace(1.5, 2.5, 4)), ("epsilon", [0.1, 0.3, 0.5]),
                                n_steps=32, out=handle)
        studies.campbell(problem, np.linspace(1.0, 3.0, 5), n_steps=32, out=handle)
        studies.steady_state(problem, n_steps=32).to_hdf5(handle.create_group("steady_state"))
    return path, studies.load(path)


def _datasets(group):
    """{path inside the group: array} of every dataset, with its units."""
    found = {}

    def add(name, item):
        if hasattr(item, "shape"):
            found[name] = item    # (returning None: visititems goes on)

    group.visititems(add)
    return {name: (item.asstr()[()] if item.dtype.kind == "O" else item[()], item.attrs.get("units", ""))
            for name, item in found.items()}


def _column(path: str) -> str:
    """The data frame's column of a dataset path: ``peak_to_peak/<spec>`` -> ``peak_to_peak[<spec>]``."""
    head, _, key = path.partition("/")
    head = {"point_run_time": "run_time"}.get(head, head)   # a grid's point verdicts: status, message, run_time
    return f"{head}[{key}]" if key else head


@pytest.mark.parametrize("study, axes", [("sweep", ["speed"]), ("stability_chart", ["speed", "epsilon"]),
                                         ("campbell", ["speed"]), ("steady_state", ["t"])])
def test_every_column_is_the_file_s_array_and_unit(written, study, axes):
    path, results = written
    frame = results[study].to_dataframe()
    assert list(frame.columns[:len(axes)]) == axes
    with h5py.File(path, "r") as handle:
        arrays = _datasets(handle[study])
        grid = tuple(handle[study][name].shape[0] for name in
                     {"sweep": ["values"], "stability_chart": ["first", "second"], "campbell": ["speeds"],
                      "steady_state": ["t"]}[study])
    assert len(frame) == int(np.prod(grid))
    compared = 0
    assert not set(BOOKKEEPING_DATASETS) & {column.split("[")[0] for column in frame.columns}
    for name, (array, unit) in arrays.items():
        if name in BOOKKEEPING_DATASETS:   # the file's checksums of its points, not a field of the study
            continue
        array = np.asarray(array)
        if array.shape[:len(grid)] != grid or array.ndim > len(grid) + 1:
            continue
        flat = array.reshape((len(frame),) + array.shape[len(grid):])
        entries = range(flat.shape[1]) if flat.ndim > 1 else ()
        if unit == "SI (see labels)":      # the coordinates, by their labels
            entries = results[study].labels
        columns = [_column(name)] if flat.ndim == 1 else [f"{_column(name)}[{j}]" for j in entries]
        for j, column in enumerate(columns):
            if column not in frame:     # an axis (or a field equal to it) is the axis column
                assert name in ("values", "first", "second", "speeds", "t", "speed"), name
                continue
            expected = flat if flat.ndim == 1 else flat[:, j]
            got = frame[column].to_numpy()
            if expected.dtype.kind in "fc":
                np.testing.assert_array_equal(got.astype(expected.dtype), expected)
            else:
                assert list(got.astype(str) if expected.dtype.kind in "US" else got) == list(expected)
            assert frame.attrs["units"][column] == unit, column
            compared += 1
    assert compared >= 3
    # the rows: every combination of the axes, the first one slowest
    if study == "stability_chart":
        with h5py.File(path, "r") as handle:
            first, second = handle[study]["first"][()], handle[study]["second"][()]
        np.testing.assert_array_equal(frame["speed"], np.repeat(first, second.size))
        np.testing.assert_array_equal(frame["epsilon"], np.tile(second, first.size))


def test_the_study_s_verdict_and_scalars_are_in_attrs(written):
    path, results = written
    sweep = results["sweep"]
    frame = sweep.to_dataframe()
    assert frame.attrs["kind"] == "sweep"
    assert frame.attrs["status"] == sweep.status and frame.attrs["message"] == sweep.message
    assert frame.attrs["run_time"] == sweep.run_time
    # per point: the verdicts under the file's dataset names
    with h5py.File(path, "r") as handle:
        assert list(frame["status"]) == list(handle["sweep"]["status"].asstr()[()])
    assert frame.attrs["units"]["speed"] == "rad/s"
    steady = results["steady_state"].to_dataframe()
    assert steady.attrs["peak_to_peak"] == results["steady_state"].peak_to_peak
    assert steady.attrs["units"]["t"] == "s"


def test_xarray_has_the_swept_parameters_as_coordinates(written):
    path, results = written
    chart = results["stability_chart"].to_xarray()
    assert chart["spectral_radius"].dims == ("speed", "epsilon")
    with h5py.File(path, "r") as handle:
        group = handle["stability_chart"]
        np.testing.assert_array_equal(chart["speed"].to_numpy(), group["first"][()])
        np.testing.assert_array_equal(chart["epsilon"].to_numpy(), group["second"][()])
        np.testing.assert_array_equal(chart["spectral_radius"].to_numpy(), group["spectral_radius"][()])
        assert chart["spectral_radius"].attrs["units"] == group["spectral_radius"].attrs["units"]
    one = chart["spectral_radius"].sel(speed=chart["speed"][2], epsilon=0.5)
    assert float(one) == results["stability_chart"].spectral_radius[2, 2]
    # a Campbell diagram's frozen frequencies (speed x crank angle x mode) keep their dimensions
    campbell = results["campbell"].to_xarray()
    assert campbell["frozen"].dims[0] == "speed" and campbell["frozen"].ndim == 3
    assert "frozen" in results["campbell"].to_dataframe().attrs["left_out"]
    for table in (chart, campbell):   # the file's checksums of the points are no variable
        assert not set(BOOKKEEPING_DATASETS) & set(table.variables)


def test_rows_may_be_another_field(written):
    _, results = written
    sweep = results["sweep"]
    frame = sweep.to_dataframe(rows="values")
    assert len(frame) == sweep.values.size
    with pytest.raises(studies.StudiesError, match="rows: expected a field"):
        sweep.to_dataframe(rows="nonsense")


def test_missing_pandas_is_said_with_the_extra_to_install(written, monkeypatch):
    _, results = written
    monkeypatch.setitem(sys.modules, "pandas", None)   # import pandas now raises ImportError
    with pytest.raises(studies.StudiesError, match=r"flexvib\[tables\]"):
        results["sweep"].to_dataframe()
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(studies.StudiesError, match=r"flexvib\[tables\]"):
        results["sweep"].to_xarray()


def test_export_csv_writes_each_study_and_its_units(written, tmp_path, capsys):
    path, results = written
    folder = tmp_path / "csv"
    assert main(["export", str(path), "--csv", str(folder)]) == 0
    for name, result in results.items():
        table = pandas.read_csv(folder / f"{name}.csv")
        frame = result.to_dataframe()
        assert list(table.columns) == list(frame.columns)
        numeric = [c for c in frame.columns if frame[c].dtype.kind == "f"]
        np.testing.assert_allclose(table[numeric].to_numpy(), frame[numeric].to_numpy(), rtol=1e-15)
        with (folder / f"{name}_info.csv").open() as handle:
            info = dict(csv.reader(handle))
        assert info["status"] == result.status
        assert all(info[f"unit:{c}"] == u for c, u in frame.attrs["units"].items())
    assert main(["export", str(tmp_path / "nosuch.h5"), "--csv", str(tmp_path / "never")]) == 2
    assert not (tmp_path / "never").exists()


def test_the_coordinates_are_named_by_their_labels(written):
    path, results = written
    steady = results["steady_state"]
    frame, dataset = steady.to_dataframe(), steady.to_xarray()
    with h5py.File(path, "r") as handle:
        x = handle["steady_state"]["x"][()]
    for j, name in enumerate(steady.labels):
        np.testing.assert_array_equal(frame[f"x[{name}]"], x[:, j])
    assert dataset["x"].dims == ("t", "coordinate") and list(dataset["coordinate"].values) == list(steady.labels)
