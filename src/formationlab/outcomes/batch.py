"""Outcomes of a batch of trials: :class:`BatchResult` and :func:`classify_batch`.

Every path that ends many trials at once (the studies' kernel and driver, the
settling of equilibria) returns a :class:`BatchResult`, classified by
:func:`classify_batch`, the vectorised twin of
:func:`formationlab.outcomes.analysis.classify` (same outcomes, same tolerances).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..formation.geometry import row_norms
from ..formation.spec import Formation
from ..status import DIVERGED_SCALE, Status
from ..validation import COORDINATE_LIMIT
from .analysis import OUTCOMES, Tolerances, bearing_errors, bearings_met, chirality_agreement
from .rigid_motion import DRIFTING, ROTATING, RigidMotion, rigid_motion, rigid_outcome

__all__ = ["BatchResult", "classify_batch", "max_distance_errors"]

#: Trials classified at a time by :func:`classify_batch` (bounds its memory).
CLASSIFY_BLOCK = 1 << 16


@dataclass(frozen=True, kw_only=True)
class BatchResult:
    """Final states and outcomes of a batch of ``B`` trials.

    Attributes
    ----------
    q_final : ndarray, shape (B, n, 2)
        Last accepted positions of each trial.
    u_final : ndarray, shape (B, n, 2)
        Controls at ``q_final``.
    outcome : ndarray of str, shape (B,)
        One of :data:`formationlab.outcomes.analysis.OUTCOMES` per trial.
    max_distance_error : ndarray, shape (B,)
        Largest ``|r_ij - d_ij|`` over the edges at ``q_final``.
    converged_time : ndarray, shape (B,)
        Time the trial was first seen converged, seconds; NaN when it was not.
    min_clearance : ndarray, shape (B,)
        Least clearance over every accepted state of the run (the step rejected for
        reaching contact is not part of the run), robots and obstacles together: the
        lesser of ``min_robot_clearance`` and ``min_obstacle_clearance``.
    steps : ndarray of int64, shape (B,)
        Steps actually simulated (accepted). A trial ends early when it has
        converged, when its next step would reach contact (``"collision"``) or
        when its next step is not finite (like the simulator's ``"non-finite"``
        status: it keeps its last finite state and is classified from there).
    net_speed : ndarray, shape (B,)
        Net speed over the trial's last check interval,
        ``max_i |q_i(k) - q_i(k')| / ((k - k') dt)`` between its last two
        convergence tests ``k' < k``; NaN when it ended before its second test.
    status : ndarray of int8, shape (B,)
        :attr:`formationlab.status.Status.code` of how each trial ended
        (:meth:`statuses` gives the members).
    x_final : ndarray, shape (B, n, k)
        Last accepted states (positions first; ``q_final`` for single integrators).
    motion : RigidMotion
        Batch ``(B,)``: the rigid motion fitted between the positions at step
        ``window_step`` (``drift_window`` before the end of the full duration) and
        the final ones (:func:`formationlab.outcomes.rigid_motion.rigid_motion`); NaN for a
        trial that ended before ``window_step``. Its ``velocity`` and ``omega``
        are the drift of a ``drifting`` or ``rotating`` trial.
    max_bearing_error : ndarray, shape (B,)
        Largest ``||g_ij - g*_ij||`` over the edges at ``q_final`` for a formation judged by
        its bearings (docs/bearing.md); NaN for the others.
    min_robot_clearance : ndarray, shape (B,)
        Least robot-robot clearance ``r_ij - a_ij`` over every accepted state.
    min_obstacle_clearance : ndarray, shape (B,)
        Least robot-obstacle clearance (distance to the obstacle minus the robot's radius)
        over every accepted state; inf without obstacles.
    min_pair_distance : ndarray, shape (B,)
        Least distance of two points the safety filter keeps ``D_s`` apart (pairs within
        its sensing radius) over every accepted state; NaN without a filter.
    below_safety_distance : ndarray of bool, shape (B,)
        Whether that distance came below the filter's ``D_s``
        (:meth:`formationlab.safety.SafetyFilter.below`): the filter's promise broken;
        False without a filter.
    """

    q_final: NDArray[np.float64]
    u_final: NDArray[np.float64]
    outcome: NDArray[np.str_]
    max_distance_error: NDArray[np.float64]
    converged_time: NDArray[np.float64]
    min_clearance: NDArray[np.float64]
    steps: NDArray[np.int64]
    net_speed: NDArray[np.float64]
    status: NDArray[np.int8]
    x_final: NDArray[np.float64]
    motion: RigidMotion
    max_bearing_error: NDArray[np.float64] | None = None
    min_robot_clearance: NDArray[np.float64] | None = None
    min_obstacle_clearance: NDArray[np.float64] | None = None
    min_pair_distance: NDArray[np.float64] | None = None
    below_safety_distance: NDArray[np.bool_] | None = None

    def statuses(self) -> list[Status]:
        """The :class:`~formationlab.status.Status` of every trial."""
        return [Status.from_code(c) for c in self.status]

    @classmethod
    def from_final(
        cls,
        formation: Formation,
        *,
        x: NDArray[np.float64],
        v: NDArray[np.float64],
        status: NDArray[np.int8],
        steps: NDArray[np.int64],
        min_clearance: NDArray[np.float64],
        net_speed: NDArray[np.float64],
        dt: float,
        tolerances: Tolerances | None = None,
        q_window: NDArray[np.float64] | None = None,
        window_step: int = 0,
        q: NDArray[np.float64] | None = None,
        u: NDArray[np.float64] | None = None,
        min_obstacle_clearance: NDArray[np.float64] | None = None,
        min_pair_distance: NDArray[np.float64] | None = None,
        below_safety_distance: NDArray[np.bool_] | None = None,
    ) -> BatchResult:
        """Classify final states ``x`` / velocities ``v`` ``(B, n, k)`` (positions first).

        ``min_clearance`` ``(B,)`` is each trial's least robot-robot clearance and
        ``min_obstacle_clearance`` its least robot-obstacle one (default none: inf);
        ``min_pair_distance`` the least distance of the pairs a safety filter keeps apart
        (default NaN: no filter) and ``below_safety_distance`` whether it came below the
        filter's ``D_s`` (``SafetyFilter.below`` decides it; default False).

        ``q_window`` ``(B, n, 2)`` holds the positions at step ``window_step`` (NaN for
        trials that had ended by then, and for all when ``window_step < 0``: a run
        shorter than the drift window); without it no trial counts as moving rigidly.
        ``q``, ``u`` ``(B, n, 2)``: the law's points and their velocities, when the
        robot model's differ from the positions (near-identity hand points).
        """
        tol = tolerances or Tolerances()
        q = x[..., : formation.dim] if q is None else q
        u = v[..., : formation.dim] if u is None else u
        contact = np.isin(status, [s.code for s in Status if s.contact])
        # a trial stopped by a huge or non-finite step (Khatib's repulsion at a near
        # contact) holds coordinates whose squares overflow: its status already says
        # what happened, and its inf / NaN figures are what the table should show
        with np.errstate(over="ignore", invalid="ignore"):
            if q_window is None:
                motion = RigidMotion.unknown((len(q),), dim=formation.dim)
            else:
                motion = rigid_motion(q_window, q, (steps - window_step) * float(dt))
            outcome = classify_batch(
                formation, q, u, tol, contact=contact, net_speed=net_speed, motion=motion
            )
            errors = max_distance_errors(formation, q)
            berr = (
                np.max(bearing_errors(formation, q), axis=-1, initial=0.0)
                if formation.bearings is not None else np.full(len(q), np.nan)
            )  # fmt: skip
        status, outcome = _diverged(formation, q, status, outcome)
        converged = status == Status.CONVERGED.code
        robots = np.asarray(min_clearance, dtype=float)
        obst = (
            np.full(robots.shape, np.inf) if min_obstacle_clearance is None
            else np.asarray(min_obstacle_clearance, dtype=float)
        )  # fmt: skip
        least = (
            np.full(robots.shape, np.nan) if min_pair_distance is None
            else np.asarray(min_pair_distance, dtype=float)
        )  # fmt: skip
        below = (
            np.zeros(robots.shape, bool) if below_safety_distance is None
            else np.asarray(below_safety_distance, dtype=bool)
        )  # fmt: skip
        return cls(
            q_final=q, u_final=u, outcome=outcome,
            max_distance_error=errors,
            converged_time=np.where(converged, steps * float(dt), np.nan),
            min_clearance=np.minimum(robots, obst), steps=steps, net_speed=net_speed,
            status=status, x_final=x, motion=motion, max_bearing_error=berr,
            min_robot_clearance=robots, min_obstacle_clearance=obst, min_pair_distance=least,
            below_safety_distance=below,
        )  # fmt: skip


def _diverged(
    formation: Formation, q: NDArray[np.float64], status: NDArray[np.int8],
    outcome: NDArray[np.str_],
) -> tuple[NDArray[np.int8], NDArray[np.str_]]:  # fmt: skip
    """Statuses and outcomes of trials whose final positions ``q`` ``(B, n, 2)`` blew up,
    among those that ended ``success`` or ``converged`` (a collision or a non-finite step
    already says what happened).

    Not finite, or a coordinate beyond ``validation.COORDINATE_LIMIT`` (squared distances
    overflow): status ``non-finite``; finite but spread beyond :data:`DIVERGED_SCALE` times
    the formation's size: ``diverged``. Their outcome is ``diverged`` (a kernel that let
    such a state stop, its speed lost to overflow, called it ``converged``).
    """
    size = max(float(np.max(formation.distances, initial=0.0)), float(np.max(formation.diameters)))
    with np.errstate(over="ignore", invalid="ignore"):
        overflow = ~np.all(np.abs(q) <= COORDINATE_LIMIT, axis=(-2, -1))
        spread = np.max(np.abs(q - q.mean(axis=-2, keepdims=True)), axis=(-2, -1))
    ended = np.isin(status, [Status.SUCCESS.code, Status.CONVERGED.code])  # others say why
    overflow &= ended
    far = ended & ~overflow & (spread > DIVERGED_SCALE * size)
    status = np.where(overflow, Status.NON_FINITE.code, status)
    status = np.where(far, Status.DIVERGED.code, status).astype(np.int8)
    outcome = np.where(overflow | far, "diverged", outcome).astype(outcome.dtype)
    return status, outcome


def max_distance_errors(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Largest ``|r_ij - d_ij|`` over the edges: ``(B, n, d) -> (B,)``."""
    e = formation.edges
    out = np.zeros(q.shape[0])
    for (i, j), d in zip(e, formation.distances, strict=True):
        r = row_norms(q[:, j, :] - q[:, i, :])
        np.maximum(out, np.abs(r - d), out=out)
    return out


