"""What identifies a run: canonical JSON and its sha256 (``digest``), the numbers of a scene's text
(``scene_numbers``: what a resumed run must share with the file), and the key paths where two such
values differ (named in refusals)."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any, Mapping

import numpy as np


def plain(value: Any) -> Any:
    """JSON-ready copy: tuples to lists, numpy scalars to Python, non-finite floats kept as strings."""
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if dataclasses.is_dataclass(value):
        return plain(dataclasses.asdict(value))
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return value


def canonical(value: Any) -> str:
    """Canonical JSON of ``value``: sorted keys, no spaces, tuples and arrays as lists."""
    return json.dumps(plain(value), sort_keys=True, separators=(",", ":"))


def digest(value: Any) -> str:
    """sha256 (hex) of the canonical JSON of ``value``."""
    return hashlib.sha256(canonical(value).encode()).hexdigest()


#: Top-level scene keys that change no number: the scene's name and description, and the studies
#: (each study's options are identified on their own, the observables by the plan).
NOT_NUMBERS = ("name", "description", "studies")


def scene_numbers(text: str) -> dict[str, Any]:
    """What of a scene's text changes numbers: the TOML tables without :data:`NOT_NUMBERS` (comments
    and layout are gone once parsed); ``{"text": text}`` for a text that is not TOML (the equation of
    a ``PeriodicProblem``)."""
    import tomllib

    try:
        tables = tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        return {"text": text}
    return {key: value for key, value in tables.items() if key not in NOT_NUMBERS}


def differing_paths(old: Any, new: Any, *, limit: int = 5) -> list[str]:
    """Dotted key paths where two JSON-like values differ (at most ``limit``; "..." ends a longer list).
    A key present in one only counts; lists compare as a whole."""
    found: list[str] = []

    def walk(a: Any, b: Any, path: str) -> None:
        if isinstance(a, Mapping) and isinstance(b, Mapping):
            for key in sorted(set(a) | set(b)):
                walk(a.get(key, _ABSENT), b.get(key, _ABSENT), f"{path}.{key}" if path else str(key))
        elif a != b:
            found.append(path or "(the whole value)")

    walk(plain(old), plain(new), "")
    return found[:limit] + (["..."] if len(found) > limit else [])


_ABSENT = object()


def scene_identity(problem: Any) -> dict[str, Any]:
    """What identifies the scene of a run (its sha256 is the result file's ``scene_hash``): the
    numbers of the scene (its tables without name, description and studies,
    ``studies._identity.scene_numbers``) and the observables; for a ``PeriodicProblem`` also its name,
    parameters and observable rows (its text is an equation, not a scene)."""
    identity: dict[str, Any] = {"scene": scene_numbers(getattr(problem, "text", ""))}
    if hasattr(problem, "observable_specs"):
        identity["observables"] = problem.observable_specs
    if hasattr(problem, "parameter_values"):
        identity.update(problem=problem.name, parameters=dict(problem.parameter_values),
                        observables=problem.observable_rows, labels=problem.labels)
    return identity
