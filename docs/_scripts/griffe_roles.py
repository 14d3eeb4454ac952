"""A griffe extension for the API reference: Sphinx roles in docstrings shown as code.

The docstrings write cross-references as Sphinx roles (``:class:`~.spec.Formation```),
which Markdown would show verbatim. This turns each into inline code of the name a reader
would see in Sphinx: the last component after ``~``, the name without its leading dots
otherwise.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:mod|class|func|meth|attr|data|obj|exc|const):`([^`]+)`")


def _plain(match: re.Match[str]) -> str:
    target = match.group(1).strip()
    if "<" in target and target.endswith(">"):  # :role:`text <target>`
        return f"`{target[: target.index('<')].strip()}`"
    if target.startswith("~"):
        target = target[1:].rsplit(".", 1)[-1]
    return f"`{target.lstrip('.')}`"


def strip_roles(text: str) -> str:
    """The docstring `text` with every Sphinx role written as inline code."""
    return _ROLE.sub(_plain, text)


class SphinxRolesAsCode(griffe.Extension):
    """Rewrite the Sphinx roles of every docstring as inline code."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = strip_roles(obj.docstring.value)
