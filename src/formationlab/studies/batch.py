"""Many independent trials of one law on one formation, batched: :func:`run_batch`.

``run_batch(formation, law, q0)`` steps ``B`` initial states ``q0`` of shape
``(B, n, 2)`` with explicit Euler in float64 -- the same stepping as
``formationlab.simulate(..., integrator=Euler(dt=dt))``, trial by trial -- and
stops each trial when it has stopped moving (tested every ``check_every`` steps,
``round(tolerances.window / dt)`` by default: the instantaneous speed
``max_i |u_i|`` or the net speed since the previous test,
``max_i |q_i(k) - q_i(k - check_every)| / (check_every dt)``, at most
``tolerances.speed``; the net speed catches trials at rest on a switching
surface across which Euler chatters), when a step would bring two robots into
contact (outcome ``"collision"``, the simulator's ``"step-collision"``), or at
``duration``. The final states are classified exactly as
:func:`formationlab.analysis.classify` does (:func:`classify_batch` is its
vectorised twin).

Two backends compute the same thing: ``"numba"`` (compiled, parallel over
chunks of trials, for the laws ``distance``, ``angle-restricted``,
``squared-distance`` and ``signed-area``) and ``"numpy"`` (the readable
reference of :mod:`formationlab.studies.reference`, for any law).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..analysis import OUTCOMES, Tolerances
from ..controllers import (
    AngleRestrictedLaw,
    DistanceLaw,
    Law,
    SignedAreaLaw,
    SquaredDistanceLaw,
)
from ..controllers.signed_area import desired_areas
from ..errors import FormationError, ParameterError
from ..integrators.base import steps_for
from ..spec import Formation
from ..validation import positive, whole
from .reference import STATUS_COLLISION, STATUS_CONVERGED, RawBatch, run_reference

__all__ = ["KERNEL_LAWS", "BatchResult", "classify_batch", "run_batch"]

#: Laws the numba backend implements (the numpy backend takes any law).
KERNEL_LAWS = ("distance", "angle-restricted", "squared-distance", "signed-area")

Backend = Literal["numba", "numpy"]

#: Most trials per chunk of the numba backend (the unit of parallel work): long
#: loops over trials amortise each loop's set-up; fewer when a batch is small, so
#: that every thread gets about four chunks.
CHUNK = 1024
MIN_CHUNK = 64
#: The numba kernel already uses every core, and numba's fallback threading layer
#: ("workqueue", when neither TBB nor OpenMP is found) must not be entered from two
#: threads at once: calls are serialised.
_KERNEL_LOCK = threading.Lock()
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
        One of :data:`formationlab.analysis.OUTCOMES` per trial.
    max_distance_error : ndarray, shape (B,)
        Largest ``|r_ij - d_ij|`` over the edges at ``q_final``.
    converged_time : ndarray, shape (B,)
        Time the trial was first seen converged, seconds; NaN when it was not.
    min_clearance : ndarray, shape (B,)
        Least ``r_ij - a_ij`` over every accepted state of the run (the step
        rejected for reaching contact is not part of the run).
    steps : ndarray of int64, shape (B,)
        Steps actually simulated (accepted). A trial ends early when it has
        converged, when its next step would reach contact (``"collision"``) or
        when its next step is not finite (like the simulator's ``"non-finite"``
        status: it keeps its last finite state and is classified from there).
    net_speed : ndarray, shape (B,)
        Net speed over the trial's last check interval,
        ``max_i |q_i(k) - q_i(k')| / ((k - k') dt)`` between its last two
        convergence tests ``k' < k``; NaN when it ended before its second test.
    """

    q_final: NDArray[np.float64]
    u_final: NDArray[np.float64]
    outcome: NDArray[np.str_]
    max_distance_error: NDArray[np.float64]
    converged_time: NDArray[np.float64]
    min_clearance: NDArray[np.float64]
    steps: NDArray[np.int64]
    net_speed: NDArray[np.float64]


