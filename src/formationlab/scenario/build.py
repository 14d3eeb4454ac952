"""Building a scenario's formation (private to :mod:`formationlab.scenario`).

The formation comes from :class:`~formationlab.Formation`'s builders (the law
and the integrator from :func:`formationlab.scenario.parts.build_entry`).
Problems are raised through the caller's ``fail(where, message)``, which adds
the file and line.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import UserInputError
from ..formation.graph import edges_connected
from ..formation.graphs import build_edges, nearest_gap, overlapping_pairs
from ..formation.realisability import realisability_problems
from ..formation.spec import AlphaValues, Formation, check_alpha_signs
from ..formation.templates import lattice
from ..validation import coordinates
from .parts import Fail
from .tables import Lattice, StartAround

__all__ = [
    "FIXED",
    "build_formation",
    "initial_positions",
    "restrictions_on_at_target",
    "stem",
]


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
    template = _template(frm, fail)
    around = isinstance(rob.positions, StartAround)
    if around and template is None:
        raise fail(
            "robots.positions",
            'positions = { around = "template", ... } needs formation.template (a list of '
            'points or { lattice = "triangular", count = ..., spacing = ... })',
        )
    n = len(template) if around else len(rob.positions)  # type: ignore[arg-type]
    if isinstance(rob.diameters, list) and len(rob.diameters) != n:
        raise fail(
            "robots.diameters",
            f"give one number or one per robot: there are {n} positions but "
            f"{len(rob.diameters)} diameters",
        )
    dim = template.shape[1] if template is not None else 2
    if not around:  # the start's points: pairs in the plane, triples in space
        dim_start = len(rob.positions[0])  # type: ignore[index]
        if template is not None and dim_start != dim:
            raise fail(
                "robots.positions",
                f"the positions are {_space(dim_start)} and the template is {_space(dim)}; "
                "give both as [x, y] pairs (the plane) or both as [x, y, z] triples (space)",
            )
        dim = dim_start
    orientation = frm.orientation
    if orientation is None:
        orientation = "template" if template is not None else "table" if frm.alpha else "free"
    if dim == 3 and (orientation == "table" or frm.alpha is not None):
        raise fail(
            "formation.alpha" if frm.alpha is not None else "formation.orientation",
            "an alpha table restricts triangles in the plane; in space the orientation is "
            "the chirality of tetrahedra: give formation.template as [x, y, z] triples and "
            'orientation = "template" (docs/three-d.md)',
        )
    if template is not None:
        if len(template) != n:
            raise fail(
                "formation.template",
                f"the template has {len(template)} points but there are {n} robots "
                "(robots.positions); give one template point per robot, or start around it "
                'with robots.positions = { around = "template", sigma = ... }',
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
    built = isinstance(frm.edges, dict) or frm.edges in ("delaunay", "henneberg")
    if built and template is None:
        raise fail(
            "formation.edges",
            f"edges = {_edges_text(frm.edges)} builds the graph from the template's points; "
            "add formation.template (a list of points or { lattice = ... }) or give the "
            "edges as a list of pairs [i, j]",
        )
    distances = 1.0 if frm.distances is None else frm.distances
    try:
        if template is not None:
            edges = build_edges(frm.edges, template) if built else frm.edges
            formation = Formation.from_template(
                template,
                edges=edges,
                diameters=rob.diameters,
                orientation=orientation,  # type: ignore[arg-type]
                alpha_values=alpha_values,
                one_based=not built,
            )
        elif orientation == "table":
            check_alpha_signs(frm.alpha or [])
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
                n, edges=frm.edges, distances=distances, diameters=rob.diameters, dim=dim
            )
    except UserInputError as exc:
        raise fail(_formation_key(exc, frm), str(exc)) from None
    if frm.bearings is not None:  # desired bearings given per edge, in the order of `edges`
        if built:
            raise fail(
                "formation.bearings",
                "bearings given per edge need the edges as a list of pairs [i, j] (the rows "
                "follow them); or leave bearings out to take the template's",
            )
        try:
            order = frm.edges if isinstance(frm.edges, list) else None
            formation = formation.with_bearings(frm.bearings, edges=order)
        except UserInputError as exc:
            raise fail("formation.bearings", str(exc)) from None
    if frm.distances is None and template is None and frm.bearings is None:
        warnings.append("formation.distances not given: every d_ij = 1")
    if not edges_connected(formation.edges, formation.n):
        raise fail(
            "formation.edges",
            "the graph is not connected, so the formation cannot hold together; add edges "
            "between its parts",
        )
    if not formation.is_rigid:
        need = 2 * n - 3 if dim == 2 or n <= 3 else 3 * n - 6
        warnings.append(
            "the graph is not rigid: the distances do not fix the shape (add edges to make "
            f"it rigid; {n} robots need at least {need} well-placed edges"
            + (" in space)" if dim == 3 else ")")
        )
    if template is None:  # a template realises its own distances
        warnings.extend(
            f"formation.distances cannot all be met: {p}; runs will not reach the desired "
            "shape, check the distances"
            for p in realisability_problems(formation)
        )
    return formation


def _template(frm: Any, fail: Fail) -> NDArray[np.float64] | None:
    """The template's points: the list given, or the lattice patch (``templates.lattice``)."""
    if frm.template is None:
        return None
    if isinstance(frm.template, Lattice):
        try:
            return lattice(frm.template.lattice, frm.template.count, frm.template.spacing)
        except UserInputError as exc:
            raise fail("formation.template", str(exc)) from None
    return np.asarray(frm.template, dtype=float)


def _space(dim: int) -> str:
    return "[x, y, z] triples (space)" if dim == 3 else "[x, y] pairs (the plane)"


