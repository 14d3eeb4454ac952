"""A law as plain arrays: the data the compiled kernels step, built by each law.

:meth:`Law.kernel_terms` returns a :class:`KernelTerms`, a named tuple of
arrays and numbers that the compiled loop (:mod:`formationlab.engine.loop`, through
:func:`formationlab.controllers.stage.law_field`) evaluates for every law it supports:

* **pairs** ``i < j`` (every pair): on an edge the edge potential (the paper's
  ``phi_ij`` of eqs. 5, 7 for ``kind = LOG_BARRIER``, or Krick et al.'s
  ``1/4 (r^2 - d^2)^2`` for ``kind = SQUARED``), elsewhere Khatib's repulsion;
* **switching surfaces** ``sigma_s = beta_s c_abc + theta`` of eq. (14)
  (``Formation.surfaces``), each with the terms ``(i, j, k)``, ``j < k``, whose
  restriction it switches and their weight ``2 k_a alpha_ijk``
  (``psi_ikj = psi_ijk``: the ordered pairs ``(j, k)`` and ``(k, j)`` of eq. 13
  contribute alike). The kernel decides each surface with the arithmetic of
  :func:`formationlab.controllers.potentials.triangle_products`, so that it switches
  exactly where the numpy law does;
* **area triangles** ``(a, b, c, A*)`` of the signed-area penalty;
* **desired bearings** of the edges (and of the pairs that are edges) for the bearing-only
  term (``kind = BEARING``): ``(m, 2)`` and ``(P, 2)`` with ``bearing_stride = 1``; one
  unused row each, ``bearing_stride = 0``, for the other kinds.

A law whose terms are not of these kinds does not override
:meth:`Law.kernel_terms` and runs on the numpy path.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..formation.spec import Formation
from .kinds.edges import BEARING, LOG_BARRIER, SQUARED

__all__ = ["BEARING", "LOG_BARRIER", "PAIR_LIMIT", "SQUARED", "KernelTerms", "build_terms"]

#: Largest formation for which the batch kernel's all-pairs arrays are built
#: (``n (n - 1) / 2`` pairs); larger ones run only through the neighbour-search kernel.
PAIR_LIMIT = 2000


class KernelTerms(NamedTuple):
    """The arrays and numbers a compiled kernel evaluates ``u = f(q)`` from.

    Pair arrays have length ``n (n - 1) / 2``; surface arrays length ``s``; term
    arrays length ``m`` (terms of surface ``s`` are ``term_start[s]:term_start[s + 1]``);
    area arrays length ``t``. Index arrays are int64, the kernels' signature; built with
    ``pairs=False`` (for the compiled single run, which lays them out as int32 and needs
    no pair arrays) the robots of edges, surfaces and terms keep the formation's int32,
    half the bytes at the run's peak of memory.
    """

    kind: int  #: LOG_BARRIER, SQUARED or BEARING
    pair_i: NDArray[np.int64]
    pair_j: NDArray[np.int64]
    pair_is_edge: NDArray[np.bool_]
    pair_distance: NDArray[np.float64]  #: d_ij on edges, 0 elsewhere
    pair_contact: NDArray[np.float64]  #: a_ij
    edge_gain: float  #: k_c (log barrier) or k (squared distance)
    repulsion_gain: float  #: gain of Khatib's repulsion between non-neighbours
    repulsion_eta: float
    repulsion_influence: float  #: s0
    surface_a: NDArray[np.int64]
    surface_b: NDArray[np.int64]
    surface_c: NDArray[np.int64]
    surface_beta: NDArray[np.float64]
    theta: float
    term_start: NDArray[np.int64]  #: length s + 1
    term_i: NDArray[np.int64]
    term_j: NDArray[np.int64]
    term_k: NDArray[np.int64]
    term_weight: NDArray[np.float64]  #: 2 k_a alpha_ijk
    area_a: NDArray[np.int64]
    area_b: NDArray[np.int64]
    area_c: NDArray[np.int64]
    area_target: NDArray[np.float64]
    area_gain: float  #: k k_s
    edge_i: NDArray[np.int64]  #: the edges i < j (every size; the pair arrays are for small n)
    edge_j: NDArray[np.int64]
    edge_distance: NDArray[np.float64]
    edge_contact: NDArray[np.float64]
    radius: NDArray[np.float64]  #: rho_i / 2, so that a_ij = radius_i + radius_j
    term_surface: NDArray[np.int64]  #: the surface of each term
    edge_bearing: NDArray[np.float64]  #: (m, 2) g*_ij of the edges, or (1, 2) unused
    pair_bearing: NDArray[np.float64]  #: (P, 2) g*_ij of the pairs (0 off edges), or (1, 2)
    bearing_stride: int  #: 1 with bearings, 0 without (row e of edge_bearing is e * stride)

    def writable(self) -> KernelTerms:
        """These terms with every array a writable C-contiguous copy.

        Numba types read-only arrays (a formation's are frozen) apart from writable
        ones: with every law's arrays writable, one compiled kernel serves them all.
        """
        arrays = {k: np.array(v, order="C") for k, v in self._asdict().items()
                  if isinstance(v, np.ndarray)}  # fmt: skip
        return self._replace(**arrays)  # type: ignore[arg-type]


def build_terms(
    formation: Formation,
    *,
    kind: int,
    edge_gain: float,
    repulsion_gain: float,
    eta: float,
    influence: float,
    k_a: float = 0.0,
    theta: float = 0.0,
    areas: tuple[NDArray[np.int64], NDArray[np.float64]] | None = None,
    area_gain: float = 0.0,
    pairs: bool = True,
) -> KernelTerms:
    """Assemble :class:`KernelTerms`; the angular terms when ``k_a > 0`` and alpha is set;
    the all-pairs arrays up to ``PAIR_LIMIT`` robots when ``pairs``, and the robots' indices
    as int64 (else in the formation's index type)."""
    n = formation.n
    index = np.int64 if pairs else formation.edges.dtype  # the robots' numbers
    if n <= PAIR_LIMIT and pairs:
        pi, pj = (np.ascontiguousarray(x, dtype=np.int64) for x in np.triu_indices(n, k=1))
        is_edge = formation.adjacency[pi, pj].copy()
        dist = np.where(is_edge, np.nan_to_num(formation.distance_matrix[pi, pj]), 0.0)
        contact = formation.contact_matrix[pi, pj].copy()
    else:  # the batch kernel's all-pairs arrays: not for large formations, or not asked
        pi = pj = np.zeros(0, np.int64)
        is_edge, dist, contact = np.zeros(0, bool), np.zeros(0), np.zeros(0)
    e = formation.edges
    oriented = formation.has_orientation and k_a > 0
    if oriented:  # (i, k, j) is the same term as (i, j, k): the halves j < k the formation holds
        tris, held_beta, surface = formation.held_surfaces
        beta = held_beta.astype(np.float64)
        terms = formation.restricted_halves
    else:
        tris, beta = np.zeros((0, 3), np.int64), np.zeros(0)
        terms, surface = np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    # grouped by surface (one gather of each column, so that no copy of the (h, 3) triples
    # is made; alpha as float64 for the halves taken)
    idx = np.argsort(surface, kind="stable")
    surface = surface[idx]
    alpha = formation.half_alpha(idx).astype(np.float64) if oriented else np.zeros(0)
    i, j, k = (np.asarray(terms[idx, m], dtype=index) for m in range(3))
    del idx
    alpha *= 2.0 * float(k_a)  # the weights 2 k_a alpha_ijk, in place
    start = np.searchsorted(surface, np.arange(len(tris) + 1, dtype=surface.dtype))
    start = start.astype(np.int64, copy=False)
    corners = [np.ascontiguousarray(tris[:, c], dtype=index) for c in range(3)]
    del tris  # (the formation's, or built for this call: let go before the rest is made)
    area_tris, target = areas if areas is not None else (np.zeros((0, 3), np.int64), np.zeros(0))
    if kind == BEARING:  # the formation's desired bearings, per edge and per pair
        edge_bearing = np.array(formation.bearings, dtype=float)  # (m, 2), i -> j
        pair_bearing = np.zeros((len(pi), 2))
        if len(pi):  # pair (i, j), i < j, is row i n - i (i + 1) / 2 + j - i - 1 (triu order)
            a, b = e[:, 0].astype(np.int64), e[:, 1].astype(np.int64)
            pair_bearing[a * n - a * (a + 1) // 2 + b - a - 1] = edge_bearing
        stride = 1
    else:
        edge_bearing, pair_bearing, stride = np.zeros((1, 2)), np.zeros((1, 2)), 0
    return KernelTerms(
        kind=int(kind),
        pair_i=pi,
        pair_j=pj,
        pair_is_edge=is_edge,
        pair_distance=dist,
        pair_contact=contact,
        edge_gain=float(edge_gain),
        repulsion_gain=float(repulsion_gain),
        repulsion_eta=float(eta),
        repulsion_influence=float(influence),
        surface_a=corners[0],
        surface_b=corners[1],
        surface_c=corners[2],
        surface_beta=beta,  # (a new float64 array)
        theta=float(theta),
        term_start=start,
        term_i=i,
        term_j=j,
        term_k=k,
        term_weight=alpha,
        area_a=np.ascontiguousarray(area_tris[:, 0], dtype=np.int64),
        area_b=np.ascontiguousarray(area_tris[:, 1], dtype=np.int64),
        area_c=np.ascontiguousarray(area_tris[:, 2], dtype=np.int64),
        area_target=np.array(target, dtype=float),
        area_gain=float(area_gain),
        edge_i=np.ascontiguousarray(e[:, 0], dtype=index),
        edge_j=np.ascontiguousarray(e[:, 1], dtype=index),
        edge_distance=np.array(formation.distances, dtype=float),
        edge_contact=0.5 * (formation.diameters[e[:, 0]] + formation.diameters[e[:, 1]]),
        radius=0.5 * np.array(formation.diameters, dtype=float),
        term_surface=np.ascontiguousarray(surface, dtype=np.int64 if pairs else surface.dtype),
        edge_bearing=edge_bearing,
        pair_bearing=pair_bearing,
        bearing_stride=stride,
    )