def run_batch(
    formation: Formation,
    law: Law,
    q0: ArrayLike,
    *,
    dt: float,
    duration: float,
    tolerances: Tolerances | None = None,
    backend: Backend = "numba",
    check_every: int | None = None,
) -> BatchResult:
    """Simulate ``B`` trials of ``law`` on ``formation`` with explicit Euler (module docstring).

    Parameters
    ----------
    formation : Formation
        Robots, graph, desired distances and orientation.
    law : Law
        ``DistanceLaw``, ``AngleRestrictedLaw``, ``SquaredDistanceLaw`` or
        ``SignedAreaLaw`` (any law with ``backend="numpy"``); its parameters are
        read from the object.
    q0 : array_like, shape (B, n, 2)
        Initial positions; finite, no overlapping robots.
    dt : float
        Euler step, seconds.
    duration : float
        Longest simulated time, seconds (``ceil(duration / dt)`` steps, as the simulator).
    tolerances : Tolerances, optional
        Convergence (``speed``, ``window``) and classification tolerances. Default
        ``Tolerances()``.
    backend : {"numba", "numpy"}
        Compiled kernel or the numpy reference.
    check_every : int, optional
        Test convergence every this many steps; default
        ``max(1, round(tolerances.window / dt))`` (every 10 ms of simulated time by
        default). The net speed is measured over this interval. A trial is stopped
        at the first test it passes.

    Returns
    -------
    BatchResult
    """
    tol = tolerances or Tolerances()
    q0 = _check_initial(formation, q0)
    dt, duration = positive(dt, "dt"), positive(duration, "duration")
    n_steps = steps_for(float(duration), float(dt))
    if check_every is None:
        check_every = max(1, round(tol.window / dt))
    check_every = whole(check_every, "check_every")
    if backend == "numba":
        raw = _run_numba(formation, law, q0, float(dt), n_steps, int(check_every), tol.speed)
    elif backend == "numpy":
        raw = run_reference(
            formation,
            law,
            q0,
            dt=float(dt),
            n_steps=n_steps,
            check_every=int(check_every),
            speed=tol.speed,
        )
    else:
        raise ParameterError(f'backend must be "numba" or "numpy", got {backend!r}')
    outcome = classify_batch(
        formation,
        raw.q_final,
        raw.u_final,
        tol,
        contact=raw.status == STATUS_COLLISION,
        net_speed=raw.net_speed,
    )
    converged = raw.status == STATUS_CONVERGED
    return BatchResult(
        q_final=raw.q_final,
        u_final=raw.u_final,
        outcome=outcome,
        max_distance_error=max_distance_errors(formation, raw.q_final),
        converged_time=np.where(converged, raw.steps * float(dt), np.nan),
        min_clearance=raw.min_clearance,
        steps=raw.steps,
        net_speed=raw.net_speed,
    )


def _check_initial(formation: Formation, q0: ArrayLike) -> NDArray[np.float64]:
    """``q0`` as a C-contiguous float array ``(B, n, 2)``; finite, no overlapping robots."""
    q = np.require(np.asarray(q0, dtype=float), requirements=["C", "W"])  # one kernel signature
    n = formation.n
    if q.ndim != 3 or q.shape[1:] != (n, 2) or q.shape[0] == 0:
        raise FormationError(f"initial positions must have shape (B, {n}, 2), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise FormationError("initial positions hold NaN or infinite numbers")
    for i, j in zip(*np.triu_indices(n, k=1), strict=True):
        gap = _norm(q[:, j, :] - q[:, i, :]) - formation.contact_matrix[i, j]
        if np.any(gap <= 0):
            b = int(np.argmax(gap <= 0))
            raise FormationError(
                f"robots {i + 1} and {j + 1} overlap in trial {b + 1} of the initial positions "
                f"(clearance {gap[b]:g} <= 0); draw them apart or use smaller diameters"
            )
    return q


def _norm(v: NDArray[np.float64]) -> NDArray[np.float64]:
    """``sqrt(x^2 + y^2)`` of ``(..., 2)``, rounded as ``numpy.linalg.norm(v, axis=-1)``."""
    return np.sqrt(v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1])


