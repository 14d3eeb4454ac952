"""Every robot's command from its own measurements: the laws as per-robot controllers.

The paper's laws "depend on local information and are suitable for application in
decentralized algorithms": robot ``i``'s control ``u_i`` involves only the relative
positions ``z_ij = p_j - p_i`` of the robots it is coupled to, its neighbours (the
edge terms of eq. 8 and the triples of eq. 13) and the robots within Khatib's
clearance ``s0`` (eq. 12). :func:`local_controls` evaluates each robot's control from
*its own* measurements ``z[..., i, j]``, so that robots may measure in their own
frames, with their own errors, and hold different ideas of a desired distance:

* an edge ``(i, j)`` gives robot ``i`` ``g(|z_ij|) z_ij`` with its own ``d_ij`` and
  robot ``j`` ``g(|z_ji|) z_ji`` with its own ``d_ji`` (``g = k_c phi'(r) / r``, eq. 8;
  ``g = k (r^2 - d^2)`` for Krick et al.'s squared distances);
* a non-neighbour pair gives each robot Khatib's repulsion from its own measurement;
* a restricted triple ``(i, j, k)`` of eqs. (13), (14), (23) gives robot ``i``
  ``-w Upsilon(sigma) k x (z_ik - z_ij)``, with the switching function ``sigma`` of
  its surface computed from robot ``i``'s own measurements of the triangle (robot
  ``i`` is a vertex, so it knows the triangle up to translation);
* a signed-area triangle gives each vertex the penalty's gradient from that vertex's
  measurements.

The law enters as its :class:`~formationlab.controllers.terms.KernelTerms` (the data
each law already gives the compiled kernels), so a law gets its local form with no
second implementation of its own. All of ``u`` is in each robot's frame: rotations
commute with ``k x`` and leave lengths and triple products unchanged, so with exact
measurements the result rotated back equals the centralized law (to rounding: tested
to ``1e-12`` for every law). A reflection does not commute with ``k x``: the
angle-restricted law needs a common sense of rotation, not a common frame.

In space (``d = 3``) a robot's frame is a rotation ``R_i`` of SO(3): it measures
``z_ij = R_i^T (p_j - p_i)`` and its command ``u_i`` is ``R_i`` times the one it computes.
The laws of distances run there (:attr:`~formationlab.controllers.Law.sensed_dims`): an
edge's term is ``g(|z_ij|) z_ij``, along the measured relative position, and a pair's
Khatib repulsion likewise, so each commutes with every rotation.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..controllers.kinds.edges import edge_force, edge_force_at
from ..controllers.kinds.khatib import repulsion_gain
from ..controllers.kinds.restriction import (
    restriction_force,
    switched_on,
    switching,
    triangle_product,
)
from ..controllers.kinds.signed_area import area_force, area_gain, signed_area
from ..controllers.terms import KernelTerms
from ..formation.geometry import scatter_rows

__all__ = ["from_frames", "local_controls", "measured", "rotate", "to_frames", "uniform_rotations"]


def rotate(v: NDArray[np.float64], angle: NDArray[np.float64]) -> NDArray[np.float64]:
    """``R(angle) v`` for vectors ``(..., 2)`` and angles broadcasting against ``(...)``."""
    c, s = np.cos(angle), np.sin(angle)
    x, y = v[..., 0], v[..., 1]
    return np.stack([c * x - s * y, s * x + c * y], axis=-1)


def uniform_rotations(rng: np.random.Generator, n: int) -> NDArray[np.float64]:
    """``n`` rotation matrices ``(n, 3, 3)`` drawn uniformly (Haar measure) on SO(3).

    The unit quaternion of a Gaussian vector of four coordinates is uniform on the sphere
    ``S^3``, which covers SO(3) twice with the Haar measure (K. Shoemake, "Uniform random
    rotations", Graphics Gems III, 1992); scipy's ``Rotation.from_quat`` normalises it and
    gives its matrix. Four standard normals per robot, drawn from ``rng``.
    """
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(rng.standard_normal((n, 4))).as_matrix()


def measured(p: NDArray[np.float64], frame: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """``z[..., i, j] = R_i^T (p_j - p_i)``, each robot's view; ``(..., n, n, d)``.

    ``frame`` is each robot's frame ``R_i``: angles ``(..., n)`` in the plane (``R_i =
    R(angle_i)``), rotation matrices ``(..., n, 3, 3)`` in space; None: the common frame.
    """
    z = p[..., None, :, :] - p[..., :, None, :]
    if frame is None:
        return z
    if p.shape[-1] == 2:
        return rotate(z, -np.asarray(frame)[..., :, None])
    return np.einsum("...iba,...ijb->...ija", frame, z)  # R_i^T z_ij


def from_frames(u: NDArray[np.float64], frame: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """``R_i u_i``: every robot's vector ``(..., n, d)`` from its own frame to the common one
    (``frame`` as in :func:`measured`)."""
    if frame is None:
        return u
    if u.shape[-1] == 2:
        return rotate(u, frame)
    return np.einsum("...iab,...ib->...ia", frame, u)


def to_frames(v: NDArray[np.float64], frame: NDArray[np.float64] | None) -> NDArray[np.float64]:
    """``R_i^T v_i``: every robot's vector ``(..., n, d)`` from the common frame to its own
    (the inverse of :func:`from_frames`; ``frame`` as in :func:`measured`)."""
    if frame is None:
        return v
    if v.shape[-1] == 2:
        return rotate(v, -np.asarray(frame))
    return np.einsum("...iba,...ib->...ia", frame, v)


def _gather(z: NDArray, obs: NDArray, tgt: NDArray) -> NDArray:
    return z[..., obs, tgt, :]


def _xy(v: NDArray) -> tuple[NDArray, NDArray]:
    return v[..., 0], v[..., 1]


def _seen(seen: NDArray | None, obs: NDArray, tgt: NDArray) -> NDArray | bool:
    return True if seen is None else seen[..., obs, tgt]


def local_controls(
    terms: KernelTerms,
    z: NDArray[np.float64],
    *,
    seen: NDArray[np.bool_] | None = None,
    own_distance: NDArray[np.float64] | None = None,
) -> NDArray[np.float64]:
    """Every robot's control from its own measurements, in its own frame (module docstring).

    Parameters
    ----------
    terms : KernelTerms
        The law's terms (``law.compiled_terms(formation)``), with pair arrays (at most
        ``PAIR_LIMIT`` robots).
    z : ndarray, shape (..., n, n, d)
        ``z[..., i, j]``: robot ``i``'s measurement of ``p_j - p_i`` in its frame; in space
        (``d = 3``) the terms are the edges' and the pairs' only
        (:meth:`~formationlab.controllers.Law.sensed_terms`).
    seen : ndarray of bool, shape (..., n, n), optional
        Whether robot ``i`` has a measurement of ``j``; terms that need an unseen robot
        are left out of the robot's control. Default: everyone sees everyone.
    own_distance : ndarray, shape (..., E, 2), optional
        The desired distance of edge ``e`` as its robots ``edge_i[e]`` and ``edge_j[e]``
        hold it; default ``terms.edge_distance`` for both.

    Returns
    -------
    ndarray, shape (..., n, d)
        ``u_i`` in robot ``i``'s frame.
    """
    z = np.asarray(z, dtype=float)
    n, dim = z.shape[-2], z.shape[-1]
    t = terms
    rows: list[NDArray] = []
    vals: list[NDArray] = []

    def add(row: NDArray, value: NDArray, mask: NDArray | bool) -> None:
        rows.append(row)
        vals.append(np.where(np.asarray(mask)[..., None], value, 0.0))

    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        ei, ej, a = t.edge_i, t.edge_j, t.edge_contact
        d = (
            np.broadcast_to(t.edge_distance[:, None], (len(ei), 2))
            if own_distance is None
            else own_distance
        )
        bearing = t.edge_bearing  # (m, 2), or one unused row: broadcast
        for side, (obs, tgt) in enumerate(((ei, ej), (ej, ei))):
            v = _gather(z, obs, tgt)
            if dim == 2:
                b = (1.0 - 2.0 * side) * bearing  # g*_ji = -g*_ij
                fx, fy = edge_force(
                    t.kind, v[..., 0], v[..., 1], d[..., side], a, t.edge_gain, b[:, 0], b[:, 1]
                )  # eq. (8)
                add(obs, np.stack([fx, fy], axis=-1), _seen(seen, obs, tgt))
            else:
                add(obs, _along(t, v, d[..., side], a), _seen(seen, obs, tgt))
        other = ~t.pair_is_edge
        if t.repulsion_gain != 0 and other.any():
            pi, pj, pa = t.pair_i[other], t.pair_j[other], t.pair_contact[other]
            for obs, tgt in ((pi, pj), (pj, pi)):
                v = _gather(z, obs, tgt)
                r = np.sqrt(np.sum(v * v, axis=-1))
                g = repulsion_gain(
                    r, r - pa, t.repulsion_gain, t.repulsion_eta, t.repulsion_influence
                )  # Khatib
                add(obs, g[..., None] * v, _seen(seen, obs, tgt))
        if t.term_i.size:  # eqs. (11), (13), (14), (23), from robot i's own view
            ti, tj, tk = t.term_i, t.term_j, t.term_k
            sa, sb, sc = (x[t.term_surface] for x in (t.surface_a, t.surface_b, t.surface_c))
            pa_, pb, pc = (_gather(z, ti, s) for s in (sa, sb, sc))
            cab = triangle_product(*_xy(pa_), *_xy(pb), *_xy(pc))
            sigma = switching(t.surface_beta[t.term_surface], cab, t.theta)  # eq. (14)
            r_jk = _gather(z, ti, tk) - _gather(z, ti, tj)
            term = np.stack(restriction_force(t.term_weight * switched_on(sigma), *_xy(r_jk)), -1)
            add(ti, term, _seen(seen, ti, tj) & _seen(seen, ti, tk))
        if t.area_a.size:  # signed-area penalty, grad_a A_abc = 1/2 k x r_bc, per vertex
            for v_, o1, o2 in ((t.area_a, t.area_b, t.area_c), (t.area_b, t.area_c, t.area_a),
                               (t.area_c, t.area_a, t.area_b)):  # fmt: skip
                p1, p2 = _gather(z, v_, o1), _gather(z, v_, o2)  # the vertex at 0
                area = signed_area(0.0, 0.0, *_xy(p1), *_xy(p2))
                g = area_gain(area, t.area_target, t.area_gain)
                term = np.stack(area_force(g, *_xy(p1), *_xy(p2)), axis=-1)
                add(v_, term, _seen(seen, v_, o1) & _seen(seen, v_, o2))
    if not rows:
        return np.zeros((*z.shape[:-3], n, dim))
    return scatter_rows(np.concatenate(vals, axis=-2), np.concatenate(rows), n)


def _along(t: KernelTerms, v: NDArray, d: NDArray, a: NDArray) -> NDArray:
    """An edge's term ``g(r) v`` of a law of distances at ``v = z_ij`` in any space: the
    plane's formula (:func:`~formationlab.controllers.kinds.edges.edge_force_at`, eq. 8 or
    Krick et al.'s) evaluated on the edge's own line, at ``(r, 0)``, and pointed along
    ``v``; ``(..., m, d)``."""
    r = np.sqrt(np.sum(v * v, axis=-1))
    f, _ = edge_force_at(t.kind, r, 0.0 * r, r, d, a, t.edge_gain, 0.0, 0.0)  # eq. (8)
    return (f / r)[..., None] * v
