"""Building a scenario's formation (private to :mod:`formationlab.scenario`).

The formation comes from :class:`~formationlab.Formation`'s builders (the law
and the integrator from :func:`formationlab._scenario_parts.build_entry`).
Problems are raised through the caller's ``fail(where, message)``, which adds
the file and line.
"""

from __future__ import annotations

import re
from typing import Any

from ._scenario_parts import Fail
from .errors import UserInputError
from .realisability import realisability_problems
from .spec import AlphaValues, Formation

__all__ = ["FIXED", "build_formation", "stem"]

#: The keys of ``[controller]`` and ``[simulation]`` that are not the class's parameters.
FIXED = {"controller": ("law", "alpha_values"), "simulation": ("integrator", "duration")}


def build_formation(
    rob: Any, frm: Any, alpha_values: AlphaValues, fail: Fail, warnings: list[str]
) -> Formation:
    """The formation of validated ``[robots]`` and ``[formation]`` tables.

    Checks what the tables cannot check alone (lengths that must agree, which
    keys go together), then builds with ``Formation.from_template``,
    ``from_alpha_table`` or ``from_distances``; appends warnings (non-rigid
    graph, default distances) to ``warnings``.
    """
    n = len(rob.positions)
    if isinstance(rob.diameters, list) and len(rob.diameters) != n:
        raise fail(
            "robots.diameters",
            f"give one number or one per robot: there are {n} positions but "
            f"{len(rob.diameters)} diameters",
        )
    orientation = frm.orientation
    if orientation is None:
        orientation = "template" if frm.template is not None else "table" if frm.alpha else "free"
    if frm.template is not None:
        if len(frm.template) != n:
            raise fail(
                "formation.template",
                f"the template has {len(frm.template)} points but there are {n} robots "
                "(robots.positions); give one template point per robot",
            )
        if frm.distances is not None:
            raise fail(
                "formation.distances",
                "give distances or a template, not both: the template sets the distances",
            )
        if frm.alpha is not None:
            raise fail(
                "formation.alpha",
                "give an alpha table or a template, not both: the template sets the orientation",
            )
        if orientation == "table":
            raise fail(
                "formation.orientation",
                'orientation = "table" needs an alpha table, not a template; use "template", '
                '"mirror" or "free" with a template',
            )
    else:
        if orientation in ("template", "mirror"):
            raise fail(
                "formation.orientation",
                f'orientation = "{orientation}" needs a template; add formation.template = '
                '[[x1, y1], ...] or use orientation = "free"',
            )
        if orientation == "table" and frm.alpha is None:
            raise fail(
                "formation.orientation",
                'orientation = "table" needs formation.alpha = [[i, j, k, value], ...]',
            )
        if frm.alpha is not None and orientation != "table":
            raise fail(
                "formation.alpha",
                f'an alpha table is only used with orientation = "table", got "{orientation}"',
            )
    distances = 1.0 if frm.distances is None else frm.distances
    try:
        if frm.template is not None:
            formation = Formation.from_template(
                frm.template,
                edges=frm.edges,
                diameters=rob.diameters,
                orientation=orientation,  # type: ignore[arg-type]
                alpha_values=alpha_values,
            )
        elif orientation == "table":
            formation = Formation.from_alpha_table(
                frm.alpha or [],
                n=n,
                edges=frm.edges,
                distances=distances,
                diameters=rob.diameters,
                alpha_values=alpha_values,
            )
        else:
            formation = Formation.from_distances(
                n, edges=frm.edges, distances=distances, diameters=rob.diameters
            )
    except UserInputError as exc:
        raise fail(_formation_key(exc, frm), str(exc)) from None
    if frm.distances is None and frm.template is None:
        warnings.append("formation.distances not given: every d_ij = 1")
    if not formation.is_connected:
        raise fail(
            "formation.edges",
            "the graph is not connected, so the formation cannot hold together; add edges "
            "between its parts",
        )
    if not formation.is_rigid:
        warnings.append(
            "the graph is not rigid: the distances do not fix the shape (add edges to make "
            f"it rigid; {n} robots need at least {2 * n - 3} well-placed edges)"
        )
    warnings.extend(
        f"formation.distances cannot all be met: {p}; runs will not reach the desired shape, "
        "check the distances"
        for p in realisability_problems(formation)
    )
    return formation


#: Scenario keys of the formation builders' parameters (``FormationError.key``).
SCENARIO_KEYS = {
    "positions": "robots.positions",
    "diameters": "robots.diameters",
    "edges": "formation.edges",
    "distances": "formation.distances",
    "template": "formation.template",
    "orientation": "formation.orientation",
    "alpha": "formation.alpha",
    "alpha_values": "controller.alpha_values",
}


def _formation_key(exc: UserInputError, frm: Any) -> str:
    """The scenario key of a formation builder's error (distances from a template: the template)."""
    if exc.key == "distances" and frm.distances is None and frm.template is not None:
        return "formation.template"
    return SCENARIO_KEYS.get(exc.key or "", "formation")


def stem(source: str) -> str:
    stem = re.split(r"[\\/]", source)[-1]
    stem = stem.removesuffix(".toml")
    return "scenario" if stem.startswith("<") else stem
