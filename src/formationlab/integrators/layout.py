"""A law's kernel data laid out for the compiled single run: lists by robot, in int32.

:class:`RunLayout` is :class:`~formationlab.controllers.terms.KernelTerms` (the law
as arrays) rearranged for a time loop over many robots (``integrators/compiled.py``):

* **edges** ``(i, j)``, ``i < j``, with ``d_ij`` and ``a_ij``: each edge's force is
  computed once per step and each robot gathers it from its row of the edge list
  (``nbr_edge``: ``e`` where it is ``i``, ``~e`` where it is ``j``; ``nbr``: the
  partner), in the order of the rows, so that every robot's sum has one fixed order
  however the loop is split between threads;
* **switching surfaces** ``(a, b, c, beta)`` of eq. (14), decided once per step;
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

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..controllers.terms import KernelTerms
from ..errors import ParameterError

__all__ = ["RunLayout", "run_layout"]

_I32 = np.int32
_LIMIT = 2**31 - 1


class RunLayout(NamedTuple):
    """Arrays and numbers of one formation under one law for the compiled run (module doc)."""

    kind: int  #: LOG_BARRIER or SQUARED
    edge_gain: float
    repulsion: float  #: -k_r eta / s0: Khatib's k_r gamma'(s) = repulsion (s0 - s) / s^3
    influence: float  #: s0
    skin: float  #: the close list's margin (module ``compiled``)
    theta: float
    area_gain: float
    radius: NDArray[np.float64]  #: (n,) rho_i / 2
    edge_i: NDArray[np.int32]  #: (m,)
    edge_j: NDArray[np.int32]
    edge_d: NDArray[np.float64]  #: d_ij
    edge_a: NDArray[np.float64]  #: a_ij
    nbr_ptr: NDArray[np.int32]  #: (n + 1,)
    nbr: NDArray[np.int32]  #: (2 m,) partner
    nbr_edge: NDArray[np.int32]  #: (2 m,) e or ~e
    surf_a: NDArray[np.int32]  #: (s,)
    surf_b: NDArray[np.int32]
    surf_c: NDArray[np.int32]
    surf_beta: NDArray[np.float64]
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

    @property
    def nbytes(self) -> int:
        """Bytes held by the arrays."""
        return sum(v.nbytes for v in self if isinstance(v, np.ndarray))


def _rows(owner: NDArray[np.integer], n: int) -> tuple[NDArray[np.int32], NDArray[np.int64]]:
    """Row pointers ``(n + 1,)`` and the stable order that groups items by ``owner``."""
    if owner.size > _LIMIT:
        raise ParameterError(f"{owner.size} list items exceed the compiled run's int32 rows")
    order = np.argsort(owner, kind="stable")
    ptr = np.zeros(n + 1, _I32)
    np.cumsum(np.bincount(owner, minlength=n), out=ptr[1:])
    return ptr, order


def _i32(a: NDArray[np.integer]) -> NDArray[np.int32]:
    return np.ascontiguousarray(a, dtype=_I32)


def run_layout(terms: KernelTerms) -> RunLayout:
    """The compiled run's layout of ``terms`` (module docstring); the same sums as
    the terms, robot by robot, in the order of :func:`run_compiled` before (edges as
    robot ``i`` then robot ``j``, terms as listed by surface)."""
    n = terms.radius.shape[0]
    ei, ej = terms.edge_i, terms.edge_j
    m = ei.size
    nbr_ptr, order = _rows(np.concatenate([ei, ej]), n)
    nbr = _i32(np.concatenate([ej, ei])[order])
    signed = np.concatenate([np.arange(m, dtype=_I32), ~np.arange(m, dtype=_I32)])
    nbr_edge = _i32(signed[order])
    del order, signed
    term_ptr, torder = _rows(terms.term_i, n)
    w = terms.term_weight[torder]
    flip = w < 0
    tj, tk = terms.term_j[torder], terms.term_k[torder]
    term_j = _i32(np.where(flip, tk, tj))
    term_k = _i32(np.where(flip, tj, tk))
    del tj, tk
    term_s = _i32(terms.term_surface[torder])
    w = np.abs(w)
    uniform = w.size > 0 and bool(np.all(w == w[0]))
    term_w = w[:1].copy() if uniform else np.ascontiguousarray(w)
    del w, torder, flip
    r = terms.area_a.size
    area_ptr, aorder = _rows(np.concatenate([terms.area_a, terms.area_b, terms.area_c]), n)
    corner = np.arange(3 * r, dtype=np.int64)  # corner c of item k is 3 k + c
    area_rows = _i32((3 * (corner % r) + corner // r)[aorder])
    s0 = float(terms.repulsion_influence)
    a_max = 2.0 * float(terms.radius.max()) if n else 0.0
    return RunLayout(
        kind=int(terms.kind),
        edge_gain=float(terms.edge_gain),
        repulsion=-float(terms.repulsion_gain) * float(terms.repulsion_eta) / s0,
        influence=s0,
        skin=0.5 * (s0 + a_max),
        theta=float(terms.theta),
        area_gain=float(terms.area_gain),
        radius=np.ascontiguousarray(terms.radius, dtype=float),
        edge_i=_i32(ei),
        edge_j=_i32(ej),
        edge_d=np.ascontiguousarray(terms.edge_distance, dtype=float),
        edge_a=np.ascontiguousarray(terms.edge_contact, dtype=float),
        nbr_ptr=nbr_ptr,
        nbr=nbr,
        nbr_edge=nbr_edge,
        surf_a=_i32(terms.surface_a),
        surf_b=_i32(terms.surface_b),
        surf_c=_i32(terms.surface_c),
        surf_beta=np.ascontiguousarray(terms.surface_beta, dtype=float),
        term_ptr=term_ptr,
        term_j=term_j,
        term_k=term_k,
        term_s=term_s,
        term_w=term_w if term_w.size else np.zeros(1),
        term_stride=0 if uniform or term_w.size == 0 else 1,
        area_a=_i32(terms.area_a),
        area_b=_i32(terms.area_b),
        area_c=_i32(terms.area_c),
        area_target=np.ascontiguousarray(terms.area_target, dtype=float),
        area_ptr=area_ptr,
        area_rows=area_rows,
    )
