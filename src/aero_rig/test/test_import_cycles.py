"""No import circles inside a package (docs/design.md §2), read from the source.

Beside the layering (test_workspace_layering.py: no package imports upward), no two modules of
a package may import each other, directly or through other modules of it. Every import counts,
module level or inside a function (an import inside a function only hides a circle until the
function runs); only type-only imports under ``if TYPE_CHECKING:`` are exempt. A package's
``__init__.py`` is the module of the package's own name.
"""

import ast
from collections.abc import Iterator
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[2]
PACKAGES = sorted(p.parent.name for p in SRC.glob("*/package.xml"))


def _module_names(root: Path, package: str) -> dict[str, Path]:
    """{dotted module name: file} of every module of root/package (subpackages included)."""
    names: dict[str, Path] = {}
    for path in sorted((root / package).rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names[".".join(parts)] = path
    return names


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _import_nodes(node: ast.AST) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import statement under node, at any depth, except in `if TYPE_CHECKING:` bodies."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.If) and _is_type_checking(child.test):
            for other in child.orelse:
                yield from _import_nodes(other)
            continue
        if isinstance(child, ast.Import | ast.ImportFrom):
            yield child
        yield from _import_nodes(child)


def _imported(module: str, path: Path, known: set[str]) -> set[str]:
    """The package's modules that `module` (at path) imports."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in _import_nodes(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            if node.level:
                anchor = module.split(".")
                drop = node.level - 1 if is_package else node.level
                base = ".".join(anchor[: len(anchor) - drop])
                source = f"{base}.{node.module}" if node.module else base
            else:
                source = node.module or ""
            # `from pkg import mod` imports the module pkg.mod, `from pkg import name` pkg itself.
            targets = [
                f"{source}.{alias.name}" if f"{source}.{alias.name}" in known else source
                for alias in node.names
            ]
        found.update(t for t in targets if t in known and t != module)
    return found


def _graph(root: Path, package: str) -> dict[str, set[str]]:
    """{module: the package's modules it imports}."""
    modules = _module_names(root, package)
    known = set(modules)
    return {name: _imported(name, path, known) for name, path in modules.items()}


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    """Tarjan's strongly connected components with more than one module, each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    components: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(components)


def _a_cycle(graph: dict[str, set[str]], component: list[str]) -> list[str]:
    """One shortest circle through the component's first module: [m, ..., m]."""
    start, members = component[0], set(component)
    paths = {start: [start]}
    queue = [start]
    while queue:
        v = queue.pop(0)
        for w in sorted(graph[v] & members):
            if w == start:
                return [*paths[v], start]
            if w not in paths:
                paths[w] = [*paths[v], w]
                queue.append(w)
    raise AssertionError(f"{component} is not strongly connected")


def _cycles(package: str) -> list[str]:
    graph = _graph(SRC / package, package)
    return [" -> ".join(_a_cycle(graph, c)) for c in _strongly_connected(graph)]


@pytest.mark.parametrize("package", PACKAGES)
def test_no_two_modules_of_a_package_import_each_other(package: str) -> None:
    cycles = _cycles(package)
    assert not cycles, (
        f"{package}: import circle(s), imports inside functions included (move the shared part "
        "into a module both import, or import only under TYPE_CHECKING for annotations): "
        + "; ".join(cycles)
    )


def test_the_circle_finder_sees_hidden_relative_and_package_imports(tmp_path: Path) -> None:
    root = tmp_path / "pkg"
    root.mkdir()
    (root / "__init__.py").write_text("from pkg.a import A\n")
    (root / "a.py").write_text("from .b import B\nA = 1\n")
    (root / "b.py").write_text("def f():\n    from . import c\n    return c\nB = 2\n")
    (root / "c.py").write_text("import pkg.a\n")
    (root / "d.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from pkg import e\n"
    )
    (root / "e.py").write_text("from pkg.d import x\n")
    graph = _graph(tmp_path, "pkg")
    assert graph["pkg"] == {"pkg.a"}
    assert graph["pkg.b"] == {"pkg.c"}  # inside a function, relative `from . import c`
    assert graph["pkg.d"] == set()  # type-only
    assert _strongly_connected(graph) == [["pkg.a", "pkg.b", "pkg.c"]]
    assert _a_cycle(graph, ["pkg.a", "pkg.b", "pkg.c"]) == ["pkg.a", "pkg.b", "pkg.c", "pkg.a"]
