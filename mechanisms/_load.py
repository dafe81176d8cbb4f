"""Scene files: TOML text or a built-in scene name -> nested dicts ("specs") -> validated ``Mechanism``.

The format is documented key by key in ``docs/scenes.md``. A spec is what ``tomllib`` returns for a
scene file. ``build(spec)`` (``Mechanism.from_spec``) checks every key (unknown keys get the
nearest valid one suggested), turns section dimensions and damping ratios into the parts' derived
quantities, and returns a ``Mechanism`` that keeps the spec, so
``Mechanism.with_parameter("links.coupler.thickness", 2e-3)`` edits the spec and rebuilds with
everything derived recomputed.
"""

from __future__ import annotations

import difflib
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

from ._parts import Mechanism, MechanismError


def build(spec: Mapping[str, Any], *, source: str = "scene") -> Mechanism:
    """A validated ``Mechanism`` from a scene spec (the dict a TOML scene file parses to).

    Raises ``MechanismError`` naming ``source``, the key path and what was expected.
    """
    return Mechanism.from_spec(spec, source=source)


# ---------------------------------------------------------------------------------------------------
# Files and built-in scenes
# ---------------------------------------------------------------------------------------------------
def scenes() -> list[str]:
    """Names of the scenes shipped with the package, for ``mechanisms.load(name)``."""
    folder = resources.files("mechanisms") / "scenes"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def load(path_or_name: str | Path) -> Mechanism:
    """A ``Mechanism`` from a built-in scene name (see ``scenes()``) or a ``.toml`` file path."""
    if not isinstance(path_or_name, (str, Path)):
        raise TypeError(f"load() takes a scene name or a path, got {type(path_or_name).__name__}")
    path = Path(path_or_name)
    if path.suffix == ".toml" or path.exists():
        if not path.is_file():
            raise FileNotFoundError(f"scene file {str(path)!r} does not exist")
        source = str(path)
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as error:
            raise MechanismError(f"{source}: not a TOML text file (not UTF-8: byte {error.start} is "
                                 f"{error.object[error.start:error.start + 1]!r})") from None
    else:
        names = scenes()
        if str(path_or_name) not in names:
            close = difflib.get_close_matches(str(path_or_name), names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise MechanismError(f"no built-in scene {str(path_or_name)!r}{hint} (built-in scenes: "
                                 f"{', '.join(names)}; or give a path to a .toml file)")
        text = (resources.files("mechanisms") / "scenes" / f"{path_or_name}.toml").read_text(
            encoding="utf-8")
        source = f"scene {path_or_name!r}"
    return loads(text, source=source)


def loads(text: str, *, source: str = "scene") -> Mechanism:
    """A ``Mechanism`` from TOML text."""
    try:
        spec = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise MechanismError(f"{source}: not valid TOML: {error}") from None
    except RecursionError:   # arrays or tables nested thousands deep
        raise MechanismError(f"{source}: not valid TOML: nested deeper than the parser follows") from None
    return build(spec, source=source)
