"""Building a scenario's formation, law and integrator (private to :mod:`formationlab.scenario`).

The formation comes from :class:`~formationlab.Formation`'s builders; the law
and the integrator from their registries, with the table's keys checked
against the chosen class's dataclass fields. Problems are raised through the
caller's ``fail(where, message)``, which adds the file and line.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from typing import Any

from ._scenario_parts import Fail, param_key, params, unknown
from .errors import UserInputError
from .realisability import realisability_problems
from .spec import AlphaValues, Formation

__all__ = ["build_formation", "build_from_registry", "stem"]

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
        raise fail(_formation_key(str(exc), frm), str(exc)) from None
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


def build_from_registry(
    registry: Mapping[str, Any],
    kind: str,
    name: str,
    given: Mapping[str, Any] | None,
    section: str,
    fail: Fail,
) -> Any:
    """The ``kind`` (law, integrator) registered as ``name``, built from the table's other keys."""
    if name not in registry:
        raise fail(f"{section}.{kind}", unknown(kind, name, registry))
    cls = registry[name]
    kwargs = params(cls, dict(given or {}), section, FIXED[section], f"{kind} {name!r}", fail)
    try:
        return cls(**kwargs)
    except UserInputError as exc:
        raise fail(param_key(section, kwargs, str(exc)), str(exc)) from None


def _formation_key(message: str, frm: Any) -> str:
    """The key a formation builder's message is about (for the line number)."""
    if "collinear" in message or "template" in message:
        return "formation.template"
    if "alpha" in message:
        return "formation.alpha"
    if message.startswith("distances"):  # e.g. one number per edge, but the wrong count
        return "formation.distances"
    if "edge" in message and "desired distance" not in message:
        return "formation.edges"
    if "diameters" in message and "distance" not in message:
        return "robots.diameters"
    if frm.distances is None and frm.template is not None:
        return "formation.template"
    return "formation.distances"


def stem(source: str) -> str:
    stem = re.split(r"[\\/]", source)[-1]
    stem = stem.removesuffix(".toml")
    return "scenario" if stem.startswith("<") else stem
