"""The page's files, shipped in the package (``static/``): read them, and bundle the script.

The front end is plain JavaScript without a build step. Its parts
(``scene.js``: drawing the formation; ``plots.js``: the live plots; ``ui.js``:
controls, transport and the render loop) are concatenated at run time into one
ES module whose default export is ``{ render }`` (the anywidget entry point; anywidget
deprecates a named ``render`` export) and which exports ``socketModel`` (the websocket
transport of the stand-alone page) by name.
"""

from __future__ import annotations

from functools import cache
from importlib.resources import files

__all__ = ["SCRIPT_PARTS", "bundle", "read_asset"]

#: The script's parts, in the order they are concatenated.
SCRIPT_PARTS = ("scene.js", "plots.js", "ui.js")


def read_asset(name: str) -> str:
    """The text of ``static/<name>``."""
    return (files(__package__) / "static" / name).read_text(encoding="utf-8")


@cache
def bundle() -> str:
    """The page's script: the parts, then the module's exports."""
    parts = [f"// ---- {name}\n{read_asset(name)}" for name in SCRIPT_PARTS]
    exports = "export { socketModel };\nexport default { render };\n"
    return "\n".join([*parts, exports])