def max_distance_errors(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Largest ``|r_ij - d_ij|`` over the edges: ``(B, n, 2) -> (B,)``."""
    e = formation.edges
    out = np.zeros(q.shape[0])
    for (i, j), d in zip(e, formation.distances, strict=True):
        r = _norm(q[:, j, :] - q[:, i, :])
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
) -> NDArray[np.str_]:
    """:func:`formationlab.analysis.classify` of every trial: ``(B, n, 2) -> (B,)`` str.

    ``contact`` ``(B,)`` marks trials stopped at a step rejected for reaching contact;
    ``net_speed`` ``(B,)`` is each trial's net speed over its last check interval (NaN
    where unknown), which counts the trial as stopped when ``<= tolerances.speed``,
    as the instantaneous speed does.
    """
    tol = tolerances or Tolerances()
    q = np.asarray(q, dtype=float)
    u = np.asarray(u, dtype=float)
    n_trials = q.shape[0]
    contact = np.zeros(n_trials, bool) if contact is None else np.asarray(contact, bool)
    net = np.full(n_trials, np.nan) if net_speed is None else np.asarray(net_speed, float)
    labels = np.array(OUTCOMES)
    code = {name: m for m, name in enumerate(OUTCOMES)}
    iu, ju = np.triu_indices(formation.n, k=1)
    tri = np.argwhere(formation.restricted)  # (T, 3)
    want = formation.desired_sign[tuple(tri.T)]
    out = np.empty(n_trials, dtype=labels.dtype)
    for lo in range(0, n_trials, CLASSIFY_BLOCK):
        sl = slice(lo, min(n_trials, lo + CLASSIFY_BLOCK))
        qb = q[sl]
        r = np.linalg.norm(qb[:, ju, :] - qb[:, iu, :], axis=-1)
        collided = contact[sl] | np.any(r <= formation.contact_matrix[iu, ju], axis=-1)
        met = max_distance_errors(formation, qb) <= tol.distance
        if len(tri):
            rij = qb[:, tri[:, 1], :] - qb[:, tri[:, 0], :]
            rik = qb[:, tri[:, 2], :] - qb[:, tri[:, 0], :]
            c = rij[..., 0] * rik[..., 1] - rij[..., 1] * rik[..., 0]
            s = np.sign(c) * want
            agree, disagree = np.sum(s > 0, axis=-1), np.sum(s <= 0, axis=-1)
        else:
            agree = disagree = np.zeros(len(qb), dtype=np.int64)
        stopped = np.max(np.linalg.norm(u[sl], axis=-1), axis=-1) <= tol.speed
        stopped |= net[sl] <= tol.speed
        result = np.select(
            [collided, met & (disagree == 0), met & (agree == 0), met, stopped],
            [code[x] for x in ("collision", "desired", "mirror", "incorrect", "incorrect")],
            default=code["not-converged"],
        )
        out[sl] = labels[result]
    return out


def _run_numba(
    formation: Formation,
    law: Law,
    q0: NDArray[np.float64],
    dt: float,
    n_steps: int,
    check_every: int,
    speed: float,
) -> RawBatch:
    import numba

    from . import kernels

    args = _kernel_law(formation, law)
    n_trials, n, _ = q0.shape
    q_out = np.empty((n_trials, n, 2))
    u_out = np.empty((n_trials, n, 2))
    steps = np.zeros(n_trials, dtype=np.int64)
    status = np.zeros(n_trials, dtype=np.int8)
    mc = np.full(n_trials, np.inf)
    ns = np.full(n_trials, np.nan)
    chunk = _chunk_size(n_trials, numba.get_num_threads())
    with _KERNEL_LOCK:
        # hand the chunks out one at a time (numba's setting is per thread, restored
        # below): chunks stop early by different amounts, and a busy machine may slow
        # one thread down
        previous = numba.set_parallel_chunksize(1)
        try:
            kernels.run_chunks(  # type: ignore[call-arg]
                q0, chunk, *args, dt, n_steps, check_every, speed,
                q_out, u_out, steps, status, mc, ns,
            )  # fmt: skip
        finally:
            numba.set_parallel_chunksize(previous)
    return RawBatch(
        q_final=q_out, u_final=u_out, steps=steps, status=status, min_clearance=mc, net_speed=ns
    )


def _chunk_size(n_trials: int, threads: int) -> int:
    """Trials per chunk: about four chunks per thread, within ``[MIN_CHUNK, CHUNK]``."""
    return int(min(CHUNK, max(MIN_CHUNK, -(-n_trials // (4 * threads)))))


def _kernel_law(formation: Formation, law: Law) -> tuple:
    """The law as the arrays and numbers the numba kernel takes (see ``kernels``)."""
    from .kernels import LOG_BARRIER, SQUARED

    if type(law) not in (DistanceLaw, AngleRestrictedLaw, SquaredDistanceLaw, SignedAreaLaw):
        raise ParameterError(
            f"the numba backend implements the laws {', '.join(KERNEL_LAWS)}; got "
            f'{type(law).__name__} ({law.name!r}): use backend="numpy"'
        )
    n = formation.n
    pi, pj = (x.astype(np.int64) for x in np.triu_indices(n, k=1))
    pedge = formation.adjacency[pi, pj].copy()
    pd = np.where(pedge, np.nan_to_num(formation.distance_matrix[pi, pj]), 0.0)
    pa = formation.contact_matrix[pi, pj].copy()
    rep = law.repulsion  # type: ignore[attr-defined]
    k_area = theta = 0.0
    angular = _angular_terms(formation, 0.0)
    triangles: tuple[NDArray, ...] = (np.zeros(0, np.int64),) * 3 + (np.zeros(0),)
    if isinstance(law, DistanceLaw | AngleRestrictedLaw):
        kind, gain_edge, gain_rep = LOG_BARRIER, float(law.k_c), float(law.k_c)
        if isinstance(law, AngleRestrictedLaw) and formation.alpha is not None and law.k_a > 0:
            angular, theta = _angular_terms(formation, float(law.k_a)), float(law.theta)
    else:
        kind, gain_edge, gain_rep = SQUARED, float(law.k), float(law.k_r)  # type: ignore[attr-defined]
        if isinstance(law, SignedAreaLaw) and law.k_s > 0:
            tris, target = desired_areas(formation)
            triangles = (*(tris[:, m].astype(np.int64) for m in range(3)), target.copy())
            k_area = float(law.k * law.k_s)
    return (
        kind, pi, pj, pedge, pd, pa, gain_edge, gain_rep, float(rep.eta), float(rep.influence),
        *angular, theta, *triangles, k_area,
    )  # fmt: skip


def _angular_terms(formation: Formation, k_a: float) -> tuple:
    """The restricted triples of eq. (14) grouped by triangle, for the kernel.

    Returns the sorted triangles ``(a, b, c)`` (three arrays), offsets into the
    terms, and per term ``(i, j, k)`` with ``j < k``: ``i, j, k``, ``alpha_ijk``,
    the parity ``par`` with ``c_ijk = par c_abc``, and the weight ``2 k_a alpha_ijk``
    (the ordered pair ``(k, j)`` of eq. (13) contributes the same as ``(j, k)``).
    With ``k_a = 0`` or no alpha, all arrays are empty.
    """
    t = np.zeros((0, 3), dtype=np.int64)
    if formation.alpha is not None and k_a > 0:
        t = np.argwhere(formation.restricted).astype(np.int64)
        t = t[t[:, 1] < t[:, 2]]  # (i, k, j) is the same term as (i, j, k)
    tris = np.unique(np.sort(t, axis=1), axis=0).reshape(-1, 3)
    which = np.array([np.flatnonzero((tris == x).all(axis=1))[0] for x in np.sort(t, axis=1)])
    order = np.argsort(which, kind="stable")
    t, which = t[order], which[order].astype(np.int64)
    offsets = np.searchsorted(which, np.arange(len(tris) + 1)).astype(np.int64)
    i, j, k = (np.ascontiguousarray(t[:, m]) for m in range(3))
    # parity of the permutation taking (a, b, c), a < b < c, to (i, j, k)
    par = np.sign((j - i) * (k - i) * (k - j)).astype(float)
    alpha = formation.alpha[i, j, k] if len(t) else np.zeros(0)  # type: ignore[index]
    corners = (np.ascontiguousarray(tris[:, m]) for m in range(3))
    return (*corners, offsets, i, j, k, alpha, par, 2.0 * k_a * alpha)
