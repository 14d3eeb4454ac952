"""A griffe extension for the API reference: Sphinx roles in docstrings made into links.

The docstrings write cross-references as Sphinx roles (``:class:`~.spec.Formation```),
which Markdown would show verbatim. This turns each into an optional cross-reference of
mkdocs-autorefs (the ``<autoref ... optional>`` element that mkdocstrings itself writes
for signatures) around inline code of the name a reader would see in Sphinx: the last
component after ``~``, the name without its leading dots otherwise. The target is resolved
as Python resolves a relative import from the docstring's module (``.spec.Formation`` in
``formationlab.formation.chirality`` is ``formationlab.formation.spec.Formation``); a bare
name is looked up in the enclosing class, then in the module. A target that the reference
does not show (a private module, numpy) stays code without a link and without a warning.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:mod|class|func|meth|attr|data|obj|exc|const):`([^`]+)`")


def _shown(target: str) -> str:
    """The name Sphinx would show for ``target`` (``~`` keeps the last component)."""
    if target.startswith("~"):
        return target[1:].rsplit(".", 1)[-1]
    return target.lstrip(".")


def _candidates(target: str, module: str, package: str, owner: str | None) -> list[str]:
    """Full paths ``target`` may name, most likely first (at most two)."""
    target = target.lstrip("~")
    if target.startswith("."):  # a relative import's rule
        dots = len(target) - len(target.lstrip("."))
        base = package.split(".")
        base = base[: len(base) - (dots - 1)] if dots > 1 else base
        return [".".join([*base, target[dots:]])]
    if "." not in target:  # the enclosing class's member, else the module's
        return [f"{owner}.{target}"] * (owner is not None) + [f"{module}.{target}"]
    return [target, f"{package}.{target}"]


def link_roles(text: str, module: str, package: str, owner: str | None = None) -> str:
    """The docstring ``text`` with every Sphinx role written as an optional link.

    Parameters
    ----------
    text : str
        The docstring.
    module, package : str
        Full path of the docstring's module and of the package relative names start from
        (the module itself when it is a package's ``__init__``).
    owner : str or None
        Full path of the class whose member the docstring documents (or which it is).
    """

    def link(match: re.Match[str]) -> str:
        target = match.group(1).strip()
        if "<" in target and target.endswith(">"):  # :role:`text <target>`
            shown, target = target[: target.index("<")].strip(), target[target.index("<") + 1 : -1]
        else:
            shown = _shown(target)
        first, *rest = _candidates(target, module, package, owner)
        slug = f' slug="{rest[0]}"' if rest else ""
        return f'<autoref identifier="{first}"{slug} optional><code>{shown}</code></autoref>'

    return _ROLE.sub(link, text)


class SphinxRolesAsLinks(griffe.Extension):
    """Rewrite the Sphinx roles of every docstring as optional cross-references."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is None:
            return
        module = obj.module
        package = module.path if module.is_init_module else module.path.rsplit(".", 1)[0]
        parent = obj.parent
        owner = obj.path if obj.is_class else (parent.path if parent and parent.is_class else None)
        obj.docstring.value = link_roles(obj.docstring.value, module.path, package, owner)
