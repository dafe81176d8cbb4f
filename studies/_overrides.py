"""``flexvib run --set PATH=VALUE`` and ``--only STUDY``: a scene changed and narrowed from the
command line, without editing its file.

``--set`` replaces (or adds) the value at a dotted key path of the scene file, e.g.
``links.coupler.thickness=2e-3`` or ``studies.sweep.count=50``, before the scene is checked, so the
scene's own checks judge the new value (and name its key). VALUE is a TOML value (``2e-3``, ``true``,
``"speed"``, ``[60.0, 185.0]``); a bare word that is not one is taken as a string. The tables on the
path must exist: a misspelt table is refused, naming the path and the keys that are there.
"""

from __future__ import annotations

import argparse
import tomllib
from pathlib import Path
from typing import Any, Mapping, Sequence

from ._errors import UsageError

__all__ = ["apply_overrides", "load_mechanism", "parse_set", "select_studies"]

#: The scene table the ``studies.*`` paths of ``--set`` address (applied to the studies table after
#: the defaults are filled in, so that they reach a scene without a ``[studies]`` table too).
STUDIES = "studies"


def parse_set(text: str) -> tuple[str, Any]:
    """``"PATH=VALUE"`` -> ``(PATH, value)``; the argparse type of ``--set``: a malformed one raises
    ``argparse.ArgumentTypeError``, whose message argparse prints after "argument --set:" (exit
    code 2; a ValueError would print only "invalid parse_set value")."""
    path, sep, raw = text.partition("=")
    path = path.strip()
    if not sep or not path or any(not part.strip() for part in path.split(".")):
        raise argparse.ArgumentTypeError(f"expected PATH=VALUE such as links.coupler.thickness=2e-3 (PATH "
                                         f"dotted scene keys), got {text!r}")
    raw = raw.strip()
    try:
        value = tomllib.loads(f"value = {raw}")["value"]
    except tomllib.TOMLDecodeError:
        if not raw or any(c in raw for c in " \t[]{}\"',="):
            raise argparse.ArgumentTypeError(f"{path}: expected a TOML value (a number, true or false, a quoted "
                             f"string, an array [...]), got {raw!r}") from None
        value = raw  # a bare word: a string (`--set studies.sweep.parameter=speed`)
    return path, value


def apply_overrides(table: Mapping[str, Any], sets: Sequence[tuple[str, Any]], *,
                    prefix: str = "") -> dict[str, Any]:
    """A copy of ``table`` with each ``(path, value)`` of ``sets`` set (paths relative to ``table``,
    named with ``prefix`` in messages). Every table on a path must exist (else ``UsageError``
    naming the path and the keys there); the last key may be new (the scene's checks reject an
    unknown one and suggest the nearest)."""
    result = _copy_tables(table)
    for path, value in sets:
        node, parts = result, path.split(".")
        for depth, key in enumerate(parts[:-1]):
            child = node.get(key)
            if not isinstance(child, dict):
                where = prefix + ".".join(parts[:depth + 1])
                found = "no table" if child is None else f"a value ({child!r}), not a table,"
                raise UsageError(f"--set {prefix}{path}: the scene has {found} at {where!r} (keys "
                                 f"there: {', '.join(sorted(node)) or 'none'})")
            node = child
        if isinstance(node.get(parts[-1]), dict):
            raise UsageError(f"--set {prefix}{path}: that is a table; set one of its keys "
                             f"({', '.join(sorted(node[parts[-1]]))})")
        node[parts[-1]] = value
    return result


def _copy_tables(table: Mapping[str, Any]) -> dict[str, Any]:
    return {key: _copy_tables(value) if isinstance(value, Mapping) else value
            for key, value in table.items()}


def split_sets(sets: Sequence[tuple[str, Any]]) -> tuple[list[tuple[str, Any]], list[tuple[str, Any]]]:
    """``(scene sets, studies sets)``: the second with paths relative to the ``[studies]`` table."""
    scene = [(path, value) for path, value in sets if path.split(".")[0] != STUDIES]
    studies = [(path.partition(".")[2], value) for path, value in sets
               if path.split(".")[0] == STUDIES]
    for path, _ in studies:
        if not path:
            raise UsageError("--set studies: set a key of a study table, e.g. studies.sweep.count=50")
    return scene, studies


def load_mechanism(scene: str, sets: Sequence[tuple[str, Any]] = ()):
    """``mechanisms.load(scene)`` with the ``--set`` values of scene keys (not ``studies.*``) put
    into the parsed table before it is checked and built."""
    import mechanisms

    scene_sets, _ = split_sets(sets)
    if not scene_sets:
        return mechanisms.load(scene)
    path = Path(scene)
    if path.suffix == ".toml" or path.exists():
        try:
            spec = tomllib.loads(path.read_text(encoding="utf-8"))
        except tomllib.TOMLDecodeError as error:
            raise mechanisms.MechanismError(f"{scene}: not valid TOML: {error}") from None
        source = str(path)
    else:
        spec, source = mechanisms.load(scene).spec, f"scene {scene!r}"  # built-in scenes are valid
    changed = ", ".join(f"{p}={v!r}" for p, v in scene_sets)
    return mechanisms.build(apply_overrides(spec, scene_sets), source=f"{source} with --set {changed}")


def override_studies(table: Mapping[str, Any], sets: Sequence[tuple[str, Any]]) -> dict[str, Any]:
    """The ``[studies]`` table (declared, or the defaults) with the ``--set studies.*`` values."""
    _, studies_sets = split_sets(sets)
    return apply_overrides(table, studies_sets, prefix=f"{STUDIES}.")


def select_studies(declared: Mapping[str, Any], only: Sequence[str] | None) -> dict[str, Any]:
    """The declared studies named by ``--only`` (all of them when None); an undeclared name is a
    ``UsageError`` listing the declared ones."""
    if not only:
        return dict(declared)
    unknown = [name for name in only if name not in declared]
    if unknown:
        raise UsageError(f"--only: the scene declares no study {unknown[0]!r} (declared: "
                         f"{', '.join(declared)})")
    return {name: options for name, options in declared.items() if name in only}
