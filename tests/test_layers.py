"""The package's imports, read from its files: no import cycles, the layers' order, and a root
that stays small.

Every ``import`` and ``from ... import`` of the package's own modules counts, at module
level, under ``if TYPE_CHECKING:`` and inside functions alike: a type-only or late import
that closes a cycle is a type or a function defined a layer above the code that needs it
(docs/architecture.md, "Layers"). A cycle is reported with the import lines that close it.

The layers (:data:`LAYERS`, the table of docs/architecture.md) are ordered: a module imports
only from its own layer and the layers below it. An import that reaches up is allowed only
inside a function with its reason on its line (the two there are: a result's ``plot``
method, which imports matplotlib's figures when it draws, and the environments' former
address in ``agents``). A late import of the package's own modules stays only for an
optional extra or for start-up time, and says so on its line; the commands (``cli``) import
their work when they run, which is the rule there (its package docstring).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "src" / "formationlab"

#: modules (files) the package's root may hold: the rest lives in the folders of its layers
#: (the package itself, its entry point, and the base layer: docs/architecture.md)
ROOT_LIMIT = 12

#: the package's layers, lowest first: each a list of the top-level modules and folders it
#: holds (docs/architecture.md, "Layers")
LAYERS: list[list[str]] = [
    ["errors", "status", "_jit", "neighbours", "validation", "registry", "resources",
     "_numba_cache", "_command_start"],
    ["formation"],
    ["outcomes"],
    ["controllers"],
    ["models", "marching"],
    ["safety"],
    ["sensing"],
    ["dynamics"],
    ["engine"],
    ["integrators"],
    ["simulation"],
    ["agents"],
    ["scenario"],
    ["studies", "equilibria"],
    ["learning"],
    ["envs", "plotting", "io", "robots"],
    ["viewer"],
    ["cli"],
    ["__main__"],
]  # fmt: skip


def _module(path: Path, root: Path) -> tuple[str, bool]:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    package = parts[-1] == "__init__"
    return ".".join(parts[:-1] if package else parts), package


@dataclass(frozen=True)
class Import:
    """One import of a package module by another, where it is written."""

    module: str
    target: str
    line: int
    in_function: bool  # written inside a function (a late import)
    reason: str  # the comment on its first line ("" without one)


def imports(root: Path = ROOT) -> list[Import]:
    """Every import of one of the package's modules by another, over every file under
    ``root``: module level, ``if TYPE_CHECKING:`` and inside functions alike."""
    modules = {_module(p, root)[0]: p for p in root.rglob("*.py")}

    def known(name: str) -> str:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name

    found: list[Import] = []
    for name, path in modules.items():
        _, package = _module(path, root)
        here = name.split(".") if package else name.split(".")[:-1]
        text = path.read_text()
        lines = text.splitlines()
        tree = ast.parse(text, str(path))
        late = {
            id(node)
            for f in ast.walk(tree)
            if isinstance(f, ast.FunctionDef | ast.AsyncFunctionDef)
            for node in ast.walk(f)
        }
        for node in ast.walk(tree):
            targets = []
            if isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = here[: len(here) - (node.level - 1)]
                    base = ".".join(up + ([base] if base else []))
                targets = [known(f"{base}.{a.name}") or known(base) for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [known(a.name) for a in node.names]
            else:
                continue
            reason = lines[node.lineno - 1].partition("#")[2].strip()
            for target in dict.fromkeys(targets):
                if target.startswith("formationlab") and target != name:
                    found.append(Import(name, target, node.lineno, id(node) in late, reason))
    return found


def import_graph(root: Path = ROOT) -> dict[str, dict[str, int]]:
    """``{module: {imported module of the package: line}}`` over every file under ``root``."""
    graph: dict[str, dict[str, int]] = {}
    for imp in imports(root):
        graph.setdefault(imp.module, {}).setdefault(imp.target, imp.line)
    for p in root.rglob("*.py"):
        graph.setdefault(_module(p, root)[0], {})
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


def layer_of(module: str) -> int | None:
    """The index in :data:`LAYERS` of a module (``None`` for the package itself)."""
    parts = module.split(".")
    if len(parts) == 1:
        return None  # formationlab/__init__.py: the public names, from every layer
    for i, names in enumerate(LAYERS):
        if parts[1] in names:
            return i
    raise AssertionError(f"{module} is in no layer: add {parts[1]!r} to LAYERS and to the "
                         "table of docs/architecture.md")  # fmt: skip


def upward(found: list[Import]) -> list[Import]:
    """The imports that reach from a module up to a higher layer."""
    out = []
    for imp in found:
        a, b = layer_of(imp.module), layer_of(imp.target)
        if a is not None and b is not None and b > a:
            out.append(imp)
    return out


def unexplained(found: list[Import]) -> list[Import]:
    """Imports that break the rules: one reaching up a layer that is not a late import with
    its reason on the line, and a late import of the package (outside the commands) without
    its reason."""
    bad = [i for i in upward(found) if not (i.in_function and i.reason)]
    bad += [
        i for i in found
        if i.in_function and not i.reason and not i.module.startswith("formationlab.cli")
    ]  # fmt: skip
    return bad


def test_every_module_is_in_a_layer():
    for name in import_graph():
        layer_of(name)  # raises for a folder no layer holds


def test_imports_keep_the_layers_order():
    found = imports()
    assert len(found) > 300  # (the imports were read)
    bad = unexplained(found)
    assert not bad, "imports against the layers (docs/architecture.md, Layers):\n" + "\n".join(
        f"{i.module} line {i.line} imports {i.target}"
        + (" inside a function without its reason on the line" if i.in_function else "")
        for i in bad
    )


def test_an_import_up_a_layer_is_found(tmp_path):
    pkg = tmp_path / "formationlab"
    for folder in ("formation", "cli", "controllers"):
        (pkg / folder).mkdir(parents=True)
        (pkg / folder / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("")
    (pkg / "formation" / "spec.py").write_text("from ..controllers import law\n")
    (pkg / "controllers" / "law.py").write_text(
        "def f():\n    from ..formation import spec\n"  # down, but late without a reason
        "def g():\n    from ..cli import app  # the commands, for start-up time\n"
    )
    (pkg / "cli" / "app.py").write_text("def f():\n    from ..controllers import law\n")
    bad = {(i.module, i.target) for i in unexplained(imports(pkg))}
    assert bad == {
        ("formationlab.formation.spec", "formationlab.controllers.law"),
        ("formationlab.controllers.law", "formationlab.formation.spec"),
    }
