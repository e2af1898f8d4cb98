"""The package layout's rules, read from the sources with ast (docs/architecture.md).

- A module or name that begins with ``_`` is private to its subpackage: no module of another
  subpackage (or of the top level) imports it.
- Subpackages form layers: no import cycle between them.
- Every public namespace lists its names in a sorted ``__all__`` that resolves.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import isf

PACKAGE = Path(isf.__file__).resolve().parent


def _modules() -> dict[str, Path]:
    """Every module of isf by dotted name (``isf.fitting.engine``; packages by their name)."""
    found = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(("isf", *parts))] = path
    return found


def _subpackage(module: str) -> str:
    """The subpackage a module belongs to (``isf`` for the top-level modules)."""
    parts = module.split(".")
    path = PACKAGE.joinpath(*parts[1:2])
    return ".".join(parts[:2]) if len(parts) > 1 and path.is_dir() else "isf"


def _imports(module: str, path: Path):
    """``(target module, imported name or None, line)`` of every import of isf in a module."""
    is_package = path.name == "__init__.py"
    package = module.split(".") if is_package else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "isf":
                    yield alias.name, None, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                target = ".".join([*base, *([node.module] if node.module else [])])
            elif (node.module or "").split(".")[0] == "isf":
                target = node.module
            else:
                continue
            for alias in node.names:
                yield target, alias.name, node.lineno


MODULES = _modules()


def _resolve(target: str, name: str | None) -> tuple[str, str | None]:
    """(module, name) with a name that is itself a module folded into the module."""
    if name is not None and f"{target}.{name}" in MODULES:
        return f"{target}.{name}", None
    return target, name


def test_the_rule_reader_sees_the_whole_package():
    assert {"isf", "isf.fitting.engine", "isf.fitting._ipfo_kernel", "isf.search.kdtree",
            "isf.planning.planner"} <= set(MODULES)
    found = list(_imports("isf.fitting.engine", MODULES["isf.fitting.engine"]))
    assert ("isf.fitting._ipfo", "answer_requests") in {(t, n) for t, n, _ in found}
    assert ("isf.gripper.model", "Gripper") in {(t, n) for t, n, _ in found}


def test_private_modules_and_names_stay_inside_their_subpackage():
    crossings = []
    for module, path in MODULES.items():
        own = _subpackage(module)
        for target, name, line in _imports(module, path):
            target, name = _resolve(target, name)
            if _subpackage(target) == own:
                continue
            private_module = any(part.startswith("_") and part != "__init__"
                                 for part in target.split("."))
            private_name = name is not None and name.startswith("_") and name != "__version__"
            if private_module or private_name:
                crossings.append(f"{path.relative_to(PACKAGE)}:{line} imports "
                                 f"{target}{'.' + name if name else ''}")
    assert not crossings, "private modules or names imported across subpackages:\n" + "\n".join(crossings)


def test_subpackages_import_each_other_without_cycles():
    edges: dict[str, set[str]] = {}
    for module, path in MODULES.items():
        own = _subpackage(module)
        for target, name, _ in _imports(module, path):
            other = _subpackage(_resolve(target, name)[0])
            if other not in (own, "isf"):
                edges.setdefault(own, set()).add(other)
    visiting, done = set(), set()

    def visit(node, trail):
        if node in done:
            return
        assert node not in visiting, "import cycle: " + " -> ".join([*trail, node])
        visiting.add(node)
        for nxt in sorted(edges.get(node, ())):
            visit(nxt, [*trail, node])
        visiting.discard(node)
        done.add(node)

    for node in sorted(edges):
        visit(node, [])


@pytest.mark.parametrize("namespace", sorted(
    name for name, path in MODULES.items() if path.name == "__init__.py"))
def test_every_package_lists_its_public_names_sorted(namespace):
    module = importlib.import_module(namespace)
    names = getattr(module, "__all__", None)
    if namespace in ("isf.commands", "isf.compiled"):  # documentation only: modules imported by name
        assert names is None
        return
    assert names, f"{namespace} has no __all__"
    assert list(names) == sorted(names), f"{namespace}.__all__ is not sorted"
    for name in names:
        assert hasattr(module, name), f"{namespace}.__all__ lists {name}, which it lacks"
