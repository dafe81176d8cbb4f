"""What ``flexvib run`` shows on the terminal: log lines, progress bars and warnings, each once.

The library only logs (``logging``) and warns (``warnings``); this module decides what a person sees:

- log records of the project's packages go to stderr, INFO and above (``quiet``: ERROR and above),
  through tqdm's logging redirect so that a line is never glued to a progress bar;
- progress bars are drawn only when stderr is a terminal (never into a redirected file);
- warnings, Python ``warnings`` and WARNING log records alike, are collected while the run lasts and
  shown once each, with their count, after it (:func:`collected_warnings`), instead of once per grid
  point; ``--quiet`` shows none of them.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import warnings
from dataclasses import dataclass
from typing import Iterator

from .._progress import progress_bar, progress_wanted

__all__ = ["CollectedWarning", "collected_warnings", "console", "progress_bar", "progress_wanted"]

#: The loggers of the project's packages (every module logs under ``logging.getLogger(__name__)``,
#: the command under "flexvib").
PACKAGE_LOGGERS = ("periodic", "mechanisms", "linearize", "studies", "flexvib")


@dataclass(frozen=True)
class CollectedWarning:
    """One distinct warning of a run: its ``category`` (e.g. "NearResonanceWarning", or "warning"
    for a WARNING log record), its ``message`` and how many times it was raised (``count``)."""

    category: str
    message: str
    count: int

    def __str__(self) -> str:
        times = f" ({self.count} times)" if self.count > 1 else ""
        prefix = "" if self.category == "warning" else f"{self.category}: "
        return f"warning: {prefix}{self.message}{times}"


class _Collector:
    """Distinct warnings in the order first seen, with counts."""

    def __init__(self) -> None:
        self.counts: dict[tuple[str, str], int] = {}

    def add(self, category: str, message: str) -> None:
        key = (category, message)
        self.counts[key] = self.counts.get(key, 0) + 1

    def warnings(self) -> list[CollectedWarning]:
        return [CollectedWarning(category, message, count)
                for (category, message), count in self.counts.items()]


_collector = _Collector()


def collected_warnings() -> list[CollectedWarning]:
    """The distinct warnings of the current (or last) ``flexvib run`` in this process, in the order
    first raised, each with its count (``str()`` of each is the line the command prints)."""
    return _collector.warnings()


class _DivertWarnings(logging.Filter):
    """Keeps WARNING records off the console while the run lasts (they are collected instead) and
    passes the others from level ``shown_from`` up."""

    def __init__(self, shown_from: int) -> None:
        super().__init__()
        self.shown_from = shown_from

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno == logging.WARNING:
            _collector.add("warning", record.getMessage())
            return False
        return record.levelno >= self.shown_from


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` while the run lasts: collect, and log the place at DEBUG level."""
    _collector.add(category.__name__, str(message))
    logging.getLogger("flexvib").debug("%s:%s: %s: %s", filename, lineno, category.__name__, message)


class _BarAwareHandler(logging.StreamHandler):
    """Writes each record through ``tqdm.write`` (what ``tqdm.contrib.logging.logging_redirect_tqdm``
    installs): open bars are cleared, the line printed on its own, and the bars redrawn below it."""

    def emit(self, record: logging.LogRecord) -> None:
        from tqdm import tqdm

        try:
            tqdm.write(self.format(record), file=self.stream)
            self.flush()
        except Exception:  # noqa: BLE001 - logging must never stop the run
            self.handleError(record)


@contextlib.contextmanager
def console(*, quiet: bool = False, verbose: bool = False) -> Iterator[None]:
    """What ``flexvib run`` shows, for the duration of the ``with`` block (restored afterwards):
    log records of the project's packages at INFO (``verbose``: DEBUG; ``quiet``: ERROR only) on
    stderr, written around the progress bars; WARNING records and Python warnings collected for
    :func:`collected_warnings` instead of printed as they come."""
    _collector.counts.clear()
    handler = _BarAwareHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s"))
    # WARNING records are still made when quiet: they are collected (and not shown)
    level = logging.DEBUG if verbose else logging.WARNING if quiet else logging.INFO
    handler.addFilter(_DivertWarnings(logging.ERROR if quiet else level))
    loggers = [logging.getLogger(name) for name in PACKAGE_LOGGERS]
    saved = [(logger, logger.level) for logger in loggers]
    for logger in loggers:
        logger.addHandler(handler)
        logger.setLevel(level)
    try:
        with warnings.catch_warnings():
            # every occurrence reaches the collector, which counts them (Python's default shows
            # a warning once per place in the code, which would make the counts meaningless)
            for category in (UserWarning, RuntimeWarning):
                warnings.simplefilter("always", category)
            warnings.showwarning = _show_warning
            yield
    finally:
        for logger, old_level in saved:
            logger.removeHandler(handler)
            logger.setLevel(old_level)
