"""Orientation data of a formation: alpha from a shape, and the switching surfaces.

See ``docs/conventions.md`` for the sign of alpha (the paper's eq. 14 drives a
triangle to ``sign(c_ijk) = -sign(alpha_ijk)``).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from .errors import FormationError
from .geometry import cross, parity

__all__ = ["BETA_RTOL", "COLLINEAR_SIN", "alpha_from_shape", "signed_angle", "switching_surfaces"]

#: A template triple whose |sin| of the angle at i is below this counts as collinear.
COLLINEAR_SIN = 1e-6

#: Two triples of one triangle share a switching surface when their ``beta`` agree to this.
BETA_RTOL = 1e-9


def signed_angle(u: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """Counter-clockwise angle from ``u`` to ``v`` in ``(-pi, pi]``."""
    dot = u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1]
    return np.arctan2(cross(u, v), dot)


def alpha_from_shape(
    shape: NDArray[np.float64], edges: NDArray[np.int64], alpha_values: str
) -> NDArray[np.float64]:
    """``alpha_ijk`` that drive towards ``shape`` (paper's sign convention, eq. 2).

    ``alpha_ijk = -angle(r_ij -> r_ik)`` (angles) or its sign, for every ordered
    pair ``j != k`` of neighbours of ``i``. Collinear triples have no orientation
    and are rejected.
    """
    n = shape.shape[0]
    adj = np.zeros((n, n), bool)
    adj[edges[:, 0], edges[:, 1]] = adj[edges[:, 1], edges[:, 0]] = True
    r = shape[None, :, :] - shape[:, None, :]  # r[i, j] = q_j - q_i
    ang = signed_angle(r[:, :, None, :], r[:, None, :, :])  # ccw angle r_ij -> r_ik
    length = np.linalg.norm(r, axis=-1)
    sin = np.abs(np.sin(ang))
    mask = adj[:, :, None] & adj[:, None, :] & ~np.eye(n, dtype=bool)[None]
    coincident = mask & ((length[:, :, None] == 0) | (length[:, None, :] == 0))
    collinear = mask & ((sin < COLLINEAR_SIN) | coincident)
    if np.any(collinear):
        i, j, k = np.argwhere(collinear)[0] + 1
        raise FormationError(
            f"robots {i}, {j} and {k} are collinear in the template, so the triple has no "
            'orientation; move one of them off the line or use orientation = "free"',
            key="template",
        )
    alpha = np.where(mask, -ang, 0.0)  # paper's sign: opposite to the ccw angle
    return np.sign(alpha) if alpha_values == "sign" else alpha


def switching_surfaces(
    alpha: NDArray[np.float64], restricted: NDArray[np.bool_]
) -> tuple[NDArray[np.int64], NDArray[np.float64], NDArray[np.int64]]:
    """Distinct switching surfaces ``beta c_abc + theta = 0`` (see ``Formation.surfaces``)."""
    n = alpha.shape[0]
    index = np.full((n, n, n), -1, dtype=np.int64)
    tris: list[tuple[int, int, int]] = []
    betas: list[float] = []
    for i, j, k in np.argwhere(restricted):
        tri = (int(i), int(j), int(k))
        srt = tuple(sorted(tri))
        beta = float(alpha[i, j, k]) * float(parity(i, j, k))
        # the same surface when beta agrees to round-off (angles of a template carry it)
        for s, (t, b) in enumerate(zip(tris, betas, strict=True)):
            if t == srt and abs(b - beta) <= BETA_RTOL * max(1.0, abs(b)):
                index[i, j, k] = s
                break
        else:
            index[i, j, k] = len(tris)
            tris.append(srt)  # type: ignore[arg-type]
            betas.append(beta)
    tri_arr = np.array(tris, dtype=np.int64).reshape(-1, 3)
    beta_arr = np.array(betas, dtype=float)
    for arr in (tri_arr, beta_arr, index):
        arr.setflags(write=False)
    return tri_arr, beta_arr, index
