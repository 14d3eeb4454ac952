"""Implicit Euler for the set-valued step: sliding on the switching surfaces without chattering.

The angle-restricted law (eq. 11) switches each restriction with the unit step
``Upsilon(sigma_s)`` of eq. (14), ``sigma_s = beta_s c_abc + theta``. Reading
``Upsilon(0)`` as the whole interval ``[0, 1]`` turns the closed loop into the
differential inclusion ``q_dot in F(q)`` (Filippov). This scheme steps

    q+ = q + dt f(q, w),   w_s in Upsilon(sigma_s(q+)),

that is, it is *implicit in the switching weights* ``w`` (each weight is
decided by where the step ends) and explicit in the smooth part of the field
(the semi-implicit variant: the potentials' gradients are evaluated at ``q``).
``f(q, w)`` is ``System.rhs_with(q, w)``, affine in ``w`` (eq. 23: each
restriction enters ``u`` linearly through its step).

Each step, for a whole batch of states at once,

1. predicts with explicit Euler, ``q+ = q + dt f(q, Upsilon(sigma(q)))``; a
   member whose weights all agree with the side of its surface where ``q+``
   lands takes this step: explicit Euler, bit for bit;
2. corrects the other members: for the surfaces that disagree (the
   *involved* ones) it looks for weights in ``{0, 1, free}``, a fixed weight
   landing on its own side and a free one in ``(0, 1)`` putting ``q+`` exactly
   on its surface (``sigma_s(q+) = 0``: a small nonlinear complementarity
   problem). Each member tries its own guess first (each surface's verdict
   with the others held), then assignments with fewer free weights first;
   the first consistent one is taken. One free weight is the root of a
   parabola (``sigma`` is quadratic in ``w`` for the paper's law), refined by
   bisection when it is not a root to the tolerance (any smooth ``sigma``);
   several are found by Newton's method. A member for which no assignment is
   consistent but another surface turned inconsistent widens its involved set
   and tries again (up to ``max_surfaces``).

A trajectory that reaches an attractive surface therefore lands on it and
stays on it, ``|sigma| ~ 1e-13``, with no switching back and forth; a
transversal crossing takes the field of the side where the step ends. Away
from the surfaces the scheme is explicit Euler: first order. A single run is
the batch of one, so a trial steps the same alone or in a batch.
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..dynamics import System
from ..validation import check_fields
from .base import FixedStepIntegrator, register_integrator

__all__ = ["ImplicitEuler"]

_FREE = 2  # code of a weight solved for in an assignment (0 and 1 are fixed weights)
_SLACK = 1e-9  # solved weights within [-slack, 1 + slack] count as in [0, 1]


def _bump(counters: dict[str, float], key: str, add: float) -> None:
    if add:
        counters[key] = counters.get(key, 0) + add


@register_integrator
@dataclass(frozen=True, kw_only=True)
class ImplicitEuler(FixedStepIntegrator):
    """Fixed-step implicit Euler in the switching weights (``integrator = "implicit-euler"``).

    Parameters
    ----------
    dt : float
        Step, seconds.
    tol : float
        A weight solved for must bring ``|sigma_s(q+)|`` below ``tol``; a fixed
        weight is consistent with ``sigma_s(q+)`` up to ``tol``. Default 1e-12
        (``sigma`` is an area of order ``theta``).
    max_surfaces : int
        Most surfaces solved for together in one step (3**max_surfaces
        assignments at worst). Default 6.

    Notes
    -----
    ``stats`` gains ``corrected_steps`` (steps that were not plain explicit
    Euler), ``sliding_steps`` (steps ending on a surface with a solved weight)
    and ``unresolved_steps`` (no consistent weights found; the least
    inconsistent candidate was taken; should be 0).
    """

    name = "implicit-euler"
    tol: float = 1e-12
    max_surfaces: int = 6

    def __post_init__(self) -> None:
        super().__post_init__()
        check_fields(self, positive=("tol",), whole=("max_surfaces",))

    def advance(
        self,
        system: System,
        x: NDArray[np.float64],
        dt: float,
        counters: dict[str, float],
        t: float = 0.0,
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """One step of each state of ``x`` (``(n, k)`` or a batch ``(..., n, k)``).

        The velocity returned is the field with the weights the step settled on
        (the Filippov velocity of a sliding step).
        """
        q = np.asarray(x, dtype=float)
        flat = q.reshape(-1, *q.shape[-2:])
        sigma0 = system.sigma(flat)
        w0 = (sigma0 >= 0).astype(float)  # Upsilon(sigma(q)): the weights of System.rhs
        base = system.rhs_with(flat, w0, t)
        out = flat + dt * base
        bad = self._inconsistent(sigma0, system.sigma(out))
        rows = np.flatnonzero(np.any(bad, axis=-1))
        if rows.size == 0:  # no surface crossed: explicit Euler exactly
            return out.reshape(q.shape), base.reshape(q.shape)
        _bump(counters, "corrected_steps", rows.size)
        involved = {int(r): [int(s) for s in np.flatnonzero(bad[r])] for r in rows}
        best: dict[int, tuple[float, NDArray[np.float64]]] = {}
        pending = [int(r) for r in rows]
        while pending:
            groups: dict[int, list[int]] = defaultdict(list)
            for r in pending:
                groups[len(involved[r])].append(r)
            pending = []
            for members in groups.values():
                R = np.array(members)
                J = np.array([involved[r] for r in members])
                done, free, viol, ends, new = self._assign(system, flat, sigma0, base, R, J, dt, t)
                out[R[done]] = ends[done]
                _bump(counters, "sliding_steps", int(np.sum(done & free)))
                _bump(counters, "extra_rhs_evaluations", (1 + J.shape[1]) * R.size)
                for m in np.flatnonzero(~done):
                    r = members[m]
                    if r not in best or viol[m] < best[r][0]:
                        best[r] = (float(viol[m]), ends[m])
                    extra = [int(s) for s in np.flatnonzero(new[m])]
                    if extra and len(involved[r]) + len(extra) <= self.max_surfaces:
                        involved[r] += extra  # another surface turned inconsistent: widen
                        pending.append(r)
                    else:
                        out[r] = best[r][1]
                        _bump(counters, "unresolved_steps", 1)
        v = base.copy()
        v[rows] = (out[rows] - flat[rows]) / dt
        return out.reshape(q.shape), v.reshape(q.shape)

    def _inconsistent(
        self, sigma_start: NDArray[np.float64], sigma_end: NDArray[np.float64]
    ) -> NDArray[np.bool_]:
        """Surfaces whose predictor weight ``Upsilon(sigma(q))`` disagrees with ``sigma(q+)``."""
        on = sigma_start >= 0  # Upsilon(0) = 1, as in System.rhs
        return (on & (sigma_end < -self.tol)) | (~on & (sigma_end > self.tol))

    def _assign(
        self,
        system: System,
        q: NDArray[np.float64],
        sigma0: NDArray[np.float64],
        base: NDArray[np.float64],
        rows: NDArray[np.intp],
        involved: NDArray[np.intp],
        dt: float,
        t: float = 0.0,
    ) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
        """Weights of the ``m`` involved surfaces ``(R, m)`` of the batch members ``rows``.

        Tries every assignment in ``{0, 1, free}^m`` in each member's order (its
        guess, then fewer free weights first) and keeps the first consistent one.
        Returns, per member: decided, whether the decided assignment has a free
        weight, the least violation seen, the end state (decided, else the least
        violating), and the surfaces outside ``involved`` that turned inconsistent.
        """
        R, m = involved.shape
        r_, rr = np.arange(R), np.arange(R)[:, None]
        w0 = (sigma0[rows] >= 0).astype(float)
        w0J = w0[rr, involved]
        pred = q[rows] + dt * base[rows]
        directions = []  # d q+ / d w_j for each involved surface (f is affine in w)
        for i in range(m):
            w = w0.copy()
            w[r_, involved[:, i]] = 1.0 - w0J[:, i]
            turn = (1.0 - 2.0 * w0J[:, i])[:, None, None]
            directions.append(dt * (system.rhs_with(q[rows], w, t) - base[rows]) * turn)

        def end(x: NDArray[np.float64], sel: NDArray[np.intp] = r_) -> NDArray[np.float64]:
            """``q+`` for the weights ``x`` ``(k, m)`` of the members ``sel``."""
            out = pred[sel].copy()
            for i in range(m):
                out += (x[:, i] - w0J[sel, i])[:, None, None] * directions[i][sel]
            return out

        def own(x: NDArray[np.float64], sel: NDArray[np.intp] = r_) -> NDArray[np.float64]:
            """``sigma`` of the involved surfaces at ``end(x)``; ``(k, m)``."""
            return system.sigma(end(x, sel))[np.arange(len(sel))[:, None], involved[sel]]

        guess = np.empty((R, m), int)  # each surface's own verdict, the others held at w0
        for i in range(m):
            ends = []
            for value in (0.0, 1.0):
                x = w0J.copy()
                x[:, i] = value
                ends.append(own(x)[:, i])
            both_on = (ends[0] >= 0) & (ends[1] >= 0)
            guess[:, i] = np.where((ends[0] < 0) & (ends[1] < 0), 0, np.where(both_on, 1, _FREE))
        cands = sorted(itertools.product((0, 1, _FREE), repeat=m), key=lambda c: c.count(_FREE))
        done = np.zeros(R, bool)
        free = np.zeros(R, bool)
        viol = np.full(R, np.inf)
        ends_out = pred.copy()
        new = np.zeros((R, sigma0.shape[-1]), bool)
        for c in range(len(cands) + 1):
            assign = guess if c == 0 else np.broadcast_to(np.array(cands[c - 1]), (R, m))
            todo = ~done if c == 0 else ~done & np.any(guess != assign, axis=-1)
            sel = np.flatnonzero(todo)
            if sel.size == 0:
                if done.all():
                    break
                continue
            a = assign[sel]
            x, ok = self._solve(own, a.astype(float), a == _FREE, sel)
            q_end = end(x, sel)
            sig = system.sigma(q_end)
            w = w0[sel].copy()
            w[np.arange(sel.size)[:, None], involved[sel]] = x
            v = np.where(w >= 1.0, np.maximum(-sig, 0.0), np.maximum(sig, 0.0))
            isfree, cols, ix = a == _FREE, involved[sel], np.arange(sel.size)[:, None]
            v[ix, cols] = np.where(isfree, np.abs(sig[ix, cols]), v[ix, cols])
            v = np.where(ok[:, None], v, np.inf)
            worst = np.max(v, axis=-1, initial=0.0)
            good = ok & (worst <= self.tol) & np.all(np.isfinite(q_end), axis=(-2, -1))
            better = worst < viol[sel]
            viol[sel] = np.minimum(viol[sel], worst)
            ends_out[sel[better | good]] = q_end[better | good]
            fresh = ok[:, None] & ~good[:, None] & self._inconsistent(sigma0[rows[sel]], sig)
            fresh[ix, cols] = False
            new[sel] |= fresh
            done[sel[good]] = True
            free[sel[good]] = np.any(isfree[good], axis=-1)
        new[done] = False
        return done, free, viol, ends_out, new

    def _solve(self, own, x, isfree, sel):
        """Solve ``sigma_F(q+(x)) = 0`` for the free weights (mask ``isfree`` ``(k, m)``).

        Returns the weights ``(k, m)`` and whether a solution in ``[0, 1]`` was found.
        One free weight: the root of the parabola through ``w = 0, 1/2, 1`` (exact
        for a ``sigma`` quadratic in ``w``), else bisection of the bracket
        ``[0, 1]``; several: Newton's method from ``1/2`` with central differences.
        """
        k, m = x.shape
        ok = np.ones(k, bool)
        nfree = isfree.sum(axis=-1)
        col = np.argmax(isfree, axis=-1)
        one = np.flatnonzero(nfree == 1)
        if one.size:
            c = col[one]

            def res(value: NDArray[np.float64], idx: NDArray[np.intp] = one) -> NDArray:
                y = x[idx].copy()
                y[np.arange(idx.size), col[idx]] = value
                return own(y, sel[idx])[np.arange(idx.size), col[idx]]

            r0, r1 = res(np.zeros(one.size)), res(np.ones(one.size))
            root = np.where(r0 == 0.0, 0.0, 1.0)
            bracket = (r0 != 0.0) & (r1 != 0.0)
            ok[one] = ~bracket | (np.sign(r0) != np.sign(r1))
            live = bracket & ok[one]
            if live.any():
                par = _parabola_roots(r0, res(np.full(one.size, 0.5)), r1)
                fits = (par >= 0.0) & (par <= 1.0)
                fits &= np.abs(res(np.where(fits, par, 0.5))) <= 0.1 * self.tol
                root = np.where(live & fits, par, root)
                lo, hi, f_lo = np.zeros(one.size), np.ones(one.size), r0.copy()
                slow = np.flatnonzero(live & ~fits)
                for _ in range(60 if slow.size else 0):  # bisection of [0, 1] to round-off
                    mid = 0.5 * (lo[slow] + hi[slow])
                    f_mid = res(mid, one[slow])
                    left = np.sign(f_mid) == np.sign(f_lo[slow])
                    lo[slow] = np.where(left, mid, lo[slow])
                    f_lo[slow] = np.where(left, f_mid, f_lo[slow])
                    hi[slow] = np.where(left, hi[slow], mid)
                root[slow] = 0.5 * (lo[slow] + hi[slow])
            x[one, c] = root
        many = np.flatnonzero(nfree >= 2)
        if many.size:
            mask = isfree[many]
            y = np.where(mask, 0.5, x[many])
            h = 1e-4
            live = np.arange(many.size)
            for _ in range(50):
                r = np.where(mask[live], own(y[live], sel[many[live]]), 0.0)
                going = np.max(np.abs(r), axis=-1) > 0.1 * self.tol
                live, r = live[going], r[going]
                if live.size == 0:
                    break
                jac = np.empty((live.size, m, m))
                for b in range(m):
                    e = np.zeros(m)
                    e[b] = h
                    plus = own(y[live] + e, sel[many[live]])
                    jac[:, :, b] = (plus - own(y[live] - e, sel[many[live]])) / (2 * h)
                fixed = ~mask[live]  # fixed weights: identity rows, zero residual, no step
                jac = np.where(fixed[:, :, None] | fixed[:, None, :], 0.0, jac)
                idx = np.nonzero(fixed)
                jac[idx[0], idx[1], idx[1]] = 1.0
                step, singular = _solve_stack(jac, r)
                y[live] -= step
                failed = singular | ~np.all(np.isfinite(y[live]), axis=-1)
                ok[many[live[failed]]] = False
                live = live[~failed]
            inside = np.all((y >= -_SLACK) & (y <= 1 + _SLACK), axis=-1)
            ok[many] &= inside
            x[many] = np.where(mask, np.clip(y, 0.0, 1.0), x[many])
        return x, ok


def _solve_stack(
    a: NDArray[np.float64], b: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """``a x = b`` for a stack ``(k, m, m)``, ``(k, m)``; singular members get ``x = 0``."""
    try:
        x = np.asarray(np.linalg.solve(a, b[..., None])[..., 0], dtype=np.float64)
        return x, np.zeros(len(a), bool)
    except np.linalg.LinAlgError:
        x, singular = np.zeros_like(b), np.zeros(len(a), bool)
        for i in range(len(a)):
            try:
                x[i] = np.linalg.solve(a[i], b[i])
            except np.linalg.LinAlgError:
                singular[i] = True
        return x, singular.astype(np.bool_)


def _parabola_roots(
    r0: NDArray[np.float64], rm: NDArray[np.float64], r1: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Root in [0, 1] of the parabola through (0, r0), (1/2, rm), (1, r1); NaN where none."""
    with np.errstate(all="ignore"):
        a = 2.0 * (r1 - 2.0 * rm + r0)
        b = r1 - r0 - a
        linear = np.abs(a) <= 1e-12 * (np.abs(b) + np.abs(r0))
        disc = b * b - 4.0 * a * r0
        qq = -0.5 * (b + np.copysign(np.sqrt(np.maximum(disc, 0.0)), b))  # the stable pair
        first = qq / a
        second = np.where(qq != 0, r0 / np.where(qq != 0, qq, 1.0), np.nan)
        inside = (0.0 <= first) & (first <= 1.0)
        other = np.where((0.0 <= second) & (second <= 1.0), second, np.nan)
        quad = np.where(disc < 0, np.nan, np.where(inside, first, other))
        return np.where(linear, -r0 / b, quad)
