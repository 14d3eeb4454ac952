"""Reading a state: distance errors, orientation, and the outcome of a run.

One classification is shared by every command (``run``, ``paper``, ``study``,
``equilibria``), so an outcome means the same thing everywhere:

``collision``
    some pair at ``r_ij <= a_ij`` (or a step was rejected for reaching contact);
``desired``
    every specified distance within ``Tolerances.distance`` of ``d_ij`` and every
    restricted triple with the desired orientation (any orientation when the
    formation's orientation is free);
``mirror``
    distances met and *every* restricted triple reversed: the mirror image;
``incorrect``
    stopped (below) with distances not met, or distances met with only *some*
    triples reversed (a flip that a non-rigid graph allows);
``drifting``
    distances not met, not stopped, but moving as a rigid body: the shape kept
    over the last ``Tolerances.drift_window`` seconds while the formation
    translates (a relative equilibrium of the closed loop,
    :mod:`formationlab.outcomes.rigid_motion`, ``docs/drifting.md``);
``rotating``
    the same with a rotation: an angular velocity about a centre;
``not-converged``
    still moving at the end, distances not met, shape still changing.

**Stopped** means: the instantaneous speed ``max_i |u_i|`` *or* the net speed
over the last check interval, ``max_i |q_i(t) - q_i(t - T)| / T`` with
``T = Tolerances.window``, is at most ``Tolerances.speed``. The second test is
what recognises a sliding-mode (Filippov) equilibrium reached by explicit
Euler: the iterates chatter across a switching surface with a large ``|u_i|``
at every step while the net motion, like the Filippov velocity there, is zero.
A smooth motion faster than ``speed`` fails both tests.

**Moving rigidly** is decided by :func:`formationlab.outcomes.rigid_motion.rigid_outcome`
from the positions ``drift_window`` seconds before the end
(:func:`formationlab.outcomes.rigid_motion.rigid_motion`): shape rate at most
``Tolerances.shape`` while the rigid motion is faster than that.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..formation.chirality import signed_volumes
from ..formation.chunked import over_time, time_slices
from ..formation.geometry import cross, row_norms
from ..formation.spec import DENSE_LIMIT, Formation
from ..neighbours.kdtree import close_pairs
from .rigid_motion import DRIFTING, NOT_RIGID, ROTATING, RigidMotion, rigid_motion, rigid_outcome
from .tolerances import OUTCOMES, Outcome, Tolerances

__all__ = [
    "OUTCOMES",
    "Outcome",
    "RigidMotion",
    "Tolerances",
    "classify",
    "converged_time",
    "distance_errors",
    "edge_labels",
    "error_statistics",
    "final_motion",
    "net_speed",
    "orientation_agreement",
    "orientation_signs",
    "touching",
    "triangle_orientation",
    "turned_wrong",
]


def distance_errors(formation: Formation, q: ArrayLike) -> NDArray[np.float64]:
    """``r_ij - d_ij`` per edge, shape ``(..., m)`` in the order of ``formation.edges``."""
    q = np.asarray(q, dtype=float)
    e = formation.edges
    r = np.linalg.norm(q[..., e[:, 1], :] - q[..., e[:, 0], :], axis=-1)
    return r - formation.distances


def bearing_errors(formation: Formation, q: ArrayLike) -> NDArray[np.float64]:
    """``||g_ij - g*_ij||`` per edge of a formation defined by bearings; ``(..., m)`` (0 at
    the desired bearing, 2 at the reversed one; about the angle in radians when small)."""
    q = np.asarray(q, dtype=float)
    b = formation.bearings
    if b is None:
        raise ValueError("the formation has no desired bearings (Formation.with_bearings)")
    e = formation.edges
    r = q[..., e[:, 1], :] - q[..., e[:, 0], :]
    with np.errstate(divide="ignore", invalid="ignore"):
        g = r / np.sqrt(np.sum(r * r, axis=-1))[..., None]
    return np.sqrt(np.sum((g - b) ** 2, axis=-1))


def bearings_met(formation: Formation, q: ArrayLike, tolerances: Tolerances) -> NDArray[np.bool_]:
    """Whether every bearing of a formation defined by bearings is within
    ``tolerances.bearing`` of its desired one at ``q`` ``(..., n, 2)``: ``(...)``.

    Such a formation is judged by its bearings alone (they fix its orientation too, so no
    restricted triple can disagree and no outcome is ``mirror``): both classifiers
    (:func:`classify`, :func:`formationlab.outcomes.batch.classify_batch`) take this
    decision from here.
    """
    err = bearing_errors(formation, q)
    return np.max(np.nan_to_num(err, nan=np.inf), axis=-1, initial=0.0) <= tolerances.bearing


def error_statistics(errors: ArrayLike, tolerance: float) -> dict[str, float | int]:
    """Summary statistics of distance errors ``r_ij - d_ij``, shape ``(m,)``.

    ``edges`` (m), ``max_abs``, ``mean_abs``, ``rms``, the percentiles ``p50_abs``,
    ``p90_abs``, ``p99_abs`` of ``|r_ij - d_ij|`` (numpy's linear interpolation), the
    signed ``min`` and ``max``, and ``within_tolerance``: how many edges have
    ``|r_ij - d_ij| <= tolerance``.
    """
    e = np.asarray(errors, dtype=float).reshape(-1)
    a = np.abs(e)
    if e.size == 0:
        return {"edges": 0, "within_tolerance": 0}
    p50, p90, p99 = np.percentile(a, [50.0, 90.0, 99.0])
    return {
        "edges": int(e.size),
        "max_abs": float(a.max()),
        "mean_abs": float(a.mean()),
        "rms": float(np.sqrt(np.mean(e * e))),
        "p50_abs": float(p50),
        "p90_abs": float(p90),
        "p99_abs": float(p99),
        "min": float(e.min()),
        "max": float(e.max()),
        "within_tolerance": int(np.count_nonzero(a <= tolerance)),
    }


def edge_labels(formation: Formation) -> list[str]:
    """1-based labels ``"1-2"`` of the edges, in order."""
    return [f"{i + 1}-{j + 1}" for i, j in formation.edges.tolist()]  # ints: 30x faster


def triangle_orientation(q: ArrayLike, i: int = 0, j: int = 1, k: int = 2) -> str:
    """``"ccw"`` or ``"cw"``: the turn of robots ``i, j, k`` (0-based), from ``c_ijk``."""
    q = np.asarray(q, dtype=float)
    rij, rik = q[j] - q[i], q[k] - q[i]
    c = rij[0] * rik[1] - rij[1] * rik[0]
    return "ccw" if c > 0 else "cw" if c < 0 else "collinear"


def orientation_agreement(formation: Formation, q: ArrayLike) -> tuple[int, int]:
    """Restricted triples whose ``sign(c_ijk)`` agrees / disagrees with the desired one.

    Counts ordered triples ``(i, j, k)``; a state with no restriction returns ``(0, 0)``.
    ``(i, k, j)`` agrees exactly when ``(i, j, k)`` does (both signs change, eq. 3): the
    halves ``j < k`` the formation holds are counted twice.
    """
    q = np.asarray(q, dtype=float)
    if formation.dim == 3:
        agree, disagree = chirality_agreement(formation, q)
        return int(agree), int(disagree)
    s = orientation_signs(formation, q)
    return 2 * int(np.sum(s > 0)), 2 * int(np.sum(s <= 0))


def orientation_signs(formation: Formation, q: ArrayLike) -> NDArray[np.float64]:
    """``sign(c_ijk)`` times the desired sign, per restricted triple ``(i, j, k)`` of
    ``Formation.restricted_halves``: ``(..., T)`` of ``q`` ``(..., n, 2)``; 1 agrees, -1 or 0
    (collinear) disagrees."""
    q = np.asarray(q, dtype=float)
    i, j, k = formation.restricted_halves.T
    s = np.sign(cross(q[..., j, :] - q[..., i, :], q[..., k, :] - q[..., i, :]))
    return s * -np.sign(formation.half_alpha())  # the desired sign(c_ijk) is -sign(alpha_ijk)


def turned_wrong(formation: Formation, q: ArrayLike) -> NDArray[np.bool_]:
    """Whether each restricted triple of the plane disagrees with its desired sign of
    ``c_ijk`` (:func:`orientation_signs` not 1; collinear counts as wrong); ``(..., T)``."""
    return orientation_signs(formation, q) <= 0


def chirality_agreement(
    formation: Formation, q: ArrayLike
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Restricted quadruples whose ``sign(v_ijkl)`` agrees / disagrees with the desired one
    (a formation in space, :mod:`formationlab.formation.chirality`); each ``(...)``.

    A flat quadruple (``v = 0``) disagrees, as a collinear triple does in the plane.
    """
    if not formation.has_chirality:
        shape = np.shape(q)[:-2]
        return np.zeros(shape, np.int64), np.zeros(shape, np.int64)
    s = np.sign(signed_volumes(q, formation.chiral_quads)) * formation.chiral_sign
    return np.sum(s > 0, axis=-1), np.sum(s <= 0, axis=-1)


def touching(formation: Formation, q: ArrayLike) -> bool:
    """Whether some pair of robots at positions ``q`` ``(n, 2)`` is at ``r_ij <= a_ij``.

    Every pair up to ``DENSE_LIMIT`` robots; beyond, only the pairs a k-d tree finds
    closer than the largest diameter (:func:`formationlab.neighbours.kdtree.close_pairs`), the
    only ones that can touch: nothing ``n x n``.
    """
    q = np.asarray(q, dtype=float)
    n = formation.n
    if n <= DENSE_LIMIT:
        iu, ju = np.triu_indices(n, k=1)
        r = np.linalg.norm(q[ju] - q[iu], axis=-1)
        return bool(np.any(r <= formation.contact_matrix[iu, ju]))
    iu, ju = close_pairs(q, float(np.max(formation.diameters))).T
    r = np.linalg.norm(q[ju] - q[iu], axis=-1)
    return bool(np.any(r <= 0.5 * (formation.diameters[iu] + formation.diameters[ju])))


def classify(
    formation: Formation,
    q: ArrayLike,
    u: ArrayLike,
    tolerances: Tolerances | None = None,
    *,
    contact: bool = False,
    net_speed: float | None = None,
    motion: RigidMotion | None = None,
) -> Outcome:
    """The outcome of a final state ``q`` with controls ``u`` (both ``(n, 2)``).

    ``contact`` marks a run stopped at a rejected step (contact reached).
    ``net_speed`` is ``max_i |q_i(t) - q_i(t - T)| / T`` over the last check
    interval (:func:`net_speed`); None or NaN when unknown, and then only the
    instantaneous speed decides whether the robots have stopped. ``motion`` is
    the rigid motion over the drift window (:func:`final_motion`); None when
    unknown, and then a moving state is ``not-converged``.
    """
    tol = tolerances or Tolerances()
    q = np.asarray(q, dtype=float)
    if contact or touching(formation, q):
        return "collision"
    if formation.bearings is not None:  # judged by its bearings
        if bearings_met(formation, q, tol):
            return "desired"
        met = False
    else:
        met = np.max(np.abs(distance_errors(formation, q))) <= tol.distance
    if met:
        agree, disagree = orientation_agreement(formation, q)
        if disagree == 0:
            return "desired"
        if agree == 0:
            return "mirror"
        return "incorrect"
    with np.errstate(over="ignore"):  # a huge velocity is inf: moving, not stopped
        speed = np.max(np.linalg.norm(np.asarray(u, dtype=float), axis=-1))
    stopped = speed <= tol.speed or (net_speed is not None and net_speed <= tol.speed)
    if stopped:
        return "incorrect"
    rigid = NOT_RIGID if motion is None else int(rigid_outcome(motion, tol))
    return "drifting" if rigid == DRIFTING else "rotating" if rigid == ROTATING else "not-converged"


def final_motion(t: ArrayLike, q: ArrayLike, tolerances: Tolerances | None = None) -> RigidMotion:
    """Rigid motion over the last ``drift_window`` seconds of a saved run ``(T,)``, ``(T, n, 2)``.

    Compares the final positions with the latest saved ones at least
    ``drift_window`` before the end (to a relative 1e-9, as :func:`net_speed`);
    unknown (NaN) when the run is shorter than the window.
    """
    tol = tolerances or Tolerances()
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    j = int(np.searchsorted(t, t[-1] - tol.drift_window * (1.0 - 1e-9), side="right")) - 1
    if j < 0:
        return RigidMotion.unknown(dim=q.shape[-1])
    return rigid_motion(q[j], q[-1], t[-1] - t[j])


def net_speed(t: ArrayLike, q: ArrayLike, window: float) -> NDArray[np.float64]:
    """Net speed over the last ``window`` seconds at every saved time, shape ``(T,)``.

    At saved time ``t_k`` it is ``max_i |q_i(t_k) - q_i(t_j)| / (t_k - t_j)`` with
    ``t_j`` the latest saved time at least ``window`` before ``t_k`` (to a relative
    1e-9, so that ``k dt`` rounding does not skip a sample). When samples are saved
    more sparsely than ``window`` the interval is the shortest saved one that is
    at least ``window`` long; where no sample lies ``window`` back (the first
    ``window`` seconds of a run) the value is NaN: unknown, so that only the
    instantaneous speed can count a state as stopped there.

    Parameters
    ----------
    t : array_like, shape (T,)
        Saved times, increasing.
    q : array_like, shape (T, n, 2)
        Positions at those times.
    window : float
        Interval ``T``, seconds.
    """
    t = np.asarray(t, dtype=float)
    q = np.asarray(q, dtype=float)
    j = np.searchsorted(t, t - window * (1.0 - 1e-9), side="right") - 1
    out = np.full(t.shape, np.nan)
    rows = np.flatnonzero(j >= 0)
    for part in time_slices(len(rows), _SCRATCH * q[0].size):  # bounded scratch memory
        k = rows[part]
        d = q[k] - q[j[k]]
        disp = np.max(row_norms(d), axis=-1)
        out[k] = disp / (t[k] - t[j[k]])
    return out


#: scratch bytes per float of a saved state in :func:`net_speed` and :func:`converged_time`
_SCRATCH = 4 * 8


def _top_speed(u: NDArray[np.float64]) -> NDArray[np.float64]:
    """``max_i |u_i|`` of each state, ``(T, n, 2) -> (T,)`` (inf where a square overflows)."""
    with np.errstate(over="ignore"):
        return np.max(np.linalg.norm(u, axis=-1), axis=-1)


def converged_time(
    t: NDArray[np.float64],
    u: NDArray[np.float64],
    speed: float,
    *,
    q: NDArray[np.float64] | None = None,
    window: float = 1e-2,
) -> float | None:
    """First saved time after which the robots stay stopped; None if never.

    ``t`` has shape ``(T,)`` and ``u`` shape ``(T, n, 2)``. Stopped: every
    ``|u_i| <= speed`` or, when the positions ``q`` ``(T, n, 2)`` are given, a net
    speed over ``window`` seconds (:func:`net_speed`) ``<= speed``.
    """
    moving = over_time(_top_speed, u, _SCRATCH * u[0].size) > speed
    if q is not None:
        moving &= ~(net_speed(t, q, window) <= speed)
    if moving[-1]:
        return None
    idx = np.flatnonzero(moving)
    return float(t[0] if idx.size == 0 else t[min(idx[-1] + 1, len(t) - 1)])
