"""Event-driven Filippov reference integrator for the discontinuous law (small formations).

The angle-restricted law (eq. 11) switches each restriction with the step
``Upsilon(sigma_s)`` of eq. (14), ``sigma_s = beta_s c_abc + theta`` (the line
``s`` of eq. 26 for a moving robot). Filippov's solution concept replaces the
field on a surface by the convex combination of the fields on its two sides.
This integrator follows it literally:

* between switches every surface is in a *mode*, off (weight 0), on (weight 1)
  or sliding, and the now smooth field is integrated by an adaptive
  high-order solver (``scipy.integrate.solve_ivp``, DOP853, tight tolerances);
* events locate each crossing of a surface ``sigma_s = 0`` (watched in the
  direction that leaves the current mode) and each sliding weight reaching 0
  or 1 (the exit of a sliding phase);
* at a crossing the new modes of the surfaces that are touched are chosen so
  that they are consistent: an *off* surface must be left on its off side
  (``d sigma/dt < 0`` with weight 0), an *on* surface on its on side, and a
  sliding surface must get a weight in ``[0, 1]``. This is the sliding
  condition checked on both sides (a surface is attractive when the normal
  components of the fields on both sides point to it);
* while sliding, the weights of the sliding surfaces solve the small linear
  system ``d sigma_S / dt = -mu sigma_S`` (``d sigma/dt = 0`` plus a weak
  drift correction ``mu``), which is the Filippov convex combination, also
  for several surfaces at once.

The field must be affine in the weights (``System.rhs_with``; the paper's law
is, eq. 23) and the directional derivatives of ``sigma`` are taken by central
differences, exact for the paper's ``sigma`` (quadratic in ``q``).

It is slow (every field evaluation is Python-level, several per sliding
evaluation) and meant for a few robots: it is the yardstick the fixed-step
integrators are tested against.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from ..dynamics import System
from ..errors import ParameterError
from ..status import Status
from ..validation import check_fields, one_of
from .base import Integrator, RawSolution, register_integrator, steps_for
from .driver import Progress, position_dim

__all__ = ["OFF", "ON", "SLIDE", "Filippov"]

OFF, ON, SLIDE = 0, 1, 2
_METHODS = ("DOP853", "RK45", "RK23", "Radau", "BDF", "LSODA")  # solve_ivp's
_SLACK = 1e-9  # sliding weights within [-slack, 1 + slack] count as in [0, 1]


def _ddir(system: System, q: NDArray, v: NDArray, scale: float = 1e-3) -> NDArray:
    """``grad sigma(q) . v`` for every surface by central differences, shape (s,)."""
    vmax = float(np.max(np.abs(v)))
    if vmax == 0.0:
        return np.zeros(system.sigma(q).shape)
    h = scale / vmax
    return (system.sigma(q + h * v) - system.sigma(q - h * v)) / (2 * h)


class _Field:
    """The smooth field of one mode assignment; counts field evaluations."""

    def __init__(self, system: System, shape: tuple[int, ...], mu: float) -> None:
        self.system, self.shape, self.mu = system, shape, mu
        self.rhs_evaluations = 0
        self._cache: tuple[bytes, NDArray, NDArray] | None = None
        self.modes: NDArray[np.int64] = np.zeros(0, dtype=np.int64)

    def evaluate(self, q: NDArray, modes: NDArray) -> tuple[NDArray, NDArray]:
        """Velocity (n, 2) and full weight vector (s,) for ``modes`` at ``q``."""
        system = self.system
        w = (modes == ON).astype(float)
        S = np.flatnonzero(modes == SLIDE)
        base = system.rhs_with(q, w)
        self.rhs_evaluations += 1
        if S.size == 0:
            return base, w
        cols = []
        for b in S:
            wb = w.copy()
            wb[b] = 1.0
            cols.append(system.rhs_with(q, wb) - base)
            self.rhs_evaluations += 1
        A = np.empty((S.size, S.size))
        for m, g in enumerate(cols):
            A[:, m] = _ddir(system, q, g)[S]
        rhs = -(_ddir(system, q, base)[S] + self.mu * system.sigma(q)[S])
        try:
            wS = np.linalg.solve(A, rhs)
        except np.linalg.LinAlgError:
            wS = np.linalg.lstsq(A, rhs, rcond=None)[0]
        w[S] = wS
        f = base + sum(wS[m] * cols[m] for m in range(S.size))
        return f, w

    def at(self, y: NDArray) -> tuple[NDArray, NDArray]:
        """Cached :meth:`evaluate` for the current modes at the flat state ``y``."""
        key = y.tobytes()
        if self._cache is None or self._cache[0] != key:
            f, w = self.evaluate(y.reshape(self.shape), self.modes)
            self._cache = (key, f, w)
        return self._cache[1], self._cache[2]

    def set_modes(self, modes: NDArray) -> None:
        self.modes = modes.copy()
        self._cache = None


def _consistent(
    system: System, field: _Field, q: NDArray, modes: NDArray, touched: NDArray
) -> tuple[float, NDArray]:
    """How far ``modes`` is from consistent at ``q`` on the ``touched`` surfaces (0 = is)."""
    f, w = field.evaluate(q, modes)
    rate = _ddir(system, q, f)
    bad = 0.0
    for s in touched:
        if modes[s] == SLIDE:
            bad = max(bad, -w[s] - _SLACK, w[s] - 1.0 - _SLACK, 0.0)
        elif modes[s] == OFF:
            bad = max(bad, rate[s] if rate[s] >= 0 else 0.0)
        else:
            bad = max(bad, -rate[s] if rate[s] <= 0 else 0.0)
    return bad, w


def _decide(
    system: System, field: _Field, q: NDArray, modes: NDArray, touched: NDArray
) -> tuple[NDArray, bool]:
    """Consistent modes for the ``touched`` surfaces, fewest changes first."""
    current = modes[touched]
    options = list(itertools.product((OFF, ON, SLIDE), repeat=touched.size))
    options.sort(key=lambda o: int(np.sum(np.asarray(o) != current)))
    best_bad, best = np.inf, modes
    for o in options:
        trial = modes.copy()
        trial[touched] = o
        bad, _ = _consistent(system, field, q, trial, touched)
        if bad == 0.0:
            return trial, True
        if bad < best_bad:
            best_bad, best = bad, trial
    return best, False


def _release(field: _Field, q: NDArray, modes: NDArray) -> NDArray:
    """Let go of sliding surfaces whose weight sits at 0 or 1 at an event.

    The solver stops at the first terminal event; when two sliding weights
    reach a bound at the same time, the second has no crossing left to detect
    after the restart, so it is released here (to the side its weight selects).
    """
    modes = modes.copy()
    for _ in range(modes.size):
        sliding = modes == SLIDE
        if not sliding.any():
            break
        _, w = field.evaluate(q, modes)
        low, high = sliding & (w <= _SLACK), sliding & (w >= 1.0 - _SLACK)
        if not (low.any() or high.any()):
            break
        modes[low], modes[high] = OFF, ON
    return modes


@register_integrator
@dataclass(frozen=True, kw_only=True)
class Filippov(Integrator):
    """Event-driven Filippov solution: adaptive between switches, convex combination while sliding.

    Parameters
    ----------
    rtol, atol : float
        Tolerances of the smooth solver between events. Default 1e-10, 1e-12.
    method : str
        ``solve_ivp`` method. Default ``"DOP853"``.
    save_dt : float
        Spacing of the saved states, seconds (event times are saved too); ``run``'s
        ``save_every`` multiplies it. Default 0.01.
    touch_tol : float
        At an event, surfaces with ``|sigma| <= touch_tol`` are touched and get
        their modes decided together. Default 1e-8.
    mu : float
        Drift correction while sliding, 1/s: ``d sigma/dt = -mu sigma``. Default 10.
    max_events : int
        Stop with status ``"event-limit"`` after this many events. Default 10000.

    Notes
    -----
    ``stats``: ``steps`` (accepted solver steps), ``rhs_evaluations``,
    ``wall_time_s``, ``step_cost_s``, ``events``, ``unresolved_events`` (no
    consistent modes found; the least inconsistent ones were taken; should be
    0), and the switching diagnostics (``switch_count`` counts mode changes,
    ``sliding_time`` is exact up to the event location, ``max_excursion`` is
    the largest ``|sigma|`` of a sliding surface at the saved states).
    """

    name = "filippov"
    rtol: float = 1e-10
    atol: float = 1e-12
    method: str = "DOP853"
    save_dt: float = 1e-2
    touch_tol: float = 1e-8
    mu: float = 10.0
    max_events: int = 10_000

    def __post_init__(self) -> None:
        pos = ("rtol", "atol", "save_dt", "touch_tol")
        check_fields(self, positive=pos, nonnegative=("mu",), whole=("max_events",))
        one_of(self.method, "method", _METHODS, owner="Filippov")

    def run(
        self,
        system: System,
        q0: NDArray[np.float64],
        duration: float,
        *,
        save_every: int = 1,
        progress: Progress | None = None,
        interruptible: bool = False,
    ) -> RawSolution:
        steps_for(duration, self.save_dt)  # validates duration
        if getattr(system, "sensed", False):
            raise ParameterError(
                "[sensing] needs an explicit fixed-step integrator (euler or rk4): a robot "
                "measures once per step and holds its command; filippov is event-driven",
                key="simulation.integrator",
            )
        if system.time_dependent:
            raise ParameterError(
                "filippov steps a field that does not depend on time: a robot that stops "
                "at some t > 0 ([faults]) and a marching reference that is a function of "
                "time need a fixed-step integrator (euler, rk4, implicit-euler); or give "
                "the reference as a constant velocity",
                key="simulation.integrator",
            )
        start_clock = time.perf_counter()
        q0 = np.array(q0, dtype=float)
        shape = q0.shape
        field = _Field(system, shape, self.mu)
        sigma = system.sigma(q0)
        modes = np.where(sigma >= 0, ON, OFF).astype(np.int64)
        touched = np.flatnonzero(np.abs(sigma) <= self.touch_tol)
        unresolved = 0
        if touched.size:
            modes, ok = _decide(system, field, q0, modes, touched)
            unresolved += not ok
        field.set_modes(modes)
        save = self.save_dt * save_every
        ts: list[float] = [0.0]
        qs: list[NDArray] = [q0.copy()]
        vs: list[NDArray] = [field.at(q0.ravel())[0].reshape(shape).copy()]
        t, y = 0.0, q0.ravel().copy()
        status = Status.SUCCESS
        message = ""
        n_events = switches = steps = 0
        excursion = 0.0
        sliding_from: float | None = 0.0 if np.any(modes == SLIDE) else None
        intervals: list[tuple[float, float]] = []
        next_save = 1
        try:
            while t < duration:
                events, kinds = self._events(field, modes)
                sol = solve_ivp(
                    lambda _t, yy: field.at(yy)[0].ravel(),
                    (t, duration),
                    y,
                    method=self.method,
                    rtol=self.rtol,
                    atol=self.atol,
                    events=events or None,
                    dense_output=True,
                )
                steps += len(sol.t) - 1
                t_end = float(sol.t[-1])
                grid = np.arange(next_save, int(np.floor(t_end / save + 1e-9)) + 1) * save
                grid = grid[grid > t]
                for tk in grid:
                    qk = sol.sol(tk).reshape(shape)
                    ts.append(float(tk))
                    qs.append(qk)
                    vs.append(field.at(qk.ravel())[0].reshape(shape).copy())
                    if progress is not None:
                        progress(float(tk))
                    if np.any(modes == SLIDE):
                        sig = system.sigma(qk)[modes == SLIDE]
                        excursion = max(excursion, float(np.max(np.abs(sig))))
                next_save += grid.size
                y = sol.y[:, -1].copy()
                q = y.reshape(shape)
                if not np.all(np.isfinite(y)) or sol.status < 0:
                    status = Status.NON_FINITE
                    message = f"the smooth solver failed at t = {t_end:g} s: {sol.message}"
                    t = t_end
                    break
                if progress is not None:
                    progress(t_end)
                if sol.status != 1:
                    t = t_end
                    break
                fired = [m for m, te in enumerate(sol.t_events) if te.size]
                if any(kinds[m][0] == "contact" for m in fired):
                    status = Status.COLLISION
                    i, j, a = system.closest_pair(q)
                    message = (
                        f"robots {i} and {j} touch (r = a_{i}{j} = {a:g}) at t = {t_end:g} s: "
                        "the law lets them collide"
                    )
                    t = t_end
                    break
                # an event: decide the new modes of the touched surfaces
                n_events += 1
                if n_events > self.max_events:
                    status = Status.EVENT_LIMIT
                    message = (
                        f"more than {self.max_events} switching events by t = {t_end:g} s "
                        "(Zeno-like switching?); raise max_events or use implicit-euler"
                    )
                    t = t_end
                    break
                new = modes.copy()
                exited = np.zeros(modes.shape, dtype=bool)
                for m in fired:
                    kind, surface = kinds[m]
                    if kind in ("exit0", "exit1"):  # a sliding weight reached 0 or 1: the
                        new[surface] = OFF if kind == "exit0" else ON  # trajectory leaves
                        exited[surface] = True  # tangentially to that side
                sigma = system.sigma(q)
                touched = np.flatnonzero(
                    (np.abs(sigma) <= self.touch_tol) & (new != SLIDE) & ~exited
                )
                crossing = {kinds[m][1] for m in fired if kinds[m][0] == "cross"}
                touched = np.union1d(touched, np.fromiter(crossing, dtype=np.int64)).astype(
                    np.int64
                )
                if touched.size:
                    new, ok = _decide(system, field, q, new, touched)
                    unresolved += not ok
                new = _release(field, q, new)
                switches += int(np.count_nonzero(new != modes))
                if np.any(new == SLIDE) and sliding_from is None:
                    sliding_from = t_end
                if not np.any(new == SLIDE) and sliding_from is not None:
                    intervals.append((sliding_from, t_end))
                    sliding_from = None
                modes = new
                field.set_modes(modes)
                if ts[-1] < t_end:
                    ts.append(t_end)
                    qs.append(q.copy())
                    vs.append(field.at(q.ravel())[0].reshape(shape).copy())
                t = t_end
        except KeyboardInterrupt:
            if not interruptible:
                raise
            status = Status.INTERRUPTED
            t, y = ts[-1], qs[-1].ravel()  # keep what was saved, consistently
            vs = vs[: len(ts)]
            message = f"interrupted by the user at t = {t:g} s"
        if sliding_from is not None:
            intervals.append((sliding_from, t))
        if ts[-1] < t:
            ts.append(t)
            qs.append(y.reshape(shape).copy())
            vs.append(field.at(y)[0].reshape(shape).copy())
        if not message:
            message = f"integrated to t = {t:g} s with {n_events} switching events"
        wall = time.perf_counter() - start_clock
        stats: dict[str, Any] = {
            "steps": int(steps),
            "rhs_evaluations": int(field.rhs_evaluations),
            "wall_time_s": wall,
            "step_cost_s": wall / max(steps, 1),
            "events": int(n_events),
            "unresolved_events": int(unresolved),
            "switch_count": int(switches),
            "sliding_time": float(sum(b - a for a, b in intervals)),
            "sliding_start": float(intervals[0][0]) if intervals else float("nan"),
            "sliding_end": float(intervals[-1][1]) if intervals else float("nan"),
            "max_excursion": excursion,
        }
        return RawSolution(
            dim=position_dim(system),
            t=np.asarray(ts),
            x=np.asarray(qs),
            v=np.asarray(vs),
            status=status,
            message=message,
            stats=stats,
        )

    def _events(self, field: _Field, modes: NDArray) -> tuple[list, list[tuple[str, int]]]:
        """Event functions for the current modes and what each one means."""
        system, shape = field.system, field.shape
        events: list = []
        kinds: list[tuple[str, int]] = []

        def contact_event(_t, y):  # the contact rule of System.step_verdict, as an event
            return float(system.clearance(y.reshape(shape)))

        contact_event.terminal = True  # type: ignore[attr-defined]
        contact_event.direction = -1  # type: ignore[attr-defined]
        events.append(contact_event)
        kinds.append(("contact", -1))
        for s, mode in enumerate(modes):
            if mode == SLIDE:
                for target, kind, direction in ((0.0, "exit0", -1), (1.0, "exit1", 1)):

                    def exit_event(_t, y, s=s, target=target):
                        return field.at(y)[1][s] - target

                    exit_event.terminal = True  # type: ignore[attr-defined]
                    exit_event.direction = direction  # type: ignore[attr-defined]
                    events.append(exit_event)
                    kinds.append((kind, s))
            else:

                def cross_event(_t, y, s=s):
                    return system.sigma(y.reshape(shape))[s]

                cross_event.terminal = True  # type: ignore[attr-defined]
                cross_event.direction = 1 if mode == OFF else -1  # type: ignore[attr-defined]
                events.append(cross_event)
                kinds.append(("cross", s))
        return events, kinds
