"""A law's kernel data laid out for the compiled single run: lists by robot, in int32.

:class:`RunLayout` is :class:`~formationlab.controllers.terms.KernelTerms` (the law
as arrays) rearranged for the lists layout of the engine's loop over many robots
(:mod:`.lists`):

* **edges** ``(i, j)``, ``i < j``, with ``d_ij`` and ``a_ij``: each edge's force is
  computed once per step and each robot gathers it from its row of the edge list
  (``nbr_edge``: ``e`` where it is ``i``, ``~e`` where it is ``j``; ``nbr``: the
  partner), in the order of the rows, so that every robot's sum has one fixed order
  however the loop is split between threads;
* **switching surfaces** ``(a, b, c, beta)`` of eq. (14), decided once per step. Each
  surface's ``beta`` is made positive by exchanging its corners ``b`` and ``c``
  (``c_acb = -c_abc``, exactly, so ``beta c_abc`` is the same number); when every
  surface then has the same ``beta`` (sign-valued alpha: 1) it is stored once
  (``surf_stride = 0``), otherwise once per surface;
* **restricted terms** ``(i, j, k)``, ``j < k``, of eq. (13) in rows by robot ``i``:
  ``term_j``, ``term_k`` and the surface ``term_s``, 12 bytes a term. Each term's
  weight ``2 k_a alpha_ijk`` is made positive by exchanging ``j`` and ``k`` (the
  term ``w (q_k - q_j)^perp`` is then the same number, exactly); when every term
  then has the same weight (sign-valued alpha: ``2 k_a``) it is stored once
  (``term_stride = 0``), otherwise once per term;
* **area triangles** of the signed-area penalty in rows by corner
  (``3 item + corner``).

Row pointers are int32: at most 2**31 - 1 items of a kind.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..controllers.terms import KernelTerms
from ..errors import ParameterError

__all__ = ["PAIRS_UP_TO", "REORDER_FROM", "RunLayout", "robot_order", "run_layout", "space_order"]

_I32 = np.int32
_LIMIT = 2**31 - 1

#: A single run of at most this many robots takes the pairs layout of batches (every pair,
#: :class:`~formationlab.controllers.terms.KernelTerms`), larger ones the lists layout of
#: this module: measured with ``benchmarks/bench_layouts.py`` (a triangular lattice under
#: the distance law), the pairs layout is the faster below about 30 robots (9x for the
#: paper's triangle) and the lists layout above; and the loop a single run of a small
#: formation compiles is then the one of batches.
PAIRS_UP_TO = 32

#: From this many robots the run numbers them by :func:`robot_order` (below, the lists fit
#: the caches in any order).
REORDER_FROM = 4096


class RunLayout(NamedTuple):
    """Arrays and numbers of one formation under one law for the compiled run (module doc)."""

    kind: int  #: LOG_BARRIER, SQUARED or BEARING
    edge_gain: float
    repulsion_gain: float  #: k_r of Khatib's repulsion
    eta: float  #: Khatib's eta
    influence: float  #: s0
    skin: float  #: the close list's margin (module ``compiled``)
    theta: float
    area_gain: float
    radius: NDArray[np.float64]  #: (n,) rho_i / 2
    edge_i: NDArray[np.int32]  #: (m,)
    edge_j: NDArray[np.int32]
    edge_d: NDArray[np.float64]  #: d_ij
    edge_a: NDArray[np.float64]  #: a_ij
    edge_bx: NDArray[np.float64]  #: (m,) g*_ij of the bearing term, or (1,) unused
    edge_by: NDArray[np.float64]
    edge_b_stride: int  #: 1 with bearings, 0 without
    nbr_ptr: NDArray[np.int32]  #: (n + 1,)
    nbr: NDArray[np.int32]  #: (2 m,) partner
    nbr_edge: NDArray[np.int32]  #: (2 m,) e or ~e
    surf_a: NDArray[np.int32]  #: (s,)
    surf_b: NDArray[np.int32]
    surf_c: NDArray[np.int32]
    surf_beta: NDArray[np.float64]  #: (s,) or (1,) when surf_stride is 0; positive
    surf_stride: int
    term_ptr: NDArray[np.int32]  #: (n + 1,)
    term_j: NDArray[np.int32]  #: (t,)
    term_k: NDArray[np.int32]
    term_s: NDArray[np.int32]
    term_w: NDArray[np.float64]  #: (t,) or (1,) when term_stride is 0
    term_stride: int
    area_a: NDArray[np.int32]  #: (r,)
    area_b: NDArray[np.int32]
    area_c: NDArray[np.int32]
    area_target: NDArray[np.float64]
    area_ptr: NDArray[np.int32]  #: (n + 1,)
    area_rows: NDArray[np.int32]  #: (3 r,) 3 item + corner
    perm: NDArray[np.int32]  #: (n,) the robot each number of the run is, or (0,): the same

    @property
    def nbytes(self) -> int:
        """Bytes held by the arrays."""
        return sum(v.nbytes for v in self if isinstance(v, np.ndarray))


def _rows(owner: NDArray[np.integer], n: int) -> tuple[NDArray[np.int32], NDArray[np.int32]]:
    """Row pointers ``(n + 1,)`` and the stable order that groups items by ``owner``."""
    if owner.size > _LIMIT:
        raise ParameterError(f"{owner.size} list items exceed the compiled run's int32 rows")
    ptr = np.zeros(n + 1, _I32)
    order = np.empty(owner.size, _I32)
    _group(owner, ptr, order)
    return ptr, order


@njit(cache=True)
def _group(owner, ptr, order):
    """Counting sort: ``ptr`` the rows' starts, ``order`` the items row by row, in order."""
    n = ptr.size - 1
    for k in range(owner.size):
        ptr[owner[k] + 1] += 1
    for i in range(n):
        ptr[i + 1] += ptr[i]
    fill = ptr[:n].copy()
    for k in range(owner.size):
        order[fill[owner[k]]] = k
        fill[owner[k]] += 1


