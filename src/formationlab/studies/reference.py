"""The plain numpy reference of the batched stepping, batch-first and readable.

This is the specification the numba kernels (:mod:`formationlab.studies.kernels`)
are tested against. It steps ``B`` independent trials with explicit Euler,
exactly as :class:`formationlab.integrators.Euler` steps one
(``q_{k+1} = q_k + dt u(q_k)``, using the law's own ``control``), and stops each
trial on its own:

* **converged**: at a check, a step ``k`` with ``k % check_every == 0`` (or the
  last step), the trial has stopped: the instantaneous speed
  ``max_i |u_i(q_k)|`` or the net speed since the previous check,
  ``max_i |q_i(k) - q_i(k')| / ((k - k') dt)`` (``k'`` the previous check; none
  at ``k = 0``), is at most ``speed``. The net speed recognises a trial at
  rest on a switching surface across which explicit Euler chatters (a
  sliding-mode equilibrium: large ``|u_i|`` every step, no net motion). The
  trial ends at ``q_k`` with ``converged_time = k dt``;
* **collision**: the step from ``q_k`` would bring some pair to
  ``r_ij <= a_ij`` (the simulator's ``"step-collision"``); the trial ends at
  ``q_k``, the last accepted state;
* **non-finite**: the step would produce NaN or infinite positions; the trial
  ends at ``q_k`` (the simulator's ``"non-finite"``);
* **end**: ``k`` reached ``n_steps``.

Arrays are batch-first: positions ``(B, n, 2)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..controllers import Law
from ..spec import Formation

__all__ = [
    "STATUS_COLLISION",
    "STATUS_CONVERGED",
    "STATUS_END",
    "STATUS_NON_FINITE",
    "RawBatch",
    "run_reference",
]

#: How a trial ended (the ``status`` codes shared with the numba kernels).
STATUS_END, STATUS_CONVERGED, STATUS_COLLISION, STATUS_NON_FINITE = 0, 1, 2, 3


@dataclass(frozen=True, kw_only=True)
class RawBatch:
    """Final states of a batch and how each trial ended (before classification).

    Attributes
    ----------
    q_final, u_final : ndarray, shape (B, n, 2)
        Last accepted positions and the controls there.
    steps : ndarray of int64, shape (B,)
        Steps simulated (accepted) by each trial.
    status : ndarray of int8, shape (B,)
        ``STATUS_END``, ``STATUS_CONVERGED``, ``STATUS_COLLISION`` or ``STATUS_NON_FINITE``.
    min_clearance : ndarray, shape (B,)
        Least ``r_ij - a_ij`` over every accepted state of the trial.
    net_speed : ndarray, shape (B,)
        Net speed over the trial's last check interval; NaN when it ended before
        its second check.
    """

    q_final: NDArray[np.float64]
    u_final: NDArray[np.float64]
    steps: NDArray[np.int64]
    status: NDArray[np.int8]
    min_clearance: NDArray[np.float64]
    net_speed: NDArray[np.float64]


def clearances(formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
    """Least ``r_ij - a_ij`` over all pairs of each trial: ``(B, n, 2) -> (B,)``."""
    iu, ju = np.triu_indices(formation.n, k=1)
    r = np.linalg.norm(q[:, ju, :] - q[:, iu, :], axis=-1)
    return np.min(r - formation.contact_matrix[iu, ju], axis=-1)


def run_reference(
    formation: Formation,
    law: Law,
    q0: NDArray[np.float64],
    *,
    dt: float,
    n_steps: int,
    check_every: int,
    speed: float,
) -> RawBatch:
    """Step ``B`` trials with explicit Euler until each stops (module docstring).

    Parameters
    ----------
    formation, law
        The closed loop; any law works here (the kernels support four).
    q0 : ndarray, shape (B, n, 2)
        Initial positions, already validated.
    dt : float
        Step, seconds.
    n_steps : int
        Steps in the full duration.
    check_every : int
        Test convergence at steps ``k`` divisible by it (and at the last step).
    speed : float
        A trial has converged when its instantaneous or net speed is ``<= speed``.
    """
    q = np.array(q0, dtype=float)
    n_trials = q.shape[0]
    q_final = np.empty_like(q)
    u_final = np.empty_like(q)
    steps = np.zeros(n_trials, dtype=np.int64)
    status = np.zeros(n_trials, dtype=np.int8)
    min_clear = np.full(n_trials, np.inf)
    net = np.full(n_trials, np.nan)  # net speed over the last check interval
    live = np.arange(n_trials)  # trials still running; q[live] are their positions
    qc, kc = q, -1  # positions of the live trials at the previous check, its step

    def finish(which: NDArray[np.bool_], code: int, k: int, qk: NDArray, uk: NDArray) -> None:
        ids = live[which]
        q_final[ids], u_final[ids] = qk[which], uk[which]
        steps[ids], status[ids] = k, code

    qk = q
    for k in range(n_steps + 1):
        if live.size == 0:
            break
        uk = law.control(formation, qk)  # u(q_k), as the simulator's Euler step computes it
        min_clear[live] = np.minimum(min_clear[live], clearances(formation, qk))
        if k % check_every == 0 or k == n_steps:
            still = np.max(np.linalg.norm(uk, axis=-1), axis=-1) <= speed
            if kc >= 0:
                d = qk - qc
                net[live] = np.sqrt(np.max(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1], -1))
                net[live] /= (k - kc) * dt
                still |= net[live] <= speed
            qc, kc = qk, k
            finish(still, STATUS_CONVERGED, k, qk, uk)
        else:
            still = np.zeros(live.size, dtype=bool)
        if k == n_steps:
            finish(~still, STATUS_END, k, qk, uk)
            break
        q_new = qk + dt * uk  # explicit Euler
        finite = np.all(np.isfinite(q_new), axis=(-2, -1))
        with np.errstate(invalid="ignore"):
            contact = ~(clearances(formation, np.where(finite[:, None, None], q_new, qk)) > 0)
        bad_nf = ~still & ~finite
        bad_co = ~still & finite & contact
        finish(bad_nf, STATUS_NON_FINITE, k, qk, uk)
        finish(bad_co, STATUS_COLLISION, k, qk, uk)
        keep = ~(still | bad_nf | bad_co)
        live, qk, qc = live[keep], q_new[keep], qc[keep]
    return RawBatch(
        q_final=q_final,
        u_final=u_final,
        steps=steps,
        status=status,
        min_clearance=min_clear,
        net_speed=net,
    )
