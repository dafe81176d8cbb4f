"""Result files and their paths: one scene per file (refused before anything is written, naming the
differing keys), resuming after a description edit or an added study, ``--overwrite``, bad paths and
foreign files (one line, exit 2, the file untouched), two writers, a lock left by a dead run, an
unreachable Dask scheduler, ``flexvib info`` on a damaged file, Ctrl-C's one line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import mechanisms
import studies
from studies import _grid, _identity  # internal: patched point evaluation, parent watch, digests
from studies.cli import main

ROOT = Path(__file__).resolve().parents[1]

STEADY = """
[studies]
n_steps = 32

[studies.steady_state]
"""
SWEEP = """
[studies.sweep]
parameter = "speed"
values = [80.0, 100.0, 120.0]
"""


def _scene(folder: Path, name: str, extra: str = "", **changes: str) -> Path:
    """A four-bar scene file (1 finite element) with a steady state, ``extra`` studies and its
    lines ``key = value`` replaced per ``changes``."""
    text = mechanisms.load("four_bar_fem1").to_toml()
    for key, value in changes.items():
        lines = text.splitlines()
        index = next(i for i, line in enumerate(lines) if line.startswith(f"{key} = "))
        lines[index] = f"{key} = {value}"
        text = "\n".join(lines) + "\n"
    path = folder / f"{name}.toml"
    path.write_text(text + STEADY + extra)
    return path


def _run(scene: Path, out: Path, *extra: str) -> int:
    return main(["run", str(scene), "--out", str(out), "--quiet", *extra])


@pytest.fixture(scope="module")
def steady_file(tmp_path_factory) -> Path:
    """A result file of the small scene (steady state only); tests copy it."""
    folder = tmp_path_factory.mktemp("steady")
    path = folder / "run.h5"
    assert _run(_scene(folder, "small"), path) == 0
    return path


@pytest.fixture
def result_file(steady_file, tmp_path) -> Path:
    path = tmp_path / "run.h5"
    path.write_bytes(steady_file.read_bytes())
    return path


def _one_line_error(capsys, *words: str) -> str:
    err = capsys.readouterr().err
    assert err.startswith("flexvib: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    for word in words:
        assert word in err, (word, err)
    return err


# ---------------------------------------------------------------------------------------------------
# identities
# ---------------------------------------------------------------------------------------------------
def test_differing_paths_names_at_most_five_keys():
    old = {"links": {"a": {"length": 1.0, "width": 2.0}}, "gravity": [0, 0], "x": 1}
    new = {"links": {"a": {"length": 1.5, "width": 2.0}}, "gravity": [0, -9.81], "y": 1}
    assert _identity.differing_paths(old, new) == ["gravity", "links.a.length", "x", "y"]
    many = {f"k{i}": i for i in range(8)}
    assert _identity.differing_paths(many, {}) == ["k0", "k1", "k2", "k3", "k4", "..."]


def test_scene_numbers_leave_out_name_description_studies_and_comments():
    text = mechanisms.load("four_bar_fem1").to_toml()
    edited = ("# a comment\n" + text.replace('name = "four_bar_fem1"', 'name = "renamed"')
              .replace("description = ", "description = 'edited' #") + STEADY)
    assert _identity.digest(_identity.scene_numbers(text)) == _identity.digest(_identity.scene_numbers(edited))
    thicker = text.replace("thickness = 0.0016", "thickness = 0.0017", 1)
    assert _identity.digest(_identity.scene_numbers(text)) != _identity.digest(_identity.scene_numbers(thicker))
    assert _identity.scene_numbers("x'' + x = 0") == {"text": "x'' + x = 0"}


# ---------------------------------------------------------------------------------------------------
# one scene per file
# ---------------------------------------------------------------------------------------------------
def test_another_scene_is_refused_before_anything_is_written(result_file, tmp_path, capsys):
    before = result_file.read_bytes()
    other = _scene(tmp_path, "other", SWEEP, density="7000.0", youngs_modulus="210000000000.0")
    assert _run(other, result_file) == 2
    err = _one_line_error(capsys, str(result_file), "another scene", "--out", "--overwrite",
                          "scene.links.coupler.youngs_modulus", "scene.links.crank.density")
    assert len(err) < 400  # key paths, not the scene's text
    assert result_file.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.toml", "run.h5"]  # no lock, no scratch


def test_overwrite_starts_the_file_afresh(result_file, tmp_path):
    other = _scene(tmp_path, "other", density="7000.0")
    assert _run(other, result_file, "--overwrite") == 0
    with h5py.File(result_file, "r") as handle:
        assert '"density":7000.0' in handle.attrs["scene"] and list(handle) == ["steady_state"]


def test_a_description_edit_and_an_added_study_resume(result_file, tmp_path):
    with h5py.File(result_file, "r") as handle:
        run_time = handle["steady_state"].attrs["run_time"]
    edited = _scene(tmp_path, "edited", SWEEP, description="'another description'")
    assert _run(edited, result_file) == 0
    with h5py.File(result_file, "r") as handle:
        assert handle["steady_state"].attrs["run_time"] == run_time  # skipped, not recomputed
        assert handle["sweep"]["done"][()].all()


def test_a_grid_asked_with_other_options_is_refused_before_anything_is_written(result_file, tmp_path,
                                                                             capsys):
    assert _run(_scene(tmp_path, "first", SWEEP), result_file) == 0
    before = result_file.read_bytes()
    changed = _scene(tmp_path, "changed", SWEEP.replace("120.0", "130.0") + "\n[studies.steady_state]\n"
                     .replace("steady_state", "campbell") + "values = [90.0]\n")
    assert _run(changed, result_file) == 2
    _one_line_error(capsys, str(result_file), "sweep (values)", "--overwrite")
    assert result_file.read_bytes() == before


def test_a_file_of_an_older_flexvib_without_a_scene_identity_is_refused(result_file, tmp_path, capsys):
    with h5py.File(result_file, "a") as handle:
        del handle.attrs["scene_hash"]
    before = result_file.read_bytes()
    assert _run(_scene(tmp_path, "small"), result_file) == 2
    _one_line_error(capsys, "did not record its scene", "--overwrite")
    assert result_file.read_bytes() == before


# ---------------------------------------------------------------------------------------------------
# paths: one line, exit code 2, nothing touched
# ---------------------------------------------------------------------------------------------------
def _foreign(path: Path) -> None:
    with h5py.File(path, "w") as handle:
        handle["steady_state"] = np.arange(3.0)


@pytest.mark.parametrize("make, out, cause", [
    (lambda d: (d / "folder.h5").mkdir(), "folder.h5", "is a folder"),
    (lambda d: (d / "plain").write_text("x"), "plain/run.h5", "is a file, not a folder"),
    (lambda d: (d / "notes.h5").write_text("not HDF5"), "notes.h5", "is not an HDF5 file"),
    (lambda d: _foreign(d / "theirs.h5"), "theirs.h5", "not written by flexvib"),
])
@pytest.mark.parametrize("overwrite", [False, True])
def test_a_bad_path_exits_2_in_one_line_and_is_left_untouched(make, out, cause, overwrite, tmp_path,
                                                              capsys):
    scene = _scene(tmp_path, "small")
    make(tmp_path)
    before = {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()}
    assert _run(scene, tmp_path / out, *(["--overwrite"] if overwrite else [])) == 2
    _one_line_error(capsys, str(tmp_path / out), cause)
    assert {p: p.read_bytes() for p in tmp_path.rglob("*") if p.is_file()} == before


def test_an_unwritable_folder_exits_2(tmp_path, capsys):
    import os

    scene = _scene(tmp_path, "small")
    locked = tmp_path / "locked"
    locked.mkdir()
    if os.geteuid() == 0:  # root writes anywhere: a read-only mount, where one can be made
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(locked)],
                              capture_output=True)
        if done.returncode:
            pytest.skip("root ignores permissions and cannot mount a read-only tmpfs here")
    else:
        locked.chmod(0o500)
    try:
        assert _run(scene, locked / "run.h5") == 2
        _one_line_error(capsys, str(locked / "run.h5"), "no permission to write")
    finally:
        if os.geteuid() == 0:
            subprocess.run(["umount", str(locked)], check=True)
        else:
            locked.chmod(0o700)


# ---------------------------------------------------------------------------------------------------
# processes: two writers, a lock left behind, an unreachable scheduler, Ctrl-C
# ---------------------------------------------------------------------------------------------------
HOLD = ("import sys; from studies import ResultFile\n"
        "with ResultFile(sys.argv[1]):\n"
        "    print('locked', flush=True); sys.stdin.read()\n")


@pytest.mark.slow
def test_a_second_live_writer_is_refused_naming_the_other_run(result_file, tmp_path, capsys):
    before = result_file.read_bytes()
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(result_file)], cwd=ROOT, text=True,
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        assert holder.stdout.readline().strip() == "locked"
        assert _run(_scene(tmp_path, "small"), result_file) == 2
        _one_line_error(capsys, str(result_file), "being written by another flexvib run",
                        f"pid {holder.pid} on ", "--out")
    finally:
        holder.communicate("", timeout=30)
    assert holder.returncode == 0 and result_file.read_bytes() == before
    assert not result_file.with_name("run.h5.lock").exists()


def test_a_lock_left_by_a_dead_run_is_released_with_a_message(result_file, tmp_path, caplog):
    result_file.with_name("run.h5.lock").write_text("pid 999999999 on elsewhere")
    result_file.with_name("run.h5.work").write_text("half a file")
    with caplog.at_level("WARNING"):
        assert _run(_scene(tmp_path, "small"), result_file) == 0
    assert "released the lock left by a run that ended without finishing (pid 999999999 on elsewhere)" \
        in caplog.text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.h5", "small.toml"]


def test_an_unreachable_dask_scheduler_exits_2_in_one_line(tmp_path, capsys):
    pytest.importorskip("distributed")
    assert main(["run", "mathieu", "--out", str(tmp_path / "m.h5"), "--quiet", "--executor", "dask",
                 "--scheduler", "tcp://127.0.0.1:1"]) == 2
    _one_line_error(capsys, "--scheduler tcp://127.0.0.1:1", "cannot reach the Dask scheduler")
    assert not (tmp_path / "m.h5").exists()


def test_ctrl_c_saves_what_is_done_and_says_so_in_one_line(result_file, tmp_path, monkeypatch, capsys):
    evaluate, calls = _grid.evaluate, []

    def interrupted_at_the_third_point(*args):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(args)
        return evaluate(*args)

    monkeypatch.setattr(_grid, "evaluate", interrupted_at_the_third_point)
    assert _run(_scene(tmp_path, "small", SWEEP), result_file) == 130
    assert capsys.readouterr().err == (f"interrupted: 3 of 4 points saved in {result_file}; run the same "
                                       f"command to resume\n")  # the steady state and two speeds
    sweep = studies.load(result_file)["sweep"]
    assert sweep.done.tolist() == [True, True, False]


CHART = """
[studies.stability_chart]
x = { parameter = "speed", start = 60.0, stop = 120.0, count = 4 }
y = { parameter = "links.coupler.thickness", start = 1.2e-3, stop = 2.0e-3, count = 3 }
"""


def test_a_grid_committed_every_few_points_saves_each_point_as_computed(tmp_path, monkeypatch, capsys):
    """A run commits every few seconds and writes the points finished since in one go (the block of
    the grid they fill, strings point by point where they do not fill it). Committed every third
    point, a 3 x 4 chart's commits cut its rows of 4 (blocks the points do not fill); interrupted at
    its eighth point, the file must hold the seven finished points as they were computed (their
    status and message words included, which the end of a grid judges again and rewrites), each
    point's digest must hold, and the resumed run must end equal to an uninterrupted one."""
    from studies import _resultfile

    scene = _scene(tmp_path, "chart", CHART)
    assert _run(scene, tmp_path / "once.h5") == 0
    maybe_commit, evaluate, write = _resultfile.ResultFile.maybe_commit, _grid.evaluate, _grid.GridStore.write
    calls, evaluated, written = [], [], {}

    def recorded(self, index, outcome):
        written[index] = outcome
        write(self, index, outcome)

    def every_third_point(self):
        calls.append(1)
        if len(calls) % 3 == 0:
            self.commit()

    def interrupted_at_the_eighth_point(*args):
        if len(evaluated) == 7:
            raise KeyboardInterrupt
        evaluated.append(args)
        return evaluate(*args)

    monkeypatch.setattr(_resultfile.ResultFile, "maybe_commit", every_third_point)
    monkeypatch.setattr(_grid, "evaluate", interrupted_at_the_eighth_point)
    monkeypatch.setattr(_grid.GridStore, "write", recorded)
    assert _run(scene, tmp_path / "often.h5") == 130
    monkeypatch.setattr(_grid, "evaluate", evaluate)
    monkeypatch.setattr(_grid.GridStore, "write", write)
    assert "8 of 13 points saved" in capsys.readouterr().err   # the steady state and 7 of the chart's
    assert len(written) == 7
    with h5py.File(tmp_path / "often.h5", "r") as handle:
        group = handle["stability_chart"]
        assert group["done"][()].sum() == 7
        for index, outcome in written.items():
            assert group["done"][index]
            assert group["status"].asstr()[index] == outcome.status
            assert group["message"].asstr()[index] == outcome.message
            assert group["point_run_time"][index] == outcome.run_time
            assert group["spectral_radius"][index] == outcome.data["spectral_radius"]
    assert main(["info", str(tmp_path / "often.h5")]) == 0   # every saved point's digest holds
    assert _run(scene, tmp_path / "often.h5") == 0
    monkeypatch.setattr(_resultfile.ResultFile, "maybe_commit", maybe_commit)
    once = studies.load(tmp_path / "once.h5")["stability_chart"]
    often = studies.load(tmp_path / "often.h5")["stability_chart"]
    for field in ("spectral_radius", "spectral_radius_error", "point_status", "point_message", "done"):
        np.testing.assert_array_equal(getattr(once, field), getattr(often, field), err_msg=field)