def classify_batch(
    formation: Formation,
    q: NDArray[np.float64],
    u: NDArray[np.float64],
    tolerances: Tolerances | None = None,
    *,
    contact: NDArray[np.bool_] | None = None,
    net_speed: NDArray[np.float64] | None = None,
    motion: RigidMotion | None = None,
) -> NDArray[np.str_]:
    """:func:`formationlab.outcomes.analysis.classify` of every trial: ``(B, n, 2) -> (B,)`` str.

    ``contact`` ``(B,)`` marks trials stopped at a step rejected for reaching contact;
    ``net_speed`` ``(B,)`` is each trial's net speed over its last check interval (NaN
    where unknown), which counts the trial as stopped when ``<= tolerances.speed``,
    as the instantaneous speed does; ``motion`` (batch ``(B,)``) the rigid motion over
    the drift window, which makes a moving trial ``drifting`` or ``rotating``
    (:func:`formationlab.outcomes.rigid_motion.rigid_outcome`).
    """
    tol = tolerances or Tolerances()
    q = np.asarray(q, dtype=float)
    u = np.asarray(u, dtype=float)
    n_trials = q.shape[0]
    contact = np.zeros(n_trials, bool) if contact is None else np.asarray(contact, bool)
    net = np.full(n_trials, np.nan) if net_speed is None else np.asarray(net_speed, float)
    rigid = (
        np.zeros(n_trials, np.int8) if motion is None else rigid_outcome(motion, tol).reshape(-1)
    )
    labels = np.array(OUTCOMES)
    code = {name: m for m, name in enumerate(OUTCOMES)}
    iu, ju = np.triu_indices(formation.n, k=1)
    tri = formation.restricted_triples  # (T, 3)
    want = formation.restricted_sign
    out = np.empty(n_trials, dtype=labels.dtype)
    for lo in range(0, n_trials, CLASSIFY_BLOCK):
        sl = slice(lo, min(n_trials, lo + CLASSIFY_BLOCK))
        qb = q[sl]
        r = np.linalg.norm(qb[:, ju, :] - qb[:, iu, :], axis=-1)
        collided = contact[sl] | np.any(r <= formation.contact_matrix[iu, ju], axis=-1)
        if formation.bearings is not None:  # judged by its bearings (no triple disagrees)
            met = bearings_met(formation, qb, tol)
        else:
            met = max_distance_errors(formation, qb) <= tol.distance
        if len(tri) and formation.bearings is None:
            rij = qb[:, tri[:, 1], :] - qb[:, tri[:, 0], :]
            rik = qb[:, tri[:, 2], :] - qb[:, tri[:, 0], :]
            c = rij[..., 0] * rik[..., 1] - rij[..., 1] * rik[..., 0]
            s = np.sign(c) * want
            agree, disagree = np.sum(s > 0, axis=-1), np.sum(s <= 0, axis=-1)
        elif formation.has_chirality and formation.bearings is None:  # in space
            agree, disagree = chirality_agreement(formation, qb)
        else:
            agree = disagree = np.zeros(len(qb), dtype=np.int64)
        stopped = np.max(np.linalg.norm(u[sl], axis=-1), axis=-1) <= tol.speed
        stopped |= net[sl] <= tol.speed
        result = np.select(
            [
                collided, met & (disagree == 0), met & (agree == 0), met, stopped,
                rigid[sl] == DRIFTING, rigid[sl] == ROTATING,
            ],
            [
                code[x]
                for x in (
                    "collision", "desired", "mirror", "incorrect", "incorrect", "drifting",
                    "rotating",
                )
            ],
            default=code["not-converged"],
        )  # fmt: skip
        out[sl] = labels[result]
    return out
