"""The checked reader of one table of a scene spec (the dicts a TOML scene file parses to).

Each part's ``from_table(name, table)`` reads its keys through it: units, bounds and the key's
dotted path in every error message, and unknown keys refused with the nearest valid one suggested.
"""

from __future__ import annotations

import difflib
import math
from typing import Any, Mapping

from .checks import MAX_TEXT, MechanismError, _is_number

_REQUIRED = object()


class _Table:
    """One table of a spec, read key by key with its dotted path in every error message."""

    def __init__(self, data: object, path: str, allowed: tuple[str, ...]):
        if not isinstance(data, Mapping):
            raise MechanismError(f"{path} must be a table, got {data!r}")
        for key in data:
            if key not in allowed:
                close = difflib.get_close_matches(str(key), allowed, n=1, cutoff=0.5)
                hint = f"; did you mean {close[0]!r}?" if close else ""
                raise MechanismError(f"{path}: unknown key {key!r}{hint} (valid keys: "
                                     f"{', '.join(allowed)})")
        self.data, self.path = data, path

    def _at(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default: Any = _REQUIRED) -> Any:
        if key in self.data:
            return self.data[key]
        if default is _REQUIRED:
            raise MechanismError(f"{self.path or 'scene'}: missing key {key!r}")
        return default

    def number(self, key: str, unit: str, default: Any = _REQUIRED, *, positive: bool = False,
               nonnegative: bool = False) -> float:
        value = self.raw(key, default)
        if not _is_number(value) or not math.isfinite(value):
            raise MechanismError(f"{self._at(key)} must be a finite number ({unit}), got "
                                 f"{value!r}")
        if positive and not value > 0:
            raise MechanismError(f"{self._at(key)} must be positive ({unit}), got {value!r}")
        if nonnegative and not value >= 0:
            raise MechanismError(f"{self._at(key)} must be zero or positive ({unit}), got "
                                 f"{value!r}")
        return float(value)

    def integer(self, key: str, default: Any = _REQUIRED, *, minimum: int | None = None,
                maximum: int | None = None, why: str = "") -> int:
        """An integer value; with ``maximum`` (and the reason ``why``) an upper bound too."""
        value = self.raw(key, default)
        if not isinstance(value, int) or isinstance(value, bool):
            raise MechanismError(f"{self._at(key)} must be an integer, got {value!r}")
        if minimum is not None and value < minimum:
            raise MechanismError(f"{self._at(key)} must be an integer >= {minimum}, got {value!r}")
        if maximum is not None and value > maximum:
            raise MechanismError(f"{self._at(key)} must be at most {maximum} ({why}), got {value!r}")
        return value

    def string(self, key: str, default: Any = _REQUIRED, choices: tuple[str, ...] = ()) -> str:
        value = self.raw(key, default)
        if not isinstance(value, str):
            raise MechanismError(f"{self._at(key)} must be a string, got {value!r}"[:500])
        if len(value) > MAX_TEXT:
            raise MechanismError(f"{self._at(key)} must be at most {MAX_TEXT} characters (free text is "
                                 f"kept in every result file), got {len(value)}; shorten it")
        if choices and value not in choices:
            close = difflib.get_close_matches(value, choices, n=1, cutoff=0.5)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise MechanismError(f"{self._at(key)} must be one of {choices}, got {value!r}{hint}")
        return value

    def boolean(self, key: str, default: bool) -> bool:
        value = self.raw(key, default)
        if not isinstance(value, bool):
            raise MechanismError(f"{self._at(key)} must be true or false, got {value!r}")
        return value

    def pair(self, key: str, unit: str, default: Any = _REQUIRED) -> tuple[float, float]:
        value = self.raw(key, default)
        if (not isinstance(value, (list, tuple)) or len(value) != 2
                or not all(_is_number(v) and math.isfinite(v) for v in value)):
            raise MechanismError(f"{self._at(key)} must be a pair [x, y] of finite numbers "
                                 f"({unit}), got {value!r}")
        return (float(value[0]), float(value[1]))

    def point(self, key: str) -> str | float:
        value = self.raw(key)
        if isinstance(value, str):
            return value
        if _is_number(value) and math.isfinite(value):
            return float(value)
        raise MechanismError(f"{self._at(key)} must be 'start', 'end', a named point or a "
                             f"distance along the link in metres, got {value!r}")

    def table(self, key: str) -> Mapping[str, Any]:
        value = self.raw(key, {})
        if not isinstance(value, Mapping):
            raise MechanismError(f"{self._at(key)} must be a table, got {value!r}")
        return value


