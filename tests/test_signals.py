"""Issue 23: a signal at any moment of ``flexvib run``, from the process's start (the imports of
numpy, scipy, numba, the study kinds) to its end, ends it with exit code 130 and one "interrupted"
line (what was saved, or that nothing was), never a traceback or the signal's own code.

The command runs as the console script does (``studies._entry:main``, here ``python -m
studies._entry``) in a session of its own; the moments are counted from when its entry module has
run (before it, the interpreter's own start-up, some tens of milliseconds, keeps the default
handlers). SIGINT goes to its whole process group as a terminal's Ctrl-C does, SIGTERM to the
process as ``kill`` does, at 12 moments spread over an uninterrupted run's duration. The file each
interrupted run leaves is then resumed to completion."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ONLY = ["--only", "steady_state", "--only", "sweep"]


def _start(out: Path) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-m", "studies._entry", "run", "mathieu", "--out", str(out), "--quiet",
                             *ONLY], cwd=out.parent, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def _handlers_installed(pid: int) -> bool:
    """Whether the process catches SIGTERM (``/proc/PID/status``, SigCgt): ``studies._entry`` has run.
    Before it only the interpreter's own start-up runs (importing ``site``), where no Python code of
    flexvib can handle a signal: the moments are counted from there."""
    try:
        fields = dict(line.split(":", 1) for line in Path(f"/proc/{pid}/status").read_text().splitlines())
    except (OSError, ValueError):
        return False
    return bool(int(fields.get("SigCgt", "0").strip(), 16) >> (signal.SIGTERM - 1) & 1)


@pytest.fixture(scope="module")
def duration(tmp_path_factory) -> float:
    out = tmp_path_factory.mktemp("whole") / "run.h5"
    start = time.perf_counter()
    process = _start(out)
    _, err = process.communicate(timeout=600)
    assert process.returncode == 0, err
    return time.perf_counter() - start


@pytest.mark.slow
@pytest.mark.parametrize("moment", range(12))
def test_a_signal_at_any_moment_ends_the_run_with_130_and_one_line(moment, duration, tmp_path):
    fraction = [0.01, 0.03, 0.06, 0.1, 0.2, 0.3, 0.45, 0.6, 0.75, 0.85, 0.93, 0.98][moment]
    number = signal.SIGINT if moment % 2 == 0 else signal.SIGTERM
    out = tmp_path / "run.h5"
    process = _start(out)
    start = time.perf_counter()
    while not _handlers_installed(process.pid) and process.poll() is None:
        time.sleep(0.005)
    time.sleep(max(0.0, fraction * duration - (time.perf_counter() - start)))
    if process.poll() is None:
        if number == signal.SIGINT:
            os.killpg(process.pid, number)   # a terminal's Ctrl-C: the whole foreground group
        else:
            process.send_signal(number)
    _, err = process.communicate(timeout=600)
    assert "Traceback" not in err and "internal error" not in err, err
    if process.returncode == 0:   # the run had ended before the signal came
        return
    assert process.returncode == 130, (fraction, number, process.returncode, err)
    lines = err.strip().splitlines()
    assert lines and lines[-1].startswith("interrupted"), (fraction, err)
    assert len(lines) == 1, err
    # what it left resumes to a complete file
    resumed = _start(out)
    _, err = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, err


# ---------------------------------------------------------------------------------------------------
# the window the moments above found by chance: a signal inside an extension module's import
# ---------------------------------------------------------------------------------------------------
_CUT_IMPORT = """
import sys

class CutBySignal:
    '''An import cut by a signal as a pybind11 module's initialisation reports it (scipy's HiGHS,
    imported with scipy.optimize, did): ImportError("initialization failed") raised from the
    interrupt; here scipy.linalg's, which every run imports at its start (scipy.optimize is imported
    only where it is called).'''
    def find_spec(self, name, path=None, target=None):
        if name == "scipy.linalg":
            try:
                raise KeyboardInterrupt("SIGINT")
            except KeyboardInterrupt as interrupt:
                raise ImportError("initialization failed") from interrupt
        return None

