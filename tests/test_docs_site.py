"""The documentation site's sources (mkdocs.yml, docs/): what its strict build relies on.

``mkdocs build --strict`` itself runs in ``.ci/run`` (about 35 s with the gallery's runs);
these checks take a few seconds: every page in the navigation, every public subpackage and
lazily imported name in the API reference, every docstring readable in numpy style (what
mkdocstrings renders), the README's links landing on a file and a heading, and the home
page's quick start the README's.
"""

from __future__ import annotations

import ast
import importlib.util
import logging
import re
from pathlib import Path

import griffe
import pytest
import yaml

import formationlab

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
#: subpackages left out of the API reference: the command line's reference is its --help
NOT_IN_API = {"cli"}


def nav_pages() -> list[str]:
    """The pages mkdocs.yml's navigation names, in order."""
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    found: list[str] = []

    def walk(entry: object) -> None:
        if isinstance(entry, str):
            found.append(entry)
        elif isinstance(entry, list):
            for e in entry:
                walk(e)
        elif isinstance(entry, dict):
            for e in entry.values():
                walk(e)

    walk(config["nav"])
    return found


def gallery_examples() -> list[str]:
    """The ``name`` of every ``Example(...)`` in the gallery script (read, not run)."""
    tree = ast.parse((DOCS / "_scripts" / "gallery.py").read_text())
    return [
        kw.value.value
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "Example"
        for kw in node.keywords
        if kw.arg == "name"
    ]


