"""The geofence of a flight: a box the drones stay in, and the commands that keep them there.

Near a wall (closer than ``margin``) the component of a drone's velocity that pushes out
through that wall is removed, the others kept (:func:`guard`); a drone found outside the
box lands the flight (:meth:`Fence.outside`). Arrays: positions and velocities ``(n, 3)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError
from ..validation import nonnegative

__all__ = ["Fence", "guard"]


@dataclass(frozen=True, kw_only=True)
class Fence:
    """A box ``[x0, x1] x [y0, y1] x [z0, z1]``, metres, in the drones' world frame.

    Parameters
    ----------
    bounds : sequence of 6 floats
        ``(x0, x1, y0, y1, z0, z1)`` with each lower bound below its upper one.
    margin : float
        Distance from a wall within which a velocity pushing out through it is removed.
    """

    bounds: tuple[float, float, float, float, float, float] = (-2.0, 2.0, -2.0, 2.0, 0.0, 2.0)
    margin: float = 0.2

    def __post_init__(self) -> None:
        nonnegative(self.margin, "margin", owner="fence")
        b = tuple(float(v) for v in self.bounds)
        if len(b) != 6 or not all(np.isfinite(b)):
            raise ParameterError(
                f"a fence is six finite numbers x0,x1,y0,y1,z0,z1 (metres), got {self.bounds!r}",
                key="fence",
            )
        for axis, (lo, hi) in zip("xyz", (b[0:2], b[2:4], b[4:6]), strict=True):
            if not lo < hi - 2 * self.margin:
                raise ParameterError(
                    f"the fence's {axis} range [{lo:g}, {hi:g}] must be wider than twice its "
                    f"margin ({self.margin:g} m): give {axis}0 < {axis}1 - {2 * self.margin:g}",
                    key="fence",
                )
        object.__setattr__(self, "bounds", b)

    @classmethod
    def parse(cls, text: str, *, margin: float = 0.2) -> Fence:
        """A fence from ``"x0,x1,y0,y1,z0,z1"`` (the ``--fence`` option)."""
        try:
            values = tuple(float(v) for v in text.split(","))
        except ValueError:
            values = ()
        if len(values) != 6:
            raise ParameterError(
                f"--fence takes six numbers x0,x1,y0,y1,z0,z1 in metres, got {text!r}",
                key="fence",
            )
        return cls(bounds=values, margin=margin)  # type: ignore[arg-type]

    @property
    def low(self) -> NDArray[np.float64]:
        """``(x0, y0, z0)``."""
        return np.array(self.bounds[0::2])

    @property
    def high(self) -> NDArray[np.float64]:
        """``(x1, y1, z1)``."""
        return np.array(self.bounds[1::2])

    def outside(self, q: NDArray[np.float64], axes: Sequence[int] = (0, 1, 2)) -> NDArray[np.bool_]:
        """Which drones at ``q`` ``(n, 3)`` are outside the box along ``axes``: ``(n,)``."""
        a = list(axes)
        return np.any((q[:, a] < self.low[a]) | (q[:, a] > self.high[a]), axis=-1)


def guard(fence: Fence, q: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``v`` ``(n, 3)`` without the components that push a drone at ``q`` ``(n, 3)`` out
    through a wall it is within ``fence.margin`` of."""
    out = (q < fence.low + fence.margin) & (v < 0) | (q > fence.high - fence.margin) & (v > 0)
    return np.where(out, 0.0, v)
