"""Compile the numba kernels a run needs before any study starts its clock, and say so.

The kernels are compiled on first use and cached on disk (``cache=True``; numba's cache folder, or
``NUMBA_CACHE_DIR``). Without a warm-up, the first study of a fresh install would report the
compilation (tens of seconds) as its run time. :func:`warm_up` runs each declared study's code path
once on a tiny grid (32 steps per period; one point of each grid study, a two-period nonlinear
check, one Newton step of a shooting), so that every kernel is compiled, with the argument types of
the real run, before the timed work: the run times a study reports are then computing times. The
compile time is measured apart (numba's ``numba:compile`` events, which a load from the disk cache
does not raise), announced when it starts ("compiling numerical kernels (first run only, ...)"),
and recorded in the result file as the attribute ``compile_time`` (s).
"""

from __future__ import annotations

import inspect
import logging
import math
import threading
import time
import warnings
from typing import Any, Callable, Mapping

from .._compile_helper import take_early
from .._kind import WARM_UP_STEPS, kind_named
from .._problem import SPEED
from ._kernel_list import STEADY_STATE_STEP, Helper, compile_listed, load_list, probe_entries

__all__ = ["CompileClock", "warm_up"]

# under "flexvib" (the command's logger), not muted with the library's packages during the warm-up
logger = logging.getLogger("flexvib.jit")

#: The off-nominal speed of the warm-up grid point, as a multiple of the scene's speed (grid points
#: off the scene's speed go through the speed family's coefficients, another code path).
OFF_NOMINAL = 1.05
#: What the announcement says to expect (the compile of the README's main job on a 2-core machine:
#: 5.6 s here, 9.6 s on a slower one; docs/benchmarks.md, session 12).
EXPECTED = "about 10 s"
#: The packages whose log records and warnings the warm-up keeps to itself.
_MUTED = ("periodic", "mechanisms", "linearize", "studies")


class CompileClock:
    """Wall time spent compiling numba kernels while it runs (``start()`` ... ``stop()``), from
    numba's ``numba:compile`` events; nested compilations (a kernel's callees) count once, in their
    caller. ``announce``: log "compiling numerical kernels ..." at the first compilation;
    ``on_first()`` is called then too (the warm-up starts its helper process there)."""

    def __init__(self, *, announce: bool = True, on_first: Callable[[], None] | None = None) -> None:
        self.seconds = 0.0
        self.on_first = on_first
        self.count = 0
        self.announce = announce
        self._depth = 0
        self._started = 0.0
        self._listener = None
        self._thread = threading.get_ident()

    def start(self) -> "CompileClock":
        from numba.core import event

        clock = self

        class _Listener(event.Listener):
            def on_start(self, ev):
                if threading.get_ident() != clock._thread:
                    return
                if clock._depth == 0:
                    if clock.count == 0 and clock.announce:
                        logger.info("compiling numerical kernels (first run only, %s)...", EXPECTED)
                    if clock.count == 0 and clock.on_first is not None:
                        clock.on_first()
                    clock._started = time.perf_counter()
                    clock.count += 1
                clock._depth += 1

            def on_end(self, ev):
                if threading.get_ident() != clock._thread:
                    return
                clock._depth -= 1
                if clock._depth == 0:
                    clock.seconds += time.perf_counter() - clock._started

        self._listener = _Listener()
        event.register("numba:compile", self._listener)
        return self

    def stop(self) -> float:
        """Stop listening; the compile time in s."""
        from numba.core import event

        if self._listener is not None:
            event.unregister("numba:compile", self._listener)
            self._listener = None
        return self.seconds


def warm_up_steps(problem: Any, studies: Mapping[str, Mapping[str, Any]]) -> list[tuple[str, Any]]:
    """The warm-up's steps for the declared ``studies``, in order: ``(name, run)``, ``run()`` runs
    the step's code path on ``problem`` (the linear steady state first, then each kind's own)."""
    steps: list[tuple[str, Any]] = [(STEADY_STATE_STEP, lambda: _steady_state(problem))]
    for name in studies:
        kind = kind_named(name)
        if kind.warm_up is not None:
            steps.append((name, lambda hook=kind.warm_up: hook(problem)))
        elif kind.grid and kind.point is not None:
            steps.append((name, lambda point=kind.point: _grid_point(problem, point)))
    return steps


