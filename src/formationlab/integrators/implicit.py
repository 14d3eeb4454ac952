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

Each step
1. predicts with explicit Euler, ``q+ = q + dt f(q, Upsilon(sigma(q)))``; if
   every weight the predictor used agrees with the side of its surface where
   ``q+`` lands, the step *is* explicit Euler, bit for bit;
2. otherwise, for the surfaces that disagree (and any that start disagreeing
   while it works), it looks for weights in ``{0, 1, free}``: a fixed weight
   must land on its own side, a free one in ``(0, 1)`` must put ``q+`` exactly
   on its surface (``sigma_s(q+) = 0``, solved to round-off with a bracketing
   root finder for one surface, Newton for several: a small nonlinear
   complementarity problem). Fewer free weights are tried first.

A trajectory that reaches an attractive surface therefore lands on it and
stays on it, ``|sigma| ~ 1e-13``, with no switching back and forth; a
transversal crossing takes the field of the side where the step ends.
Away from the surfaces the scheme is explicit Euler: first order.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from ..dynamics import System
from ..validation import check_fields
from ._implicit_batch import BatchCorrection
from .base import FixedStepIntegrator, register_integrator

__all__ = ["ImplicitEuler"]

_FREE = -1.0  # marker of a weight solved for in an assignment
_VECTORISE_FROM = 4  # members to correct in a batch step from which the vectorised path pays