# ---------------------------------------------------------------------------------------------------
# flexvib info reads every dataset
# ---------------------------------------------------------------------------------------------------
def test_info_calls_a_study_whose_data_cannot_be_read_corrupt(result_file, capsys):
    with h5py.File(result_file, "a") as handle:  # a compressed dataset whose bytes are then damaged
        dataset = handle["steady_state"].create_dataset("extra", data=np.arange(4096.0), chunks=(4096,),
                                                        compression="gzip")
        chunk = dataset.id.get_chunk_info(0)
    with open(result_file, "r+b") as raw:
        raw.seek(chunk.byte_offset)
        raw.write(b"\xff" * chunk.size)
    assert main(["info", str(result_file)]) == 1
    captured = capsys.readouterr()
    assert "[steady_state] steady_state of four_bar_fem1, CORRUPT (extra: " in captured.out
    assert captured.err.startswith("flexvib: error: ") and "cannot read steady_state" in captured.err


def test_worker_initializer_ignores_ctrl_c_and_keeps_a_watchdog(monkeypatch):
    import os
    import signal
    import threading

    started = []
    monkeypatch.setattr(threading.Thread, "start", lambda self: started.append(self.name))
    previous = signal.getsignal(signal.SIGINT)
    try:
        _grid.die_with_parent(os.getppid())
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
    assert started == ["flexvib-parent-watchdog"]