def warm_up(problem: Any, studies: Mapping[str, Mapping[str, Any]]) -> CompileClock:
    """Compile the kernels the declared ``studies`` ({kind: options}, as ``plan`` gives them) need on
    ``problem``, by running each kind's code path on a tiny grid; returns the running
    :class:`CompileClock` (stop it after the run: compilations the warm-up missed are counted too).

    Every run warms up a linear steady state (what every kind builds on); then each kind its own
    path: its ``warm_up`` hook, or for a grid kind one point. Before the steps, the kernels the list
    names for these steps are compiled on two cores (:mod:`studies.cli._kernel_list`: this process
    and a helper started at the first kernel that misses the disk cache); the steps then load them.
    Nothing the warm-up computes is kept; a warm-up run that fails (a tiny grid may not converge) is
    logged at DEBUG level and skipped, and its kernels compile when the study needs them."""
    steps = warm_up_steps(problem, studies)
    names = [name for name, _ in steps]
    helper = None
    started = time.perf_counter()
    try:   # from before the helper's folder exists: an interrupt at any moment removes it
        # the helper ``flexvib run`` started while importing (a cold cache), or one of its own
        helper = take_early(names) or Helper(names)
        clock = CompileClock(on_first=helper.start).start()
        with _muted():
            listed = load_list(helper.steps)
            if listed:
                # the probe: one kernel the code calls, with its few callees; loaded from the
                # cache, the cache is taken as warm and the steps load what they need (walking the
                # list would load every callee too, which a kernel loaded from the cache does not need)
                before = clock.count
                probe = probe_entries(listed)
                taken = compile_listed(listed, helper.folder, only=probe, other_alive=helper.alive)
                # warm: this process took every probe entry and loaded each (an entry the helper
                # took first, or one compiled here, says cold)
                warm = taken == len(probe) and clock.count == before
                if warm:
                    helper.stop()   # a helper started at an import's compilation: nothing to share
                else:
                    compile_listed(listed, helper.folder, other_alive=helper.alive)
            clock.seconds += helper.wait()   # the helper's share is compile time too
            for name, run in steps:
                _attempt(name, run)
    finally:
        if helper is not None:
            helper.stop()
    if clock.count:
        logger.info("compiled the numerical kernels in %.0f s (cached for the next runs; "
                    "not counted in the studies' run times)", time.perf_counter() - started)
    return clock


def _attempt(what: str, run, *args) -> None:
    try:
        run(*args)
    except Exception as error:  # noqa: BLE001 - a warm-up failure only defers the compilation
        logger.debug("warm-up of %s skipped: %s: %s", what, type(error).__name__, error)


def _steady_state(problem: Any) -> None:
    """The steady state at the scene's values, every piece of it (linearisation, periodic solve,
    observables, the drawing): what every kind builds on."""
    from .._kinds.steady_state import steady_state

    steady_state(problem, n_steps=WARM_UP_STEPS)


def _off_nominal(problem: Any) -> dict[str, float]:
    speed = problem.parameters.get(SPEED)
    return {} if speed is None or not math.isfinite(speed) else {SPEED: OFF_NOMINAL * speed}


def _grid_point(problem: Any, point) -> None:
    """One point of a grid study off the scene's speed, with the smallest sizes its function takes
    (the keyword options every point function has are ``n_steps`` and sample counts)."""
    sizes = {"n_steps": WARM_UP_STEPS, "frozen_samples": 2}
    options = {name: sizes[name] for name in inspect.signature(point).parameters if name in sizes}
    point(problem, _off_nominal(problem), **options)


class _muted:
    """The library's log records below ERROR and its warnings kept out of the run's console while
    the warm-up's tiny grids run."""

    def __enter__(self):
        self._levels = [(logging.getLogger(name), logging.getLogger(name).level) for name in _MUTED]
        for log, _ in self._levels:
            log.setLevel(logging.ERROR)
        self._warnings = warnings.catch_warnings()
        self._warnings.__enter__()
        warnings.simplefilter("ignore")
        return self

    def __exit__(self, *exc):
        self._warnings.__exit__(*exc)
        for log, level in self._levels:
            log.setLevel(level)
        return False
