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


# ---------------------------------------------------------------------------------------------------
# no import circle inside a package (every import counts, also those deferred into functions)
# ---------------------------------------------------------------------------------------------------
def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_graph(package: str) -> dict[str, set[str]]:
    """``{module: modules of the package it imports}`` over every module of ``package``. An import
    names the module it loads: ``from . import _x`` and ``from ._x import y`` both give ``_x`` (and
    ``from .sub import mod`` gives ``sub.mod`` when that is a module); the parent packages an import
    initialises on the way are not counted (their ``__init__`` runs once, before the module)."""
    modules = {_module_name(path): path for path in sorted((ROOT / package).rglob("*.py"))}
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for _, imported in _imports(path, package):
            if imported.split(".")[0] != package:
                continue
            # `from a import b`: the module a.b if it exists, else the module a
            target = imported if imported in modules else imported.rpartition(".")[0]
            if target in modules and target != name:
                graph[name].add(target)
            elif target == name:
                graph[name].add(name)
    return graph


def _circle(graph: dict[str, set[str]]) -> list[str]:
    """One import circle of ``graph`` (``[a, b, ..., a]``), or ``[]``: a depth-first search that
    stops at the first edge back into the current path."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str]:
        state[node] = 1
        path.append(node)
        for target in sorted(graph[node]):
            if state.get(target) == 1:
                return path[path.index(target):] + [target]
            if target not in state:
                found = visit(target)
                if found:
                    return found
        path.pop()
        state[node] = 2
        return []

    for start in sorted(graph):
        if start not in state:
            found = visit(start)
            if found:
                return found
    return []


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_circle(package):
    circle = _circle(_import_graph(package))
    assert not circle, f"{package} has an import circle: {' -> '.join(circle)}"


def test_the_circle_finder_sees_a_deferred_circle(tmp_path, monkeypatch):
    """The circle test must be able to fail: a circle closed by an import inside a function, through
    a relative import of a subpackage, is found; a straight chain is not a circle."""
    fake = tmp_path / "studies"
    (fake / "sub").mkdir(parents=True)
    (fake / "__init__.py").write_text("from ._a import f\n")
    (fake / "_a.py").write_text("from .sub import _b\n\ndef f():\n    return _b\n")
    (fake / "sub" / "__init__.py").write_text("")
    (fake / "sub" / "_b.py").write_text("def g():\n    from .._c import h\n    return h\n")
    (fake / "_c.py").write_text("def h():\n    from studies import _a\n    return _a\n")
    (fake / "_d.py").write_text("from . import _c\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert _circle(_import_graph("studies")) == ["studies._a", "studies.sub._b", "studies._c", "studies._a"]
    (fake / "_c.py").write_text("def h():\n    return 1\n")
    assert _circle(_import_graph("studies")) == []


def test_the_studies_library_does_not_import_the_command():
    """``studies/cli/`` (the command's machinery) imports the library, never the other way round
    (the package's face included: ``import studies`` loads no command module). The console script's
    entry, ``studies._entry``, which installs the signal handlers and then starts the command, is the
    command's and not the library's (it lives beside ``studies.cli`` so that importing it is light)."""
    graph = _import_graph("studies")
    library = [name for name in graph if not name.startswith("studies.cli") and name != "studies._entry"]
    assert library and any(name.startswith("studies.cli.") for name in graph)
    assert sorted(f"{name} imports {target}" for name in library for target in graph[name]
                  if target.startswith("studies.cli")) == []
