"""The package's shape: no import circle between its modules, almost nothing at its top level, and layers
that import only downwards, so that a lower layer (the simulation, the agent) can be read and tested without
the ones built on it (training, the command line).

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
LAYERS = (
    "core",
    "tasks",
    "language",
    "sim",
    "envs",
    "agent",
    "config",
    "evaluation",
    "train",
    "sweep",
    "report",
    "integrations",
    "pretrained",
    "cli",
)
"""The package's subpackages from the bottom up: each may import those before it and itself, never one after."""
TOP_LEVEL_MODULES = 2
"""Modules the package may have outside its subpackages: ``__init__`` and at most one more, so that every
other module sits in the layer it belongs to."""


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
                targets = [
                    f"{base}.{alias.name}" if f"{base}.{alias.name}" in paths else base for alias in statement.names
                ]
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


def layer(module: str) -> str | None:
    """The subpackage ``module`` belongs to (``pkg.sim.world`` is in ``sim``), or None for the package itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def upward_imports(graph: dict[str, set[str]], layers: tuple[str, ...]) -> list[tuple[str, str]]:
    """The imports of ``graph`` from a module in one layer to a module in a layer above it, sorted."""
    rank = {name: index for index, name in enumerate(layers)}
    return sorted(
        (module, target)
        for module, targets in graph.items()
        for target in targets
        if layer(module) is not None and layer(target) is not None and rank[layer(target)] > rank[layer(module)]
    )


def test_the_modules_import_each_other_without_a_circle() -> None:
    graph = import_graph(PACKAGE)
    assert "lanrocli.train.runfolder" in graph["lanrocli.train.pipeline"]  # the imports are read
    assert find_cycle(graph) is None


def test_the_package_keeps_almost_no_modules_at_its_top_level() -> None:
    assert len(list(PACKAGE.glob("*.py"))) <= TOP_LEVEL_MODULES


def test_every_subpackage_has_a_layer() -> None:
    subpackages = {path.parent.name for path in PACKAGE.glob("*/__init__.py")}
    assert subpackages == set(LAYERS)


def test_each_layer_imports_only_the_layers_below_it() -> None:
    assert upward_imports(import_graph(PACKAGE), LAYERS) == []


def _package(root: Path, modules: dict[str, str]) -> Path:
    package = root / "pkg"
    for name, text in {"__init__": "", **modules}.items():
        path = package / f"{name.replace('.', '/')}.py"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return package


def test_the_checks_find_a_circle(tmp_path: Path) -> None:
    package = _package(
        tmp_path,
        {
            "sub/__init__": "",
            "sub/a": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg.sub import b\n",
            "sub/b": "from . import c\n",
            "sub/c": "import pkg.sub.a\n\ndef later():\n    import pkg.d\n",
            "d": "x = 1\n",
        },
    )
    graph = import_graph(package)
    assert graph["pkg.sub.c"] == {"pkg.sub.a"}  # the import inside a function is not an edge
    assert find_cycle(graph) == ["pkg.sub.a", "pkg.sub.b", "pkg.sub.c", "pkg.sub.a"]
    graph["pkg.sub.c"] = set()
    assert find_cycle(graph) is None


def test_the_checks_find_an_upward_import(tmp_path: Path) -> None:
    package = _package(
        tmp_path,
        {
            "low/__init__": "from pkg.low import base\n",
            "low/base": "from pkg import high\n\ndef later():\n    from pkg.high import user\n",
            "high/__init__": "",
            "high/user": "from ..low import base\nimport pkg\n",
        },
    )
    graph = import_graph(package)
    assert upward_imports(graph, ("low", "high")) == [("pkg.low.base", "pkg.high")]
    assert upward_imports(graph, ("high", "low")) == [("pkg.high.user", "pkg.low.base")]
