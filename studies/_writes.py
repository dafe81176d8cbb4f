"""What makes a write to a result file one piece: Ctrl-C and SIGTERM wait for the end of the write in
progress (so a commit never sees half a write), and the registry of the open result files, so that an
h5py object's write can ask the file it belongs to (``owner_of``) for free space and a commit."""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from typing import Any, Iterator

_DEFERRAL = threading.local()


def _deferral() -> Any:
    if not hasattr(_DEFERRAL, "depth"):
        _DEFERRAL.depth, _DEFERRAL.pending = 0, False
    return _DEFERRAL


def interrupt_handler(signum: int, frame: Any) -> None:
    """Signal handler for SIGINT and SIGTERM: ``KeyboardInterrupt`` now, or at the end of the write
    in progress (see :func:`deferred_interrupts`). The request stays pending until a write's end
    raises it, in case the first ``KeyboardInterrupt`` landed where Python swallows exceptions (a
    fork hook, a finaliser)."""
    state = _deferral()
    state.pending = True
    if not state.depth:
        raise KeyboardInterrupt(signal.Signals(signum).name)


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """A block that SIGINT/SIGTERM (through :func:`interrupt_handler`) do not cut in two: an interrupt
    arriving inside, or before it and lost, is raised when the block ends."""
    state = _deferral()
    state.depth += 1
    try:
        yield
    finally:
        state.depth -= 1
        if not state.depth and state.pending:
            import sys

            if sys.exc_info()[0] is None:  # an error already on its way keeps precedence
                raise KeyboardInterrupt("deferred")


@contextlib.contextmanager
def interrupts_handled() -> Iterator[None]:
    """Install :func:`interrupt_handler` for SIGINT and SIGTERM (main thread only) for the block."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    import sys

    previous = {sig: signal.signal(sig, interrupt_handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    hook = sys.unraisablehook
    sys.unraisablehook = _quiet_about_interrupts(hook)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        sys.unraisablehook = hook
        _deferral().pending = False  # the interrupt has been delivered: a new run starts clean


def _quiet_about_interrupts(hook: Any) -> Any:
    """``sys.unraisablehook`` that says nothing of a ``KeyboardInterrupt`` Python swallowed (raised
    in a finaliser or fork hook): it stays pending and is raised at the end of the next write."""
    def quiet(unraisable: Any) -> None:
        if not issubclass(unraisable.exc_type, KeyboardInterrupt):
            hook(unraisable)

    return quiet


# ---------------------------------------------------------------------------------------------------
# the open result files (studies._resultfile.ResultFile registers its working copy here)
# ---------------------------------------------------------------------------------------------------
_OPEN_FILES: dict[str, Any] = {}


def register_open(path: Any, owner: Any) -> None:
    """Make ``owner`` (a ``ResultFile``) the owner of the h5py objects of the file at ``path``."""
    _OPEN_FILES[os.path.realpath(path)] = owner


def forget_open(path: Any) -> None:
    _OPEN_FILES.pop(os.path.realpath(path), None)


def owner_of(item: Any) -> Any:
    """The ``ResultFile`` whose working copy ``item`` (an h5py object) belongs to, if any."""
    try:
        return _OPEN_FILES.get(os.path.realpath(item.file.filename))
    except (AttributeError, ValueError, RuntimeError):  # closed or not an h5py object
        return None


@contextlib.contextmanager
def writing_to(item: Any, extra: int = 0) -> Iterator[None]:
    """A write of about ``extra`` bytes to ``item``: through its ``ResultFile`` when it has one (free
    space checked, interrupts deferred), else as is."""
    owner = owner_of(item)
    with owner.writing(extra) if owner is not None else contextlib.nullcontext():
        yield
