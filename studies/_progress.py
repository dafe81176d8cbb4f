"""Progress bars of long computations (grid points, a run's studies): tqdm on stderr, drawn only when
stderr is a terminal (never into a redirected file)."""

from __future__ import annotations

import sys

__all__ = ["progress_bar", "progress_wanted"]


def progress_wanted(enabled: bool = True) -> bool:
    """Whether to draw progress bars: asked for, and stderr is a terminal (never into a file)."""
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(enabled and isatty is not None and isatty())


def progress_bar(iterable=None, *, enabled: bool, **options):
    """A ``tqdm`` bar on stderr, disabled unless :func:`progress_wanted` (``options`` go to tqdm)."""
    from tqdm import tqdm

    return tqdm(iterable, disable=not progress_wanted(enabled), file=sys.stderr, **options)