def _i32(a: NDArray[np.integer]) -> NDArray[np.int32]:
    return np.ascontiguousarray(a, dtype=_I32)


def robot_order(
    edge_i: NDArray[np.integer],
    edge_j: NDArray[np.integer],
    n: int,
    positions: NDArray[np.floating] | None = None,
) -> NDArray[np.int32]:
    """An order of the robots in which neighbours have near numbers, new to old, int32
    ``(n,)``.

    In the plane (and without ``positions``): reverse Cuthill-McKee on the graph
    (``scipy.sparse.csgraph``). In space, given the robots' places ``positions`` ``(n, 3)``
    (the template): along the Morton (Z-order) curve of cubes about one edge long
    (:func:`space_order`). Reverse Cuthill-McKee numbers a 3-D patch in wavefronts, so that a
    robot's neighbours in the previous front are some ``n^(2/3)`` numbers back (about 3,800
    in a 100,000-robot fcc patch, beyond the second-level cache for the forces they read);
    along the curve half of them are within a few numbers and nine in ten within a few
    hundred.
    """
    if positions is not None and positions.shape[-1] == 3:
        return space_order(positions, edge_i, edge_j)
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    ones = np.ones(edge_i.size, dtype=np.int8)
    graph = csr_matrix((ones, (edge_i, edge_j)), shape=(n, n))
    return _i32(reverse_cuthill_mckee(graph + graph.T, symmetric_mode=True))


#: bits of each axis in a Morton key (three of them fill 63 bits)
_MORTON_BITS = 21


def _spread(v: NDArray[np.uint64]) -> NDArray[np.uint64]:
    """The 21 low bits of ``v`` moved to every third bit (bit ``b`` to bit ``3 b``)."""
    v = v & np.uint64(0x1FFFFF)
    for shift, mask in (
        (32, 0x1F00000000FFFF),
        (16, 0x1F0000FF0000FF),
        (8, 0x100F00F00F00F00F),
        (4, 0x10C30C30C30C30C3),
        (2, 0x1249249249249249),
    ):
        v = (v | (v << np.uint64(shift))) & np.uint64(mask)
    return v


