"""The explicit Euler step of the compiled loop, with what the step rule needs of it.

``x_{k+1} = x_k + dt f(x_k)`` for robots ``lo:hi`` of a chunk of trials (states
``(n, k, C)``, the trials innermost), with each trial's largest squared displacement of a
position and whether the new state is finite (its coordinates, and the squares of its
positions: beyond about 1.3e154 squared distances overflow, and the law's forces with
them, so such a state is not finite either, as ``System.step_verdict`` judges it): the
numbers the contact rule
(:mod:`.contact`) and the close list (:mod:`.lists`) judge the step by. The loop over all
robots of a chunk (:func:`formationlab.engine.loop.step_chunk`) and the robots' chunks of a
run of many robots on numba's threads (:func:`formationlab.engine.lists.advance_parallel`)
both take the step here.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import NDArray

__all__ = ["PLANE", "SPACE", "axes_for", "euler"]

#: The marker of the positions' dimension that the loop's functions take (``axes``): an
#: array of ``d`` axes of length 1 (``d = 2`` in the plane, 3 in space), whose ``axes.ndim``
#: is a constant where numba compiles them, so that each dimension compiles its own code from
#: the one source (the plane's as it was before space was added) and no loop runs over a
#: dimension. (An array rather than a tuple: numba's parallel loops cannot take tuples.)
PLANE, SPACE = np.zeros((1, 1)), np.zeros((1, 1, 1))
PLANE.flags.writeable = SPACE.flags.writeable = False  # (one numba type, here and as globals)


def axes_for(dim: int) -> NDArray[np.float64]:
    """:data:`PLANE` or :data:`SPACE` for positions of ``dim`` coordinates."""
    return SPACE if dim == 3 else PLANE


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True)
def euler(x, f, xn, dt, lo, hi, nact, disp, fin, axes):
    """``xn = x + dt f`` for robots ``lo:hi`` of the first ``nact`` trials, whose positions
    are the first ``axes.ndim`` numbers of a state (2 or 3).

    ``disp[b]`` becomes the larger of itself and trial ``b``'s largest squared move of a
    position (``|xn_i - x_i|^2``, as computed from ``xn``); ``fin[b]`` stays 0 while every
    new coordinate and the square of every new position coordinate is finite (NaN
    otherwise).
    """
    kk = x.shape[1]
    if axes.ndim == 3:  # (a constant: the plane's code below is compiled as it was)
        _euler_in_space(x, f, xn, dt, lo, hi, nact, disp, fin)
        return
    for i in range(lo, hi):
        # (three loops over trials, each writing one array, so that each is vectorised; in
        # one loop the checks that the five arrays do not overlap are too many for the
        # compiler, and it stays scalar, and a loop writing both disp and fin keeps the
        # largest move scalar)
        for b in range(nact):
            xn[i, 0, b] = x[i, 0, b] + dt * f[i, 0, b]  # explicit Euler
            xn[i, 1, b] = x[i, 1, b] + dt * f[i, 1, b]
        for b in range(nact):
            ex = xn[i, 0, b] - x[i, 0, b]
            ey = xn[i, 1, b] - x[i, 1, b]
            disp[b] = max(disp[b], ex * ex + ey * ey)
        for b in range(nact):
            nx = xn[i, 0, b]
            ny = xn[i, 1, b]
            fin[b] += (nx * nx + ny * ny) * 0.0  # NaN unless finite, squares too
        for d in range(2, kk):
            for b in range(nact):
                xn[i, d, b] = x[i, d, b] + dt * f[i, d, b]
            for b in range(nact):
                fin[b] += xn[i, d, b] * 0.0


@njit(cache=True, fastmath=False, error_model="numpy", nogil=True, inline="always")
def _euler_in_space(x, f, xn, dt, lo, hi, nact, disp, fin):
    """:func:`euler` for positions in space (the first three numbers of a state)."""
    kk = x.shape[1]
    for i in range(lo, hi):
        for b in range(nact):
            xn[i, 0, b] = x[i, 0, b] + dt * f[i, 0, b]  # explicit Euler
            xn[i, 1, b] = x[i, 1, b] + dt * f[i, 1, b]
            xn[i, 2, b] = x[i, 2, b] + dt * f[i, 2, b]
        for b in range(nact):
            nx = xn[i, 0, b]
            ny = xn[i, 1, b]
            nz = xn[i, 2, b]
            ex = nx - x[i, 0, b]
            ey = ny - x[i, 1, b]
            ez = nz - x[i, 2, b]
            disp[b] = max(disp[b], ex * ex + ey * ey + ez * ez)
            fin[b] += (nx * nx + ny * ny + nz * nz) * 0.0  # NaN unless finite, squares too
        for d in range(3, kk):
            for b in range(nact):
                xn[i, d, b] = x[i, d, b] + dt * f[i, d, b]
            for b in range(nact):
                fin[b] += xn[i, d, b] * 0.0
