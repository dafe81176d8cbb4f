"""Kills at any moment of a run: ``flexvib run`` killed (SIGKILL, SIGTERM) at 20 moments spread over
an uninterrupted run's duration leaves, after every kill, a file that loads and that ``flexvib info``
reads, every point it calls done equal to the uninterrupted run's; re-running ends bit-identical. The
same for the parent of a 2-process pool, with no process of the run alive 5 s after the kill. A disk
that fills mid-run (a small tmpfs, where the test may mount one) stops the run with one line and
exit code 1, the file holding what was saved before.

The runs are children forked by one warm Python (``tests/_support/launcher.py``): killed like commands, but
started without twenty interpreter start-ups. One test kills a real ``python -m studies.cli`` too.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import mechanisms
import studies
from studies.cli import main

ROOT = Path(__file__).resolve().parents[1]

STUDIES = """
[studies]
n_steps = 32

[studies.steady_state]

[studies.sweep]
parameter = "speed"
start = 60.0
stop = 140.0
count = 24

[studies.stability_chart]
x = { parameter = "speed", values = [70.0, 90.0, 110.0, 130.0] }
y = { parameter = "links.coupler.thickness", values = [1.4e-3, 1.8e-3] }
n_steps = 32

[studies.nonlinear_check]
n_periods = 2
"""

KILLS = 20


class Launcher:
    """The warm launcher process: ``run(argv, log, kill_after=None, sig=SIGKILL)`` -> outcome."""

    def __init__(self, warm_argv: list[str]) -> None:
        self.process = subprocess.Popen([sys.executable, "-m", "tests._support.launcher", "--warm", *warm_argv],
                                        cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                        stderr=subprocess.DEVNULL, text=True)
        assert self.process.stdout.readline().strip() == "ready"

    def start(self, argv: list[str], log: Path) -> int:
        self.process.stdin.write(json.dumps({"argv": [str(a) for a in argv], "log": str(log)}) + "\n")
        self.process.stdin.flush()
        kind, pid = self.process.stdout.readline().split()
        assert kind == "pid"
        return int(pid)

    def wait(self) -> str:
        """"exit CODE" or "signal NUMBER" of the last child."""
        return self.process.stdout.readline().strip()

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait(timeout=30)


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("scene") / "small.toml"
    path.write_text(mechanisms.load("four_bar_fem1").to_toml() + STUDIES)
    return path


@pytest.fixture(scope="module")
def launcher(scene, tmp_path_factory):
    warm = tmp_path_factory.mktemp("warm") / "warm.h5"
    running = Launcher(["run", str(scene), "--out", str(warm), "--quiet"])
    yield running
    running.close()


@pytest.fixture(scope="module")
def reference(launcher, scene, tmp_path_factory):
    """``(results, duration in s)`` of an uninterrupted run (a child of the warm launcher)."""
    folder = tmp_path_factory.mktemp("reference")
    start = time.perf_counter()
    launcher.start(["run", scene, "--out", folder / "ref.h5", "--quiet"], folder / "log")
    assert launcher.wait() == "exit 0", (folder / "log").read_text()
    return studies.load(folder / "ref.h5"), time.perf_counter() - start


def _same_where_done(saved, expected, assert_same) -> None:
    """A result read from an interrupted file: a complete one equals ``expected``; a grid's points
    marked done equal ``expected``'s at those points, to the last bit. The verdict words of an
    incomplete stability chart or Campbell diagram are provisional (the radius's mesh term, estimated
    at the grid's headline cells once every cell is done, judges them again: docs/studies.md); their
    numbers are final."""
    if not hasattr(saved, "done"):
        assert_same(expected, saved)
        return
    done = saved.done
    # the term is written with the study's end: a file without it holds the provisional words
    provisional = ("point_status", "point_message") if (
        getattr(saved, "spectral_radius_mesh_error", None) is None
        and getattr(expected, "spectral_radius_mesh_error", None) is not None) else ()
    for name, value in vars(saved).items():
        per_point = isinstance(value, np.ndarray) and value.shape[:done.ndim] == done.shape
        if name == "point_run_time" or name in provisional or not per_point:
            continue
        mine, theirs = value[done], getattr(expected, name)[done]
        if mine.dtype.kind in "fcb":
            np.testing.assert_array_equal(mine.astype(theirs.dtype), theirs, err_msg=name)
        else:
            assert (mine == theirs).all(), name


def _check_readable(path: Path, expected: dict, assert_same, capsys) -> int:
    """The file after a kill: ``flexvib info`` reads it (exit 0) and ``studies.load`` too, with every
    saved point intact; returns the number of grid points saved."""
    if not path.exists():
        return 0  # killed before the first commit: nothing claimed
    capsys.readouterr()
    assert main(["info", str(path)]) == 0, capsys.readouterr()
    assert "CORRUPT" not in capsys.readouterr().out
    saved = studies.load(path)
    for name, result in saved.items():
        _same_where_done(result, expected[name], assert_same)
    return sum(int(r.done.sum()) for r in saved.values() if hasattr(r, "done"))


def _alive(pids: list[int]) -> list[int]:
    import psutil

    alive = []
    for pid in pids:
        try:
            if psutil.Process(pid).status() != psutil.STATUS_ZOMBIE:
                alive.append(pid)
        except psutil.NoSuchProcess:
            pass
    return alive


def _descendants(pid: int) -> list[int]:
    import psutil

    try:
        return [child.pid for child in psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


@pytest.mark.slow
def test_kills_at_any_moment_leave_a_readable_file_and_the_rerun_is_bit_identical(
        launcher, scene, reference, tmp_path, assert_same, capsys):
    """Kill moments spread over an uninterrupted run's duration; even kills hit a fresh run, odd ones
    the run resuming the previous kill's file, which then runs to the end and must equal the
    uninterrupted run to the last bit."""
    expected, duration = reference
    path, log = tmp_path / "run.h5", tmp_path / "log"
    argv = ["run", scene, "--out", path, "--quiet"]

    def finish_and_compare() -> None:
        launcher.start(argv, log)
        assert launcher.wait() == "exit 0", log.read_text()
        final = studies.load(path)
        assert final.keys() == expected.keys()
        for name, result in final.items():
            assert_same(expected[name], result)

    saved_counts = []
    for i in range(KILLS):
        fresh = i % 2 == 0
        if fresh:
            path.unlink(missing_ok=True)
        sig = signal.SIGTERM if i % 4 == 3 else signal.SIGKILL
        pid = launcher.start(argv, log)
        time.sleep(duration * (i + 0.5) / KILLS)
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass
        outcome = launcher.wait()
        text = log.read_text()
        if outcome != "exit 0":  # the kill landed inside the run
            if sig == signal.SIGTERM:
                assert outcome == "exit 130", text
                *before, last = text.strip().splitlines()
                assert last.startswith("interrupted: ") and \
                    last.endswith(f" points saved in {path}; run the same command to resume"), text
                # a run after a SIGKILL reports the lock it found (the console shows warnings); a
                # SIGTERM after the last point was saved can land while the studies' summaries are
                # printed (stdout, at the end): those lines then come before it (seen in CI, kill 8)
                saved, total = (int(x) for x in re.match(r"interrupted: (\d+) of (\d+) points", last).groups())
                others = [line for line in before if "released the lock left by a run" not in line]
                assert not others or saved == total, text
                assert "Traceback" not in text, text
            else:
                assert outcome == f"signal {int(signal.SIGKILL)}", (outcome, text)
            saved_counts.append(_check_readable(path, expected, assert_same, capsys))
        if not fresh:
            finish_and_compare()
    assert len(saved_counts) >= KILLS // 2  # the kills landed inside runs (the early ones surely)
    assert 0 in saved_counts and any(0 < count < 32 for count in saved_counts), saved_counts
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log", "run.h5"]  # no scratch left


@pytest.mark.slow
def test_killing_the_parent_of_a_process_pool_kills_its_workers(launcher, scene, reference, tmp_path,
                                                                 assert_same, capsys):
    pytest.importorskip("psutil")
    expected, duration = reference
    path, log = tmp_path / "pool.h5", tmp_path / "log"
    argv = ["run", scene, "--out", path, "--quiet", "--jobs", "2"]
    for fraction in (0.3, 0.5, 0.7, 0.9):
        pid = launcher.start(argv, log)
        deadline = time.monotonic() + duration * fraction
        workers: set[int] = set()
        while time.monotonic() < deadline:  # the pool starts its workers on demand
            workers.update(_descendants(pid))
            time.sleep(0.02)
        workers.update(_descendants(pid))
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:  # the run ended first
            pass
        outcome = launcher.wait()
        if outcome == "exit 0":
            path.unlink()
            continue
        gone_by = time.monotonic() + 5.0
        while _alive(sorted(workers)) and time.monotonic() < gone_by:
            time.sleep(0.05)
        assert not _alive(sorted(workers)), f"workers {sorted(workers)} outlived their parent"
        _check_readable(path, expected, assert_same, capsys)
    launcher.start(argv, log)
    assert launcher.wait() == "exit 0", log.read_text()
    for name, result in studies.load(path).items():
        assert_same(expected[name], result)


@pytest.mark.slow
def test_sigterm_to_the_command_saves_and_says_so_in_one_line(scene, reference, tmp_path, assert_same,
                                                              capsys):
    """A real ``python -m studies.cli run --jobs 2``, SIGTERM once the first study is saved."""
    pytest.importorskip("psutil")
    expected, _ = reference
    path = tmp_path / "term.h5"
    command = subprocess.Popen([sys.executable, "-m", "studies.cli", "run", str(scene), "--out", str(path),
                                "--quiet", "--jobs", "2"], cwd=ROOT, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not path.exists() and command.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    # the first commit (the steady state) is in place; the grids and the nonlinear check follow,
    # a fraction of a second on a quiet machine: no wait before the signal
    workers = _descendants(command.pid)
    command.send_signal(signal.SIGTERM)
    out, err = command.communicate(timeout=60)
    if command.returncode == 0:
        pytest.skip("the run ended before its SIGTERM (a very fast machine)")
    assert command.returncode == 130, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    saved, total = map(int, err.split("interrupted: ")[1].split(" points")[0].split(" of "))
    assert 1 <= saved < total == 1 + 24 + 8 + 1, err
    gone_by = time.monotonic() + 5.0
    while _alive(workers) and time.monotonic() < gone_by:
        time.sleep(0.05)
    assert not _alive(workers)
    _check_readable(path, expected, assert_same, capsys)


@pytest.mark.slow
def test_a_disk_that_fills_mid_run_stops_it_with_exit_1_and_the_saved_results_intact(
        launcher, scene, reference, tmp_path, assert_same, capsys):
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root (CI runs as root)")
    expected, _ = reference
    disk = tmp_path / "disk"
    disk.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=4m", "tmpfs", str(disk)],
                             capture_output=True, text=True)
    if mounted.returncode:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.strip()}")
    try:
        # room for the reserve and the first study's commit (its working copy and the copy renamed
        # into place, a little more than twice its size), not for the whole run's: the run fills it
        expected["steady_state"].save(tmp_path / "steady_only.h5")
        first = (tmp_path / "steady_only.h5").stat().st_size
        free = os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize
        ballast = disk / "ballast"
        ballast.write_bytes(b"\0" * (free - (1 << 20) - int(2.2 * first)))
        path, log = disk / "run.h5", tmp_path / "log"
        argv = ["run", scene, "--out", path, "--quiet"]
        launcher.start(argv, log)
        assert launcher.wait() == "exit 1", log.read_text()
        message = log.read_text().strip()
        assert len(message.splitlines()) == 1 and str(path) in message and "free space" in message, message
        _check_readable(path, expected, assert_same, capsys)
        assert "steady_state" in studies.load(path)  # the study saved before the disk filled
        assert sorted(p.name for p in disk.iterdir()) == ["ballast", "run.h5"]
        ballast.unlink()
        launcher.start(argv, log)
        assert launcher.wait() == "exit 0", log.read_text()
        for name, result in studies.load(path).items():
            assert_same(expected[name], result)
    finally:
        subprocess.run(["umount", str(disk)], check=True)
