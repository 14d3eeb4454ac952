"""Switching diagnostics shared by every integrator: switches, sliding time, excursions.

The angle-restricted law (eq. 11) switches each restriction on and off with the
step ``Upsilon`` of eq. (14), so its closed loop is a Filippov system with
switching functions ``sigma_s(q)`` (``System.sigma``; a restriction is on where
``sigma_s >= 0``). These diagnostics say what an integrator did at the surfaces
``sigma_s = 0``, so that a user can tell the law's behaviour from the scheme's:

``switch_count``
    How many times any surface changed state between consecutive accepted
    states. A surface's state is *off* (``sigma < -tol``), *on*
    (``sigma > tol``) or *on the surface* (``|sigma| <= tol``). A transversal
    crossing counts 1; landing on a surface and leaving it counts 2; explicit
    Euler chattering across a sliding surface counts about one per step.
``sliding_time``
    Time during which at least one surface is in a sliding phase: its state
    stays on the surface (sliding-mode integrators), or it is crossed back
    before the state got farther from it than ``chatter_factor`` times the
    jump of the step that crossed it (explicit schemes, which cannot stay on a
    surface and chatter across it instead: each step across the surface is
    pushed back by the field of the other side). After a genuine transversal
    crossing the state moves on, away from the surface.
``sliding_start``, ``sliding_end``
    Start of the first and end of the last sliding phase (NaN if none).
``max_excursion``
    Largest ``|sigma|`` reached during a sliding phase: zero to round-off for a
    scheme that stays on the surface, about ``k_a dt |grad sigma|^2`` for
    explicit Euler. In the units of ``sigma`` (for the paper's law an area,
    ``beta c_abc + theta``).

For a smooth law (no surfaces) all of them are zero (NaN for the times).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["CHATTER_FACTOR", "SURFACE_TOL", "SwitchMonitor", "switching_diagnostics"]

#: ``|sigma| <= SURFACE_TOL`` counts as on the surface (sigma is O(theta) = O(0.1-1)).
SURFACE_TOL = 1e-9
#: a return across a surface before ``|sigma|`` exceeded this many times the jump of the
#: step that crossed it is chattering
CHATTER_FACTOR = 2.0


def _labels(sigma: NDArray[np.float64], tol: float) -> NDArray[np.int8]:
    """-1 off, 0 on the surface, +1 on; shape of ``sigma``."""
    return np.where(sigma > tol, 1, np.where(sigma < -tol, -1, 0)).astype(np.int8)


@dataclass(kw_only=True)
class SwitchMonitor:
    """Accumulates the switching diagnostics one accepted state at a time.

    Memory does not grow with the number of steps (only with the number of
    separate sliding phases). Vectorised over the ``s`` surfaces.

    Parameters
    ----------
    sigma0 : ndarray, shape (s,)
        Switching functions at the initial state.
    t0 : float
        Initial time.
    tol : float
        Half-width of the band ``|sigma| <= tol`` that counts as on the surface.
    chatter_factor : float
        A surface crossed back before ``|sigma|`` exceeded ``chatter_factor`` times
        the jump ``|sigma_k - sigma_{k-1}|`` of the step that crossed it is chattering.
    """

    sigma0: NDArray[np.float64]
    t0: float = 0.0
    tol: float = SURFACE_TOL
    chatter_factor: float = CHATTER_FACTOR
    switch_count: int = 0
    max_excursion: float = 0.0
    intervals: list[list[float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        s = np.asarray(self.sigma0, dtype=float).reshape(-1)
        self._sigma = s.copy()
        self._label = _labels(s, self.tol)
        self._t = float(self.t0)
        self._crossed = np.zeros(s.shape, dtype=bool)  # crossed at least once
        self._last_cross_t = np.zeros(s.shape)
        self._jump = np.zeros(s.shape)
        self._peak = np.abs(s)

    def _add_interval(self, a: float, b: float) -> None:
        iv = self.intervals
        while iv and a <= iv[-1][1]:
            a0, b0 = iv.pop()
            a, b = min(a, a0), max(b, b0)
        iv.append([a, b])

    def record(self, t: float, sigma: NDArray[np.float64]) -> None:
        """Take the accepted state at time ``t`` with switching functions ``sigma`` (s,)."""
        if self._sigma.size == 0:
            self._t = t
            return
        sigma = np.asarray(sigma, dtype=float).reshape(-1)
        t_prev = self._t
        label = _labels(sigma, self.tol)
        changed = label != self._label
        if changed.any():
            self.switch_count += int(np.count_nonzero(changed))
        absval = np.abs(sigma)
        crossed = (label.astype(np.int16) * self._label) == -1
        self._peak = np.where(crossed, self._peak, np.maximum(self._peak, absval))
        for c in np.flatnonzero(crossed):
            jump = abs(sigma[c] - self._sigma[c])
            if self._crossed[c] and self._peak[c] <= self.chatter_factor * self._jump[c]:
                self._add_interval(float(self._last_cross_t[c]), t)  # crossed back: chattering
                self.max_excursion = max(self.max_excursion, float(self._peak[c]), absval[c])
            self._crossed[c] = True
            self._last_cross_t[c] = t_prev
            self._jump[c] = jump
            self._peak[c] = absval[c]
        resting = (label == 0) & (self._label == 0)
        if resting.any():
            self._add_interval(t_prev, t)
            self.max_excursion = max(self.max_excursion, float(np.max(absval[resting])))
        self._sigma, self._label, self._t = sigma, label, t

    def stats(self) -> dict[str, float]:
        """The diagnostics so far, a dict of floats (keys as in the module docstring)."""
        iv = self.intervals
        return {
            "switch_count": float(self.switch_count),
            "sliding_time": float(sum(b - a for a, b in iv)),
            "sliding_start": float(iv[0][0]) if iv else float("nan"),
            "sliding_end": float(iv[-1][1]) if iv else float("nan"),
            "max_excursion": float(self.max_excursion),
        }


def switching_diagnostics(
    t: ArrayLike,
    sigma: ArrayLike,
    *,
    tol: float = SURFACE_TOL,
    chatter_factor: float = CHATTER_FACTOR,
) -> dict[str, float]:
    """The switching diagnostics of a stored history (every step, not a thinned one).

    What :class:`SwitchMonitor` gives when fed the states one by one (tested equal), with
    the loop over time done by numpy: the crossings of each surface and the maxima of
    ``|sigma|`` between them, the steps spent on a surface, and the union of the sliding
    intervals.

    Parameters
    ----------
    t : array_like, shape (T,)
        Times of the accepted states.
    sigma : array_like, shape (T, s)
        Switching functions at those states.
    tol, chatter_factor
        As in :class:`SwitchMonitor`.

    Returns
    -------
    dict
        ``switch_count``, ``sliding_time``, ``sliding_start``, ``sliding_end``,
        ``max_excursion``.
    """
    t = np.asarray(t, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    sigma = sigma.reshape(len(t), -1)
    if sigma.shape[1] == 0 or len(t) < 2:  # a smooth law: nothing switches
        return SwitchMonitor(sigma0=sigma[0] if len(t) else np.zeros(0)).stats()
    label = _labels(sigma, tol)
    absval = np.abs(sigma)
    switches = int(np.count_nonzero(label[1:] != label[:-1]))
    intervals: list[tuple[NDArray[np.float64], NDArray[np.float64]]] = []
    excursions = [np.zeros(1)]
    # resting: on the surface at both ends of step k (k = 1..T-1)
    resting = (label[1:] == 0) & (label[:-1] == 0)
    steps = np.flatnonzero(resting.any(axis=1)) + 1
    if steps.size:
        intervals.append((t[steps - 1], t[steps]))
        excursions.append(np.where(resting, absval[1:], 0.0).max(axis=1))
    # crossings: a strict change of side at step k; a crossing back at k after one at k'
    # with max |sigma| over k'..k-1 at most chatter_factor times the jump of step k' chatters
    crossed = (label[1:].astype(np.int16) * label[:-1]) == -1
    surface, k = np.nonzero(crossed.T)  # by surface, then step (of k = 1..T-1, minus one)
    k = k + 1
    again = np.flatnonzero(surface[1:] == surface[:-1])  # pairs (k', k) of one surface
    if again.size:
        c, first, then = surface[again], k[again], k[again + 1]
        T = len(t)
        flat = absval.T.ravel()
        bounds = np.stack([c * T + first, c * T + then], axis=1).ravel()
        peak = np.maximum.reduceat(flat, bounds)[::2]  # max |sigma| over k'..k-1
        jump = np.abs(sigma[first, c] - sigma[first - 1, c])
        chatter = peak <= chatter_factor * jump
        if chatter.any():
            intervals.append((t[first[chatter] - 1], t[then[chatter]]))
            excursions += [peak[chatter], absval[then[chatter], c[chatter]]]
    merged = _union(intervals)
    return {
        "switch_count": float(switches),
        "sliding_time": float(sum(b - a for a, b in merged)),
        "sliding_start": float(merged[0][0]) if merged else float("nan"),
        "sliding_end": float(merged[-1][1]) if merged else float("nan"),
        "max_excursion": float(np.max(np.concatenate(excursions))),
    }


def _union(
    intervals: list[tuple[NDArray[np.float64], NDArray[np.float64]]],
) -> list[tuple[float, float]]:
    """The union of closed intervals ``[a, b]``, as sorted disjoint ones (touching ones merged)."""
    if not intervals:
        return []
    a = np.concatenate([iv[0] for iv in intervals])
    b = np.concatenate([iv[1] for iv in intervals])
    order = np.argsort(a, kind="stable")
    out: list[tuple[float, float]] = []
    for lo, hi in zip(a[order].tolist(), b[order].tolist(), strict=True):
        if out and lo <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], hi))
        else:
            out.append((lo, hi))
    return out
