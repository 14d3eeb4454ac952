"""``barrier._solve`` by the dual active-set method: the driver with exact QPs.

The batch kernel solves the centralized QP exactly (``safety/dual_active_set.py``); the
stepping driver's ``barrier_filter`` calls Clarabel, accurate to about 1e-7 on these
commands. Tests that hold the kernel to the driver trial by trial to 1e-9 patch
``formationlab.safety.barrier._solve`` with :func:`exact_solve` in the driver's run, so
that both sides solve the same QPs exactly (Clarabel is the reference of the solver's
own tests, ``test_centralized_kernel_qp.py``).
"""

from __future__ import annotations

import numpy as np

from formationlab.safety.dual_active_set import dual_active_set, workspace


def solve_rows(ri, rj, ra, rb, u_hat):
    """``(code, u, multipliers)`` of :func:`dual_active_set` on the rows, ``u_hat`` ``(n, 2)``."""
    n = u_hat.shape[0]
    mats, vecs, lam, act, _ = workspace(n, len(rb))
    out = np.empty((n, 2))
    code = dual_active_set(ri, rj, ra, rb, u_hat, out, lam, mats, vecs, act)
    return code, out, lam


def exact_solve(G, bound, x_hat):
    """``barrier._solve``'s ``(x, multipliers)``, or None when the rows are infeasible."""
    Gd = G.toarray()
    n = Gd.shape[1] // 2
    blocks = Gd.reshape(len(bound), n, 2)
    on = np.any(blocks != 0.0, axis=-1)  # a row acts on one robot, or on two (+a, -a)
    ri = np.argmax(on, axis=1)
    two = on.sum(axis=1) == 2
    rj = np.where(two, n - 1 - np.argmax(on[:, ::-1], axis=1), -1)
    ra = blocks[np.arange(len(bound)), ri]
    assert np.all(blocks[two, rj[two]] == -ra[two])
    code, out, lam = solve_rows(ri.astype(np.int64), rj.astype(np.int64),
                                np.ascontiguousarray(ra), np.ascontiguousarray(bound),
                                np.asarray(x_hat, dtype=float).reshape(n, 2))  # fmt: skip
    assert code != -2
    return None if code == -1 else (out.reshape(-1), lam)
