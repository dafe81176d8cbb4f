"""The structure rules of docs/architecture.md that a reader cannot see at a glance: no source file of the
packages past 700 lines, no dispatch on class names, and the tree clean under ruff (pyproject.toml)."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("periodic", "mechanisms", "linearize", "studies")
#: Past this many lines a module holds more than one noun: split it (issue 19).
MAX_LINES = 700


def package_sources() -> list[Path]:
    return sorted(path for package in PACKAGES for path in (ROOT / package).rglob("*.py"))


def test_no_source_file_is_past_the_line_limit():
    long = {str(path.relative_to(ROOT)): n for path in package_sources()
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, f"files past {MAX_LINES} lines (split them by noun): {long}"


# ``type(x).__name__ == "Name"`` or ``... in ("A", "B")``, and ``x.__class__.__name__`` compared: a kind
# told by its class name instead of by what the object declares.
CLASS_NAME_DISPATCH = re.compile(r"(type\([^)]*\)|__class__)\.__name__\s*(==|!=|in\b|not in\b)")


def test_no_dispatch_on_class_names():
    found = [f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
             for path in package_sources()
             for number, line in enumerate(path.read_text().splitlines(), start=1)
             if CLASS_NAME_DISPATCH.search(line)]
    assert not found, "dispatch on a class name (let the object declare its route):\n" + "\n".join(found)


def test_the_tree_is_clean_under_ruff():
    ruff = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    if not Path(ruff).exists():
        pytest.skip("ruff is not installed (pip install -e '.[test]' brings it)")
    done = subprocess.run([ruff, "check", "--no-cache", str(ROOT)], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout[-4000:] + done.stderr[-2000:]
