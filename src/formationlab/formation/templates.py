"""Lattice templates: compact patches of the triangular, square and honeycomb lattices.

A swarm's desired shape is often a piece of a regular lattice. :func:`lattice`
returns the ``count`` lattice points nearest to the patch's centre, so the
patch is compact and roughly round, for any ``count``; the nearest-neighbour
distance is ``spacing``. The result is deterministic: points are ordered by
their exact squared distance from the centre (an integer in lattice units) and
then by their polar angle, and the first ``count`` are kept.

The three lattices share one integer grid ``(i, j)``:

* ``"square"``: ``p = s (i, j)``; every interior point has 4 neighbours.
* ``"triangular"``: ``p = s (i + j/2, j sqrt(3)/2)``; 6 neighbours.
* ``"hexagonal"`` (honeycomb): the triangular grid without its index-3
  sublattice ``i - j = 0 (mod 3)``, the centres of the hexagons; 3 neighbours.
  The patch is centred on a hexagon's centre.

Examples
--------
>>> pts = lattice("triangular", 7, 1.0)
>>> pts.shape
(7, 2)
>>> float(np.round(np.linalg.norm(pts[1] - pts[0]), 12))
1.0
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..errors import FormationError
from ..resources import check_memory
from ..validation import choices

__all__ = ["LATTICES", "SPACING_FLOOR", "LatticeKind", "lattice"]

LatticeKind = Literal["triangular", "square", "hexagonal"]

#: The smallest lattice spacing: the sixth power of a distance (the barrier's ``h^3``, with
#: ``h`` a squared distance) stays a normal double down to about 1e-51.
SPACING_FLOOR = 1e-50

#: The lattice kinds :func:`lattice` knows, with the area per point in units of ``spacing**2``.
LATTICES: dict[str, float] = {
    "triangular": math.sqrt(3.0) / 2.0,
    "square": 1.0,
    "hexagonal": 3.0 * math.sqrt(3.0) / 4.0,
}


#: bytes per point of the square grid a lattice patch is cut from, at the peak (indices,
#: squared radii, masks and numpy's temporaries)
_GRID_BYTES = 64


def lattice(kind: str, count: int, spacing: float = 1.0) -> NDArray[np.float64]:
    """The ``count`` points of a lattice nearest to its centre.

    Parameters
    ----------
    kind : {"triangular", "square", "hexagonal"}
        The lattice; ``"hexagonal"`` is the honeycomb (three neighbours per point).
    count : int
        Number of points, at least 2.
    spacing : float
        Nearest-neighbour distance, > 0.

    Returns
    -------
    ndarray, shape (count, 2)
        Points ordered by distance from the centre (the origin), then by angle
        in ``(-pi, pi]``; the first point is the centre for the triangular and
        square lattices.

    Raises
    ------
    FormationError
        An unknown kind (with a suggestion), ``count < 2`` or a spacing that is
        not a positive finite number; ``key`` is ``"template"``.
    """
    if kind not in LATTICES:
        raise FormationError(
            f"unknown lattice {kind!r}{choices(str(kind), LATTICES)}",
            key="template",
        )
    if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 2:
        raise FormationError(
            f"a lattice template needs a whole count >= 2 of points, got {count!r}",
            key="template",
        )
    if (
        isinstance(spacing, bool)
        or not isinstance(spacing, int | float | np.floating)
        or not math.isfinite(spacing)
        or spacing <= 0
    ):
        raise FormationError(
            f"a lattice spacing must be a positive finite number, got {spacing!r}",
            key="template",
        )
    if spacing < SPACING_FLOOR:
        raise FormationError(
            f"a lattice spacing of {spacing:.3g} m is below {SPACING_FLOOR:g} m, where the "
            "sixth powers of distances that the laws and filters compute underflow double "
            "precision (every robot would look collinear with every other); give the spacing "
            "in metres",
            key="template",
        )
    count = int(count)
    # radius (in spacings) of a disc holding about `count` points, with margin
    radius = math.sqrt(count * LATTICES[kind] / math.pi) + 3.0
    side = 2 * (math.ceil(2.0 * radius) + 2) + 1  # of the square grid it is cut from
    check_memory(
        _GRID_BYTES * side * side, f"a {kind} lattice of {count:,} points", key="template",
        fix="use fewer points",
    )  # fmt: skip
    while True:
        i, j, r2 = _grid(kind, math.ceil(2.0 * radius) + 2)
        inside = r2 <= radius * radius
        if np.count_nonzero(inside) >= count:
            break
        radius *= 1.5  # pragma: no cover - the margin above always suffices
    i, j, r2 = i[inside], j[inside], r2[inside]
    xy = _coordinates(kind, i, j)
    angle = np.arctan2(xy[:, 1], xy[:, 0])
    r2_int = np.rint(r2).astype(np.int64)  # exact: an integer in lattice units
    order = np.lexsort((angle, r2_int))[:count]
    return np.ascontiguousarray(xy[order] * float(spacing))


def _grid(kind: str, half: int) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.float64]]:
    """Grid indices ``i, j`` in ``[-half, half]`` of the lattice and their squared radius.

    The squared radius is in units of ``spacing**2``: ``i^2 + j^2`` on the
    square grid, ``i^2 + i j + j^2`` on the triangular grid (the honeycomb is
    that grid without its hexagon centres); an integer either way.
    """
    r = np.arange(-half, half + 1, dtype=np.int64)
    i, j = (a.ravel() for a in np.meshgrid(r, r, indexing="ij"))
    if kind == "square":
        r2 = (i * i + j * j).astype(float)
    else:
        r2 = (i * i + i * j + j * j).astype(float)
        if kind == "hexagonal":
            keep = (i - j) % 3 != 0  # drop the hexagon centres
            i, j, r2 = i[keep], j[keep], r2[keep]
    return i, j, r2


def _coordinates(kind: str, i: NDArray[np.int64], j: NDArray[np.int64]) -> NDArray[np.float64]:
    """Cartesian coordinates, shape ``(len(i), 2)``, at unit spacing."""
    if kind == "square":
        return np.stack([i, j], axis=1).astype(float)
    return np.stack([i + 0.5 * j, (math.sqrt(3.0) / 2.0) * j], axis=1)