sys.meta_path.insert(0, CutBySignal())
from studies._entry import run
sys.exit(run(sys.argv[1:]))
"""


def test_a_signal_inside_an_extension_module_s_import_ends_with_130_and_one_line(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    process = subprocess.run([sys.executable, "-c", _CUT_IMPORT, "run", "mathieu", "--out", str(tmp_path / "r.h5"),
                              "--quiet", *ONLY], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert process.returncode == 130, process.stderr
    assert process.stderr.strip().splitlines() == ["interrupted: nothing was saved"], process.stderr


def _cut_by_signal(*args, **kwargs):
    try:
        raise KeyboardInterrupt("SIGTERM")
    except KeyboardInterrupt as interrupt:
        raise ImportError("initialization failed") from interrupt


def test_a_lazy_import_cut_by_a_signal_in_a_command_or_a_run_ends_with_130_and_one_line(tmp_path, monkeypatch,
                                                                                         capsys):
    from studies.cli import _main, _run, main  # the command's handlers and the run's loop: no public face

    monkeypatch.setattr(_main, "_info", _cut_by_signal)
    assert main(["info", str(tmp_path / "none.h5")]) == 130
    assert capsys.readouterr().err.strip().splitlines() == ["interrupted: nothing was saved"]
    monkeypatch.setattr(_run, "_run_studies", _cut_by_signal)
    out = tmp_path / "run.h5"
    assert main(["run", "mathieu", "--out", str(out), "--quiet", *ONLY]) == 130
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("interrupted: 0 of ") and str(out) in lines[0], lines


def _interrupted(*args, **kwargs):
    raise KeyboardInterrupt("SIGTERM")


def test_a_signal_after_the_run_saved_everything_says_all_points_are_saved(tmp_path, monkeypatch, capsys):
    """The signal lands while the summary is printed: the file is complete, and the line says so
    (not "nothing was saved"); the same command then only reports the file."""
    from studies import _summary
    from studies.cli import main

    out = tmp_path / "run.h5"
    monkeypatch.setattr(_summary, "text_table", _interrupted)
    assert main(["run", "mathieu", "--out", str(out), "--quiet", *ONLY]) == 130
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    saved, _, rest = lines[0].removeprefix("interrupted: ").partition(" of ")
    total = rest.split()[0]
    assert saved == total and int(total) > 1, lines   # a sweep's points and the steady state
    assert lines[0].endswith(f" points saved in {out}; run the same command to resume"), lines
    monkeypatch.undo()
    assert main(["run", "mathieu", "--out", str(out), "--quiet", *ONLY]) == 0


_CALLBACK_SCRIPT = """
import os, signal, sys, time
from studies import _entry

sys.unraisablehook = _entry._signal_again(sys.unraisablehook)
signal.signal(signal.SIGTERM, _entry._interrupt)


class SignalledInDel:
    def __del__(self):
        os.kill(os.getpid(), signal.SIGTERM)
        for _ in range(1000):      # the handler runs here, where its exception cannot propagate
            pass


try:
    SignalledInDel()
    for _ in range(2000):
        time.sleep(0.001)
    print("not interrupted")
except KeyboardInterrupt as error:
    print("interrupted by", error)
"""


def test_a_signal_inside_a_callback_that_cannot_raise_ends_the_command_without_a_traceback():
    """A handler that ran inside a callback Python cannot raise from (a ``__del__``, a weak reference's
    callback of the import locks) raises into ``sys.unraisablehook``: the hook of ``studies._entry``
    raises the interrupt again at the next ordinary line, so it ends the command instead of being
    printed with a traceback and lost, and the hook itself raises nothing (a signal sent again at once
    ran its handler inside the hook: "Exception ignored in sys.unraisablehook", a traceback)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", _CALLBACK_SCRIPT], env=env, capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "interrupted by SIGTERM", (done.stdout, done.stderr)
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr, done.stderr


