"""The summary table of a run (``flexvib run`` prints it, ``flexvib report`` writes it): per study
its headline numbers with units and errors, its status in words and its run time.

Each study kind says what its headlines are (``StudyKind.headlines(result) -> Summary``); this module
only converts units for reading (m to mm, Pa to MPa) and lays the rows out as text or Markdown.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from ._plots import plain

#: Units shown in the table instead of the SI unit a result holds: ``unit: (shown unit, factor)``.
DISPLAY_UNITS = {"m": ("mm", 1e3), "Pa": ("MPa", 1e-6)}
#: Observables whose peak (largest magnitude), not only their peak-to-peak, is a headline: forces,
#: moments and stresses (a designer sizes a joint or a section by the peak load).
PEAK_UNITS = ("N", "N m", "Pa")
COLUMNS = ("study", "quantity", "value", "error", "status", "run time")


@dataclass(frozen=True)
class Headline:
    """One row of the table: ``quantity`` (words), ``value`` (a number in ``unit``, or words such as
    a list of resonance speeds), ``error`` its estimated error (same unit; NaN: none), ``where``
    (words: "at speed 185 rad/s")."""

    quantity: str
    value: float | str
    unit: str = ""
    error: float = math.nan
    where: str = ""

    def shown(self) -> tuple[str, str]:
        """``(value, error)`` as the table writes them, in the display unit (mm, MPa) with its unit."""
        unit, factor = DISPLAY_UNITS.get(self.unit, (self.unit, 1.0))
        suffix = f" {unit}" if unit and unit != "1" else ""
        if isinstance(self.value, str):
            value = self.value
        else:
            value = plain(factor * float(self.value), 3) + suffix
        value += f" {self.where}" if self.where else ""
        error = f"± {plain(factor * float(self.error))}{suffix}" if math.isfinite(self.error) else ""
        return value, error


@dataclass(frozen=True)
class Summary:
    """What a study says in the table: its ``status`` in words, ``run_time`` s and its ``rows``."""

    status: str
    run_time: float
    rows: Sequence[Headline] = field(default_factory=tuple)


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return ""
    return f"{plain(seconds, 2)} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def table_rows(summaries: Mapping[str, Summary]) -> list[tuple[str, ...]]:
    """The table's rows (``COLUMNS``), the study's name, status and run time on its first row."""
    rows = []
    for name, summary in summaries.items():
        lines = list(summary.rows) or [Headline("(no numbers)", "")]
        for i, headline in enumerate(lines):
            value, error = headline.shown()
            first = i == 0
            rows.append((name if first else "", headline.quantity, value, error,
                         summary.status if first else "", _duration(summary.run_time) if first else ""))
    return rows


def text_table(summaries: Mapping[str, Summary], *, width: int = 40) -> str:
    """The table as aligned plain text (cells longer than ``width`` characters wrapped to it)."""
    import textwrap

    rows = [COLUMNS] + table_rows(summaries)
    wrapped = [[textwrap.wrap(cell, width) or [""] for cell in row] for row in rows]
    widths = [max(len(line) for row in wrapped for line in row[c]) for c in range(len(COLUMNS))]
    lines = []
    for r, row in enumerate(wrapped):
        for k in range(max(len(cell) for cell in row)):
            parts = [(cell[k] if k < len(cell) else "").ljust(w) for cell, w in zip(row, widths)]
            lines.append("  ".join(parts).rstrip())
        if r == 0:
            lines.append("  ".join("-" * w for w in widths))
    return "\n".join(lines)


def markdown_table(summaries: Mapping[str, Summary]) -> str:
    """The table in Markdown (pipes in cells escaped)."""
    def cell(text: str) -> str:
        return text.replace("|", "\\|")

    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "|".join(" --- " for _ in COLUMNS) + "|"]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in table_rows(summaries)]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------
# helpers the kinds' headline hooks share
# ---------------------------------------------------------------------------------------------------
def response_rows(response: Mapping[str, np.ndarray], error: Mapping[str, float],
                  units: Mapping[str, str], *, budget: Any = None) -> list[Headline]:
    """Rows of a response over one period: each observable's peak to peak (error: twice the
    response's error estimate, as the extremes of two curves each within e differ by at most 2 e;
    with the peak-to-peak's error ``budget``, a ``studies._budget.ErrorBudget``, its total and its
    dominant term named) and, for forces, moments and stresses, its peak (largest magnitude)."""
    rows = []
    for spec, values in response.items():
        values = np.asarray(values, dtype=float)
        e = float(error.get(spec, math.nan))
        if budget is not None and spec in budget.terms:
            dominant = budget.dominant(spec)
            rows.append(Headline(f"{spec} peak to peak", float(np.ptp(values)), units[spec],
                                 float(budget.total(spec)),
                                 f"(error mostly {dominant.replace('_', ' ')})" if dominant else ""))
        else:
            rows.append(Headline(f"{spec} peak to peak", float(np.ptp(values)), units[spec], 2.0 * e))
        if units[spec] in PEAK_UNITS:
            rows.append(Headline(f"{spec} peak", float(np.abs(values).max()), units[spec], e))
    return rows


def largest_over_grid(name: str, values: np.ndarray, error: np.ndarray | None, unit: str,
                      point: Any) -> Headline:
    """The row of the largest finite entry of a grid field, with its error and where it is
    (``point(index) -> str``); NaN when no point holds a number."""
    values = np.asarray(values, dtype=float)
    if not np.isfinite(values).any():
        return Headline(name, math.nan, unit)
    index = np.unravel_index(np.nanargmax(values), values.shape)
    e = math.nan if error is None else float(np.asarray(error, dtype=float)[index])
    return Headline(name, float(values[index]), unit, e, f"at {point(index)}")


def ranges(intervals: Sequence[tuple[float, float]], unit: str) -> str:
    """"120–135, 180–190 rad/s" or "none"."""
    if not intervals:
        return "none"
    suffix = f" {unit}" if unit and unit != "1" else ""
    return ", ".join(f"{plain(a, 3)}–{plain(b, 3)}" for a, b in intervals) + suffix


def listed(items: Sequence[str], *, most: int = 6) -> str:
    """Items joined by commas, the first ``most`` and how many more."""
    if not items:
        return "none"
    more = f" and {len(items) - most} more" if len(items) > most else ""
    return ", ".join(items[:most]) + more
