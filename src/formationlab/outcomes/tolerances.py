"""The outcomes a run or trial can have, and the tolerances that decide between them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from ..validation import positive

__all__ = ["NET_STEPS", "OUTCOMES", "Outcome", "Tolerances"]

Outcome = Literal[
    "desired", "mirror", "incorrect", "collision", "drifting", "rotating", "not-converged",
    "diverged",
]  # fmt: skip
OUTCOMES: tuple[Outcome, ...] = (
    "desired", "mirror", "incorrect", "collision", "drifting", "rotating", "not-converged",
    "diverged",
)  # fmt: skip


#: The net speed stops a run only over a check interval of at least this many steps. Over
#: one step it is the speed at the step's start, which the instantaneous speed already
#: judges, and is wrong for a robot whose velocity is state: one at rest, commanded to
#: move, has not moved yet after its first step (double integrators, quadrotors). The
#: compiled loop reads it as a constant: naming numba here puts this module in the numba
#: cache's digest (``_numba_cache``), so that a change compiles the loop again.
NET_STEPS = 2


@dataclass(frozen=True, kw_only=True)
class Tolerances:
    """Tolerances of the outcome classification.

    Parameters
    ----------
    distance : float
        Largest ``|r_ij - d_ij|`` over the edges for the distances to count as met.
    bearing : float
        Largest ``||g_ij - g*_ij||`` over the edges (about the angle in radians) for the
        bearings of a formation defined by bearings to count as met.
    speed : float
        Largest speed for the robots to count as stopped: instantaneous,
        ``max_i |u_i|``, or net over the last ``window`` seconds (module docstring).
    window : float
        Length ``T`` of the check interval of the net speed
        ``max_i |q_i(t) - q_i(t - T)| / T``, seconds. The batched studies test
        convergence every ``window`` seconds (``round(window / dt)`` steps).
    shape : float
        Largest shape rate, m/s, for a moving formation to count as rigid
        (``drifting`` or ``rotating``): ``max_i |B_i - R A_i| / T`` after the best
        rigid fit of the positions ``T = drift_window`` seconds apart
        (:mod:`formationlab.outcomes.rigid_motion`); the rigid motion must also move some
        robot faster than this, and a rotation must move the robots about their
        centroid faster than this to count as ``rotating``. The default 2e-2 m/s
        (4 cm over the default window) lies above the shape rate that explicit
        Euler's chatter on a switching surface leaves at ``dt = 1e-3`` (at most
        1.1e-2 m/s, median 3e-3, over the moving trials of the hexagon's study) and
        far below the drift speeds seen (0.24 to 1.2 m/s).
    drift_window : float
        The window ``T`` of the rigid-motion fit, seconds: the positions this long
        before the end are compared with the final ones (a run shorter than this is
        never ``drifting`` or ``rotating``). Rotations faster than ``pi / T`` rad/s alias.
    """

    distance: float = 1e-2
    bearing: float = 1e-2
    speed: float = 1e-3
    window: float = 1e-2
    shape: float = 2e-2
    drift_window: float = 2.0

    def __post_init__(self) -> None:
        for name in ("distance", "bearing", "speed", "window", "shape", "drift_window"):
            positive(getattr(self, name), name, owner="tolerance")

    def drift_steps(self, dt: float) -> int:
        """Steps of ``dt`` in the drift window, ``max(1, round(drift_window / dt))``."""
        return max(1, round(self.drift_window / dt))