def space_order(
    positions: NDArray[np.floating], edge_i: NDArray[np.integer], edge_j: NDArray[np.integer]
) -> NDArray[np.int32]:
    """The robots at ``positions`` ``(n, 3)`` along the Morton curve of cubes whose side is
    the median length of the edges ``(edge_i, edge_j)`` (at least ``2^-21`` of the extent),
    new to old, int32 ``(n,)``; robots in one cube keep their order."""
    p = np.asarray(positions, dtype=float)
    low = p.min(axis=0) if p.size else np.zeros(3)
    extent = float(np.max(p.max(axis=0) - low)) if p.size else 0.0
    side = float(np.median(np.linalg.norm(p[edge_j] - p[edge_i], axis=1))) if edge_i.size else 0
    side = max(side, extent / (2**_MORTON_BITS - 1))
    if not (np.isfinite(side) and side > 0.0):
        return np.arange(p.shape[0], dtype=_I32)
    cells = np.floor((p - low) / side).astype(np.uint64)
    x, y, z = (_spread(cells[:, a]) for a in range(3))
    key = (x << np.uint64(2)) | (y << np.uint64(1)) | z
    return _i32(np.argsort(key, kind="stable"))


def run_layout(
    terms: KernelTerms | dict[str, Any], *, reorder: bool | NDArray[np.int32] | None = None
) -> RunLayout:
    """The compiled run's layout of ``terms`` (module docstring); the same sums as
    the terms, robot by robot, in the order of the kernel before (edges as robot
    ``i`` then robot ``j``, terms as listed by surface).

    ``terms`` may be given as the dict of :meth:`KernelTerms._asdict`, which is then
    emptied as it is read: each array is let go once laid out, so that the law's
    int64 arrays and their int32 layout are not held in full at the same time.

    ``reorder`` (default: from :data:`REORDER_FROM` robots; or the order itself, new to
    old) numbers the robots inside the run by :func:`robot_order`, so that a robot's
    neighbours, its edges and its terms lie near it in memory (a 100,000-robot lattice
    numbered at random took twice the CPU time per step without it). Every edge keeps
    its ends and every surface its corners, and each robot its rows in their order, so
    the field is the same, bit for bit, but for the order of a robot's close pairs (by
    partner number). Edges, surfaces and area triangles are stored by their least robot.
    """
    t = dict(terms._asdict()) if isinstance(terms, KernelTerms) else terms
    radius = np.ascontiguousarray(t.pop("radius"), dtype=float)
    n = radius.shape[0]
    ei, ej = _i32(t.pop("edge_i")), _i32(t.pop("edge_j"))
    m = ei.size
    if reorder is None:
        reorder = n >= REORDER_FROM
    if isinstance(reorder, np.ndarray) or reorder:
        perm = _i32(reorder) if isinstance(reorder, np.ndarray) else robot_order(ei, ej, n)
        new = np.empty(n, _I32)  # old number -> new number
        new[perm] = np.arange(n, dtype=_I32)
        radius = radius[perm]
        ei, ej = new[ei], new[ej]
    else:
        perm = np.zeros(0, _I32)
        new = None

    def relabel(a: NDArray[np.integer]) -> NDArray[np.int32]:
        return _i32(a) if new is None else new[a]

    # the restricted terms first: the largest arrays, let go soonest
    term_ptr, torder = _rows(relabel(t.pop("term_i")), n)
    # (each int64 array is made int32 before it is gathered)
    term_s = _i32(t.pop("term_surface"))[torder]  # renumbered with the surfaces below
    term_j = relabel(_i32(t.pop("term_j"))[torder])
    term_k = relabel(_i32(t.pop("term_k"))[torder])
    w = t.pop("term_weight")[torder]
    del torder
    flip = np.flatnonzero(w < 0)
    term_j[flip], term_k[flip] = term_k[flip], term_j[flip]
    np.abs(w, out=w)
    del flip
    uniform = w.size > 0 and bool(np.all(w == w[0]))
    term_w = w[:1].copy() if uniform else w
    del w
    # surfaces stored by their least robot (new numbers), each keeping its corners' roles
    surf = [relabel(t.pop(f"surface_{c}")) for c in "abc"]
    s_order = np.argsort(np.minimum(np.minimum(surf[0], surf[1]), surf[2]), kind="stable")
    s_pos = np.empty(s_order.size, _I32)
    s_pos[s_order] = np.arange(s_order.size, dtype=_I32)
    surf = [c[s_order] for c in surf]
    beta = np.ascontiguousarray(t.pop("surface_beta")[s_order], dtype=float)
    del s_order
    flip = np.flatnonzero(beta < 0)  # beta c_abc = |beta| c_acb, exactly
    surf[1][flip], surf[2][flip] = surf[2][flip], surf[1][flip]
    np.abs(beta, out=beta)
    del flip
    same = beta.size > 0 and bool(np.all(beta == beta[0]))
    surf_beta = beta[:1].copy() if same else beta
    del beta
    term_s = s_pos[term_s]
    del s_pos
    # edges stored by their least robot (new numbers), each keeping its ends' roles; each
    # robot's row as before
    e_order = np.argsort(np.minimum(ei, ej), kind="stable")
    e_pos = np.empty(m, _I32)
    e_pos[e_order] = np.arange(m, dtype=_I32)
    nbr_ptr, order = _rows(np.concatenate([ei, ej]), n)
    nbr = _i32(np.concatenate([ej, ei])[order])
    nbr_edge = _i32(np.concatenate([e_pos, ~e_pos])[order])
    del order
    ei, ej = ei[e_order], ej[e_order]
    edge_d = np.ascontiguousarray(t.pop("edge_distance")[e_order], dtype=float)
    edge_a = np.ascontiguousarray(t.pop("edge_contact")[e_order], dtype=float)
    bearing = t.pop("edge_bearing")  # each edge keeps its ends' roles, so its bearing
    t.pop("pair_bearing")
    b_stride = int(t.pop("bearing_stride"))
    if b_stride:
        bearing = bearing[e_order]
    edge_bx, edge_by = (np.ascontiguousarray(bearing[:, c], dtype=float) for c in (0, 1))
    del e_order, e_pos
    # area triangles stored by their least robot, in rows by corner: 3 item + corner
    area = [relabel(t.pop(f"area_{c}")) for c in "abc"]
    a_order = np.argsort(np.minimum(np.minimum(area[0], area[1]), area[2]), kind="stable")
    a_pos = np.empty(a_order.size, np.int64)
    a_pos[a_order] = np.arange(a_order.size)
    r = area[0].size
    area_ptr, aorder = _rows(np.concatenate(area), n)
    corner = np.arange(3 * r, dtype=np.int64)  # corner c of item k
    area_rows = _i32((3 * a_pos[corner % r] + corner // r)[aorder])
    area = [c[a_order] for c in area]
    area_target = np.ascontiguousarray(t.pop("area_target")[a_order], dtype=float)
    s0 = float(t["repulsion_influence"])
    a_max = 2.0 * float(radius.max()) if n else 0.0
    return RunLayout(
        kind=int(t["kind"]),
        edge_gain=float(t["edge_gain"]),
        repulsion_gain=float(t["repulsion_gain"]),
        eta=float(t["repulsion_eta"]),
        influence=s0,
        skin=0.5 * (s0 + a_max),
        theta=float(t["theta"]),
        area_gain=float(t["area_gain"]),
        radius=radius,
        edge_i=ei,
        edge_j=ej,
        edge_d=edge_d,
        edge_a=edge_a,
        edge_bx=edge_bx,
        edge_by=edge_by,
        edge_b_stride=b_stride,
        nbr_ptr=nbr_ptr,
        nbr=nbr,
        nbr_edge=nbr_edge,
        surf_a=surf[0],
        surf_b=surf[1],
        surf_c=surf[2],
        surf_beta=surf_beta if surf_beta.size else np.zeros(1),
        surf_stride=0 if same or surf_beta.size == 0 else 1,
        term_ptr=term_ptr,
        term_j=term_j,
        term_k=term_k,
        term_s=term_s,
        term_w=term_w if term_w.size else np.zeros(1),
        term_stride=0 if uniform or term_w.size == 0 else 1,
        area_a=area[0],
        area_b=area[1],
        area_c=area[2],
        area_target=area_target,
        area_ptr=area_ptr,
        area_rows=area_rows,
        perm=perm,
    )
