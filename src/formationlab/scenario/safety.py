"""A scenario's ``[[obstacles]]`` and ``[safety]`` tables (private to :mod:`formationlab.scenario`).

The tables' structure is checked by pydantic (:class:`~formationlab.scenario.tables.
SafetyModel`; each obstacle is a table); here the obstacles are built (circle radius,
simple polygons, through :mod:`formationlab.safety`), checked against the robots'
starts, and the filter's distances against the contact distances. Every problem is a
:class:`~formationlab.errors.ScenarioError` naming the key, its line and the fix.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..errors import MissingExtraError, ScenarioError, UserInputError
from ..formation.spec import Formation
from ..neighbours.kdtree import pairs_within
from ..safety import SafetyFilter, check_extra, clearances, obstacle_from_mapping
from ..validation import line_of

if TYPE_CHECKING:
    from ..safety import Obstacle, SafetyFilter

__all__ = ["build_safety"]

_HEADER = re.compile(r"^\s*\[\[\s*obstacles\s*\]\]")


def _obstacle_line(text: str, k: int) -> int | None:
    """1-based line of the ``k``-th (0-based) ``[[obstacles]]`` header, or of ``obstacles =``."""
    lines = text.splitlines()
    headers = [i + 1 for i, line in enumerate(lines) if _HEADER.match(line)]
    if k < len(headers):
        return headers[k]
    inline = [i + 1 for i, line in enumerate(lines) if re.match(r"^\s*obstacles\s*=", line)]
    return inline[0] if inline else None


def build_safety(
    obstacles: Sequence[dict[str, Any]] | None,
    safety: Any,
    formation: Formation,
    q0: NDArray[np.float64],
    *,
    source: str,
    text: str,
    warnings: list[str],
) -> tuple[tuple[Obstacle, ...], SafetyFilter | None]:
    """The obstacles and the filter of a scenario, validated (module docstring).

    Parameters
    ----------
    obstacles : list of dict or None
        The ``[[obstacles]]`` tables as parsed.
    safety : SafetyModel or None
        The validated ``[safety]`` table.
    formation : Formation
        Its contact distances bound ``distance`` and ``obstacle_distance``.
    q0 : ndarray, shape (n, d)
        The robots' starts, which must be clear of every obstacle (circles and polygons in
        the plane, spheres and boxes in space: another kind is refused with its line).
    """
    if not obstacles and safety is None:
        return (), None
    try:
        check_extra()
    except MissingExtraError as exc:
        table = "safety" if safety is not None else "obstacles"
        line = line_of(text, table) or _obstacle_line(text, 0)
        at = f" (line {line})" if line else ""
        raise ScenarioError(f"{source}: [{table}]{at}: {exc}", key=table) from None

    def where(key: str, line: int | None) -> str:
        return f"{source}: {key}" + (f" (line {line})" if line else "")

    built: list[Obstacle] = []
    radii = formation.diameters / 2
    for k, spec in enumerate(obstacles or ()):
        at = where(f"obstacles, item {k + 1}", _obstacle_line(text, k))
        try:
            ob = obstacle_from_mapping(spec, dim=formation.dim)
        except UserInputError as exc:
            raise ScenarioError(f"{at}: {exc}", key="obstacles") from None
        s = clearances(q0, radii, [ob])[0][:, 0]
        if np.any(s <= 0):
            i = int(np.argmin(s))
            raise ScenarioError(
                f"{at}: the {ob.describe()} overlaps robot {i + 1}'s start "
                f"{q0[i].tolist()} (clearance {s[i]:.4g} <= 0, robot radius {radii[i]:g}); "
                "move the obstacle or robots.positions",
                key="obstacles",
            )
        built.append(ob)
    if safety is None:
        return tuple(built), None
    values = safety.model_dump()
    if values["sensing_radius"] is None:
        values["sensing_radius"] = float("inf")
    given = safety.model_fields_set
    try:
        config = SafetyFilter(**values)
        config.check_diameters(formation.diameters)
        config.check_space(formation.dim)
    except UserInputError as exc:
        key = f"safety.{exc.key or 'distance'}"
        raise ScenarioError(f"{where(key, line_of(text, key))}: {exc}", key=key) from None
    if config.enabled and len(q0) > 1:  # pairs that start inside the safety distance
        close = pairs_within(q0, config.distance)
        gap = np.linalg.norm(q0[close[:, 1]] - q0[close[:, 0]], axis=-1)
        close, gap = close[gap < config.distance], gap[gap < config.distance]
        if len(close):
            m = int(np.argmin(gap))
            more = f" (and {len(close) - 1} more pairs)" if len(close) > 1 else ""
            warnings.append(
                f"[safety] distance = {config.distance:g}: robots {close[m, 0] + 1} and "
                f"{close[m, 1] + 1} start {gap[m]:.3g} m apart{more}, closer than it; the "
                "filter pushes such pairs apart (their barrier h_ij < 0 must grow) and keeps "
                "the distance only once they reach it; move them apart or lower the distance"
            )
    if not config.enabled and given - {"filter"}:
        unused = ", ".join(sorted(given - {"filter"}))
        warnings.append(
            f'[safety] keys {unused}: no effect with filter = "none"; set filter = '
            '"barrier" or "barrier-decentralized" to use them'
        )
    return tuple(built), config
