"""The ``flexvib`` console script's entry point (``studies._entry:main``): signal handlers first,
then the heavy imports and the command.

SIGINT (Ctrl-C) and SIGTERM raise ``KeyboardInterrupt`` from the first line of the process that
Python runs of flexvib, before numpy, scipy and numba are imported (``studies/__init__.py`` is light,
``studies._face`` the heavy face), so a signal at any moment of a run ends it with exit code 130 and
one line: what was saved (``studies.cli._run.RunInterrupted``) or that nothing was; an interrupt that
arrives wrapped (an extension module's import cut by it raises ``ImportError`` from it:
``studies._errors.interruption``) too. After the command
has returned, the process ends at once (``os._exit``), and a signal before that with 130 too.
Only the interpreter's own start-up (before this module runs, some tens of milliseconds) keeps the
default handlers.

Before the heavy imports it also sets one BLAS thread for the command's processes
(``studies._threads``) and, for ``flexvib run``, listens for the first kernel compilation, which
starts the compile helper of a cold cache while the imports still run (``studies._compile_helper``);
a helper no warm-up took is ended when the command returns."""

from __future__ import annotations

import os
import signal
import sys
import threading

from studies._errors import interruption  # light: no numpy

#: What ``flexvib`` prints when it is interrupted before a run has saved anything.
NOTHING_SAVED = "interrupted: nothing was saved"
#: The exit code of an interrupted command (128 + SIGINT, as shells report Ctrl-C).
INTERRUPTED = 130


def _interrupt(signum: int, frame) -> None:
    raise KeyboardInterrupt(signal.Signals(signum).name)



#: Seconds after which an interrupt that arrived where Python cannot raise it is raised again.
RETRY_SECONDS = 0.001


def _raise_later(name: str):
    """A SIGALRM handler that raises ``KeyboardInterrupt(name)`` at an ordinary line: where it runs
    inside the unraisable hook still (the hook has not returned), it waits another ``RETRY_SECONDS``."""
    def handler(signum: int, frame) -> None:
        if frame is not None and frame.f_code is _HOOK_CODE:
            signal.setitimer(signal.ITIMER_REAL, RETRY_SECONDS)
            return
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        raise KeyboardInterrupt(name)
    return handler


def _signal_again(previous_hook):
    """``sys.unraisablehook`` that does not lose an interrupt: a signal whose handler ran inside a
    callback Python cannot raise from (a weak reference's callback of the import machinery's module
    locks, a ``__del__``) would be printed there as "Exception ignored ... KeyboardInterrupt", with a
    traceback, and the run would go on. Instead the interrupt is raised again ``RETRY_SECONDS`` later
    (a SIGALRM timer), at the next ordinary line, and ends the command as any interrupt does. Not the
    same signal sent again at once: its handler would run inside this hook, at the call's return, and
    its ``KeyboardInterrupt`` would be printed as the hook's own failure, with a traceback."""
    def hook(unraisable) -> None:
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            name = str(unraisable.exc_value) or "SIGINT"   # "SIGTERM", "SIGINT"
            if threading.current_thread() is not threading.main_thread():
                # only the main thread may set a handler; there the signal sent again is handled in
                # the main thread, not inside this hook
                os.kill(os.getpid(), getattr(signal, name, signal.SIGINT))
                return
            signal.signal(signal.SIGALRM, _raise_later(name))
            signal.setitimer(signal.ITIMER_REAL, RETRY_SECONDS)
            return
        previous_hook(unraisable)
    return hook


_HOOK_CODE = _signal_again(None).__code__


def _exit_now(signum: int, frame) -> None:
    """After the command returned: end at once, without tracebacks from the shutdown."""
    try:
        sys.stdout.flush()
    except (OSError, ValueError):
        pass
    os.write(2, b"interrupted: after the command had finished (its results are saved)\n")
    os._exit(INTERRUPTED)


def _discard_compile_helper() -> None:
    """End a compile helper started at the first compilation that no warm-up took (a run that never
    warmed up), if the module that starts one was imported."""
    helper_side = sys.modules.get("studies._compile_helper")
    if helper_side is not None:
        helper_side.discard_early()


def run(argv=None) -> int:
    """Run ``flexvib`` (``studies.cli.main``) with SIGINT and SIGTERM handled from the start; returns
    the exit code (130 when interrupted). From its return on, a signal ends the process at once."""
    try:
        try:
            sys.unraisablehook = _signal_again(sys.unraisablehook)
            for number in (signal.SIGINT, signal.SIGTERM):
                signal.signal(number, _interrupt)
            from studies._compile_helper import start_at_first_compilation, stop_listening  # light: no numpy
            from studies._threads import one_blas_thread  # light: no numpy

            one_blas_thread()   # before the imports: this process's libraries and the compile helper's

            # `flexvib run` on a cold cache: the compile helper starts at the first compilation,
            # while the imports below still run (their first kernel compiles in periodic.lapack)
            start_at_first_compilation(sys.argv[1:] if argv is None else list(argv))
            from studies.cli import main as command  # numpy, scipy, numba, the study kinds

            stop_listening()   # from here on the warm-up starts its helper, if it needs one

            code = command(argv)
        except BaseException as error:
            # raised during the imports (an extension module's import cut by a signal raises
            # ImportError from it), or during the command outside its own handling
            interrupt = interruption(error)
            if interrupt is None:
                raise
            print(getattr(interrupt, "line", NOTHING_SAVED), file=sys.stderr)
            code = INTERRUPTED
    except KeyboardInterrupt:   # a second signal while the first was being reported
        code = INTERRUPTED
    except SystemExit:   # argparse's errors and --help: the process ends here, its helper first
        try:
            _discard_compile_helper()
        except KeyboardInterrupt:
            _exit_now(signal.SIGINT, None)
        raise
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.0)   # no retried interrupt after the command
        for number in (signal.SIGINT, signal.SIGTERM):
            signal.signal(number, _exit_now)
        _discard_compile_helper()   # after the handlers: a signal in it ends the process at once
    except KeyboardInterrupt:   # a signal as the command returned, before _exit_now took over
        _exit_now(signal.SIGINT, None)
    return code


def main() -> None:
    """The console script: :func:`run`, then the process ends with its code at once. The interpreter's
    own shutdown is skipped: it restores the default signal handlers first, so a signal in it ended
    the process with the signal's code (143, -2) and no line; and after an import cut by a signal it
    may itself end with -2. What a run writes is committed before ``run`` returns (the result file's
    commits; a pool's workers die with this process), so only the standard streams need flushing."""
    code = run()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


if __name__ == "__main__":
    main()
