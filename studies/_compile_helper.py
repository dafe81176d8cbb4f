"""The compile helper process: a second interpreter that compiles its share of the warm-up's numba
kernels into the disk cache while this process compiles the rest (``studies.cli._kernel_list`` holds
the list and how the two share it), and when to start it.

The helper starts at the first kernel that misses the cache, where the machine leaves a core free
(:func:`free_core`; ``FLEXVIB_COMPILE_PROCESSES`` overrides it). For ``flexvib run`` that moment comes
while the command is still importing its packages: :func:`start_at_first_compilation`, called by the
console script before its imports, listens for it (on a cold cache the first kernel compiles when
``periodic.lapack`` is imported, about a second before the warm-up begins), so the helper's own
start-up (its imports, about a second) runs beside this process's instead of after it; the warm-up
then takes that helper (:func:`take_early`) and tells it the steps of the run (a file in the claims
folder). A helper no warm-up took (bad input, a complete result file) the console script ends when
the command returns (:func:`discard_early`); a helper whose parent was killed stops compiling and
removes the claims folder itself, and a run killed before it had a helper (SIGKILL in a warm
cache's warm-up) leaves a folder named by its pid that the next run removes
(:func:`remove_stale_folders`). Light to import (no numpy, no numba): the console script imports
it first.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Iterable

from ._errors import UsageError

__all__ = ["Helper", "discard_early", "free_core", "helper_setting", "read_steps", "remove_stale_folders",
           "start_at_first_compilation", "stop_listening", "take_early", "FOLDER_PREFIX", "PROCESSES_VARIABLE",
           "STEPS_FILE", "WAIT_LIMIT"]

#: Environment variable: ``1`` compiles in this process only (no helper process).
PROCESSES_VARIABLE = "FLEXVIB_COMPILE_PROCESSES"
#: The load average (1 min) must leave this many cores free for the helper process (where the
#: machine's CPU times cannot be read: ``free_core``).
FREE_CORE = 1.0
#: ``free_core`` measures the machine's idle time over this window (s), this process asleep, at the
#: first kernel that misses the cache (a cold cache only): the 1-min load average lags by a minute,
#: so right after a busy minute (``pip install``, the previous run) it said "no free core" on an idle
#: machine and the cold start compiled on one core (11.4 s against 7.6 s for the linear studies,
#: docs/benchmarks.md, session 12).
MEASURE_WINDOW = 0.1
#: ... and starts the helper when at least this many cores were idle over it: one for this process
#: (asleep while measuring), most of one for the helper.
IDLE_CORES = 1.5
#: The longest wait (s) for the other process's callee before compiling it here (it may have ended).
WAIT_LIMIT = 120.0
#: The file of the claims folder that names the warm-up's steps, one a line (written by this process
#: once it knows them; the helper waits for it).
STEPS_FILE = "steps"
#: How often (s) the helper looks for the steps file and for its parent.
POLL = 0.02
#: The claims folders' names in the temporary directory: this prefix, the pid of the run that made
#: it, a dash and tempfile's random part.
FOLDER_PREFIX = "flexvib-compile-"


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def helper_setting() -> bool | None:
    """``FLEXVIB_COMPILE_PROCESSES``: ``1`` False (never a helper), ``2`` True (always, for
    measurements), unset None (decided by :func:`free_core`); anything else ``UsageError``."""
    setting = os.environ.get(PROCESSES_VARIABLE, "").strip()
    if setting in ("1", "2"):
        return setting == "2"
    if setting:
        raise UsageError(f"{PROCESSES_VARIABLE}: expected 1 (compile in this process only) or 2 (and in a "
                         f"helper process), got {setting!r}; unset it to decide by the free cores")
    return None


def _cpu_ticks() -> tuple[int, int, int] | None:
    """(all, idle, CPUs) of the machine's CPU time so far (``/proc/stat``, clock ticks; idle counts
    I/O waits), or None where it cannot be read (not Linux)."""
    try:
        lines = Path("/proc/stat").read_text().splitlines()
        fields = [int(x) for x in lines[0].split()[1:9]]
    except (OSError, ValueError, IndexError):
        return None
    cpus = sum(1 for line in lines if line.startswith("cpu") and line[3:4].isdigit())
    return sum(fields), fields[3] + fields[4], cpus


def _cpu_quota() -> float | None:
    """The CPUs this process's control group may use (cgroup v2 ``cpu.max``: quota / period, e.g.
    ``docker --cpus=1``), or None where it sets no quota or cannot be read."""
    try:
        quota, period = Path("/sys/fs/cgroup/cpu.max").read_text().split()[:2]
        return None if quota == "max" else int(quota) / int(period)
    except (OSError, ValueError):
        return None


def free_core(window: float = MEASURE_WINDOW) -> bool:
    """Whether this process may use two cores and the machine's idle time over ``window`` s (this
    process asleep) leaves ``IDLE_CORES`` of them: one for this process, one for the helper. On a
    machine without a free core the helper only competes with this process and adds its own start-up
    and the callees both compile. Where the CPU times cannot be read, or cover other CPUs than this
    process's (a container showing the host's), the 1-min load average decides (``FREE_CORE``). A
    control group's CPU quota below two CPUs (``_cpu_quota``) leaves no core for the helper."""
    cores = _cores()
    quota = _cpu_quota()
    if cores < 2 or (quota is not None and quota < 2.0):
        return False
    before = _cpu_ticks()
    if before is not None and before[2] == cores:
        time.sleep(window)
        after = _cpu_ticks()
        if after is not None and after[0] > before[0]:
            idle_share = (after[1] - before[1]) / (after[0] - before[0])
            return idle_share * cores >= IDLE_CORES
    return os.getloadavg()[0] <= cores - FREE_CORE


