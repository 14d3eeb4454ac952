"""A step split into substeps where a trial is fast or near contact: robust settling.

Far from the formation the cubic laws (e.g. ``squared-distance``) are fast and
stiff, and near contact every barrier law is: :class:`Substepped` wraps any
fixed-step scheme so that one step of ``dt`` is taken in ``2**k`` equal
substeps (``k <= max_level``) for a trial whose robots would otherwise move
more than ``reach`` in it, and retried in ``retry`` substeps when the contact
rule (:meth:`System.step_verdict`) rejects it. The rest of the batch keeps the
plain step. The settling of equilibria runs the stepping driver with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from ..validation import positive
from .base import FixedStepIntegrator
from .driver import position_dim

__all__ = ["Substepped"]


@dataclass(frozen=True, kw_only=True)
class Substepped(FixedStepIntegrator):
    """``inner`` in ``2**k`` substeps where a trial is fast, ``retry`` where it hits contact.

    Parameters
    ----------
    inner : FixedStepIntegrator
        The scheme; its ``dt`` is the step.
    reach : float
        Largest move of a robot in one substep before the step is split.
    max_level : int
        At most ``2**max_level`` substeps for speed. Default 8.
    retry : int
        Substeps of a step retried after the contact rule rejected it. Default 50.
    """

    inner: FixedStepIntegrator
    reach: float
    max_level: int = 8
    retry: int = 50

    def __post_init__(self) -> None:
        object.__setattr__(self, "dt", self.inner.dt)
        super().__post_init__()
        positive(self.reach, "reach", owner="Substepped")

    def advance(
        self,
        system: System,
        x: NDArray[np.float64],
        dt: float,
        counters: dict[str, float],
        t: float = 0.0,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        with np.errstate(all="ignore"):
            pos = system.rhs(x, t)[..., : position_dim(system)]
            speed = np.sqrt(np.max(np.sum(pos * pos, axis=-1), axis=-1))
        need = np.clip(np.ceil(np.log2(np.maximum(speed * dt / self.reach, 1.0))), 0, 8)
        need = np.minimum(need, self.max_level).astype(int)
        out = np.empty_like(x)
        for level in np.unique(need):
            sel = need == level
            out[sel] = self._substeps(system, x[sel], dt, 2**level, counters, t)
        bad = system.step_verdict(x, out)[0] > 0
        if bad.any():  # near contact the field is stiff: retry in substeps
            out[bad] = self._substeps(system, x[bad], dt, self.retry, counters, t)
        return out, (out - x) / dt

    def _substeps(
        self,
        system: System,
        x: NDArray,
        dt: float,
        count: int,
        counters: dict[str, float],
        t: float,
    ) -> NDArray:
        with np.errstate(all="ignore"):
            for s in range(count):
                x = self.inner.advance(system, x, dt / count, counters, t + s * dt / count)[0]
        return x
