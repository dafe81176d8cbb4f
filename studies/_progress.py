"""Progress bars of long computations (grid points, a run's studies): tqdm on stderr, drawn only when
stderr is a terminal (never into a redirected file).

Two things a plain ``tqdm`` gets wrong on a command's terminal, fixed here:

- a pseudo-terminal that nobody gave a size (``script`` run without a terminal of its own, a ``pty``
  opened by a program, some CI runners) reports 0 columns and 0 rows, and tqdm then draws nothing at
  all: such a terminal is taken as 80 x 24 (``FALLBACK_SIZE``);
- a bar that advances rarely (the run's bar over its studies, one step per study) would show the
  same frozen line for the whole of a long study: ``ticking`` bars redraw themselves every
  ``TICK`` s, so their elapsed time runs, and appear only after ``delay`` s (no flash of a bar for a
  study that takes a fraction of a second).
"""

from __future__ import annotations

import os
import sys
import threading
import time

__all__ = ["FALLBACK_SIZE", "TICK", "progress_bar", "progress_wanted"]

#: Columns and rows assumed for a terminal that reports a size of 0 (a pseudo-terminal never sized).
FALLBACK_SIZE = (80, 24)
#: Seconds between the redraws of a ticking bar.
TICK = 0.5


def progress_wanted(enabled: bool = True) -> bool:
    """Whether to draw progress bars: asked for, and stderr is a terminal (never into a file)."""
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(enabled and isatty is not None and isatty())


def progress_bar(iterable=None, *, enabled: bool, ticking: bool = False, **options):
    """A ``tqdm`` bar on stderr, disabled unless :func:`progress_wanted` (``options`` go to tqdm).

    ``ticking``: the bar redraws itself every :data:`TICK` s while it is open (its elapsed time runs
    even when it does not advance); give it a ``delay`` (s) to keep it off the terminal for short
    runs."""
    from tqdm import tqdm

    wanted = progress_wanted(enabled)
    if wanted:
        for name, size in zip(("ncols", "nrows"), _terminal_size()):
            if size is not None:
                options.setdefault(name, size)
    bar = tqdm(iterable, disable=not wanted, file=sys.stderr, **options)
    if wanted and ticking:
        _Ticker(bar).start()
    return bar


def _terminal_size() -> tuple[int | None, int | None]:
    """(columns, rows) to impose on tqdm: the fallback for each that stderr's terminal reports as 0,
    None where it reports a size (tqdm then follows the terminal itself)."""
    try:
        size = os.get_terminal_size(sys.stderr.fileno())
    except (AttributeError, OSError, ValueError):  # no file descriptor (a captured stream)
        return FALLBACK_SIZE
    return (FALLBACK_SIZE[0] if size.columns == 0 else None,
            FALLBACK_SIZE[1] if size.lines == 0 else None)


class _Ticker(threading.Thread):
    """Redraws ``bar`` every :data:`TICK` s once its ``delay`` has passed, until the bar is closed."""

    def __init__(self, bar) -> None:
        super().__init__(daemon=True, name="flexvib-progress-tick")
        self.bar = bar
        self.stopped = threading.Event()
        close = bar.close

        def close_and_stop():
            self.stopped.set()
            close()

        bar.close = close_and_stop

    def run(self) -> None:
        bar = self.bar
        while not self.stopped.wait(TICK):
            if bar.disable:  # closed
                return
            if time.time() >= bar.start_t + bar.delay:  # tqdm's clock is time.time
                bar.refresh()