def _edges_text(edges: Any) -> str:
    if isinstance(edges, dict):
        key, value = next(iter(edges.items()))
        return f"{{ {key} = {value} }}"
    return f'"{edges}"'


def initial_positions(rob: Any, formation: Formation, fail: Fail) -> NDArray[np.float64]:
    """The start ``q0`` (n, 2) of ``[robots] positions``: the list, or around the template.

    Checked for overlapping robots (``Formation.check_positions``); a start drawn around
    the template that overlaps names the first pair, counts the pairs and suggests a
    smaller ``sigma`` or another ``seed``.
    """
    start = rob.positions
    if not isinstance(start, StartAround):
        try:
            q0 = np.asarray(start, dtype=float)
            coordinates(q0, "positions")
            return formation.check_positions(q0)
        except UserInputError as exc:
            raise fail("robots.positions", str(exc)) from None
    assert formation.template is not None  # build_formation requires it
    rng = np.random.default_rng(start.seed)
    q0 = formation.template + rng.normal(scale=start.sigma, size=formation.template.shape)
    try:
        coordinates(q0, f"the start drawn around the template (sigma = {start.sigma:g})")
    except UserInputError as exc:
        raise fail("robots.positions", str(exc)) from None
    pairs = overlapping_pairs(q0, formation.diameters)
    if len(pairs):
        i, j = pairs[0]
        r = float(np.linalg.norm(q0[j] - q0[i]))
        a = 0.5 * float(formation.diameters[i] + formation.diameters[j])
        raise fail(
            "robots.positions",
            f"robots {i + 1} and {j + 1} overlap in the start drawn around the template "
            f"(sigma = {start.sigma:g}, seed = {start.seed}): distance {r:g} <= "
            f"a_{i + 1},{j + 1} = {a:g} ({len(pairs)} overlapping pairs); "
            + _sigma_hint(formation, start.sigma),
        )
    return q0


def _sigma_hint(formation: Formation, sigma: float) -> str:
    """Advice for a perturbed start that overlaps: a sigma that keeps robots apart."""
    tpl = formation.template
    assert tpl is not None
    gap = nearest_gap(tpl, formation.diameters)
    if gap <= 0:
        return "the template itself has touching robots: use smaller diameters or a larger spacing"
    # the difference of two starts has std sigma * sqrt(2) per axis; keep the gap ~8 std wide
    good = 10.0 ** np.floor(np.log10(gap / (8.0 * np.sqrt(2.0))))
    good = min(good * np.floor(gap / (8.0 * np.sqrt(2.0)) / good), sigma / 2)
    return f"use a smaller sigma (e.g. sigma = {good:.2g}) or another seed"


def restrictions_on_at_target(formation: Formation, law: Any) -> str | None:
    """A warning when restrictions of a switching law are on at the desired shape, else ``None``.

    The restriction of eq. (14) is on while ``alpha_ijk c_ijk + theta >= 0``. At the
    template (or its mirror image) ``alpha_ijk c_ijk = -|c_ijk|`` for sign-valued alpha, so
    a template triangle with ``|c_ijk| <= theta`` (thinner than theta: nearly collinear
    neighbours) keeps its restriction on, its angular term pushes, and the desired shape is
    not an equilibrium of the law: with a rigid graph, random starts then almost never reach
    it (docs/swarms.md); with a graph that is not rigid, another shape with the same
    distances may still be reached.
    """
    switching = getattr(law, "switching", None)
    theta = getattr(law, "theta", None)
    if switching is None or theta is None or not formation.has_orientation:
        return None
    if formation.template is None or formation.orientation not in ("template", "mirror"):
        return None
    shape = formation.template
    if formation.orientation == "mirror":
        shape = shape * np.array([-1.0, 1.0, 1.0][: formation.dim])
    sigma = np.asarray(switching(formation, shape))
    on = np.flatnonzero(sigma >= 0)
    if on.size == 0:
        return None
    bound = float(np.min(theta - sigma))  # the smallest |beta_s c_abc| at the desired shape
    worst = on[np.argmax(sigma[on])]
    if formation.dim == 3:  # in space: tetrahedra flatter than theta (docs/three-d.md)
        tets, beta3, _ = formation.chiral_surfaces
        robots = ", ".join(str(int(x) + 1) for x in tets[worst])
        size = abs(float(sigma[worst] - theta) / float(beta3[worst]))  # |v_abcd|
        label = "v_" + "".join(str(int(x) + 1) for x in tets[worst])
        tip = (
            f"use theta below {bound:.3g} (the flattest restricted tetrahedron), "
            if bound > 0
            else ""
        )
        return (
            f"{on.size} of the {sigma.size} restrictions of law {law.name!r} are on at the "
            f"desired shape (e.g. robots {robots}: |{label}| = {size:.3g} <= theta = "
            f"{theta:g}, a tetrahedron flatter than theta), so the desired formation is not an "
            f"equilibrium of the law; {tip}or a graph without these quadruples"
        )
    tris, beta, _ = formation.surfaces
    a, b, c = (int(x) + 1 for x in tris[worst])
    area = abs(float(sigma[worst] - theta) / float(beta[worst]))  # |c_abc|
    tip = f"use theta below {bound:.3g} (the thinnest restricted triangle), " if bound > 0 else ""
    what = (
        "the desired formation is not an equilibrium of the law"
        if formation.is_rigid
        else "the template itself is not an equilibrium of the law (the graph is not rigid: "
        "another shape with the same distances may be)"
    )
    return (
        f"{on.size} of the {sigma.size} restrictions of law {law.name!r} are on at the desired "
        f"shape (e.g. robots {a}, {b}, {c}: |c_{a}{b}{c}| = {area:.3g} <= theta = {theta:g}, a "
        f"triangle thinner than theta), so {what}; {tip}a template without such thin "
        "triangles, or a graph without these triples"
    )


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
