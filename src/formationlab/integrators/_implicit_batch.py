"""The vectorised part of :class:`~formationlab.integrators.implicit.ImplicitEuler`'s batched step.

Batch members at one or two switching surfaces are corrected together, with the
same candidates, root formula, checks and Newton iterations as the per-member
solver of ``implicit.py``, which stays the fallback for every other case.
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System

__all__: list[str] = []


class BatchCorrection:
    """Mixin of :class:`ImplicitEuler`: corrections of many batch members at once.

    Uses the integrator's ``tol``, ``max_surfaces`` and ``_inconsistent``.
    """

    tol: float
    max_surfaces: int

    def _inconsistent(
        self, sigma_start: NDArray[np.float64], sigma_end: NDArray[np.float64]
    ) -> NDArray[np.bool_]:
        raise NotImplementedError

    def _correct_vectorised(self, system, q, sigma0, base, q_pred, bad, rows, dt, counters):
        """Correct the members ``rows`` at one or two surfaces at once; return the others."""
        count = np.count_nonzero(bad[rows], axis=-1)
        one, two = rows[count == 1], rows[count == 2]
        done, widen = self._correct_batch(
            system, q, sigma0, base, q_pred, one, np.argmax(bad[one], axis=-1)[:, None], dt,
            counters,
        )  # fmt: skip
        wider = widen >= 0 if self.max_surfaces >= 2 else np.zeros(one.size, bool)
        pairs = np.concatenate(
            [
                np.nonzero(bad[two])[1].reshape(-1, 2),
                np.stack([np.argmax(bad[one[wider]], axis=-1), widen[wider]], axis=-1),
            ]
        )
        both = np.concatenate([two, one[wider]])
        if both.size == 0:
            return np.setdiff1d(rows, one[done])
        done2, _ = self._correct_batch(system, q, sigma0, base, q_pred, both, pairs, dt, counters)
        return np.setdiff1d(rows, np.concatenate([one[done], both[done2]]))

    def _correct_batch(
        self,
        system: System,
        q: NDArray[np.float64],
        sigma0: NDArray[np.float64],
        base: NDArray[np.float64],
        q_pred: NDArray[np.float64],
        rows: NDArray[np.intp],
        involved: NDArray[np.intp],
        dt: float,
        counters: dict[str, float],
    ) -> tuple[NDArray[np.bool_], NDArray[np.intp]]:
        """:meth:`_correct` for the batch members ``rows`` at once, ``m`` = 1 or 2 surfaces.

        ``involved`` (R, m) are the surfaces of each member, in :meth:`_correct`'s
        order; the other arrays are the batch's, ``(B, ...)``. The same candidates
        in the same order (the guess, then fewest free weights first), the same
        arithmetic (Newton included), member by member; ``q_pred[rows]`` is
        overwritten where the step is decided. Returns ``decided`` (R,) and, for
        the members where no candidate was consistent and exactly one other
        surface turned inconsistent (which :meth:`_correct` would add), that
        surface, else -1 (R,). Undecided members (a candidate needing Brent
        before the first consistent one, several new surfaces, not finite) are
        left to :meth:`_correct`.
        """
        R, m = involved.shape
        r = np.arange(R)
        rr = r[:, None]
        w0 = (sigma0[rows] >= 0).astype(float)
        w0J = w0[rr, involved]
        qb, bb, pred = q[rows], base[rows], q_pred[rows]
        directions = []
        for i in range(m):
            w = w0.copy()
            w[r, involved[:, i]] = 1.0 - w0J[:, i]
            turn = (1.0 - 2.0 * w0J[:, i])[:, None, None]
            directions.append((system.rhs_with(qb, w) - bb) * turn)

        def end(x: NDArray[np.float64], sel: NDArray = r) -> NDArray[np.float64]:
            """``q+`` for the weights ``x`` (k, m) of the members ``sel``, as in _correct."""
            out = pred[sel].copy()
            for i in range(m):
                out += (dt * (x[:, i] - w0J[sel, i]))[:, None, None] * directions[i][sel]
            return out

        def own(x: NDArray[np.float64], cols: list[int], sel: NDArray = r) -> NDArray:
            """``sigma`` of the surfaces ``involved[:, cols]`` at ``end(x)``; (k, len(cols))."""
            return system.sigma(end(x, sel))[np.arange(len(sel))[:, None], involved[sel][:, cols]]

        guess = np.empty((R, m), int)
        for i in range(m):
            ends = []
            for value in (0.0, 1.0):
                x = w0J.copy()
                x[:, i] = value
                ends.append(own(x, [i])[:, 0])
            both_on = (ends[0] >= 0) & (ends[1] >= 0)
            guess[:, i] = np.where((ends[0] < 0) & (ends[1] < 0), 0, np.where(both_on, 1, 2))

        cands = list(itertools.product((0, 1, 2), repeat=m))  # 2: free
        status = np.zeros((len(cands), R), int)  # 0 failed, 1 consistent, 2 undecided
        q_ends = np.empty((len(cands), R, *q.shape[-2:]))
        new = np.zeros((len(cands), R, sigma0.shape[-1]), bool)
        finite = np.all([np.isfinite(d).all(axis=(-2, -1)) for d in directions], axis=0)
        for c, cand in enumerate(cands):
            free = [i for i in range(m) if cand[i] == 2]
            x = np.array([0.5 if v == 2 else float(v) for v in cand]) * np.ones((R, 1))
            ok = np.ones(R, bool)
            if len(free) == 1:
                ok, undecided = self._solve_one_batch(own, x, free[0])
                status[c, undecided] = 2
            elif len(free) == 2:
                ok = self._solve_two_batch(own, x)
            q_ends[c] = end(x)
            sig = system.sigma(q_ends[c])
            finite &= np.isfinite(sig).all(axis=-1) | ~ok
            w = w0.copy()
            w[rr, involved] = x
            v = np.where(w >= 1.0, np.maximum(-sig, 0.0), np.maximum(sig, 0.0))
            for i in free:
                v[r, involved[:, i]] = np.abs(sig[r, involved[:, i]])
            good = ok & (np.max(v, axis=-1, initial=0.0) <= self.tol)
            status[c, good] = 1
            new[c] = ok[:, None] & ~good[:, None] & self._inconsistent(sigma0[rows], sig)
            new[c, rr, involved] = False

        # _assignments' order for each member: its guess first, then fewest free weights
        nfree = np.array([sum(v == 2 for v in cand) for cand in cands])
        is_guess = np.array([np.all(guess == np.array(cand), axis=-1) for cand in cands])
        rank = np.where(is_guess, -1, nfree[:, None] * len(cands) + np.arange(len(cands))[:, None])
        order = np.argsort(rank, axis=0, kind="stable")
        ordered = status[order, r]
        first = np.argmax(ordered > 0, axis=0)
        hit = ordered[first, r]
        decided = (hit == 1) & finite
        chosen = order[first, r]
        q_pred[rows[decided]] = q_ends[chosen, r][decided]
        widen = np.full(R, -1)
        lone = (hit == 0) & finite & (np.count_nonzero(new.any(axis=0), axis=-1) == 1)
        widen[lone] = np.argmax(new.any(axis=0), axis=-1)[lone]
        n = int(decided.sum())
        n_free = int(np.sum(decided & (nfree[chosen] > 0)))
        for key, add in (
            ("corrected_steps", n),
            ("extra_rhs_evaluations", (1 + m) * n),
            ("sliding_steps", n_free),
        ):
            if add:
                counters[key] = counters.get(key, 0.0) + add
        return decided, widen

    def _solve_one_batch(self, own, x, i):
        """:meth:`_solve_free` with the one free weight ``x[:, i]``, in place.

        Returns ``ok`` (a root in [0, 1] found as _solve_free finds it without
        Brent) and ``undecided`` (_solve_free would call Brent).
        """
        cols = [i]

        def res(value):
            y = x.copy()
            y[:, i] = value
            return own(y, cols)[:, 0]

        r0, r1 = res(0.0), res(1.0)
        x[:, i] = np.where(r0 == 0.0, 0.0, 1.0)
        bracket = (r0 != 0.0) & (r1 != 0.0)
        ok = ~bracket | (np.sign(r0) != np.sign(r1))
        undecided = np.zeros(len(x), bool)
        if np.any(bracket & ok):
            root = _parabola_roots(r0, res(0.5), r1)
            fits = (0.0 <= root) & (root <= 1.0)
            fits &= np.abs(res(np.where(fits, root, 0.5))) <= 0.1 * self.tol
            undecided = bracket & ok & ~fits
            x[:, i] = np.where(bracket, np.where(fits, root, 0.5), x[:, i])
        return ok & ~undecided, undecided

    def _solve_two_batch(self, own, x):
        """:meth:`_solve_free`'s Newton for two free weights, member by member, in place."""
        R = len(x)
        cols = [0, 1]
        y = np.full((R, 2), 0.5)
        ok = np.ones(R, bool)
        live = np.arange(R)
        h = 1e-4
        for _ in range(50):
            if live.size == 0:
                break
            res = own(y[live], cols, live)
            going = np.max(np.abs(res), axis=-1) > 0.1 * self.tol
            live, res = live[going], res[going]
            if live.size == 0:
                break
            jac = np.empty((live.size, 2, 2))
            for b in range(2):
                e = np.zeros(2)
                e[b] = h
                jac[:, :, b] = (own(y[live] + e, cols, live) - own(y[live] - e, cols, live)) / (
                    2 * h
                )
            try:
                step = np.linalg.solve(jac, res[..., None])[..., 0]
                singular = np.zeros(live.size, bool)
            except np.linalg.LinAlgError:
                step, singular = np.zeros((live.size, 2)), np.zeros(live.size, bool)
                for k in range(live.size):
                    try:
                        step[k] = np.linalg.solve(jac[k], res[k])
                    except np.linalg.LinAlgError:
                        singular[k] = True
            y[live] = y[live] - step
            failed = singular | ~np.all(np.isfinite(y[live]), axis=-1)
            ok[live[failed]] = False
            live = live[~failed]
        slack = 1e-9
        ok &= ~(np.any(y < -slack, axis=-1) | np.any(y > 1 + slack, axis=-1))
        x[:] = np.where(ok[:, None], np.clip(y, 0.0, 1.0), x)
        return ok


def _parabola_roots(
    r0: NDArray[np.float64], rm: NDArray[np.float64], r1: NDArray[np.float64]
) -> NDArray[np.float64]:
    """:func:`implicit._parabola_root` elementwise, the same arithmetic; NaN where it has none."""
    with np.errstate(all="ignore"):
        a = 2.0 * (r1 - 2.0 * rm + r0)
        b = r1 - r0 - a
        linear = np.abs(a) <= 1e-12 * (np.abs(b) + np.abs(r0))
        disc = b * b - 4.0 * a * r0
        qq = -0.5 * (b + np.copysign(np.sqrt(np.maximum(disc, 0.0)), b))
        first = qq / a
        second = np.where(qq != 0, r0 / np.where(qq != 0, qq, 1.0), np.nan)
        inside = (0.0 <= first) & (first <= 1.0)
        other = np.where((0.0 <= second) & (second <= 1.0), second, np.nan)
        quad = np.where(disc < 0, np.nan, np.where(inside, first, other))
        return np.where(linear, -r0 / b, quad)
