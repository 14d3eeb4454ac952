"""Lattice templates: compact patches of the plane's triangular, square and honeycomb
lattices, and of the simple, face-centred and body-centred cubic lattices in space.

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

The cubic lattices share one integer grid ``(i, j, k)``, and ``count`` nearest points of a
ball are kept, ordered by squared radius, then height ``k``, then polar angle:

* ``"cubic"`` (simple cubic): ``p = s (i, j, k)``; 6 neighbours.
* ``"fcc"`` (face-centred cubic, the densest packing of equal spheres): the points with
  ``i + j + k`` even, ``p = s (i, j, k) / sqrt(2)``; 12 neighbours.
* ``"bcc"`` (body-centred cubic): the points with ``i, j, k`` all even or all odd,
  ``p = s (i, j, k) / sqrt(3)``; 8 neighbours.

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

__all__ = ["LATTICES", "LATTICE_DIM", "SPACING_FLOOR", "LatticeKind", "lattice"]

LatticeKind = Literal["triangular", "square", "hexagonal", "cubic", "fcc", "bcc"]

#: The smallest lattice spacing: the sixth power of a distance (the barrier's ``h^3``, with
#: ``h`` a squared distance) stays a normal double down to about 1e-51.
SPACING_FLOOR = 1e-50

#: The lattice kinds :func:`lattice` knows, with the area per point in units of ``spacing**2``
#: in the plane, the volume per point in units of ``spacing**3`` in space.
LATTICES: dict[str, float] = {
    "triangular": math.sqrt(3.0) / 2.0,
    "square": 1.0,
    "hexagonal": 3.0 * math.sqrt(3.0) / 4.0,
    "cubic": 1.0,
    "fcc": 1.0 / math.sqrt(2.0),  # a cube of side 2 grid units holds 4 points
    "bcc": 4.0 / (3.0 * math.sqrt(3.0)),  # a cube of side 2 grid units holds 2 points
}

#: The space of each lattice kind.
LATTICE_DIM: dict[str, int] = {"cubic": 3, "fcc": 3, "bcc": 3}

#: Nearest-neighbour distance of the cubic lattices in grid units.
_GRID_SPACING = {"cubic": 1.0, "fcc": math.sqrt(2.0), "bcc": math.sqrt(3.0)}


#: bytes per point of the square grid a lattice patch is cut from, at the peak (indices,
#: squared radii, masks and numpy's temporaries)
_GRID_BYTES = 64


def lattice(kind: str, count: int, spacing: float = 1.0) -> NDArray[np.float64]:
    """The ``count`` points of a lattice nearest to its centre.

    Parameters
    ----------
    kind : {"triangular", "square", "hexagonal", "cubic", "fcc", "bcc"}
        The lattice; ``"hexagonal"`` is the honeycomb (three neighbours per point); the
        last three are in space.
    count : int
        Number of points, at least 2.
    spacing : float
        Nearest-neighbour distance, > 0.

    Returns
    -------
    ndarray, shape (count, 2) or, for the cubic lattices, (count, 3)
        Points ordered by distance from the centre (the origin), then (in space) by
        height, then by angle in ``(-pi, pi]``; the first point is the centre for every
        lattice but the honeycomb.

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
    if LATTICE_DIM.get(kind) == 3:
        return _cubic(kind, count, float(spacing))
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


def _cubic(kind: str, count: int, spacing: float) -> NDArray[np.float64]:
    """The ``count`` points of a cubic lattice nearest to the origin (see the module)."""
    unit = _GRID_SPACING[kind]  # grid units per spacing
    # radius (in grid units) of a ball holding about `count` points, with margin
    radius = unit * ((3.0 * count * LATTICES[kind] / (4.0 * math.pi)) ** (1.0 / 3.0) + 2.0)
    half = math.ceil(radius) + 1
    check_memory(
        _GRID_BYTES * (2 * half + 1) ** 3, f"a {kind} lattice of {count:,} points",
        key="template", fix="use fewer points",
    )  # fmt: skip
    r = np.arange(-half, half + 1, dtype=np.int64)
    i, j, k = (a.ravel() for a in np.meshgrid(r, r, r, indexing="ij"))
    if kind == "fcc":
        keep = (i + j + k) % 2 == 0
    elif kind == "bcc":
        keep = (i % 2 == j % 2) & (j % 2 == k % 2)
    else:
        keep = np.ones(i.shape, dtype=bool)
    i, j, k = i[keep], j[keep], k[keep]
    r2 = i * i + j * j + k * k  # exact: an integer in grid units
    inside = r2 <= radius * radius
    assert np.count_nonzero(inside) >= count  # the margin above always suffices
    i, j, k, r2 = i[inside], j[inside], k[inside], r2[inside]
    angle = np.arctan2(j.astype(float), i.astype(float))
    order = np.lexsort((angle, k, r2))[:count]
    xyz = np.stack([i[order], j[order], k[order]], axis=1).astype(float)
    return np.ascontiguousarray(xyz * (spacing / unit))


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
