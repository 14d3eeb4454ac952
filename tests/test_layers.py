"""The package's imports, read from its files: no import cycles, and a root that stays small.

Every ``import`` and ``from ... import`` of the package's own modules counts, at module
level, under ``if TYPE_CHECKING:`` and inside functions alike: a type-only or late import
that closes a cycle is a type or a function defined a layer above the code that needs it
(docs/architecture.md, "Layers"). A cycle is reported with the import lines that close it.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "src" / "formationlab"

#: modules (files) the package's root may hold: the rest lives in the folders of its layers
#: (the package itself, its entry point, and the base layer: docs/architecture.md)
ROOT_LIMIT = 12


def _module(path: Path, root: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    package = parts[-1] == "__init__"
    return ".".join(parts[:-1] if package else parts), package


def import_graph(root: Path = ROOT) -> dict[str, dict[str, int]]:
    """``{module: {imported module of the package: line}}`` over every file under ``root``."""
    modules = {_module(p, root)[0]: p for p in root.rglob("*.py")}

    def known(name: str) -> str:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name

    graph: dict[str, dict[str, int]] = {}
    for name, path in modules.items():
        _, package = _module(path, root)
        here = name.split(".") if package else name.split(".")[:-1]
        out = graph.setdefault(name, {})
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets = []
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = here[: len(here) - (node.level - 1)]
                    base = ".".join(up + ([base] if base else []))
                targets = [known(f"{base}.{a.name}") or known(base) for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [known(a.name) for a in node.names]
            for target in targets:
                if target.startswith("formationlab") and target != name:
                    out.setdefault(target, node.lineno)
    return graph


def cycles(graph: dict[str, dict[str, int]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, {}):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_package_has_no_import_cycle():
    graph = import_graph()
    assert len(graph) > 100  # (the files were found)
    found = cycles(graph)
    lines = [
        f"{a} line {graph[a][b]} imports {b}"
        for comp in found
        for a in comp
        for b in comp
        if b in graph[a]
    ]
    assert not found, "import cycles:\n" + "\n".join(lines)


def test_a_cycle_is_found(tmp_path):
    pkg = tmp_path / "formationlab"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    from .sub.b import B\n")  # fmt: skip
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "b.py").write_text("def f():\n    from ..a import A\n")
    graph = import_graph(pkg)
    assert cycles(graph) == [["formationlab.a", "formationlab.sub.b"]]
    (pkg / "sub" / "b.py").write_text("X = 1\n")
    assert cycles(import_graph(pkg)) == []


def test_the_root_holds_few_modules():
    root = sorted(p.name for p in ROOT.glob("*.py"))
    assert len(root) <= ROOT_LIMIT, root
