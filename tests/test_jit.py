"""The numba warm-up of ``flexvib run`` (studies/_jit.py) and the compile-time economies of the
kernels: the compile clock, the warm-up covering every kernel a run calls (so that no study's run
time includes a compilation) and one signature per kernel (the continuation's in-kernel solve is
tested in tests/test_lapack.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numba
import pytest

from studies.cli._jit import CompileClock  # the command's warm-up machinery: no public face

ROOT = Path(__file__).resolve().parent.parent


def test_compile_clock_counts_a_compilation_once_with_its_callees():
    @numba.njit  # defined here: not in any cache, so it compiles
    def inner(x):
        return 2.0 * x

    @numba.njit
    def outer(x):
        return inner(x) + 1.0

    clock = CompileClock(announce=False).start()
    try:
        assert outer(1.0) == 3.0
        assert outer(2.0) == 5.0  # compiled already: not counted again
    finally:
        seconds = clock.stop()
    assert clock.count == 1 and seconds > 0.0
    assert inner.signatures and outer.signatures


_COVERAGE_SCRIPT = textwrap.dedent("""
    import json, sys
    import numba
    import mechanisms, studies
    # the command's warm-up, run and [studies] check, called apart: no public face
    from studies.cli._jit import warm_up
    from studies.cli._run import run_plan
    from studies.cli._scene import plan

    scene = mechanisms.load("four_bar_thesis").to_toml() + sys.argv[2]
    problem = studies.MechanismProblem.from_mechanism(mechanisms.loads(scene),
                                                      parameter_paths=["links.coupler.thickness"])
    common, declared = plan(mechanisms.loads(scene).studies)

    def signatures():
        found = {}
        for name, module in list(sys.modules.items()):
            if name.split(".")[0] in ("periodic", "mechanisms", "linearize", "studies"):
                for attr, value in vars(module).items():
                    if isinstance(value, numba.core.registry.CPUDispatcher):
                        found[f"{name}.{attr}"] = [str(s) for s in value.signatures]
        return found

    clock = warm_up(problem, declared)
    after_warm_up = signatures()
    run_plan(problem, declared, sys.argv[1])
    clock.stop()
    print(json.dumps({"warm_up": after_warm_up, "run": signatures()}))
""")

_SCENE = """
[studies]
n_steps = 32

[studies.steady_state]

[studies.sweep]
parameter = "speed"
values = [60.0, 140.0]

[studies.stability_chart]
x = { parameter = "speed", values = [80.0, 120.0] }
y = { parameter = "links.coupler.thickness", values = [1.4e-3, 1.8e-3] }
n_steps = 32

[studies.nonlinear_check]
speeds = [60.0, 100.0]
n_periods = 2

