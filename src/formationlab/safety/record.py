"""What a run's obstacles and safety filter did, per saved step: for summaries and plots.

:class:`SafetyRecord` is built by :func:`formationlab.simulate` from the saved states
of a run: the filter is applied again at every saved state (one batched call; for
explicit Euler that is exactly the filter call the step from that state made), so the
record costs one filter evaluation per *saved* step, not per step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .config import SafetyFilter
from .obstacles import Obstacle
from .result import FilterResult, FilterStatus

__all__ = ["SafetyRecord", "describe_obstacle"]


def describe_obstacle(ob: Obstacle) -> dict[str, Any]:
    """JSON-ready scenario form of an obstacle: ``{"circle": {...}}``, ``{"polygon": [...]}``,
    ``{"sphere": {...}}`` or ``{"box": {...}}``."""
    return ob.scenario()


@dataclass(frozen=True, kw_only=True, eq=False)
class SafetyRecord:
    """The obstacles and the filter's activity over the ``T`` saved states of a run.

    Attributes
    ----------
    filter : SafetyFilter or None
        The filter (None: no filter).
    obstacles : tuple of Circle, Polygon, Sphere or Box
        The static obstacles.
    status : ndarray of int8, shape (T,)
        :class:`FilterStatus` at each saved state (0 everywhere without a filter).
    active : ndarray of bool, shape (T, n)
        Robots with a constraint holding with equality at each saved state.
    active_pairs : ndarray of int, shape (k, 3)
        ``(saved step, i, j)``, 0-based, ``i < j``: active pair constraints.
    active_obstacles : ndarray of int, shape (k, 3)
        ``(saved step, robot, obstacle)``, 0-based: active obstacle constraints.
    obstacle_clearance : ndarray, shape (T,)
        Least robot-obstacle clearance ``delta - rho_i / 2`` at each saved state
        (``inf`` without obstacles).
    pair_distance : ndarray, shape (T,)
        Least centre distance ``|q_i - q_j|`` at each saved state.
    least_distance : float
        Least distance of two points the filter keeps ``D_s`` apart over *every* step of
        the run, saved or not (:meth:`SafetyFilter.least_distance`: the robots' positions,
        a near-identity unicycle's hand points; pairs within the sensing radius); NaN where
        the run did not measure it (no filter, ``filippov``).
    """

    filter: SafetyFilter | None
    obstacles: tuple[Obstacle, ...]
    status: NDArray[np.int8]
    active: NDArray[np.bool_]
    active_pairs: NDArray[np.int64]
    active_obstacles: NDArray[np.int64]
    obstacle_clearance: NDArray[np.float64]
    pair_distance: NDArray[np.float64]
    least_distance: float = math.nan

    @classmethod
    def from_states(
        cls,
        q: NDArray[np.float64],
        *,
        filter: SafetyFilter | None,
        obstacles: Sequence[Obstacle],
        result: FilterResult | None,
        obstacle_clearance: NDArray[np.float64],
        least_distance: float = math.nan,
    ) -> SafetyRecord:
        """The record of positions ``q`` ``(T, n, 2)`` and the filter ``result`` at them."""
        T, n = q.shape[:2]
        iu, ju = np.triu_indices(n, k=1)
        d = q[:, ju] - q[:, iu]
        pair = np.sqrt(np.min(np.sum(d * d, axis=-1), axis=-1))
        if result is None:
            status = np.zeros(T, np.int8)
            active = np.zeros((T, n), bool)
            pairs = obs = np.zeros((0, 3), np.int64)
        else:
            status = np.asarray(result.status, np.int8).reshape(T)
            active = np.asarray(result.active, bool).reshape(T, n)
            pairs, obs = result.active_pairs, result.active_obstacles
        return cls(
            filter=filter, obstacles=tuple(obstacles), status=status, active=active,
            active_pairs=pairs, active_obstacles=obs, obstacle_clearance=obstacle_clearance,
            pair_distance=pair, least_distance=float(least_distance),
        )  # fmt: skip

    def pair_matrix(self, k: int) -> NDArray[np.bool_]:
        """Active pair constraints at saved step ``k`` as a symmetric ``(n, n)`` matrix."""
        n = self.active.shape[1]
        out = np.zeros((n, n), bool)
        sel = self.active_pairs[self.active_pairs[:, 0] == k]
        out[sel[:, 1], sel[:, 2]] = out[sel[:, 2], sel[:, 1]] = True
        return out

    @property
    def min_pair_distance(self) -> float:
        """The least pair distance of the run: over every step where the run measured it
        (:attr:`least_distance`), else over the saved states (centres)."""
        saved = float(np.min(self.pair_distance, initial=np.inf))
        if self.filter is not None and math.isfinite(self.least_distance):
            return self.least_distance
        return saved

    @property
    def below_safety_distance(self) -> bool:
        """Whether two robots came closer than the filter's ``D_s`` (the filter's promise
        broken; :meth:`SafetyFilter.below` decides); False without a filter."""
        return self.filter is not None and bool(self.filter.below(self.min_pair_distance))

    def summary(self) -> dict[str, Any]:
        """JSON-ready: the filter, the obstacles and what was active (robots 1-based).

        Keys: ``filter`` (its parameters, or None), ``obstacles`` (scenario form),
        ``status_counts`` (saved steps per :class:`FilterStatus`), ``active_fraction``
        (saved steps with an active constraint), ``active_final`` (robots, pairs
        ``"i-j"`` and ``"robot i - obstacle o"`` active at the last state),
        ``robots_ever_active``, ``min_pair_distance`` (:attr:`min_pair_distance`: over
        every step with a filter), ``below_safety_distance`` (:attr:`below_safety_distance`),
        ``min_obstacle_clearance`` (over the saved states; None without obstacles).
        """
        f = self.filter
        counts = {s.name.lower(): int(np.sum(self.status == s)) for s in FilterStatus}
        last = len(self.status) - 1
        fin_p = self.active_pairs[self.active_pairs[:, 0] == last]
        fin_o = self.active_obstacles[self.active_obstacles[:, 0] == last]
        clear = float(np.min(self.obstacle_clearance)) if self.obstacles else None
        config = None
        if f is not None:
            radius = f.sensing_radius if np.isfinite(f.sensing_radius) else None
            config = {
                "filter": f.filter,
                "distance": f.distance,
                "gamma": f.gamma,
                "max_speed": f.max_speed,
                "obstacle_distance": f.d_obstacle,
                "sensing_radius": radius,
                "condition": f.condition,
                "step": f.rows_step or None,
            }
        return {
            "filter": config,
            "obstacles": [describe_obstacle(ob) for ob in self.obstacles],
            "status_counts": counts,
            "active_fraction": float(np.mean(self.active.any(axis=-1))) if last >= 0 else 0.0,
            "active_final": {
                "robots": [int(i) + 1 for i in np.flatnonzero(self.active[-1])],
                "pairs": [f"{i + 1}-{j + 1}" for _, i, j in fin_p],
                "obstacles": [f"robot {i + 1} - obstacle {o + 1}" for _, i, o in fin_o],
            },
            "robots_ever_active": [int(i) + 1 for i in np.flatnonzero(self.active.any(axis=0))],
            "min_pair_distance": self.min_pair_distance,
            "below_safety_distance": self.below_safety_distance,
            "min_obstacle_clearance": clear,
        }
