"""Result files carry a format version; files of an older format still load (a file written by
flexvib 56570dd, the last version before the format was recorded, is committed in tests/data), and a
file of a newer format is refused with a message naming the version that wrote it and what to do."""

from __future__ import annotations

import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

import studies
from studies.cli import main

#: ``flexvib run mathieu --only steady_state --only sweep --set studies.n_steps=64
#: --set studies.sweep.count=5 --set studies.sweep.start=0.5 --set studies.sweep.stop=1.5``, written
#: by 56570dd (result format 1: no ``format_version``, ``kind`` the result class's name).
FORMAT_1 = Path(__file__).parent / "data" / "mathieu_format1.h5"


@pytest.fixture(scope="module")
def old():
    return studies.load(FORMAT_1)


def test_the_committed_file_is_of_format_1():
    with h5py.File(FORMAT_1, "r") as handle:
        assert "format_version" not in handle.attrs
        assert handle["steady_state"].attrs["kind"] == "SteadyStateResult"


def test_a_format_1_steady_state_loads_with_the_numbers_of_a_fresh_one(old):
    steady = old["steady_state"]
    assert studies.kind_of(steady).name == "steady_state"
    assert steady.parameters["speed"] == 0.7 and steady.n_steps == 64
    fresh = studies.steady_state(studies.mathieu_problem(), {"speed": 0.7}, n_steps=64)
    np.testing.assert_allclose(steady.t, fresh.t, rtol=1e-12)
    np.testing.assert_allclose(steady.response["x"], fresh.response["x"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(steady.multipliers, fresh.multipliers, rtol=1e-9)
    assert steady.spectral_radius == pytest.approx(fresh.spectral_radius, rel=1e-9)
    # the period is the forcing's: T = 2 pi / speed
    assert steady.t[-1] - steady.t[0] == pytest.approx(2.0 * np.pi / 0.7, rel=1e-12)


def test_a_format_1_sweep_loads_with_the_numbers_of_a_fresh_one(old):
    sweep = old["sweep"]
    assert studies.kind_of(sweep).name == "sweep" and sweep.done.all()
    np.testing.assert_array_equal(sweep.values, [0.5, 0.75, 1.0, 1.25, 1.5])
    fresh = studies.sweep(studies.mathieu_problem(), "speed", sweep.values, n_steps=64)
    np.testing.assert_allclose(sweep.spectral_radius, fresh.spectral_radius, rtol=1e-9)
    np.testing.assert_allclose(sweep.peak_to_peak["x"], fresh.peak_to_peak["x"], rtol=1e-9)
    assert list(sweep.status) == list(fresh.status)


def test_new_files_record_the_format(tmp_path):
    path = tmp_path / "new.h5"
    studies.steady_state(studies.mathieu_problem(), n_steps=16).save(path)
    with h5py.File(path, "r") as handle:
        assert handle.attrs["format_version"] == studies.FORMAT_VERSION
        assert handle["steady_state"].attrs["format_version"] == studies.FORMAT_VERSION
        assert handle["steady_state"].attrs["kind"] == "steady_state"
    assert studies.kind_of(studies.load(path)["steady_state"]).name == "steady_state"


@pytest.mark.parametrize("where", ["file", "group"])
def test_a_newer_format_is_refused_naming_its_writer(tmp_path, where):
    path = tmp_path / "newer.h5"
    shutil.copyfile(FORMAT_1, path)
    newer = studies.FORMAT_VERSION + 7
    with h5py.File(path, "a") as handle:
        (handle if where == "file" else handle["sweep"]).attrs["format_version"] = newer
    with pytest.raises(studies.ResultFileError) as refused:
        studies.load(path)
    message = str(refused.value)
    assert f"result format {newer}" in message and "flexvib 0.1.0" in message
    assert "Upgrade flexvib" in message and f"formats 1 to {studies.FORMAT_VERSION}" in message
    with pytest.raises(studies.ResultFileError, match=f"result format {newer}"):
        studies.open_file(path)  # nor added to


def test_flexvib_info_names_the_format_and_refuses_a_newer_one(tmp_path, capsys):
    assert main(["info", str(FORMAT_1)]) == 0
    assert "flexvib 0.1.0, result format 1" in capsys.readouterr().out
    path = tmp_path / "newer.h5"
    shutil.copyfile(FORMAT_1, path)
    with h5py.File(path, "a") as handle:
        handle.attrs["format_version"] = studies.FORMAT_VERSION + 1
    assert main(["info", str(path)]) == 2
    assert f"result format {studies.FORMAT_VERSION + 1}" in capsys.readouterr().err


def test_a_run_does_not_add_to_a_file_of_another_format(tmp_path, capsys):
    path = tmp_path / "old.h5"
    shutil.copyfile(FORMAT_1, path)
    assert main(["run", "mathieu", "--out", str(path), "--only", "steady_state", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "result format 1" in err and "--overwrite" in err
    assert studies.load(path)["steady_state"].n_steps == 64  # untouched