class Helper:
    """The helper process that compiles its share of the list entries of the warm-up ``steps`` in a
    fresh interpreter: ``start()`` (at the first kernel that misses the cache; nothing when
    :func:`helper_setting` says no, or, unset, :func:`free_core` measured then: ``declined``),
    ``set_steps(steps)`` (when they were not known at the start), ``wait()`` (the wall time waited,
    s), ``stop()`` (end it if it runs; remove the claims). ``folder``: the claims both processes
    share; ``alive()``: whether the helper may still save a kernel (not started yet, or running)."""

    def __init__(self, steps: Iterable[str] | None = None, *, setting: bool | None = None) -> None:
        self.steps = None if steps is None else list(steps)
        self.process: subprocess.Popen | None = None
        self._folder: Path | None = None
        # unset: the free cores are measured at ``start``, on a cold cache only (a warm run never
        # waits for the measurement); until then the claims are kept as if the helper would run
        setting = helper_setting() if setting is None else setting
        self._measure = setting is None
        self.declined = False
        if setting is not False:
            remove_stale_folders()
            self._folder = Path(tempfile.mkdtemp(prefix=f"{FOLDER_PREFIX}{os.getpid()}-"))
            if self.steps is not None:
                self._write_steps()

    @property
    def folder(self) -> Path | None:
        return self._folder

    def alive(self) -> bool:
        return not self.declined and (self.process is None or self.process.poll() is None)

    def start(self) -> None:
        if self._folder is not None and self.process is None and not self.declined:
            if self._measure and not free_core():
                self.declined = True   # this process compiles every entry (the claims stay its own)
                return
            self.process = subprocess.Popen(
                [sys.executable, "-m", "studies.cli._kernel_list", str(self._folder), str(os.getpid())],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def set_steps(self, steps: Iterable[str]) -> None:
        """Name the warm-up's steps to a helper started before they were known."""
        self.steps = list(steps)
        if self._folder is not None:
            self._write_steps()

    def _write_steps(self) -> None:
        # whole or not at all: the helper reads the file as soon as it exists
        partial = self._folder / f"{STEPS_FILE}.partial"
        partial.write_text("\n".join(self.steps) + "\n")
        os.replace(partial, self._folder / STEPS_FILE)

    def wait(self, timeout: float = 5 * WAIT_LIMIT) -> float:
        """Wait for the helper to end (at most ``timeout`` s: then it is stopped, and what it has
        not saved compiles in the warm-up); the wall time waited, s."""
        started = time.perf_counter()
        if self.process is not None:
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.stop()
        return time.perf_counter() - started

    def stop(self) -> None:
        try:
            if self.process is not None and self.process.poll() is None:
                self.process.terminate()
                self.process.wait()
        finally:   # a second signal in the wait: the folder goes all the same
            if self._folder is not None:
                shutil.rmtree(self._folder, ignore_errors=True)
                self._folder = None


def remove_stale_folders(directory: str | Path | None = None) -> list[Path]:
    """Remove the claims folders in ``directory`` (the temporary directory by default) whose run
    has ended: a run killed (SIGKILL) before it could remove its own leaves one behind, and nothing
    else would. A folder whose run is alive, or whose name carries no pid, stays. Returns the
    folders removed."""
    removed = []
    for folder in Path(directory or tempfile.gettempdir()).glob(f"{FOLDER_PREFIX}*"):
        pid = folder.name[len(FOLDER_PREFIX):].partition("-")[0]
        if pid.isdigit() and not _alive(int(pid)):
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(folder)
    return removed


def _alive(pid: int) -> bool:
    """Whether process ``pid`` exists (another user's, or where signals cannot tell, counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:   # PermissionError (another user's process) and the like: keep its folder
        pass
    return True


def read_steps(folder: Path, parent_alive) -> list[str] | None:
    """In the helper: the steps this process's parent names in ``folder`` (:data:`STEPS_FILE`),
    once it has written them; None when the parent ended first (a run that never warmed up)."""
    path = folder / STEPS_FILE
    while not path.exists():
        if not parent_alive():
            return None
        time.sleep(POLL)
    return [line for line in path.read_text().splitlines() if line]


# -------------------------------------------------------------------------------------------------
# the helper started while ``flexvib run`` imports its packages
# -------------------------------------------------------------------------------------------------
class _Early:
    """The listener of numba's first compilation and the helper it started (see the module's text)."""

    helper: Helper | None = None
    listener = None
    acted = False


def start_at_first_compilation(argv: list[str]) -> None:
    """For ``flexvib run`` (``argv``: the command's arguments): start the compile helper at the
    first numba compilation of this process's main thread, before the warm-up knows its steps
    (:func:`take_early` gives it to the warm-up). Nothing for other commands, with
    ``FLEXVIB_COMPILE_PROCESSES=1`` or a value the warm-up will refuse, or on a warm cache (no
    compilation happens before the warm-up, which then starts its own helper as before)."""
    if not argv or argv[0] != "run" or _Early.listener is not None:
        return
    _Early.acted = False
    try:
        setting = helper_setting()
    except UsageError:
        return   # the warm-up's helper says what is wrong with it
    if setting is False:
        return
    from numba.core import event

    thread = threading.get_ident()

    class _FirstCompilation(event.Listener):
        def on_start(self, ev):
            if _Early.acted or threading.get_ident() != thread or _Early.listener is not self:
                return
            _Early.acted = True   # once: the first compilation only, whatever comes of it
            # inside numba's compilation of the first kernel (inside an import): a process started,
            # nothing imported; a helper that cannot start (no process, no folder) is no error here:
            # the warm-up starts its own, or compiles alone
            helper = None
            try:
                helper = Helper(setting=setting)
                helper.start()
            except BaseException as error:  # OSError and the like from the folder or the process
                if helper is not None:
                    helper.stop()
                if not isinstance(error, Exception):
                    raise   # an interrupt: the command reports it
                return
            _Early.helper = helper

        def on_end(self, ev):
            pass

    _Early.listener = _FirstCompilation()
    event.register("numba:compile", _Early.listener)


def stop_listening() -> None:
    """No helper from here on unless one has started already: the console script calls it once
    its imports are done (a kernel that compiles later, outside a warm-up, starts none)."""
    if _Early.listener is not None:
        from numba.core import event

        event.unregister("numba:compile", _Early.listener)
        _Early.listener = None


def _pop_early() -> Helper | None:
    """The helper the first compilation started, no longer kept here (None if none); listening stops."""
    stop_listening()
    helper, _Early.helper = _Early.helper, None
    return helper


def discard_early() -> None:
    """End the helper :func:`start_at_first_compilation` started if no warm-up took it (a run that
    never warmed up: bad input, a complete result file), and remove its claims folder; stop
    listening. The console script calls it when the command has returned."""
    helper = _pop_early()
    if helper is not None:
        helper.stop()


def take_early(steps: Iterable[str]) -> Helper | None:
    """The helper :func:`start_at_first_compilation` started, told the warm-up's ``steps`` (None when
    none was started); the listening stops either way (later compilations are the warm-up's)."""
    helper = _pop_early()
    if helper is not None:
        helper.set_steps(steps)
    return helper