[studies.nonlinear_steady_state]
n_steps = 32
"""


@pytest.mark.slow
def test_the_warm_up_compiles_every_kernel_the_run_calls(tmp_path):
    """In a fresh process (numba's disk cache as the suite left it), the studies of a run call no
    kernel, with no argument types, that the warm-up did not already compile or load: their run
    times hold no compilation. And no kernel has two signatures (read-only against writable arrays,
    a literal against an integer)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    done = subprocess.run([sys.executable, "-c", _COVERAGE_SCRIPT, str(tmp_path / "run.h5"), _SCENE],
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    found = json.loads(done.stdout.splitlines()[-1])
    assert found["run"] == found["warm_up"]
    called = {name: sigs for name, sigs in found["run"].items() if sigs}
    assert "periodic._newmark.newmark_march" in called and "mechanisms._kernels.force_jacobians" in called
    assert "mechanisms._alpha_tangent._tangent_steps" in called    # the shooting's monodromy
    assert not [name for name, sigs in called.items() if len(sigs) != 1]
    assert not [name for name, sigs in called.items() if any("Literal" in s for s in sigs)]



# --- the kernel list and the helper process that compiles on the second core ---------------------

def test_the_kernel_list_resolves_and_orders_callees_before_their_callers():
    """Every entry of the shipped list names a kernel of the loaded packages and a signature this
    numba reads back; a kernel comes after the kernels it calls (each process compiles callees
    first, so that the other finds them in the cache), and its ``callees`` point at them."""
    import linearize  # noqa: F401 - the packages whose kernels the list names
    import mechanisms  # noqa: F401
    import periodic  # noqa: F401
    from studies.cli._kernel_list import KERNEL_LIST, first_root, load_list, probe_entries

    entries = json.loads(KERNEL_LIST.read_text())
    listed = load_list({entry["step"] for entry in entries})
    assert len(listed) == len(entries) > 20
    assert {(e.kernel, repr(tuple(e.signature))) for e in listed} == {(e["kernel"], e["signature"]) for e in entries}
    position = {entry.kernel: k for k, entry in enumerate(listed)}
    continuation = listed[position["mechanisms._batch.continue_positions_kernel"]]
    assert position["mechanisms._kernels.constraints"] in continuation.callees
    assert position["mechanisms._kernels.constraint_jacobian"] in continuation.callees
    # every listed kernel a kernel calls (read from its code here, not from the list's own record)
    # comes before it
    from studies.cli._kernel_list import _callees, _dispatchers

    calls = _callees(_dispatchers())
    for k, entry in enumerate(listed):
        called_here = {j for j, other in enumerate(listed) if other.kernel in calls[entry.kernel]}
        assert set(entry.callees) == called_here and all(j < k for j in called_here), entry.kernel
    # the warm-up's probe of the cache: a kernel no listed kernel calls (the code calls it), with
    # the fewest callees (compiled with it on a cold cache)
    probe = first_root(listed)
    roots = [k for k in range(len(listed)) if not [entry for entry in listed if k in entry.callees]]
    assert probe in roots
    assert len(listed[probe].callees) == min(len(listed[k].callees) for k in roots)
    assert probe_entries(listed) == [*listed[probe].callees, probe]
    assert all(entry.cost > 0.0 for entry in listed)
    # a step the run does not declare lists nothing
    assert load_list(["no such step"]) == []


def test_the_list_goes_by_the_longest_chain_of_compilations_first(tmp_path):
    """An entry's rank is its cost plus the largest rank of the listed kernels that call it; the
    list goes by falling rank (then by name), so a chain's callees come first and a costly kernel
    nothing waits for still goes before the short chains (worked out by hand for four kernels)."""
    import mechanisms  # noqa: F401 - the kernels named below
    import periodic  # noqa: F401
    from studies.cli._kernel_list import load_list

    signature = "(float64,)"   # not the kernels' real types: load_list only reads the names and costs
    costs = {"mechanisms._alpha_kernel._newton": 1.0, "mechanisms._kernels.forces": 1.0,
             "mechanisms._kernels.mass_matrix": 0.5, "periodic._newmark.newmark_march": 1.8}
    path = tmp_path / "list.json"
    path.write_text(json.dumps([{"step": "s", "kernel": k, "signature": signature, "cost": c}
                                for k, c in costs.items()]))
    listed = load_list(["s"], path)
    # ranks: forces 1 + 1 = 2, newmark_march 1.8, mass_matrix 0.5 + 1 = 1.5, _newton 1
    assert [entry.kernel for entry in listed] == [
        "mechanisms._kernels.forces", "periodic._newmark.newmark_march", "mechanisms._kernels.mass_matrix",
        "mechanisms._alpha_kernel._newton"]
    assert listed[3].callees == (0, 2) and listed[1].callees == ()
    # a list without costs (recorded before them) takes the same cost for each: callees still first
    path.write_text(json.dumps([{"step": "s", "kernel": k, "signature": signature} for k in costs]))
    order = [entry.kernel for entry in load_list(["s"], path)]
    assert order.index("mechanisms._kernels.forces") < order.index("mechanisms._alpha_kernel._newton")


def test_an_entry_waiting_for_the_other_process_lets_the_next_one_go_first(tmp_path):
    """The other process is compiling a callee of this process's next entry: the entry after it,
    which waits for nothing, compiles meanwhile; the waiting one compiles when the other ends."""
    from studies.cli._kernel_list import Listed, compile_listed

    @numba.njit
    def callee(x):
        return x - 1.0

    @numba.njit
    def caller(x):
        return callee(x) * 2.0

    @numba.njit
    def independent(x):
        return x * 3.0

    signature = (numba.float64,)
    listed = [Listed("callee", callee, signature, ()), Listed("caller", caller, signature, (0,)),
              Listed("independent", independent, signature, ())]
    (tmp_path / "0").touch()   # the other process claimed the callee and has not saved it
    seen = []

    def other_alive():
        seen.append((bool(caller.signatures), bool(independent.signatures)))
        return len(seen) < 3   # it ends after a few looks

    assert compile_listed(listed, tmp_path, other_alive=other_alive, timeout=60.0) == 2
    assert seen[0] == (False, True)   # the independent entry went while the caller waited
    assert caller.signatures == [signature]   # with its callee, which the other never saved
    assert (tmp_path / "1.done").exists() and not (tmp_path / "0.done").exists()


def test_compile_listed_stops_when_told(tmp_path):
    """``stop()`` (the helper's parent has ended) ends the walk before the next entry."""
    from studies.cli._kernel_list import Listed, compile_listed

    @numba.njit
    def first(x):
        return x + 4.0

    @numba.njit
    def second(x):
        return x * 5.0

    signature = (numba.float64,)
    listed = [Listed("first", first, signature, ()), Listed("second", second, signature, ())]
    looks = []
    assert compile_listed(listed, tmp_path, stop=lambda: looks.append(1) or len(looks) > 1) == 1
    assert first.signatures == [signature] and not second.signatures and not (tmp_path / "1").exists()


def test_a_helper_whose_parent_ended_removes_its_claims():
    """A parent killed before it stopped its helper (no ``finally`` ran): the helper sees it gone,
    does nothing more and removes the claims folder, which nobody else would."""
    import time

    script = textwrap.dedent("""
        import os
        from studies._compile_helper import Helper
        helper = Helper(setting=True)   # started before the steps were known, as for flexvib run
        helper.start()
        print(helper.folder, flush=True)
        os._exit(9)                     # as a killed process: nothing cleaned up
    """)
    done = subprocess.run([sys.executable, "-c", script], env=dict(os.environ, PYTHONPATH=str(ROOT)),
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 9, done.stderr
    folder = Path(done.stdout.strip())
    assert folder.name.startswith("flexvib-compile-")
    deadline = time.monotonic() + 60.0
    while folder.exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not folder.exists()


def test_a_killed_runs_claims_folder_is_removed_by_the_next_run(tmp_path):
    """A run killed before its helper existed (SIGKILL in a warm cache's warm-up: no helper to clean
    up) leaves its claims folder; the next run's warm-up removes it, and leaves alone the folders of
    live runs and any folder whose name carries no pid."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), TMPDIR=str(tmp_path))
    killed = subprocess.run([sys.executable, "-c", textwrap.dedent("""
        import os
        from studies._compile_helper import Helper
        print(Helper(["steady state"], setting=True).folder, flush=True)
        os._exit(9)                     # as a killed process: nothing cleaned up
    """)], env=env, capture_output=True, text=True, timeout=120)
    assert killed.returncode == 9, killed.stderr
    left = Path(killed.stdout.strip())
    assert left.parent == tmp_path and left.is_dir() and left.name.startswith("flexvib-compile-")
    live = tmp_path / f"flexvib-compile-{os.getpid()}-live"      # this test's process: alive
    unnamed = tmp_path / "flexvib-compile-notapid"
    live.mkdir()
    unnamed.mkdir()
    next_run = subprocess.run([sys.executable, "-c", textwrap.dedent("""
        from studies._compile_helper import Helper
        helper = Helper(["steady state"], setting=True)
        print(helper.folder, flush=True)
        helper.stop()
    """)], env=env, capture_output=True, text=True, timeout=120)
    assert next_run.returncode == 0, next_run.stderr
    assert not left.exists()
    assert live.is_dir() and unnamed.is_dir()
    assert not Path(next_run.stdout.strip()).exists()   # its own removed by stop()


def test_compile_listed_takes_only_the_entries_it_claims(tmp_path):
    """Two processes share the list through claim files: an entry claimed by the other process is
    left to it (and its callees are waited for only while the other process is alive)."""
    from studies.cli._kernel_list import Listed, compile_listed

    @numba.njit  # defined here: not in any cache
    def twice(x):
        return 2.0 * x

    @numba.njit
    def thrice(x):
        return 3.0 * x

    signature = (numba.float64,)
    listed = [Listed("twice", twice, signature, ()), Listed("thrice", thrice, signature, (0,))]
    (tmp_path / "0").touch()   # the other process claimed entry 0 and has not finished it
    assert compile_listed(listed, tmp_path, other_alive=lambda: False) == 1
    assert not twice.signatures and thrice.signatures == [signature]
    assert (tmp_path / "1.done").exists() and not (tmp_path / "0.done").exists()
    assert compile_listed(listed, None) == 2 and twice.signatures == [signature]
    assert compile_listed(listed, None, only=(i for i in [0, 1])) == 2   # any iterable of indices


def test_an_unclaimed_callee_is_not_waited_for(tmp_path):
    """The warm-up's probe compiles one kernel out of the list's order: a callee nobody claimed is
    compiled with it at once, not waited for (the other process, alive or not yet started, will
    never mark it done)."""
    import time

    from studies.cli._kernel_list import Listed, compile_listed

    @numba.njit
    def inner(x):
        return x + 1.0

    @numba.njit
    def outer(x):
        return inner(x) * 2.0

    signature = (numba.float64,)
    listed = [Listed("inner", inner, signature, ()), Listed("outer", outer, signature, (0,))]
    started = time.perf_counter()
    assert compile_listed(listed, tmp_path, only=[1], other_alive=lambda: True, timeout=60.0) == 1
    assert time.perf_counter() - started < 30.0 and outer.signatures == [signature]


def test_the_helper_process_runs_its_share_of_the_list(monkeypatch):
    """The helper process (``python -m studies.cli._kernel_list CLAIMS PARENT_PID``, its steps in the claims
    folder) starts, takes the entries left to it and ends with exit code 0 (the cache is warm here:
    it loads them)."""
    from studies.cli._kernel_list import PROCESSES_VARIABLE, Helper

    monkeypatch.setenv(PROCESSES_VARIABLE, "2")
    monkeypatch.setenv("PYTHONPATH", str(ROOT))
    helper = Helper(["steady state"])
    try:
        helper.start()
        assert helper.wait() >= 0.0 and helper.process.returncode == 0
        assert list(helper.folder.glob("*.done"))
    finally:
        helper.stop()
    assert helper.folder is None


def test_run_starts_the_helper_at_its_first_compilation_and_the_warm_up_takes_it(monkeypatch):
    """``flexvib run``: the first kernel this process compiles starts the helper before the steps are
    known (a cold cache: while the command imports); the warm-up takes it and names its steps (here
    one the list does not hold: it has nothing to compile and ends with 0). Other commands, a setting
    of 1, a compilation after ``stop_listening`` or in another thread start none."""
    from studies import _compile_helper

    monkeypatch.setenv("PYTHONPATH", str(ROOT))
    monkeypatch.setenv(_compile_helper.PROCESSES_VARIABLE, "2")
    try:
        _starts_and_takes(_compile_helper, monkeypatch)
    finally:   # no listener or helper left to the rest of the suite, whatever failed
        _compile_helper.discard_early()


def _starts_and_takes(_compile_helper, monkeypatch):
    import threading

    def compile_one():
        @numba.njit  # defined here: not in any cache
        def fresh(x):
            return x + 2.0

        fresh.compile((numba.float64,))

    _compile_helper.start_at_first_compilation(["check"])
    compile_one()
    assert _compile_helper.take_early(["steady state"]) is None
    _compile_helper.start_at_first_compilation(["run", "--out", "x.h5"])
    worker = threading.Thread(target=compile_one)
    worker.start()
    worker.join()
    assert _compile_helper._Early.helper is None            # not this process's main thread
    compile_one()
    helper = _compile_helper.take_early(["no such step"])
    try:
        assert helper is not None and helper.process is not None
        assert (helper.folder / _compile_helper.STEPS_FILE).read_text() == "no such step\n"
        assert helper.wait(timeout=120.0) >= 0.0 and helper.process.returncode == 0
    finally:
        helper.stop()
    assert helper.folder is None
    compile_one()
    assert _compile_helper.take_early(["steady state"]) is None   # the warm-up took it: listening ended
    _compile_helper.start_at_first_compilation(["run"])
    _compile_helper.stop_listening()
    compile_one()
    assert _compile_helper.take_early(["steady state"]) is None
    # a run that never warms up: the console script ends the helper nobody took, and its folder
    _compile_helper.start_at_first_compilation(["run"])
    compile_one()
    untaken = _compile_helper._Early.helper
    assert untaken is not None and untaken.process.poll() is None   # waiting for its steps
    folder = untaken.folder
    _compile_helper.discard_early()
    assert untaken.process.poll() is not None and not folder.exists()
    assert _compile_helper._Early.helper is None and _compile_helper._Early.listener is None
    monkeypatch.setenv(_compile_helper.PROCESSES_VARIABLE, "1")
    _compile_helper.start_at_first_compilation(["run"])
    assert _compile_helper._Early.listener is None


def test_the_helper_waits_for_its_steps_while_its_parent_lives(tmp_path, monkeypatch):
    """A helper started before the steps were known waits for the steps file while its parent
    lives, and reads them once written whole (``Helper.set_steps``); its parent ended before naming
    them (a run that never warmed up), it ends with nothing to do."""
    from studies import _compile_helper

    assert _compile_helper.read_steps(tmp_path, lambda: False) is None
    monkeypatch.setattr(_compile_helper.time, "sleep", lambda seconds: None)
    helper = _compile_helper.Helper(setting=False)   # no folder of its own: only its writer is used
    helper._folder = tmp_path
    looks = []

    def parent_alive():   # the parent names the steps at the third look
        looks.append(1)
        if len(looks) == 3:
            helper.set_steps(["steady state", "nonlinear_check"])
        return True

    assert _compile_helper.read_steps(tmp_path, parent_alive) == ["steady state", "nonlinear_check"]
    assert len(looks) == 3 and not list(tmp_path.glob("*.partial"))


def test_a_helper_that_cannot_start_at_the_first_compilation_is_no_error(monkeypatch):
    """The process or the folder cannot be had (EAGAIN, a full /tmp): the first compilation goes on
    (it runs inside an import), no helper is kept and its folder is removed; the warm-up then
    starts its own, or compiles alone."""
    from studies import _compile_helper

    monkeypatch.setenv(_compile_helper.PROCESSES_VARIABLE, "2")
    folders = []

    def failing_start(self):
        folders.append(self.folder)
        raise OSError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(_compile_helper.Helper, "start", failing_start)

    @numba.njit
    def fresh(x):
        return x + 6.0

    try:
        _compile_helper.start_at_first_compilation(["run"])
        fresh.compile((numba.float64,))
        assert fresh.signatures and _compile_helper._Early.helper is None
        assert folders and not folders[0].exists()
    finally:
        _compile_helper.discard_early()


def test_the_processes_setting_is_checked(monkeypatch):
    from studies._errors import UsageError
    from studies.cli._kernel_list import PROCESSES_VARIABLE, helper_setting

    monkeypatch.setenv(PROCESSES_VARIABLE, "1")
    assert helper_setting() is False
    monkeypatch.setenv(PROCESSES_VARIABLE, "2")
    assert helper_setting() is True
    monkeypatch.delenv(PROCESSES_VARIABLE)
    assert helper_setting() is None          # decided by the free cores, at the first cache miss
    monkeypatch.setenv(PROCESSES_VARIABLE, "two")
    with pytest.raises(UsageError, match="FLEXVIB_COMPILE_PROCESSES: expected 1 .* or 2 .* got 'two'"):
        helper_setting()


def test_the_free_cores_are_measured_not_read_off_the_load_average(monkeypatch):
    """``free_core``: the machine's idle time over a short window (this process asleep) decides, not
    the 1-min load average, which lags a busy minute (``pip install``, the last run) by a minute; the
    load average only where the CPU times cannot be read or cover other CPUs than this process's."""
    from studies import _compile_helper

    monkeypatch.setattr(_compile_helper, "_cores", lambda: 2)
    monkeypatch.setattr(_compile_helper, "_cpu_quota", lambda: None)
    monkeypatch.setattr(_compile_helper.os, "getloadavg", lambda: (1.9, 1.9, 1.9))   # just after a busy minute
    monkeypatch.setattr(_compile_helper.time, "sleep", lambda seconds: None)

    def ticks(*readings):
        readings = iter(readings)
        monkeypatch.setattr(_compile_helper, "_cpu_ticks", lambda: next(readings))

    ticks((1000, 500, 2), (1020, 519, 2))          # 19 of 20 ticks idle: both cores free
    assert _compile_helper.free_core()
    ticks((1000, 500, 2), (1020, 511, 2))          # 11 of 20: 1.1 cores idle, one of them this process's
    assert not _compile_helper.free_core()
    ticks(None)                                    # unreadable: the load average
    assert not _compile_helper.free_core()
    monkeypatch.setattr(_compile_helper.os, "getloadavg", lambda: (0.3, 0.3, 0.3))
    ticks((1000, 500, 64))                         # the host's 64 CPUs: the load average
    assert _compile_helper.free_core()
    ticks((1000, 500, 2), (1020, 519, 2))
    monkeypatch.setattr(_compile_helper, "_cpu_quota", lambda: 1.0)   # docker --cpus=1: no core for a helper
    assert not _compile_helper.free_core()
    monkeypatch.setattr(_compile_helper, "_cpu_quota", lambda: None)
    monkeypatch.setattr(_compile_helper, "_cores", lambda: 1)
    assert not _compile_helper.free_core()


def test_the_cpu_times_read_this_machine():
    from studies import _compile_helper

    found = _compile_helper._cpu_ticks()
    if found is None:
        pytest.skip("no /proc/stat here")
    total, idle, cpus = found
    assert 0 <= idle <= total and cpus >= 1


def test_a_helper_declined_at_the_first_miss_leaves_every_kernel_to_this_process(monkeypatch):
    """Unset, the free cores are measured at ``start`` (a cold cache only); a busy machine declines:
    no process, ``alive()`` False (nothing waits for it), the claims folder kept for this process."""
    from studies import _compile_helper

    monkeypatch.delenv(_compile_helper.PROCESSES_VARIABLE, raising=False)
    asked = []
    monkeypatch.setattr(_compile_helper, "free_core", lambda: asked.append(1) or False)
    helper = _compile_helper.Helper(["steady state"])
    try:
        assert not asked and helper.folder is not None and helper.alive()   # a warm run measures nothing
        helper.start()
        assert asked == [1] and helper.declined and helper.process is None and not helper.alive()
        helper.start()
        assert asked == [1]
        assert helper.wait() < 1.0
    finally:
        helper.stop()
    assert helper.folder is None


_RECORD_SCRIPT = textwrap.dedent("""
    import json
    from studies.cli._kernel_record import main_job_list
    print(json.dumps(main_job_list()))
""")


@pytest.mark.slow
def test_the_kernel_list_is_what_the_main_job_warm_up_compiles(tmp_path):
    """In a fresh process on an empty numba cache, the warm-up of the main job (default scene, its
    studies) adds, step by step, exactly the signatures of the shipped list: the list the helper
    process compiles cannot drift from the kernels. (It compiles every kernel of the main job.)"""
    from studies.cli._kernel_list import KERNEL_LIST

    env = dict(os.environ, PYTHONPATH=str(ROOT), NUMBA_CACHE_DIR=str(tmp_path))
    done = subprocess.run([sys.executable, "-c", _RECORD_SCRIPT], env=env, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, done.stderr
    recorded = json.loads(done.stdout.splitlines()[-1])
    shipped = json.loads(KERNEL_LIST.read_text())

    def names(entries):   # the costs (CPU s) vary from run to run and machine to machine
        return [{key: value for key, value in entry.items() if key != "cost"} for entry in entries]

    assert names(recorded) == names(shipped), ("studies/cli/kernel_list.json is out of date: run "
                                               "`.venv/bin/python -m studies.cli._kernel_record` and commit it")
    # each entry's compile CPU (s, its callees apart): what orders the list
    assert all(entry["cost"] > 0.0 for entry in recorded + shipped)
