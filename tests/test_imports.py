"""The import rules of the four packages, read from their source (every import, also inside functions).

* Dependencies run one way: ``studies -> linearize -> (mechanisms, periodic)``; ``periodic`` imports none of
  the others, and ``mechanisms`` only ``periodic.lapack`` (the packages' one home of the LAPACK bindings, a
  public module of the generic numerics), nothing else of ``periodic``.
* No package imports another package's private module (``mechanisms._batch`` from ``linearize``).
* File and figure libraries (h5py, matplotlib) are imported only in ``studies``.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("periodic", "mechanisms", "linearize", "studies")
#: package -> the packages it may import (directly).
ALLOWED = {
    "periodic": set(),
    "mechanisms": {"periodic"},
    "linearize": {"mechanisms", "periodic"},
    "studies": {"linearize", "mechanisms", "periodic"},
}
#: package -> {imported package: the only modules of it that it may import} (narrower than ALLOWED).
ONLY = {"mechanisms": {"periodic": {"periodic.lapack"}}}
STUDIES_ONLY = {"h5py", "matplotlib"}


def _imports(path: Path, package: str) -> list[tuple[int, str]]:
    """``(line, dotted module)`` of every import in ``path``, relative imports made absolute."""
    tree = ast.parse(path.read_text(), filename=str(path))
    module_parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if module_parts[-1] == "__init__":
        module_parts = module_parts[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                # `from . import x` inside package/a/b.py: the base is package/a
                is_package = path.name == "__init__.py"
                base = module_parts[:len(module_parts) - node.level + (1 if is_package else 0)]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            # `from mechanisms import _batch` imports the module mechanisms._batch
            found += [(node.lineno, f"{stem}.{alias.name}") for alias in node.names]
    return found


def _violations(package: str) -> list[str]:
    problems = []
    for path in sorted((ROOT / package).rglob("*.py")):
        where = path.relative_to(ROOT)
        for line, name in _imports(path, package):
            top, *rest = name.split(".")
            if top in PACKAGES and top != package:
                if top not in ALLOWED[package]:
                    problems.append(f"{where}:{line}: {package} imports {name} (upward or sideways)")
                elif any(part.startswith("_") for part in rest):
                    problems.append(f"{where}:{line}: {package} imports the private module {name}")
                elif top in ONLY.get(package, {}) and not any(
                        name == module or name.startswith(module + ".") for module in ONLY[package][top]):
                    problems.append(f"{where}:{line}: {package} imports {name} (only "
                                    f"{', '.join(sorted(ONLY[package][top]))} of {top})")
            if top in STUDIES_ONLY and package != "studies":
                problems.append(f"{where}:{line}: {package} imports {top} (only studies may)")
    return problems


@pytest.mark.parametrize("package", PACKAGES)
def test_package_imports_follow_the_rules(package):
    assert _violations(package) == []


def test_the_checker_sees_a_violation(tmp_path, monkeypatch):
    """The rule test must be able to fail: a planted upward import and private import are found."""
    fake = tmp_path / "periodic"
    fake.mkdir()
    (fake / "__init__.py").write_text("")
    (fake / "_bad.py").write_text("def f():\n    import studies\n    from mechanisms._batch import x\n"
                                  "    import matplotlib.pyplot\n")
    (tmp_path / "linearize").mkdir()
    (tmp_path / "linearize" / "_ok.py").write_text("from mechanisms import assemble\nfrom . import _core\n"
                                                   "from mechanisms import _batch\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert [v.split(": ", 1)[1] for v in _violations("periodic")] == [
        "periodic imports studies (upward or sideways)",
        "periodic imports mechanisms._batch.x (upward or sideways)",
        "periodic imports matplotlib (only studies may)",
    ]
    assert [v.split(": ", 1)[1] for v in _violations("linearize")] == [
        "linearize imports the private module mechanisms._batch"]
    (tmp_path / "mechanisms").mkdir()
    (tmp_path / "mechanisms" / "_ok.py").write_text(
        "from periodic import lapack\nfrom periodic.lapack import factor_loops\n"
        "from periodic import steady_state\nimport periodic\n")
    assert [v.split(": ", 1)[1] for v in _violations("mechanisms")] == [
        "mechanisms imports periodic.steady_state (only periodic.lapack of periodic)",
        "mechanisms imports periodic (only periodic.lapack of periodic)"]
