"""The page's files, shipped in the package (``static/``): read them, and bundle the script.

The front end is plain JavaScript without a build step. Its parts
(``scene.js``: drawing a formation in the plane; ``scene3d.js``: one in space, with
three.js; ``plots.js``: the live plots; ``ui.js``:
controls, transport and the render loop) are concatenated at run time into one
ES module whose default export is ``{ render }`` (the anywidget entry point; anywidget
deprecates a named ``render`` export) and which exports ``socketModel`` (the websocket
transport of the stand-alone page) by name. three.js is vendored unmodified from its npm
package (``static/three/``, with its licence, :data:`THREE_FILES`) and loaded by the page
only for a formation in space: from the server (:func:`three_module`) or, in a notebook,
from the widget's ``_three`` trait.
"""

from __future__ import annotations

from functools import cache
from importlib.resources import files

__all__ = ["SCRIPT_PARTS", "THREE_FILES", "bundle", "read_asset", "three_module"]

#: The script's parts, in the order they are concatenated.
SCRIPT_PARTS = ("scene.js", "scene3d.js", "plots.js", "ui.js")
#: The three.js modules of the scene in space (``static/three/``: three.js r179, MIT).
THREE_FILES = ("three.core.min.js", "three.module.min.js", "OrbitControls.js")


def read_asset(name: str) -> str:
    """The text of ``static/<name>``."""
    return (files(__package__) / "static" / name).read_text(encoding="utf-8")


@cache
def bundle() -> str:
    """The page's script: the parts, then the module's exports."""
    parts = [f"// ---- {name}\n{read_asset(name)}" for name in SCRIPT_PARTS]
    exports = "export { socketModel };\nexport default { render };\n"
    return "\n".join([*parts, exports])


def three_module(name: str) -> str:
    """The text of the vendored three.js module ``name`` (one of :data:`THREE_FILES`), with
    OrbitControls' bare import ``'three'`` pointed at the file beside it (the page then
    needs no import map).

    Raises
    ------
    KeyError
        ``name`` is not one of :data:`THREE_FILES`.
    """
    if name not in THREE_FILES:
        raise KeyError(name)
    return read_asset(f"three/{name}").replace("from 'three';", "from './three.module.min.js';")