def test_the_unraisable_hook_passes_anything_else_on():
    import types

    from studies import _entry

    others = []
    hook = _entry._signal_again(others.append)
    error = types.SimpleNamespace(exc_value=ValueError("other"), object=None)
    hook(error)
    assert others == [error]


def test_the_unraisable_hook_off_the_main_thread_signals_the_main_thread():
    """Only the main thread may set a signal handler: an interrupt caught in a callback of another
    thread is sent again as its signal, whose handler then runs in the main thread."""
    import threading
    import types

    from studies import _entry

    handled = []
    previous = signal.signal(signal.SIGUSR1, lambda signum, frame: handled.append(
        threading.current_thread() is threading.main_thread()))
    try:
        hook = _entry._signal_again(lambda unraisable: handled.append("passed on"))
        caught = types.SimpleNamespace(exc_value=KeyboardInterrupt("SIGUSR1"), object=None)
        failures = []
        thread = threading.Thread(target=lambda: _call(hook, caught, failures))
        thread.start()
        thread.join()
        for _ in range(200):
            if handled:
                break
            time.sleep(0.005)
        assert failures == [] and handled == [True]
    finally:
        signal.signal(signal.SIGUSR1, previous)


def _call(hook, caught, failures):
    try:
        hook(caught)
    except Exception as error:  # noqa: BLE001 - the test reports it
        failures.append(error)


# ---------------------------------------------------------------------------------------------------
# a cold cache: the compile helper started during the imports (studies._compile_helper)
# ---------------------------------------------------------------------------------------------------
def _helpers_of(folder: Path) -> list[int]:
    """The pids of the processes whose command line names a claims folder under ``folder``."""
    found = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and str(folder) in (entry / "cmdline").read_bytes().decode(errors="replace"):
                found.append(int(entry.name))
        except OSError:
            continue
    return found


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/cmdline").exists(), reason="reads /proc")
@pytest.mark.parametrize("number", [signal.SIGTERM, signal.SIGKILL])
def test_a_run_killed_while_its_early_helper_compiles_leaves_no_helper_or_folder(number, tmp_path):
    """On an empty numba cache the helper starts while the command imports; the run stopped once it
    has (SIGTERM: 130 and one line; SIGKILL: nothing runs in it), no helper process is left and
    no claims folder (a killed parent's helper stops and removes it itself)."""
    scratch, cache = tmp_path / "tmp", tmp_path / "numba-cache"
    scratch.mkdir()
    cache.mkdir()
    env = dict(os.environ, PYTHONPATH=str(ROOT), TMPDIR=str(scratch), NUMBA_CACHE_DIR=str(cache),
               FLEXVIB_COMPILE_PROCESSES="2")
    out = tmp_path / "run.h5"
    process = subprocess.Popen([sys.executable, "-m", "studies._entry", "run", "mathieu", "--out", str(out),
                                "--quiet", *ONLY], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, start_new_session=True)
    # The claims folder is made just before the helper process is spawned: wait for the process itself.
    deadline = time.monotonic() + 120.0
    while not _helpers_of(scratch) and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert process.poll() is None, "the run ended before its helper started"
    assert _helpers_of(scratch), "no helper process was started during the imports"
    time.sleep(0.5)   # the helper at work
    process.send_signal(number)
    _, err = process.communicate(timeout=120)
    if number == signal.SIGTERM:
        assert process.returncode == 130 and "Traceback" not in err, err
        assert err.strip().splitlines()[-1].startswith("interrupted"), err
    deadline = time.monotonic() + 60.0
    while (_helpers_of(scratch) or list(scratch.glob("flexvib-compile-*"))) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _helpers_of(scratch) and not list(scratch.glob("flexvib-compile-*"))
