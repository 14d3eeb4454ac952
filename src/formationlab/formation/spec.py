"""Formation specification: robots, graph, desired distances and orientation.

A formation is the data of section 2 of the paper: ``N`` robots of diameter
``rho_i``, neighbour sets ``N_i`` with desired distances ``d_ij = d_ji``, and,
optionally, a desired orientation given by the angles ``alpha_ijk`` of eq. (2).

Conventions (written down once, see ``docs/conventions.md``)
-------------------------------------------------------------
* Robot indices are 0-based in code; 1-based wherever a person reads or writes
  them (tables given by users, messages, files, plots).
* ``r_ij = q_j - q_i`` (the paper's definition) and
  ``c_ijk = (r_ij x r_ik) . k`` is twice the signed area of the triangle
  ``(i, j, k)``: positive when ``i, j, k`` turn counter-clockwise.
* **Sign of alpha.** The restriction (14) is active while
  ``alpha_ijk c_ijk > -theta`` and its gradient lowers ``alpha_ijk c_ijk``, so
  it drives the triangle to ``sign(c_ijk) = -sign(alpha_ijk)``. In the paper's
  formulas ``alpha_ijk`` therefore carries the sign *opposite* to the
  counter-clockwise angle from ``r_ij`` to ``r_ik``. Tables given as printed in
  the paper are used as they are; alpha derived from a template follows the
  same convention, so that the template is what the law drives towards.
* ``alpha_ikj = -alpha_ijk`` (eq. 3); a table needs one of the two.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import FormationError
from ..neighbours.kdtree import close_pairs
from ..validation import COORDINATE_LIMIT, coordinates
from .chirality import chirality_from_shape, chirality_surfaces
from .geometry import parity, row_norms
from .graph import as_edges, complete_edges, edges_connected, is_rigid
from .orientation import alpha_from_shape, both_orders, neighbour_triples, switching_surfaces

__all__ = [
    "DENSE_LIMIT",
    "HELD_LIMIT",
    "AlphaValues",
    "Formation",
    "FormationError",
    "Orientation",
    "complete_edges",
]

Orientation = Literal["free", "template", "mirror", "table"]

#: Formations of at most this many robots also carry the dense ``(n, n, n)`` views of
#: their orientation (``alpha``, ``restricted``, ``desired_sign``); larger ones only the
#: lists of restricted triples, which every computation of the package uses.
DENSE_LIMIT = 64
AlphaValues = Literal["sign", "angle"]

#: A formation holds one of each pair of restricted triples, ``(i, j, k)`` with ``j < k``
#: (``alpha_ikj = -alpha_ijk``, eq. 3, gives the other). What it derives from them (the
#: ordered list of both, the switching surfaces) it keeps once built when there are at most
#: this many restricted triples, and builds again at each access beyond (a triangular
#: lattice of more than about 44,000 robots): memory for time, where the compiled run
#: reads them once and the held lists would be most of the memory. At 100,000 robots they
#: take about 0.2 s each to build and would hold 0.45 KB per robot (docs/swarms.md).
HELD_LIMIT = 1 << 20
#: The names under which a formation keeps what it derives from its halves.
_DERIVED = ("_ordered_lists", "_surfaces_held", "_triple_surface")

#: Robot indices (edges, restricted triples, surfaces) are stored as int32 when robot
#: numbers fit (every formation that fits in memory): half the bytes of int64.
_INDEX_LIMIT = 2**31 - 1


def _index(a: NDArray[np.integer], n: int) -> NDArray[np.integer]:
    """Indices ``a`` (values in ``0..n-1``) in the formation's index type: int32 where ``n``
    allows, else int64. Numpy indexes with either; code that combines indices into keys
    (``i n + j``) or hands them to compiled kernels casts them to int64 first."""
    return np.ascontiguousarray(a, dtype=np.int32 if n <= _INDEX_LIMIT else np.int64)


def _bearing_rows(dim: int) -> str:
    """How a bearing is written in ``dim`` dimensions (for messages)."""
    return "[x, y]" if dim == 2 else "[x, y, z]"


def _unit_bearings(bearings: ArrayLike, m: int, dim: int = 2) -> NDArray[np.float64]:
    """Desired bearings ``(m, d)``, one per edge, as read-only unit vectors."""
    b = np.array(bearings, dtype=float)
    if b.shape != (m, dim):
        raise FormationError(
            f"bearings must be one {_bearing_rows(dim)} per edge ({m} edges), got shape {b.shape}",
            key="bearings",
        )
    norm = np.sqrt(np.sum(b * b, axis=-1))
    bad = np.flatnonzero(~(np.isfinite(norm) & (norm > 0) & np.isfinite(b).all(axis=-1)))
    if bad.size:
        raise FormationError(
            f"bearing {bad[0] + 1} (edge {bad[0] + 1}) is {b[bad[0]].tolist()}: a bearing is a "
            f"finite direction, not zero; give {_bearing_rows(dim)} with a non-zero entry",
            key="bearings",
        )
    b /= norm[:, None]
    b.setflags(write=False)
    return b


def _in_edge_order(
    rows: NDArray[np.float64], given: ArrayLike, edges: NDArray[np.integer], n: int,
    one_based: bool,
) -> NDArray[np.float64]:  # fmt: skip
    """``rows`` given for the edges ``given`` (in that order and direction) put in the stored
    order of ``edges`` (``i < j``, sorted), reversed where an edge was given as ``(j, i)``."""
    pairs = np.asarray(given, dtype=np.int64).reshape(-1, 2) - (1 if one_based else 0)
    if len(pairs) != len(rows) or len(pairs) != len(edges):
        raise FormationError(
            f"bearings: {len(rows)} rows for {len(pairs)} given edges of {len(edges)}",
            key="bearings",
        )
    where = {(int(i), int(j)): t for t, (i, j) in enumerate(edges)}
    out = np.empty_like(rows)
    for t, (i, j) in enumerate(pairs):
        lo, hi = (int(i), int(j)) if i < j else (int(j), int(i))
        if (lo, hi) not in where:
            raise FormationError(f"bearing row {t + 1} names ({i + 1}, {j + 1}), not an edge",
                                 key="bearings")  # fmt: skip
        out[where[(lo, hi)]] = rows[t] if i < j else -rows[t]
    return out


def _signs(values: NDArray[np.float64]) -> NDArray[np.int8] | None:
    """``values`` as int8 when every one is exactly +1 or -1 (sign-valued alpha and its
    ``beta``): an eighth of the bytes, and :func:`_floats` gives back the same float64
    numbers, bit for bit. None otherwise (angles, given values), which stay float64."""
    if values.size == 0 or not np.all(np.abs(values) == 1.0):
        return None
    signs = values.astype(np.int8)
    signs.setflags(write=False)
    return signs


def _floats(stored: NDArray) -> NDArray[np.float64]:
    """The float64 numbers of values stored by :func:`_signs` (or already float64), read-only."""
    if stored.dtype == np.float64:
        return stored
    out = stored.astype(np.float64)
    out.setflags(write=False)
    return out


def _per_item(value: float | ArrayLike, count: int, what: str, per: str) -> NDArray[np.float64]:
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(count, float(arr))
    if arr.shape != (count,):
        raise FormationError(
            f"{what} must be one number or one per {per} ({count}), got shape {arr.shape}",
            key=what,
        )
    if not np.all(np.isfinite(arr)):
        raise FormationError(f"{what} must be finite numbers, got {arr.tolist()}", key=what)
    return arr


def check_alpha_signs(rows: Iterable[Sequence[float]]) -> None:
    """Refuse an alpha table whose signs no triangle realises (rows ``[i, j, k, alpha]``).

    The sign of ``alpha_ijk`` is the way the triangle ``i, j, k`` turns: kept by a cyclic
    permutation of ``i, j, k`` and flipped by a swap (eq. (3), and the angle sum (4) of a
    triangle), so two entries on the same three robots must agree. The scenario loader
    checks its tables so; :meth:`Formation.from_alpha_table` accepts any table (the laws
    refuse what they cannot follow).
    """
    turns: dict[tuple[int, ...], tuple[tuple[int, int, int], float]] = {}
    for row in rows:
        if len(row) != 4 or not math.isfinite(float(row[3])) or float(row[3]) == 0:
            continue  # (from_alpha_table says what is wrong with the row)
        i, j, k = (int(x) for x in row[:3])
        if len({i, j, k}) != 3:
            continue
        value = float(row[3])
        sign = math.copysign(1.0, value) * float(parity(i, j, k))
        first = turns.setdefault(tuple(sorted((i, j, k))), ((i, j, k), sign))
        if first[1] != sign:
            (a, b, c), s0 = first
            label, other = f"{i}{j}{k}", f"{a}{b}{c}"
            v0 = s0 * float(parity(a, b, c))
            how = "a cyclic permutation" if parity(a, b, c) == parity(i, j, k) else "a swap"
            raise FormationError(
                f"alpha_{other} = {v0:+g} and alpha_{label} = {math.copysign(1.0, value):+g} "
                f"contradict: ({i}, {j}, {k}) is {how} of ({a}, {b}, {c}), so no triangle "
                f"realises both signs (eq. (3) of the paper); give alpha_{label} the sign "
                f"{-math.copysign(1.0, value):+g}",
                key="alpha",
            )


@dataclass(frozen=True, kw_only=True, eq=False)
class Formation:
    """A formation of ``n`` robots: graph, desired distances, desired orientation.

    Build it with :meth:`from_distances`, :meth:`from_template` or
    :meth:`from_alpha_table` rather than directly; they validate their inputs.

    Parameters
    ----------
    diameters : ndarray, shape (n,)
        Robot diameters ``rho_i``; ``a_ij = (rho_i + rho_j) / 2`` (eq. 5).
    edges : ndarray of int, shape (m, 2)
        0-based pairs ``(i, j)`` with ``i < j``: ``j in N_i`` and ``i in N_j``. Given as
        any integers; stored as int32 (int64 beyond 2**31 - 1 robots), as are the
        restricted triples and the surfaces.
    distances : ndarray, shape (m,)
        Desired distances ``d_ij`` per edge.
    alpha : ndarray, shape (n, n, n), optional
        ``alpha_ijk`` in the paper's sign convention (module docstring); zero
        where no restriction applies. ``None`` when the orientation is free, and
        for formations of more than :data:`DENSE_LIMIT` robots (which give their
        orientation as ``restricted_triples`` and ``restricted_alpha``). Either
        form may be given; the other is derived.
    restricted_triples : ndarray of int, shape (t, 3), optional
        The triples ``(i, j, k)`` with a non-zero ``alpha_ijk``, 0-based, sorted;
        both ``(i, j, k)`` and ``(i, k, j)``. Its size grows with the edges, not with
        ``n^3``. The formation holds the halves ``j < k`` (:attr:`restricted_halves`)
        and derives this list from them (kept up to :data:`HELD_LIMIT` triples).
    restricted_alpha : ndarray, shape (t,), optional
        ``alpha_ijk`` of those triples, float64. When every value is +1 or -1 (sign-valued
        alpha) the formation holds them as int8 signs and gives a new read-only float64
        array of the same numbers at each access (an eighth of the bytes at rest).
    orientation : {"free", "template", "mirror", "table"}
        Where ``alpha`` came from.
    alpha_values : {"sign", "angle"}
        Whether ``alpha`` holds signs (+-1) or angles in radians; the factor of
        eq. (25) is 3 for signs and pi for angles.
    template : ndarray, shape (n, 2), optional
        The template shape the distances (and orientation) came from.
    collinear_skipped : int
        Ordered triples of the template left without a restriction because their
        robots are collinear in it.
    chiral_quads : ndarray of int, shape (Q, 4), optional
        In space (``dim = 3``): the quadruples ``(i, j, k, l)``, ``j < k < l`` neighbours of
        ``i``, whose chirality is restricted (:mod:`.chirality`), 0-based, sorted.
    chiral_signs : ndarray of int8, shape (Q,), optional
        Their ``beta_ijkl`` (+1 or -1): the restriction drives towards
        ``sign(v_ijkl) = -beta_ijkl``, the paper's convention for alpha.
    dim : int
        The space the robots move in: 2 (the plane, the paper's) or 3. Follows the
        template's columns when a template is given.
    bearings : ndarray, shape (m, d), optional
        The desired bearings ``g*_ij`` of the edges (unit vectors from robot ``i`` to robot
        ``j``, edges in the stored order ``i < j``): a formation defined by bearings (Zhao
        and Zelazo 2016), whose outcome is judged by them (:mod:`formationlab.outcomes`).
        Build with :meth:`with_bearings` (from the template, or given per edge).
    """

    diameters: NDArray[np.float64]
    edges: NDArray[np.integer]
    distances: NDArray[np.float64]
    alpha: NDArray[np.float64] | None = None
    #: (given or derived in ``__post_init__``: never None on a built formation)
    restricted_triples: NDArray[np.integer] = None  # type: ignore[assignment]
    restricted_alpha: NDArray[np.float64] = None  # type: ignore[assignment]
    collinear_skipped: int = 0
    orientation: Orientation = "free"
    alpha_values: AlphaValues = "sign"
    template: NDArray[np.float64] | None = field(default=None)
    bearings: NDArray[np.float64] | None = field(default=None)
    chiral_quads: NDArray[np.integer] | None = field(default=None)
    chiral_signs: NDArray[np.int8] | None = field(default=None)
    dim: int = 2

    def __post_init__(self) -> None:
        d = np.asarray(self.diameters, dtype=float)
        n = d.shape[0] if d.ndim == 1 else 0
        if d.ndim != 1 or n < 2:
            raise FormationError(
                f"diameters must be a list of n >= 2 numbers, got {d.shape}", key="diameters"
            )
        if not np.all(np.isfinite(d)) or np.any(d < 0):
            raise FormationError(
                f"diameters must be finite and >= 0, got {d.tolist()}", key="diameters"
            )
        if np.any(d > COORDINATE_LIMIT):  # contact distances add them: they would overflow
            raise FormationError(
                f"diameters must be at most {COORDINATE_LIMIT:g} m, got {float(d.max()):.3g}; "
                "give them in metres",
                key="diameters",
            )
        edges = as_edges(self.edges, n, one_based=False)
        dist = _per_item(self.distances, len(edges), "distances", "edge")
        if np.any(dist > COORDINATE_LIMIT):  # their squares would overflow
            raise FormationError(
                f"desired distances must be at most {COORDINATE_LIMIT:g} m, got "
                f"{float(dist.max()):.3g}; give them in metres",
                key="distances",
            )
        a = 0.5 * (d[edges[:, 0]] + d[edges[:, 1]])
        bad = np.flatnonzero(dist <= a)
        if bad.size:
            e = bad[0]
            i, j = edges[e] + 1
            raise FormationError(
                f"desired distance d_{i}{j} = {dist[e]:g} must exceed the contact distance "
                f"a_{i}{j} = (rho_{i} + rho_{j})/2 = {a[e]:g}; use smaller diameters or "
                "larger distances",
                key="distances",
            )
        if self.orientation not in ("free", "template", "mirror", "table"):
            raise FormationError(
                f'orientation must be "free", "template", "mirror" or "table", '
                f"got {self.orientation!r}",
                key="orientation",
            )
        if self.alpha_values not in ("sign", "angle"):
            raise FormationError(
                f'alpha_values must be "sign" or "angle", got {self.alpha_values!r}',
                key="alpha_values",
            )
        triples, values = self._restrictions(n, edges)
        if len(triples) == 0 and self.chiral_quads is None and self.orientation != "free":
            raise FormationError(
                f"orientation {self.orientation!r} needs alpha values", key="orientation"
            )
        alpha = None
        if n <= DENSE_LIMIT and len(triples):
            alpha = np.zeros((n, n, n))
            alpha[tuple(triples.T)] = values
            alpha.setflags(write=False)
        dim = self.dim
        template = None
        if self.template is not None:
            template = np.asarray(self.template, dtype=float)
            if template.ndim == 2 and template.shape[1] in (2, 3):
                dim = template.shape[1]
            if template.shape != (n, dim) or not np.all(np.isfinite(template)):
                raise FormationError(
                    f"template must be a finite ({n}, 2) or ({n}, 3) array", key="template"
                )
            template.setflags(write=False)
        if isinstance(dim, bool) or dim not in (2, 3):
            raise FormationError(f"dim must be 2 or 3, got {dim!r}", key="dim")
        quads, quad_signs = self._chirality(n, edges, int(dim))
        if dim == 3 and len(triples):
            raise FormationError(
                "alpha restricts triangles in the plane; in space the orientation is the "
                "chirality of tetrahedra (chiral_quads, chiral_signs, or a 3-D template)",
                key="alpha",
            )
        bearings = None if self.bearings is None else _unit_bearings(self.bearings, len(edges), dim)
        half = triples[:, 1] < triples[:, 2]  # the mirrors follow from eq. (3)
        index, halves = _index(edges, n), _index(triples[half], n)
        values = values[half]
        del triples, half
        for arr in (d, index, dist, halves):
            arr.setflags(write=False)
        object.__setattr__(self, "diameters", d)
        object.__setattr__(self, "edges", index)
        object.__setattr__(self, "distances", dist)
        object.__setattr__(self, "alpha", alpha)
        signs = _signs(values)
        for given in ("_restricted_triples", "_restricted_alpha"):  # replaced by the halves
            self.__dict__.pop(given, None)
        object.__setattr__(self, "_halves", halves)
        object.__setattr__(self, "_half_alpha", values if signs is None else signs)
        object.__setattr__(self, "template", template)
        object.__setattr__(self, "bearings", bearings)
        object.__setattr__(self, "dim", int(dim))
        object.__setattr__(self, "chiral_quads", quads)
        object.__setattr__(self, "chiral_signs", quad_signs)

    def _chirality(
        self, n: int, edges: NDArray[np.int64], dim: int
    ) -> tuple[NDArray[np.integer] | None, NDArray[np.int8] | None]:
        """The restricted quadruples and their signs, validated (:mod:`.chirality`)."""
        if self.chiral_quads is None and self.chiral_signs is None:
            return None, None
        if dim != 3:
            raise FormationError(
                "chirality (chiral_quads) restricts tetrahedra in space; a planar formation "
                "restricts its orientation through alpha",
                key="chirality",
            )
        quads = np.asarray(self.chiral_quads, dtype=np.int64).reshape(-1, 4)
        signs = np.asarray(self.chiral_signs, dtype=float).reshape(-1)
        if signs.shape != (len(quads),) or not np.all(np.isin(signs, (-1.0, 1.0))):
            raise FormationError(
                "chiral_signs must hold one +1 or -1 per restricted quadruple", key="chirality"
            )
        if np.any((quads < 0) | (quads >= n)) or np.any(
            ~((quads[:, 1] < quads[:, 2]) & (quads[:, 2] < quads[:, 3]))
            | np.any(quads[:, 1:] == quads[:, :1], axis=1)
        ):
            raise FormationError(
                f"restricted quadruples (i, j, k, l) name four robots in 0..{n - 1} with "
                "j < k < l and i different from them",
                key="chirality",
            )
        adj = {(int(i), int(j)) for i, j in edges} | {(int(j), int(i)) for i, j in edges}
        for row in quads:
            i, *others = (int(v) for v in row)
            for j in others:
                if (i, j) not in adj:
                    raise FormationError(
                        f"the chirality of robots {i + 1}, {others[0] + 1}, {others[1] + 1}, "
                        f"{others[2] + 1} is restricted at robot {i + 1}, but robot {j + 1} is "
                        f"not its neighbour; add the edge or drop the quadruple",
                        key="chirality",
                    )
        order = np.lexsort(quads.T[::-1])
        quads, signs8 = _index(quads[order], n), signs[order].astype(np.int8)
        quads.setflags(write=False)
        signs8.setflags(write=False)
        return quads, signs8

    def _restrictions(self, n: int, edges: NDArray[np.int64]) -> tuple[NDArray, NDArray]:
        """The restricted triples and their alpha from either form, validated (eq. 3)."""
        if self.alpha is not None:
            alpha = np.asarray(self.alpha, dtype=float)
            if alpha.shape != (n, n, n) or not np.all(np.isfinite(alpha)):
                raise FormationError(f"alpha must be a finite ({n}, {n}, {n}) array", key="alpha")
            t = np.argwhere(alpha != 0).astype(np.int64)
            v = alpha[tuple(t.T)]
        elif self.restricted_triples is not None:
            t = np.asarray(self.restricted_triples, dtype=np.int64).reshape(-1, 3)
            v = np.asarray(self.restricted_alpha, dtype=float).reshape(-1)
            if v.shape != (len(t),) or not np.all(np.isfinite(v)) or np.any(v == 0):
                raise FormationError(
                    "restricted_alpha must hold one finite non-zero number per restricted triple",
                    key="alpha",
                )
            if np.any((t < 0) | (t >= n)) or np.any(
                (t[:, 0] == t[:, 1]) | (t[:, 0] == t[:, 2]) | (t[:, 1] == t[:, 2])
            ):
                raise FormationError(
                    f"restricted triples must name three different robots in 0..{n - 1}",
                    key="alpha",
                )
            order = np.lexsort((t[:, 2], t[:, 1], t[:, 0]))
            t, v = t[order], v[order]
        else:
            return np.zeros((0, 3), np.int64), np.zeros(0)
        key = (t[:, 0] * n + t[:, 1]) * n + t[:, 2]
        mirror = (t[:, 0] * n + t[:, 2]) * n + t[:, 1]
        at = np.searchsorted(key, mirror)
        found = at < len(key)
        found[found] = key[at[found]] == mirror[found]
        if not np.all(found) or not np.allclose(v[np.minimum(at, len(v) - 1)][found], -v[found]):
            raise FormationError("alpha must satisfy alpha_ikj = -alpha_ijk (eq. 3)", key="alpha")
        pair = np.sort(edges, axis=1)
        edge_key = np.sort(pair[:, 0] * n + pair[:, 1])
        for col in (1, 2):
            lo, hi = np.minimum(t[:, 0], t[:, col]), np.maximum(t[:, 0], t[:, col])
            want = lo * n + hi
            pos = np.minimum(np.searchsorted(edge_key, want), max(len(edge_key) - 1, 0))
            ok = (edge_key[pos] == want) if len(edge_key) else np.zeros(len(t), bool)
            if not np.all(ok):
                i, j, k = t[np.argmin(ok)] + 1
                raise FormationError(
                    f"alpha_{i}{j}{k} is given but robots {j} and {k} are not both "
                    f"neighbours of robot {i}; add the edges or drop the entry",
                    key="alpha",
                )
        for arr in (t, v):
            arr.setflags(write=False)
        return t, v

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_distances(
        cls,
        n: int,
        *,
        edges: str | ArrayLike = "complete",
        distances: float | ArrayLike = 1.0,
        diameters: float | ArrayLike = 0.2,
        one_based: bool = True,
        dim: int = 2,
    ) -> Formation:
        """A formation with free orientation from a graph and desired distances.

        Parameters
        ----------
        n : int
            Number of robots.
        edges : "complete" or sequence of pairs
            The graph; pairs are 1-based robot numbers unless ``one_based=False``.
        distances : float or sequence of float
            ``d_ij``: one number for every edge, or one per edge in the given order.
        diameters : float or sequence of float
            ``rho_i``: one number for every robot, or one per robot.
        dim : {2, 3}
            The space the robots move in (3: drones).
        """
        if not isinstance(n, int | np.integer) or n < 2:
            raise FormationError(f"a formation needs an integer n >= 2 robots, got {n!r}")
        diam = _per_item(diameters, int(n), "diameters", "robot")
        raw_edges = edges
        e = as_edges(edges, int(n), one_based=one_based)
        dist = np.asarray(distances, dtype=float)
        if dist.ndim == 1 and not isinstance(raw_edges, str):
            # distances follow the user's edge order; _as_edges sorted the pairs
            given = np.asarray(raw_edges, dtype=np.int64) - (1 if one_based else 0)
            order = {(min(i, j), max(i, j)): t for t, (i, j) in enumerate(given)}
            dist = _per_item(dist, len(e), "distances", "edge")
            dist = dist[[order[(i, j)] for i, j in e]]
        dist = _per_item(dist, len(e), "distances", "edge")
        return cls(diameters=diam, edges=e, distances=dist, dim=dim)

    @classmethod
    def from_template(
        cls,
        template: ArrayLike,
        *,
        edges: str | ArrayLike = "complete",
        diameters: float | ArrayLike = 0.2,
        orientation: Orientation = "template",
        alpha_values: AlphaValues = "sign",
        one_based: bool = True,
    ) -> Formation:
        """A formation whose distances (and orientation) are those of a template shape.

        Parameters
        ----------
        template : array_like, shape (n, 2)
            Desired positions; only their relative geometry matters.
        orientation : {"template", "mirror", "free"}
            Drive towards the template itself, its mirror image, or either.
        alpha_values : {"sign", "angle"}
            Store the signs of the template's angles or the angles themselves,
            both in the paper's sign convention (module docstring).
        """
        tpl = np.asarray(template, dtype=float)
        if tpl.ndim != 2 or tpl.shape[1] not in (2, 3) or tpl.shape[0] < 2:
            raise FormationError(
                f"template must have shape (n, 2) or, in space, (n, 3) with n >= 2, got "
                f"{tpl.shape}",
                key="template",
            )
        if not np.all(np.isfinite(tpl)):
            raise FormationError("template holds NaN or infinite numbers", key="template")
        if orientation not in ("template", "mirror", "free"):
            raise FormationError(
                f'a template orientation is "template", "mirror" or "free", got {orientation!r}',
                key="orientation",
            )
        n = tpl.shape[0]
        e = as_edges(edges, n, one_based=one_based)
        dist = np.linalg.norm(tpl[e[:, 1]] - tpl[e[:, 0]], axis=-1)
        diam = _per_item(diameters, n, "diameters", "robot")
        triples: NDArray[np.int64] | None = None
        values: NDArray[np.float64] | None = None
        skipped = 0
        if tpl.shape[1] == 3:  # in space: the chirality of tetrahedra (.chirality)
            if alpha_values != "sign":
                raise FormationError(
                    "in space the orientation is a chirality, which has signs only: use "
                    'alpha_values = "sign"',
                    key="alpha_values",
                )
            quads = signs = None
            if orientation != "free":
                shape = tpl if orientation == "template" else tpl * np.array([-1.0, 1.0, 1.0])
                quads, signs, skipped = chirality_from_shape(shape, e)
            return cls(
                diameters=diam, edges=e, distances=dist, collinear_skipped=skipped,
                orientation=orientation, template=tpl, chiral_quads=quads, chiral_signs=signs,
            )  # fmt: skip
        if orientation != "free":
            shape = tpl if orientation == "template" else tpl * np.array([-1.0, 1.0])
            triples, values, skipped = alpha_from_shape(shape, e, alpha_values)
        return cls(
            diameters=diam,
            edges=e,
            distances=dist,
            restricted_triples=triples,  # type: ignore[arg-type]
            restricted_alpha=values,  # type: ignore[arg-type]
            collinear_skipped=skipped,
            orientation=orientation,
            alpha_values=alpha_values,
            template=tpl,
        )

    @classmethod
    def from_alpha_table(
        cls,
        table: Mapping[tuple[int, int, int], float] | Iterable[Sequence[float]],
        *,
        n: int,
        edges: str | ArrayLike = "complete",
        distances: float | ArrayLike = 1.0,
        diameters: float | ArrayLike = 0.2,
        alpha_values: AlphaValues = "sign",
    ) -> Formation:
        """A formation with the paper's ``alpha_ijk`` table, as printed (1-based).

        Parameters
        ----------
        table : mapping ``(i, j, k) -> alpha`` or rows ``[i, j, k, alpha]``
            1-based robot numbers. ``alpha_ikj = -alpha_ijk`` completes the table;
            a row that contradicts another is an error.

        Examples
        --------
        Simulation 2 of section 4 (``alpha_123 = alpha_312 = -alpha_213 = 1``):

        >>> f = Formation.from_alpha_table(
        ...     {(1, 2, 3): 1, (3, 1, 2): 1, (2, 1, 3): -1}, n=3, distances=1.0)
        >>> int(f.alpha[1, 2, 0])  # alpha_231 = -alpha_213
        1
        """
        base = cls.from_distances(n, edges=edges, distances=distances, diameters=diameters)
        if isinstance(table, Mapping):
            rows = list(table.items())
        else:
            rows = []
            for r in table:
                if not (isinstance(r, Sequence | np.ndarray) and len(r) == 4):
                    raise FormationError(
                        f"an alpha row is [i, j, k, alpha] (three robots and a value), got {r!r}",
                        key="alpha",
                    )
                rows.append((tuple(r[:3]), r[3]))
        given: dict[tuple[int, int, int], float] = {}  # a list, never an (n, n, n) array
        for key, value in rows:
            numbers = isinstance(key, Sequence | np.ndarray) and len(key) == 3
            if not (numbers and all(_robot_number(x) for x in key)):
                raise FormationError(
                    f"an alpha entry names three robots i, j, k (whole numbers), got {key!r}",
                    key="alpha",
                )
            i, j, k = (int(x) - 1 for x in key)
            label = "".join(str(x + 1) for x in (i, j, k))
            if not all(0 <= x < n for x in (i, j, k)):
                raise FormationError(f"alpha_{label} names a robot outside 1..{n}", key="alpha")
            if len({i, j, k}) != 3:
                raise FormationError(f"alpha_{label} needs three different robots", key="alpha")
            try:
                v = float(value)
            except (TypeError, ValueError):
                v = math.nan
            if not math.isfinite(v) or v == 0:
                raise FormationError(
                    f"alpha_{label} must be a finite non-zero number, got {value!r}", key="alpha"
                )
            for (a, b, c), w in (((i, j, k), v), ((i, k, j), -v)):
                if given.get((a, b, c), w) != w:
                    raise FormationError(
                        f"alpha_{a + 1}{b + 1}{c + 1} is given twice with different values "
                        "(remember alpha_ikj = -alpha_ijk)",
                        key="alpha",
                    )
                given[a, b, c] = w
        return cls(
            diameters=base.diameters,
            edges=base.edges,
            distances=base.distances,
            restricted_triples=np.array(list(given), np.int64).reshape(-1, 3),
            restricted_alpha=np.array(list(given.values()), float),
            orientation="table",
            alpha_values=alpha_values,
        )

    def with_orientation(self, orientation: Orientation) -> Formation:
        """The same formation driven to the template, its mirror image, or either."""
        if orientation == "free":
            return Formation(
                diameters=self.diameters, edges=self.edges, distances=self.distances,
                template=self.template, bearings=self.bearings, dim=self.dim,
            )  # fmt: skip
        if self.template is None:
            raise FormationError(f"orientation {orientation!r} needs a template", key="orientation")
        out = Formation.from_template(
            self.template,
            edges=self.edges,
            diameters=self.diameters,
            orientation=orientation,
            alpha_values=self.alpha_values,
            one_based=False,
        )
        return out if self.bearings is None else out._rebuilt(bearings=self.bearings)

    def with_bearings(
        self,
        bearings: ArrayLike | None = None,
        *,
        edges: ArrayLike | None = None,
        one_based: bool = True,
    ) -> Formation:
        """The same formation defined by desired bearings ``g*_ij`` (Zhao and Zelazo 2016).

        Parameters
        ----------
        bearings : array_like, shape (m, d), optional
            One direction per edge (normalised here), ``d`` the formation's space. Without
            it, the template's bearings
            ``(t_j - t_i) / ||t_j - t_i||``, the natural way to give them.
        edges : array_like of pairs, optional
            The edges the rows of ``bearings`` belong to, in their order and direction
            (robot numbers, 1-based unless ``one_based=False``); the formation's own edge
            order (``i < j``, sorted) when omitted. A row given for ``(j, i)`` is the
            bearing from ``j`` to ``i`` and is stored reversed.
        """
        m = len(self.edges)
        if bearings is None:
            if self.template is None:
                raise FormationError(
                    "desired bearings come from a template or are given per edge: add "
                    "[formation] template = [...] or bearings = [[x, y], ...] (one per edge)",
                    key="bearings",
                )
            t = self.template
            given = t[self.edges[:, 1]] - t[self.edges[:, 0]]
        else:
            given = np.asarray(bearings, dtype=float)
            if given.ndim != 2 or given.shape != (m, self.dim):
                raise FormationError(
                    f"bearings must be one {_bearing_rows(self.dim)} per edge ({m} edges), "
                    f"got shape {given.shape}", key="bearings",
                )  # fmt: skip
            if edges is not None:
                given = _in_edge_order(given, edges, self.edges, self.n, one_based)
        return self._rebuilt(bearings=given)

    def without_bearings(self) -> Formation:
        """The same formation defined by its distances (and orientation) alone."""
        return self if self.bearings is None else self._rebuilt(bearings=None)

    def _rebuilt(self, **change: Any) -> Formation:
        """This formation with some fields changed, validated again."""
        return dataclasses.replace(self, **change)

    def with_diameters(self, diameters: float | ArrayLike) -> Formation:
        """The same formation with other robot diameters (validated again)."""
        return self._rebuilt(diameters=_per_item(diameters, self.n, "diameters", "robot"))

    # ------------------------------------------------------------ derived data
    @property
    def n(self) -> int:
        """Number of robots."""
        return int(self.diameters.shape[0])

    @cached_property
    def adjacency(self) -> NDArray[np.bool_]:
        """``A[i, j]`` is true when ``j in N_i``; shape ``(n, n)``."""
        adj = np.zeros((self.n, self.n), bool)
        adj[self.edges[:, 0], self.edges[:, 1]] = True
        adj[self.edges[:, 1], self.edges[:, 0]] = True
        adj.setflags(write=False)
        return adj

    @cached_property
    def distance_matrix(self) -> NDArray[np.float64]:
        """``d_ij`` on edges, ``nan`` elsewhere; shape ``(n, n)``."""
        dm = np.full((self.n, self.n), np.nan)
        dm[self.edges[:, 0], self.edges[:, 1]] = self.distances
        dm[self.edges[:, 1], self.edges[:, 0]] = self.distances
        dm.setflags(write=False)
        return dm

    @cached_property
    def contact_matrix(self) -> NDArray[np.float64]:
        """``a_ij = (rho_i + rho_j) / 2`` for every pair; shape ``(n, n)`` (eq. 5)."""
        a = 0.5 * (self.diameters[:, None] + self.diameters[None, :])
        a.setflags(write=False)
        return a

    def _dense(self, what: str) -> None:
        if self.n > DENSE_LIMIT:
            raise FormationError(
                f"{what} is an (n, n, n) view, kept for formations of at most {DENSE_LIMIT} "
                f"robots (this one has {self.n}); use restricted_triples and restricted_alpha"
            )

    @cached_property
    def triples(self) -> NDArray[np.bool_]:
        """``T[i, j, k]``: ordered pair ``j != k`` of neighbours of ``i`` (the sum of eq. 13).

        A dense view for small formations; :func:`orientation.neighbour_triples` lists them.
        """
        self._dense("Formation.triples")
        t = np.zeros((self.n,) * 3, bool)
        t[tuple(neighbour_triples(self.edges, self.n).T)] = True
        t.setflags(write=False)
        return t

    @cached_property
    def restricted(self) -> NDArray[np.bool_]:
        """Triples ``(i, j, k)`` with a non-zero ``alpha_ijk``; dense view ``(n, n, n)``."""
        self._dense("Formation.restricted")
        r = np.zeros((self.n,) * 3, bool)
        r[tuple(self.restricted_triples.T)] = True
        r.setflags(write=False)
        return r

    @property
    def restricted_sign(self) -> NDArray[np.float64]:
        """Desired ``sign(c_ijk)`` of each restricted triple, ``-sign(alpha_ijk)``; ``(t,)``
        (a new read-only array at each access)."""
        s = -np.sign(self.restricted_alpha)
        s.setflags(write=False)
        return s

    @cached_property
    def desired_sign(self) -> NDArray[np.float64]:
        """Desired ``sign(c_ijk)`` on restricted triples, 0 elsewhere; dense view ``(n, n, n)``."""
        self._dense("Formation.desired_sign")
        s = np.zeros((self.n,) * 3)
        s[tuple(self.restricted_triples.T)] = self.restricted_sign
        s.setflags(write=False)
        return s

    @property
    def has_orientation(self) -> bool:
        """Whether some triple is restricted (the orientation is not free); in space,
        whether some quadruple's chirality is (:attr:`has_chirality`)."""
        return len(self.restricted_halves) > 0 or self.has_chirality

    @property
    def has_chirality(self) -> bool:
        """Whether some quadruple's chirality is restricted (a formation in space)."""
        return self.chiral_quads is not None and len(self.chiral_quads) > 0

    @cached_property
    def chiral_surfaces(self) -> tuple[NDArray[np.int64], NDArray[np.int8], NDArray[np.int64]]:
        """The distinct switching surfaces of the chirality restrictions: sorted tetrahedra
        ``(s, 4)``, their ``beta_s`` and the surface of each quadruple
        (:func:`.chirality.chirality_surfaces`)."""
        if not self.has_chirality:
            return np.zeros((0, 4), np.int64), np.zeros(0, np.int8), np.zeros(0, np.int64)
        out = chirality_surfaces(self.chiral_quads, self.chiral_signs)  # type: ignore[arg-type]
        for arr in out:
            arr.setflags(write=False)
        return out

    @property
    def chiral_sign(self) -> NDArray[np.float64]:
        """Desired ``sign(v_ijkl)`` of each restricted quadruple, ``-beta_ijkl``; ``(Q,)``."""
        if self.chiral_signs is None:
            return np.zeros(0)
        return -self.chiral_signs.astype(float)

    @property
    def restricted_halves(self) -> NDArray[np.integer]:
        """The restricted triples ``(i, j, k)`` with ``j < k``, sorted, int32 ``(h,)``: what
        the formation holds; ``(i, k, j)`` is restricted with ``alpha_ikj = -alpha_ijk``."""
        halves: NDArray[np.integer] = self.__dict__["_halves"]
        return halves

    def half_alpha(self, which: slice | NDArray[np.integer] = slice(None)) -> NDArray:
        """``alpha_ijk`` of :attr:`restricted_halves` ``[which]`` as held: int8 signs
        (sign-valued alpha) or float64. Multiplied into a float64 array the signs give the
        same numbers as their float64 values (numpy casts int8 exactly)."""
        held: NDArray = self.__dict__["_half_alpha"]
        return held[which]

    def _kept(self, name: str, build: Callable[[], Any]) -> Any:
        """What the formation derives from its halves: kept once built up to
        :data:`HELD_LIMIT` restricted triples, built at each access beyond."""
        held = self.__dict__.get(name)
        if held is None:
            held = build()
            for arr in held if isinstance(held, tuple) else (held,):
                arr.setflags(write=False)
            if not self._beyond_limit or self.__dict__.get("_holding", 0):
                self.__dict__[name] = held
        return held

    @property
    def _beyond_limit(self) -> bool:
        """Whether the formation has more than :data:`HELD_LIMIT` restricted triples."""
        return 2 * len(self.restricted_halves) > HELD_LIMIT

    @contextmanager
    def holding(self) -> Iterator[Formation]:
        """Keep what the formation derives from its halves while the block runs, whatever
        its size (the numpy driver's run: its field reads them at every step); beyond
        :data:`HELD_LIMIT` restricted triples they are dropped at the end."""
        depth = self.__dict__.get("_holding", 0)
        self.__dict__["_holding"] = depth + 1
        try:
            yield self
        finally:
            self.__dict__["_holding"] = depth
            if depth == 0 and self._beyond_limit:
                for name in _DERIVED:
                    self.__dict__.pop(name, None)

    @property
    def _ordered(self) -> tuple[NDArray[np.integer], NDArray]:
        """Both orders of every restricted triple, sorted, and their alpha as held
        (:func:`orientation.both_orders`)."""

        def build() -> tuple[NDArray[np.integer], NDArray]:
            t, a, _ = both_orders(self.restricted_halves, self.half_alpha())
            return _index(t, self.n), a

        return self._kept("_ordered_lists", build)  # type: ignore[no-any-return]

    @property
    def held_surfaces(self) -> tuple[NDArray[np.integer], NDArray, NDArray[np.integer]]:
        """:attr:`surfaces` as held: the triangles, ``beta`` (int8 signs when every one is +1
        or -1, as :meth:`half_alpha`) and the surface of each of :attr:`restricted_halves`
        (the same surfaces, numbered alike, as from both orders: a triple's mirror lies on
        its surface, after it). One build where both orders are not needed."""

        def build() -> tuple[NDArray[np.integer], NDArray, NDArray[np.integer]]:
            tris, beta, surface = switching_surfaces(self.restricted_halves, self.half_alpha())
            signs = _signs(beta)
            # surfaces are numbered below the number of triples
            return (
                _index(tris, self.n),
                beta if signs is None else signs,
                _index(surface, len(surface)),
            )

        return self._kept("_surfaces_held", build)  # type: ignore[no-any-return]

    @property
    def half_surface(self) -> NDArray[np.integer]:
        """Surface of each of :attr:`restricted_halves`, int32 ``(h,)``."""
        return self.held_surfaces[2]

    @property
    def surfaces(self) -> tuple[NDArray[np.integer], NDArray[np.float64], NDArray[np.integer]]:
        """The distinct switching surfaces ``beta_s c_abc + theta = 0`` of eq. (14).

        ``alpha_ijk c_ijk`` equals ``beta c_abc`` for the sorted triangle
        ``a < b < c`` with ``beta = alpha_ijk * parity(i, j, k)``; triples with the
        same triangle and ``beta`` switch together (``psi_ikj = psi_ijk`` always,
        and with sign-valued alpha the cyclic triples as well).

        Returns
        -------
        triangles : ndarray of int32, shape (s, 3)
            Sorted 0-based robots of each surface's triangle.
        beta : ndarray of float64, shape (s,)
            Coefficient of ``c_abc`` in the switching function. Held as int8 signs when
            every one is +1 or -1 (sign-valued alpha), then a new read-only float64 array
            of the same numbers at each access.
        surface : ndarray of int32, shape (t,)
            Surface of each restricted triple (``restricted_triples[m]``).

        Built from the halves on first access and kept (up to :data:`HELD_LIMIT`
        restricted triples; built at each access beyond).
        """
        tris, beta, _ = self.held_surfaces
        return tris, _floats(beta), self.triple_surface

    @property
    def triple_surface(self) -> NDArray[np.integer]:
        """Surface of each restricted triple, int32 ``(t,)``: ``surfaces[2]``, without making
        the float64 ``beta`` of :attr:`surfaces`."""
        return self._kept(  # type: ignore[no-any-return]
            "_triple_surface",
            lambda: self.half_surface[both_orders(self.restricted_halves, self.half_alpha())[2]],
        )

    @cached_property
    def surface_labels(self) -> list[str]:
        """1-based label of each switching surface, ``"alpha_ijk"`` of its first triple; in
        space ``"v_abcd"``, the tetrahedron whose chirality switches on it."""
        if self.dim == 3:
            return ["v_{}{}{}{}".format(*t) for t in (self.chiral_surfaces[0] + 1).tolist()]
        first = np.unique(self.half_surface, return_index=True)[1]  # (a half: before its mirror)
        firsts = (self.restricted_halves[first] + 1).tolist()  # ints: 10x faster to format
        return ["alpha_{}{}{}".format(*ijk) for ijk in firsts]

    @property
    def kappa(self) -> float:
        """The constant of eqs. (24)-(25): pi for angles, 3 for signs; in space 4, the
        robots of a tetrahedron that each hold its restriction (docs/three-d.md)."""
        if self.dim == 3:
            return 4.0
        return math.pi if self.alpha_values == "angle" else 3.0

    @cached_property
    def is_connected(self) -> bool:
        """Whether the graph is connected."""
        return edges_connected(self.edges, self.n)  # sparse: no (n, n) adjacency

    @cached_property
    def is_rigid(self) -> bool:
        """Generic infinitesimal rigidity of the graph in the formation's space
        (:func:`graph.is_rigid`)."""
        return is_rigid(self.edges, self.n, dim=self.dim)

    def check_positions(self, q: ArrayLike, *, what: str = "initial positions") -> NDArray:
        """Validate positions ``q`` of shape ``(..., n, dim)``: finite, no overlapping robots.

        Returns the positions as a float array. Raises :class:`FormationError`
        naming the first overlapping pair (1-based).
        """
        arr = np.asarray(q, dtype=float)
        if arr.ndim < 2 or arr.shape[-2:] != (self.n, self.dim):
            raise FormationError(
                f"{what} must have shape (..., {self.n}, {self.dim}), got {arr.shape}",
                key="positions",
            )
        if not np.all(np.isfinite(arr)):
            raise FormationError(f"{what} hold NaN or infinite numbers", key="positions")
        coordinates(arr, what)  # squared distances must not overflow
        if self.n <= DENSE_LIMIT:
            iu = np.triu_indices(self.n, k=1)
            pi, pj = iu
        else:  # only pairs that could touch
            pi, pj = close_pairs(arr, float(self.diameters.max())).T
        diff = arr[..., pj, :] - arr[..., pi, :]
        r = row_norms(diff)
        gap = r - 0.5 * (self.diameters[pi] + self.diameters[pj])
        if np.any(gap <= 0):
            flat = np.argwhere(gap <= 0)[0]
            p = flat[-1]
            i, j = int(pi[p]), int(pj[p])
            rr = r[tuple(flat)]
            a = 0.5 * (self.diameters[i] + self.diameters[j])
            raise FormationError(
                f"robots {i + 1} and {j + 1} overlap in the {what}: distance {rr:g} <= "
                f"a_{i + 1}{j + 1} = {a:g}; move them apart or use smaller diameters",
                key="positions",
            )
        return arr


def _given(self: Formation, name: str) -> NDArray | None:
    """The value given for ``name`` while the formation is being built."""
    return self.__dict__.get(f"_{name}")


def _get_restricted_triples(self: Formation) -> NDArray[np.integer]:
    if "_halves" in self.__dict__:  # a built formation
        return self._ordered[0]
    return _given(self, "restricted_triples")  # type: ignore[return-value]


def _get_restricted_alpha(self: Formation) -> NDArray[np.float64]:
    if "_halves" in self.__dict__:
        return _floats(self._ordered[1])
    return _given(self, "restricted_alpha")  # type: ignore[return-value]


def _setter(name: str) -> Callable[[Formation, NDArray | None], None]:
    def put(self: Formation, value: NDArray | None) -> None:
        self.__dict__[f"_{name}"] = value  # by the dataclass's __init__ only (frozen)

    return put


# ``restricted_triples`` and ``restricted_alpha`` stay fields (arguments of the
# constructor, of ``dataclasses.replace``), read through these properties: both orders of
# every triple, derived from the halves the formation holds; alpha as float64 (held as
# int8 signs when every one is +1 or -1, ``_signs``).
for _name, _get, _doc in (
    (
        "restricted_triples",
        _get_restricted_triples,
        "The restricted triples, both ``(i, j, k)`` and ``(i, k, j)``, sorted, int32 ``(t, "
        "3)``, read-only; derived from :attr:`Formation.restricted_halves`.",
    ),
    (
        "restricted_alpha",
        _get_restricted_alpha,
        "``alpha_ijk`` of the restricted triples, float64 ``(t,)``, read-only; held as "
        "int8 signs when every value is +1 or -1 (then a new array at each access).",
    ),
):
    setattr(Formation, _name, property(_get, _setter(_name), doc=_doc))


def _robot_number(x: Any) -> bool:
    """Whether ``x`` is a whole number (a robot's number as a person writes it)."""
    if isinstance(x, bool | np.bool_):
        return False
    if isinstance(x, int | np.integer):
        return True
    return isinstance(x, float | np.floating) and math.isfinite(x) and x == int(x)
