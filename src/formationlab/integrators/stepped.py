"""What the stepping driver is told and what it returns: :class:`StopRule` and :class:`Stepped`.

Both belong to :func:`formationlab.integrators.driver.drive` (and its body,
:class:`~formationlab.integrators.driver.Stepping`), which re-exports them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..status import Status

__all__ = ["Stepped", "StopRule"]


@dataclass(frozen=True, kw_only=True)
class StopRule:
    """When a trial counts as stopped (module docstring).

    Parameters
    ----------
    speed : float
        Stopped when the instantaneous or the net speed is at most this.
    check_every : int
        Test every this many steps (and at the last step).
    """

    speed: float
    check_every: int = 1


@dataclass(frozen=True, kw_only=True, eq=False)
class Stepped:
    """What :func:`drive` returns: final states, statuses and saved steps of ``B`` trials.

    Attributes
    ----------
    x, v : ndarray, shape (B, n, k)
        Last accepted state of each trial and the velocity of the step that
        left it (for a rejected step, the rejected step's velocity).
    steps : ndarray of int64, shape (B,)
        Accepted steps of each trial.
    status : ndarray of int8, shape (B,)
        :attr:`Status.code` of how each trial ended.
    message : list of str
        Why each trial ended, in words (says what to change when it failed).
    min_clearance : ndarray, shape (B,)
        Least ``r_ij - a_ij`` over every accepted state (robot-robot).
    min_obstacle_clearance : ndarray, shape (B,)
        Least robot-obstacle clearance over every accepted state (inf without obstacles).
    min_pair_distance : ndarray, shape (B,)
        Least distance of two points the safety filter keeps apart over every accepted
        state (:meth:`formationlab.safety.SafetyFilter.least_distance`); NaN without one.
    net_speed : ndarray, shape (B,)
        Net speed over the last check interval (NaN before the second check
        or without a stop rule).
    q_window : ndarray, shape (B, n, 2)
        Positions at step ``window_step`` (NaN for trials that had ended by then,
        and for all without ``window``).
    window_step : int
        ``n_steps - window`` (-1 without ``window``; negative: no positions kept).
    saved : list
        Blocks ``(k, trials, x, v)`` saved at step ``k``; see :meth:`trajectory`.
    stats : dict
        ``steps``, ``rhs_evaluations``, ``wall_time_s``, ``step_cost_s``, the
        scheme's counters and, with ``diagnostics``, the switching diagnostics
        of the first trial.
    dt : float
        The step.
    """

    x: NDArray[np.float64]
    v: NDArray[np.float64]
    steps: NDArray[np.int64]
    status: NDArray[np.int8]
    message: list[str]
    min_clearance: NDArray[np.float64]
    net_speed: NDArray[np.float64]
    q_window: NDArray[np.float64]
    window_step: int
    saved: list[tuple[int, NDArray[np.intp], NDArray[np.float64], NDArray[np.float64]]]
    stats: dict[str, Any] = field(default_factory=dict)
    dt: float = 0.0
    min_obstacle_clearance: NDArray[np.float64] | None = None
    min_pair_distance: NDArray[np.float64] | None = None

    def statuses(self) -> list[Status]:
        """The :class:`Status` of every trial."""
        return [Status.from_code(c) for c in self.status]

    def trajectory(self, b: int = 0) -> tuple[NDArray, NDArray, NDArray]:
        """Saved times ``(T,)``, states and velocities ``(T, n, k)`` of trial ``b``."""
        ks, xs, vs = [], [], []
        for k, ids, x, v in self.saved:
            hit = np.flatnonzero(ids == b)
            if hit.size:
                ks.append(k)
                xs.append(x[hit[0]])
                vs.append(v[hit[0]])
        return np.asarray(ks, dtype=float) * self.dt, np.asarray(xs), np.asarray(vs)