@register_integrator
@dataclass(frozen=True, kw_only=True)
class ImplicitEuler(BatchCorrection, FixedStepIntegrator):
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

    ``step`` accepts a batch ``q`` of shape ``(..., n, 2)``: the predictor is
    vectorised and only the members near a surface are corrected. When four or
    more need it, those with one or two surfaces to resolve (including one that
    widens to a second) are corrected all at once: the same candidates in the
    same order with the same arithmetic as the per-member solver, which stays
    the fallback for the rest (a root that needs Brent, three or more surfaces,
    no consistent weights). The result is the per-member step's.
    """

    name = "implicit-euler"
    tol: float = 1e-12
    max_surfaces: int = 6

    def __post_init__(self) -> None:
        super().__post_init__()
        check_fields(self, positive=("tol",), whole=("max_surfaces",))

    def step(self, system: System, q: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
        """One step from ``q`` (shape ``(n, 2)`` or a batch ``(..., n, 2)``) of length ``dt``."""
        return self._advance(system, q, dt, {})

    def _advance(
        self, system: System, q: NDArray[np.float64], dt: float, counters: dict[str, float]
    ) -> NDArray[np.float64]:
        q = np.asarray(q, dtype=float)
        flat = q if q.ndim == 2 else q.reshape(-1, *q.shape[-2:])
        sigma0 = system.sigma(flat)
        # explicit Euler predictor with the weights Upsilon(sigma(q)) of the surfaces; the
        # same numbers as System.rhs, except on a surface, where the law's steps of the
        # triples that share it could disagree in the last bit of c_ijk
        w0 = (sigma0 >= 0).astype(float)
        base = system.rhs_with(flat, w0)
        q_pred = flat + dt * base
        bad = self._inconsistent(sigma0, system.sigma(q_pred))
        if q.ndim == 2:
            if not bad.any():
                return q_pred  # no surface crossed: explicit Euler exactly
            return self._correct(system, q, sigma0, base, q_pred, bad, dt, counters)
        rows = np.flatnonzero(np.any(bad, axis=-1))
        if rows.size >= _VECTORISE_FROM:
            rows = self._correct_vectorised(
                system, flat, sigma0, base, q_pred, bad, rows, dt, counters
            )
        for b in rows:  # the rest, one by one
            q_pred[b] = self._correct(
                system, flat[b], sigma0[b], base[b], q_pred[b], bad[b], dt, counters
            )
        return q_pred.reshape(q.shape)

    def _inconsistent(
        self, sigma_start: NDArray[np.float64], sigma_end: NDArray[np.float64]
    ) -> NDArray[np.bool_]:
        """Surfaces whose predictor weight ``Upsilon(sigma(q))`` disagrees with ``sigma(q+)``."""
        on = sigma_start >= 0  # Upsilon(0) = 1, as in System.rhs
        return (on & (sigma_end < -self.tol)) | (~on & (sigma_end > self.tol))

    def _correct(
        self,
        system: System,
        q: NDArray[np.float64],
        sigma0: NDArray[np.float64],
        base: NDArray[np.float64],
        q_pred: NDArray[np.float64],
        bad: NDArray[np.bool_],
        dt: float,
        counters: dict[str, float],
    ) -> NDArray[np.float64]:
        """The step from one state ``q`` (n, 2) whose explicit-Euler prediction is inconsistent.

        ``sigma0`` (s,) are the switching functions at ``q``, ``base`` (n, 2) the
        field with the predictor's weights ``Upsilon(sigma0)``, ``q_pred`` the
        predicted end ``q + dt base`` and ``bad`` (s,) the surfaces it disagrees with.
        """
        w0 = (sigma0 >= 0).astype(float)
        counters["corrected_steps"] = counters.get("corrected_steps", 0.0) + 1
        evals = 1
        involved: list[int] = []
        directions: dict[int, NDArray[np.float64]] = {}
        new = [int(j) for j in np.flatnonzero(bad)]
        best: tuple[float, NDArray[np.float64], bool] | None = None
        while new and len(involved) + len(new) <= max(self.max_surfaces, len(new)):
            for j in new:
                w = w0.copy()
                w[j] = 1.0 - w0[j]
                directions[j] = (system.rhs_with(q, w) - base) * (1.0 - 2.0 * w0[j])
                evals += 1
            involved += new
            new = []

            def end_state(wj: NDArray[np.float64], J: list[int] = involved) -> NDArray:
                """``q+`` for the weights ``wj`` of the involved surfaces (f is affine in w)."""
                out = q_pred.copy()
                for m, j in enumerate(J):
                    out += (dt * (wj[m] - w0[j])) * directions[j]
                return out

            guess = self._guess(system, involved, end_state, w0)
            for wj, free in self._assignments(len(involved), guess):
                ok, wj = self._solve_free(system, involved, end_state, wj, free)
                if not ok:
                    continue
                q_end = end_state(wj)
                w = w0.copy()
                w[involved] = wj
                sig = system.sigma(q_end)
                violation = self._violation(w, sig, involved, free)
                if best is None or violation < best[0]:
                    best = (violation, q_end, bool(free))
                if violation <= self.tol:
                    if free:
                        counters["sliding_steps"] = counters.get("sliding_steps", 0.0) + 1
                    counters["extra_rhs_evaluations"] = (
                        counters.get("extra_rhs_evaluations", 0.0) + evals
                    )
                    return q_end
                others = [
                    s for s in np.flatnonzero(self._inconsistent(sigma0, sig)) if s not in involved
                ]
                for s in others:
                    if s not in new:
                        new.append(int(s))
            # a surface outside the involved set became inconsistent: widen and retry
        counters["unresolved_steps"] = counters.get("unresolved_steps", 0.0) + 1
        counters["extra_rhs_evaluations"] = counters.get("extra_rhs_evaluations", 0.0) + evals
        return best[1] if best is not None else q_pred

    @staticmethod
    def _guess(system, involved, end_state, w0) -> tuple[float, ...]:
        """Each surface's own verdict, the others held at ``w0``: off, on or free.

        Off if ``q+`` lands on the off side with either weight, on if on the on
        side with either, free if the two weights land on opposite sides.
        """
        m = len(involved)
        base = np.array([w0[j] for j in involved])
        guess = []
        for i, j in enumerate(involved):
            ends = []
            for value in (0.0, 1.0):
                wj = base.copy()
                wj[i] = value
                ends.append(system.sigma(end_state(wj))[j])
            if ends[0] < 0 and ends[1] < 0:
                guess.append(0.0)
            elif ends[0] >= 0 and ends[1] >= 0:
                guess.append(1.0)
            else:
                guess.append(_FREE)
        return tuple(guess) if m else ()

    @staticmethod
    def _assignments(m: int, first: tuple[float, ...] = ()):
        """Weights in {0, 1, free} for ``m`` surfaces: ``first``, then fewer free ones first."""
        choices = list(itertools.product((0.0, 1.0, _FREE), repeat=m))
        choices.sort(key=lambda c: (c != first, sum(x == _FREE for x in c)))
        for c in choices:
            wj = np.array(c)
            yield wj, [i for i in range(m) if c[i] == _FREE]

    def _violation(
        self,
        w: NDArray[np.float64],
        sig: NDArray[np.float64],
        involved: list[int],
        free: list[int],
    ) -> float:
        """How far the weights ``w`` are from ``w_s in Upsilon(sigma_s(q+))`` (0 if consistent)."""
        v = np.where(w >= 1.0, np.maximum(-sig, 0.0), np.maximum(sig, 0.0))
        for m in free:
            s = involved[m]
            v[s] = abs(sig[s])
        return float(np.max(v, initial=0.0))

    def _solve_free(self, system, involved, end_state, wj, free):
        """Solve ``sigma_F(q+(w)) = 0`` for the free weights; ``(ok, w)`` with ``w`` in [0, 1]."""
        if not free:
            return True, wj
        F = [involved[m] for m in free]
        wj = wj.copy()

        def residual(x: NDArray[np.float64]) -> NDArray[np.float64]:
            w = wj.copy()
            w[free] = x
            return system.sigma(end_state(w))[F]

        if len(free) == 1:  # bracket the root in [0, 1]
            r0, r1 = residual(np.zeros(1))[0], residual(np.ones(1))[0]
            if r0 == 0.0 or r1 == 0.0:
                wj[free] = 0.0 if r0 == 0.0 else 1.0
                return True, wj
            if np.sign(r0) == np.sign(r1):
                return False, wj
            # sigma is quadratic in w for the paper's law (c_abc is bilinear in positions,
            # which are affine in w): the parabola through w = 0, 1/2, 1 gives the root;
            # keep it if it is one to the tolerance, else bracket it (any smooth sigma)
            x = _parabola_root(r0, residual(np.full(1, 0.5))[0], r1)
            if not (0.0 <= x <= 1.0 and abs(residual(np.array([x]))[0]) <= 0.1 * self.tol):
                x = brentq(lambda x: residual(np.array([x]))[0], 0.0, 1.0, xtol=1e-15, rtol=1e-15)
            wj[free] = x
            return True, wj
        x = np.full(len(free), 0.5)  # Newton; sigma is quadratic in w, so central
        h = 1e-4  # differences give its Jacobian exactly (up to round-off)
        for _ in range(50):
            r = residual(x)
            if np.max(np.abs(r)) <= 0.1 * self.tol:
                break
            jac = np.empty((len(free), len(free)))
            for b in range(len(free)):
                e = np.zeros(len(free))
                e[b] = h
                jac[:, b] = (residual(x + e) - residual(x - e)) / (2 * h)
            try:
                x = x - np.linalg.solve(jac, r)
            except np.linalg.LinAlgError:
                return False, wj
            if not np.all(np.isfinite(x)):
                return False, wj
        slack = 1e-9
        if np.any(x < -slack) or np.any(x > 1 + slack):
            return False, wj
        wj[free] = np.clip(x, 0.0, 1.0)
        return True, wj


def _parabola_root(r0: float, rm: float, r1: float) -> float:
    """Root in [0, 1] of the parabola through (0, r0), (1/2, rm), (1, r1), r0 r1 < 0."""
    a = 2.0 * (r1 - 2.0 * rm + r0)
    b = r1 - r0 - a
    if abs(a) <= 1e-12 * (abs(b) + abs(r0)):
        return -r0 / b
    disc = b * b - 4.0 * a * r0
    if disc < 0:
        return float("nan")
    sq = np.sqrt(disc)
    qq = -0.5 * (b + np.copysign(sq, b))  # the stable pair of roots
    roots = [qq / a, r0 / qq if qq != 0 else float("nan")]
    inside = [x for x in roots if 0.0 <= x <= 1.0]
    return float(inside[0]) if inside else float("nan")
