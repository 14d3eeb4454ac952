"""Planar geometry used by every layer: the cross product, the quarter turn, permutation parity.

The lowest module of the package (it imports nothing of it), so that the
formation specification, the potentials and the kernels' data take these
from one place.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["cross", "parity", "perp"]


def cross(u: ArrayLike, v: ArrayLike) -> NDArray[np.float64]:
    """Scalar triple product ``(u x v) . k`` of planar vectors ``(..., 2)``."""
    u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def perp(v: ArrayLike) -> NDArray[np.float64]:
    """``k x v``: planar vectors ``(..., 2)`` turned by +90 degrees."""
    v = np.asarray(v, dtype=float)
    return np.stack([-v[..., 1], v[..., 0]], axis=-1)


def parity(i: ArrayLike, j: ArrayLike, k: ArrayLike) -> NDArray[np.float64]:
    """Sign of the permutation taking the sorted ``(a, b, c)`` to ``(i, j, k)``; elementwise.

    ``c_ijk = parity(i, j, k) c_abc``: the triple product is invariant under
    cyclic permutations and odd under a swap. Distinct indices give +-1.
    """
    i, j, k = (np.asarray(x, dtype=np.int64) for x in (i, j, k))
    return np.sign((j - i) * (k - i) * (k - j)).astype(float)
