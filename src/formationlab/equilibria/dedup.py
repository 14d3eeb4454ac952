"""When two equilibria are the same: translation, rotation and allowed relabellings.

The closed loop of every law in the package is equivariant under

* translations and rotations of all robots (relative positions only);
* a relabelling ``pi`` of the robots that is an automorphism of the formation:
  it keeps the graph, the desired distances ``d_ij`` and the diameters, and
  maps the ``alpha`` table to itself, ``alpha_{pi(i) pi(j) pi(k)} = alpha_ijk``;
* a reflection combined with a relabelling that maps ``alpha`` to
  ``-alpha`` (a reflection flips every ``c_ijk``, eq. 14). With a free
  orientation (no ``alpha``) every automorphism may be combined with a
  reflection; with the paper's triangle the reflection across ``x = 0`` with
  robots 1 and 2 swapped is one (NOTES.md, "Things a faithful simulation
  shows").

Two equilibria are the same when one such transformation maps one onto the
other. :func:`same_equilibrium` searches the relabellings by backtracking:
robot ``i`` of ``a`` may go to robot ``p`` of ``b`` only when the formation data
and the pairwise distances to the robots placed so far agree, which prunes
almost everything for a generic shape; a complete match of all pairwise
distances means the shapes are congruent, and a Procrustes fit decides
whether a rotation (or, where allowed, a reflection) carries one onto the
other.

In space (positions ``(n, 3)``) the rotations are those of SO(3), fitted by Kabsch's
method (:func:`formationlab.outcomes.rigid_motion.kabsch`), and the restriction is the
chirality of tetrahedra (docs/three-d.md): a relabelling may map each restricted
quadruple's sign ``beta`` to ``eps beta`` (with the sign of the reordering of the
quadruple, ``v`` alternates), ``eps = -1`` paired with a reflection (a reflection flips
every signed volume). A reflection alone is never allowed: the mirror image of a shape
whose chirality is restricted is the other chirality.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ..formation.geometry import parity
from ..formation.spec import Formation
from ..outcomes.rigid_motion import kabsch

__all__ = ["canonical_pose", "group_equilibria", "same_equilibrium"]


def canonical_pose(q: NDArray[np.float64], invariance: str = "rotation") -> NDArray[np.float64]:
    """``q`` translated to centroid 0 and turned so that robot 1 -> robot 2 points along +x
    (``invariance = "scale"``: scaled to ``sqrt(1/n sum ||p_i||^2) = 1`` instead, not turned).

    In space (``(n, 3)``) turned, never reflected, so that robot 1 -> robot 2 points along
    +x and the first robot off that line lies in the x-y plane at positive y.
    """
    q = np.asarray(q, dtype=float)
    p = q - q.mean(axis=0)
    if invariance == "scale":
        return p / max(float(np.sqrt(np.mean(np.sum(p * p, axis=-1)))), 1e-300)
    if q.shape[-1] == 3:
        return _pose_in_space(p)
    v = p[1] - p[0]
    ang = np.arctan2(v[1], v[0])
    c, s = np.cos(-ang), np.sin(-ang)
    out = p @ np.array([[c, s], [-s, c]])
    out[np.abs(out) < 1e-14] = 0.0
    return out


def _pose_in_space(p: NDArray) -> NDArray:
    """Centred ``p`` ``(n, 3)`` turned (det +1) as :func:`canonical_pose` says."""
    x = p[1] - p[0]
    x = x / max(float(np.linalg.norm(x)), 1e-300)
    off = p - p[0] - np.outer((p - p[0]) @ x, x)  # the parts across the line 1-2
    far = np.linalg.norm(off, axis=-1)
    k = int(np.argmax(far > 1e-9 * max(float(far.max()), 1e-300)))
    if far[k] <= 1e-12:  # on one line: any turn about it
        y = np.cross(x, np.eye(3)[int(np.argmin(np.abs(x)))])
    else:
        y = off[k]
    y = y / np.linalg.norm(y)
    out = p @ np.stack([x, y, np.cross(x, y)], axis=1)  # rows x, y, x cross y: det +1
    out[np.abs(out) < 1e-14] = 0.0
    return out


def _fit_rmsd(a: NDArray, b: NDArray, reflect: bool) -> float:
    """Least RMS distance between ``a`` and ``b`` (both centred) over rotations (x reflection)."""
    if a.shape[-1] == 3:  # Kabsch's proper rotation, after a reflection through z = 0
        b = b * np.array([1.0, 1.0, -1.0]) if reflect else b
        rot, _ = kabsch(b, a)
        return float(np.sqrt(np.mean(np.sum((b @ rot.T - a) ** 2, axis=-1))))
    if reflect:
        b = b * np.array([1.0, -1.0])
    h = b.T @ a
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    rot = u @ np.diag([1.0, d]) @ vt
    return float(np.sqrt(np.mean(np.sum((b @ rot - a) ** 2, axis=-1))))


def same_equilibrium(
    formation: Formation,
    qa: NDArray[np.float64],
    qb: NDArray[np.float64],
    *,
    tol: float = 1e-5,
    invariance: str = "rotation",
) -> bool:
    """Whether ``qa`` and ``qb`` (both ``(n, d)``) are one equilibrium up to the allowed maps.

    ``tol`` bounds the differences of pairwise distances and the RMS misfit of
    the final Procrustes fit. With ``invariance = "scale"`` (the bearing law) the maps are
    translations and scalings: the two shapes, centred and scaled to 1, differ by at most
    ``tol`` (RMS).
    """
    qa = np.asarray(qa, dtype=float)
    qb = np.asarray(qb, dtype=float)
    if invariance == "scale":
        d = canonical_pose(qa, "scale") - canonical_pose(qb, "scale")
        return float(np.sqrt(np.mean(np.sum(d * d, axis=-1)))) <= tol
    n = formation.n
    ra = np.linalg.norm(qa[:, None] - qa[None], axis=-1)
    rb = np.linalg.norm(qb[:, None] - qb[None], axis=-1)
    if abs(np.sort(ra.ravel()) - np.sort(rb.ravel())).max() > 2 * tol:
        return False
    adj = formation.adjacency
    dm = np.where(adj, formation.distance_matrix, -1.0)
    # in space, desired distances equal to 1e-9 are one (a template of rounded decimals:
    # the regular tetrahedron's edges differ by 1e-11); the plane compares them exactly
    same_d = 1e-9 * float(np.max(dm)) if formation.dim == 3 else 0.0
    rho = formation.diameters
    alpha = formation.alpha
    pa = qa - qa.mean(axis=0)
    pb = qb - qb.mean(axis=0)
    perm = np.full(n, -1)
    used = np.zeros(n, bool)
    # signs eps with alpha o pi = eps alpha still possible (a reflection flips c_ijk)
    signs = (1.0, -1.0)

    def alpha_ok(i: int, eps: float) -> bool:
        if alpha is None:
            return True
        done = np.flatnonzero(perm >= 0)
        for j in done:
            for k in done:
                if j == k:
                    continue
                for a, b, c in ((i, j, k), (j, i, k), (j, k, i)):
                    if alpha[perm[a], perm[b], perm[c]] != eps * alpha[a, b, c]:
                        return False
        return True

    chiral = _chirality_map(formation)

    def place(i: int, eps: float) -> bool:
        if i == n:
            if chiral is not None and not chiral(perm, eps):
                return False
            return _fit_rmsd(pa, pb[perm], reflect=eps < 0) <= tol
        for p in range(n):
            if used[p] or rho[p] != rho[i]:
                continue
            done = np.flatnonzero(perm >= 0)
            if np.any(np.abs(dm[i, done] - dm[p, perm[done]]) > same_d):
                continue
            if np.any(np.abs(ra[i, done] - rb[p, perm[done]]) > 2 * tol):
                continue
            perm[i], used[p] = p, True
            if alpha_ok(i, eps) and place(i + 1, eps):
                return True
            perm[i], used[p] = -1, False
        return False

    return any(place(0, eps) for eps in signs)


def _chirality_map(formation: Formation) -> Callable[[NDArray, float], bool] | None:
    """In space, ``ok(perm, eps)``: whether the relabelling ``perm`` maps every restricted
    quadruple ``(i, j, k, l)`` with sign ``beta`` to one held by ``perm[i]`` with sign ``eps
    beta`` times the parity of the reordering of ``perm[j], perm[k], perm[l]``; None in the
    plane or without restrictions (every relabelling allowed, with or without reflection)."""
    if formation.dim != 3 or not formation.has_chirality:
        return None
    quads = np.asarray(formation.chiral_quads)
    signs = np.asarray(formation.chiral_signs, dtype=int)
    held = {
        (int(q[0]), *sorted(int(x) for x in q[1:])): int(b)
        for q, b in zip(quads, signs, strict=True)
    }

    def ok(perm: NDArray, eps: float) -> bool:
        for quad, b in zip(quads, signs, strict=True):
            image = [int(perm[x]) for x in quad]
            key = (image[0], *sorted(image[1:]))
            if held.get(key) != eps * b * parity(*image[1:]):
                return False
        return True

    return ok


def group_equilibria(
    formation: Formation, qs: list[NDArray[np.float64]], *, tol: float = 1e-5,
    invariance: str = "rotation",
) -> list[int]:  # fmt: skip
    """Group label of each state in ``qs``: the index of the first state it equals."""
    labels: list[int] = []
    reps: list[int] = []
    for idx, q in enumerate(qs):
        for r in reps:
            if same_equilibrium(formation, qs[r], q, tol=tol, invariance=invariance):
                labels.append(r)
                break
        else:
            reps.append(idx)
            labels.append(idx)
    return labels