def test_every_page_is_in_the_navigation_once() -> None:
    pages = nav_pages()
    assert len(pages) == len(set(pages)), "a page twice in the navigation"
    written = {str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md") if "_scripts" not in p.parts}
    generated = {p for p in pages if p.startswith("gallery/")}
    assert set(pages) - generated == written
    assert len(written) >= 19 + 20  # the 18 pages, the home page, the API's 20
    # the gallery's pages are what its script writes: an index and one page per example
    examples = gallery_examples()
    assert len(examples) >= 3
    assert generated == {"gallery/index.md"} | {f"gallery/{name}.md" for name in examples}
    for name in examples:
        assert (ROOT / "examples" / f"{name}.toml").is_file(), name


def test_api_reference_covers_the_public_subpackages() -> None:
    directives = set()
    for page in (DOCS / "api").glob("*.md"):
        directives |= set(re.findall(r"^::: ([\w.]+)", page.read_text(), re.M))
    src = ROOT / "src" / "formationlab"
    public = {
        p.parent.name
        for p in src.glob("*/__init__.py")
        if "__all__" in p.read_text() and not p.parent.name.startswith("_")
    } - NOT_IN_API
    assert len(public) >= 15
    missing = {name for name in public if f"formationlab.{name}" not in directives}
    assert not missing, f"subpackages without an API page: {sorted(missing)}"
    assert "formationlab" in directives


def test_lazily_imported_names_have_their_own_entry() -> None:
    """``fl.robotarium_script`` and ``fl.Viewer`` come from ``__getattr__``, which the static
    reading of ``formationlab`` does not see: the curated API's page names them itself."""
    package = griffe.load("formationlab", search_paths=[str(ROOT / "src")], resolve_aliases=False)
    lazy = {name for name in formationlab.__all__ if name not in package.members}
    assert "robotarium_script" in lazy
    page = (DOCS / "api" / "formationlab.md").read_text()
    entries = set(re.findall(r"^::: [\w.]+\.(\w+)$", page, re.M))
    assert lazy | {"Viewer"} <= entries


def _numpy_warnings(objects: list[griffe.Object]) -> list[str]:
    """What griffe logs while parsing the docstrings of ``objects`` and their members, and
    the text outside a section that Markdown would show as a quote (a ``>>>`` example out
    of an ``Examples`` section, a description starting with ``>``)."""
    found: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            found.append(record.getMessage())

    handler = Collect(level=logging.WARNING)
    logger = logging.getLogger("griffe")
    logger.addHandler(handler)
    try:
        stack = list(objects)
        while stack:
            obj = stack.pop()
            if obj.is_alias:
                continue
            if obj.docstring is not None:
                for section in obj.docstring.parse("numpy"):
                    texts = [section.value] if section.kind.value == "text" else []
                    texts += [
                        getattr(item, "description", "") or ""
                        for item in (section.value if isinstance(section.value, list) else [])
                    ]
                    if any(re.search(r"^\s*>", t, re.M) for t in texts):
                        found.append(f"{obj.path}: a line starting with '>' (a Markdown quote)")
            stack.extend(obj.members.values())
    finally:
        logger.removeHandler(handler)
    return found


def test_a_docstring_numpy_style_misreads_is_caught() -> None:
    module = griffe.visit(
        "example",
        Path("example.py"),
        'def f(a):\n    """Doc.\n\n    Parameters\n    ----------\n'
        '    b : int\n        No.\n    """\n',
    )
    warnings = _numpy_warnings([module])
    assert len(warnings) == 1 and "'b' does not appear" in warnings[0]
    quoted = griffe.visit(
        "example",
        Path("example.py"),
        'def f(r):\n    """Doc.\n\n    >>> f(1)\n\n    Parameters\n    ----------\n'
        '    r : float\n        > 0.\n    """\n',
    )
    quote = "example.f: a line starting with '>' (a Markdown quote)"
    assert _numpy_warnings([quoted]) == [quote, quote]  # the example, and r's description


def test_every_docstring_reads_in_numpy_style() -> None:
    """What mkdocstrings renders (``docstring_style: numpy``) and strict mode would refuse."""
    package = griffe.load("formationlab", search_paths=[str(ROOT / "src")], resolve_aliases=False)
    warnings = _numpy_warnings([package])
    assert warnings == []


def _github_anchor(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    text = re.sub(r"^```.*?^```", "", path.read_text(), flags=re.S | re.M)
    return {_github_anchor(h) for h in re.findall(r"^#{1,6} (.+)$", text, re.M)}


def test_github_anchor_rules() -> None:
    assert _github_anchor("Equations → code") == "equations--code"
    assert _github_anchor("What `run` writes") == "what-run-writes"
    assert _github_anchor("The paper's claims, checked") == "the-papers-claims-checked"


def test_readme_links_land_on_a_file_and_a_heading() -> None:
    readme = ROOT / "README.md"
    text = re.sub(r"^```.*?^```", "", readme.read_text(), flags=re.S | re.M)
    links = [
        link
        for link in re.findall(r"\]\(([^)\s]+)\)", text)
        if not re.match(r"[a-z]+:", link)  # http(s), mailto
    ]
    assert len(links) >= 30
    with_anchor = 0
    for link in links:
        target, _, anchor = link.partition("#")
        path = readme if not target else ROOT / target
        assert path.is_file(), f"README links to {link}: no such file"
        if anchor:
            with_anchor += 1
            assert anchor in _anchors(path), f"README links to {link}: no such heading"
    assert with_anchor >= 10


@pytest.mark.parametrize("page", ["README.md", "docs/index.md"])
def test_quick_start_is_two_commands(page: str) -> None:
    """The README's quick start, and the home page's copy of it: the same two commands."""
    section = re.search(r"^## Quick start\n(.*?)^## ", (ROOT / page).read_text(), re.S | re.M)
    assert section, f"{page} has no quick start"
    commands = re.findall(r"```bash\n(.*?)```", section.group(1), re.S)
    readme = re.search(r"^## Quick start\n(.*?)^## ", (ROOT / "README.md").read_text(), re.S | re.M)
    assert readme is not None
    assert len(commands) == 2
    assert commands == re.findall(r"```bash\n(.*?)```", readme.group(1), re.S)
    assert commands[0].startswith("python3 -m venv .venv") and "formationlab paper" in commands[0]


def test_sphinx_roles_become_links_resolved_as_relative_imports() -> None:
    spec = importlib.util.spec_from_file_location(
        "griffe_roles", DOCS / "_scripts" / "griffe_roles.py"
    )
    assert spec is not None and spec.loader is not None
    roles = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(roles)

    def link(text: str, owner: str | None = None) -> str:
        return roles.link_roles(text, "formationlab.engine.loop", "formationlab.engine", owner)

    assert link(":class:`~.contact.Verdict`") == (
        '<autoref identifier="formationlab.engine.contact.Verdict" optional>'
        "<code>Verdict</code></autoref>"
    )
    assert 'identifier="formationlab.models.stage.points"' in link(":func:`..models.stage.points`")
    assert "<code>models.stage.points</code>" in link(":func:`..models.stage.points`")
    # a bare name: the class's member first, the module's as the second choice
    assert link(":meth:`step`", "formationlab.engine.loop.Run") == (
        '<autoref identifier="formationlab.engine.loop.Run.step" '
        'slug="formationlab.engine.loop.step" optional><code>step</code></autoref>'
    )
    # an absolute name, or one relative to the package
    absolute = link(":func:`formationlab.simulate`")
    assert 'identifier="formationlab.simulate" slug="formationlab.engine.formationlab.' in absolute
    assert "<code>the method</code>" in link(":py:meth:`the method <A.b>`")
    assert link("no role: `x`") == "no role: `x`"
