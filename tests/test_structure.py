"""The package's shape: no module too long to read at once, and no import circle between its modules.

The import graph holds the imports a module makes when it is loaded: those at its top level, those under
``if TYPE_CHECKING:`` included (a circle there still ties the modules together for a reader and a type
checker). Imports inside functions are left out: they are how a command loads torch only once its options
are read. An import of ``lanrocli.a.b`` counts as an edge to that module alone, not to the packages above it,
which Python loads first whatever the importer.
"""

from __future__ import annotations

import ast
from pathlib import Path

import lanrocli

PACKAGE = Path(lanrocli.__file__).parent
LONGEST = 350
"""Lines a module may have at most."""


def module_name(path: Path, root: Path) -> str:
    parts = path.relative_to(root.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def loaded_imports(tree: ast.Module) -> list[ast.Import | ast.ImportFrom]:
    """The import statements run when the module loads: at its top level, also inside top-level ``if`` and
    ``try`` blocks, never inside functions or classes."""
    found: list[ast.Import | ast.ImportFrom] = []
    statements: list[ast.stmt] = list(tree.body)
    while statements:
        statement = statements.pop()
        if isinstance(statement, (ast.Import, ast.ImportFrom)):
            found.append(statement)
        elif isinstance(statement, ast.If):
            statements += statement.body + statement.orelse
        elif isinstance(statement, ast.Try):
            statements += statement.body + statement.orelse + statement.finalbody
            statements += [line for handler in statement.handlers for line in handler.body]
    return found


def import_graph(root: Path) -> dict[str, set[str]]:
    """Each module of the package in ``root`` and the modules of the same package it imports on loading."""
    paths = {module_name(path, root): path for path in root.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges = set()
        for statement in loaded_imports(ast.parse(path.read_text(), str(path))):
            if isinstance(statement, ast.Import):
                targets = [alias.name for alias in statement.names]
            else:
                base = statement.module or ""
                if statement.level:
                    above = package.split(".")[: len(package.split(".")) - statement.level + 1]
                    base = ".".join([*above, base] if base else above)
                targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in paths else base for alias in statement.names]
            edges |= {target for target in targets if target in paths and target != name}
        graph[name] = edges
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of ``graph`` as the modules along it (the first again at the end), or None."""
    finished: set[str] = set()
    path: list[str] = []

    def visit(module: str) -> list[str] | None:
        if module in path:
            return path[path.index(module) :] + [module]
        if module in finished:
            return None
        path.append(module)
        for target in sorted(graph[module]):
            cycle = visit(target)
            if cycle is not None:
                return cycle
        path.pop()
        finished.add(module)
        return None

    for module in sorted(graph):
        cycle = visit(module)
        if cycle is not None:
            return cycle
    return None


def too_long(root: Path) -> dict[str, int]:
    counts = {module_name(path, root): len(path.read_text().splitlines()) for path in root.rglob("*.py")}
    return {name: count for name, count in counts.items() if count > LONGEST}


def test_no_module_is_longer_than_the_limit() -> None:
    assert too_long(PACKAGE) == {}


def test_the_modules_import_each_other_without_a_circle() -> None:
    graph = import_graph(PACKAGE)
    assert "lanrocli.train.runfolder" in graph["lanrocli.train.pipeline"]  # the imports are read
    assert find_cycle(graph) is None


def _package(root: Path, modules: dict[str, str]) -> Path:
    package = root / "pkg"
    for name, text in {"__init__": "", **modules}.items():
        path = package / f"{name.replace('.', '/')}.py"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return package


def test_the_checks_find_a_circle_and_a_long_module(tmp_path: Path) -> None:
    package = _package(
        tmp_path,
        {
            "sub/__init__": "",
            "sub/a": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.sub import b\n",
            "sub/b": "from . import c\n",
            "sub/c": "import pkg.sub.a\n\ndef later():\n    import pkg.d\n",
            "d": "x = 1\n" * (LONGEST + 1),
        },
    )
    graph = import_graph(package)
    assert graph["pkg.sub.c"] == {"pkg.sub.a"}  # the import inside a function is not an edge
    assert find_cycle(graph) == ["pkg.sub.a", "pkg.sub.b", "pkg.sub.c", "pkg.sub.a"]
    assert too_long(package) == {"pkg.d": LONGEST + 1}
    graph["pkg.sub.c"] = set()
    assert find_cycle(graph) is None
