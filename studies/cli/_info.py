"""How ``flexvib info`` writes a study's attributes and datasets for a person: numbers to 4 significant
digits (``100``, not ``99.99999999999999``), each with its unit where the file says it (run times in
s, an observable's entries in its unit), long lists shortened, dimensionless datasets said so."""

from __future__ import annotations

import math
from typing import Any, Mapping

#: Digits of the numbers ``flexvib info`` prints (the file keeps every digit).
DIGITS = 4
#: Lists longer than this are shown by their ends and their length.
LIST_SHOWN = 6


def number(value: float) -> str:
    """``100``, ``0.00702``, ``3.071e-06``, ``nan``: 4 significant digits."""
    value = float(value)
    return f"{value:.{DIGITS}g}" if math.isfinite(value) else str(value)


#: Units of attributes by name (the rest: run times in s, an observable's entries in its unit).
NAMED_UNITS = {"drive_rate": "rad/s", "speed": "rad/s", "worst_speed": "rad/s", "check_speed": "rad/s",
               "transient_value": "", "error_estimate": "SI (see the coordinates)"}


def formatted(key: str, value: Any, units: Mapping[str, str]) -> str:
    """The text of attribute ``key`` holding ``value``; ``units`` {observable: unit} of the study: the
    entries of a dict keyed by observables get their unit, unless the attribute is relative (a
    ``relative_*`` value, a ratio) or holds no quantity of the observable (``units`` itself)."""
    unit = "s" if key.endswith("run_time") or key == "compile_time" else NAMED_UNITS.get(key, "")
    relative = key.startswith("relative") or "ratio" in key or key in ("units", "linear_range", "verdicts")
    return _text(value, unit, {} if relative else units)


def _text(value: Any, unit: str, units: Mapping[str, str]) -> str:
    if isinstance(value, bool) or value is None:
        return {True: "true", False: "false", None: "none"}[value]
    if isinstance(value, (int, float)):
        shown = number(value) if isinstance(value, float) else str(value)
        return f"{shown} {unit}" if unit and unit != "1" else shown
    if isinstance(value, str):
        return value
    if isinstance(value, Mapping):
        return "{" + ", ".join(f"{k}: {_text(v, units.get(str(k), NAMED_UNITS.get(str(k), unit)), {})}"
                               for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        items = [_text(v, unit, units) for v in value]
        if len(items) > LIST_SHOWN:
            return f"[{', '.join(items[:3])}, ..., {', '.join(items[-2:])}] ({len(items)} values)"
        return f"[{', '.join(items)}]"
    return str(value)


def dataset(shape: tuple[int, ...], unit: str) -> str:
    """A dataset's line: its shape and unit ("45 x 3, rad/s"; "45, dimensionless" for unit 1)."""
    size = " x ".join(str(n) for n in shape) if shape else "scalar"
    if unit == "1":
        return f"{size}, dimensionless"
    return f"{size}, {unit}" if unit else size
