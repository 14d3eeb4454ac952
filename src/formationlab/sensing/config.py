"""What the robots sense, and which of them fail: the ``[sensing]`` and ``[faults]`` tables.

Scenario-file form::

    [sensing]
    frames = "local"       # "global" (default) | "local"
    noise = 0.01           # std (m) of Gaussian noise on each measured relative position
    range = 2.0            # optional: neighbours farther than this are not seen
    delay = 0.05           # s: each measurement is this old (a multiple of dt)
    drop = 0.1             # probability that a measurement is lost at a step (the last
                           # one received is held)
    mismatch = 0.05        # std (m) of each robot's own error in its desired distances
    seed = 0               # of the noise, drops, frames and mismatch of a single run
    [faults]
    stop = [{ robot = 2, at = 3.0 }]   # robot 2 stops moving at t = 3 s

The defaults are the paper's setting: every robot knows the relative positions of
the others exactly, in one common frame, now. With the defaults the closed loop is
exactly what it is without these tables (the package does not take the sensed path).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError
from ..resources import check_memory
from ..validation import number
from ..validation import seed as check_seed

__all__ = ["FRAMES", "Faults", "Sensing", "Stop", "delay_ring", "delay_steps"]

FRAMES: tuple[str, ...] = ("global", "local")
#: a delay is a whole number of steps when it is within this relative distance of one
_WHOLE = 1e-9


@dataclass(frozen=True, kw_only=True)
class Sensing:
    """How each robot measures its neighbours (module docstring for the file form).

    Robot ``i`` measures ``z_ij``, the relative position ``p_j - p_i`` of the robots it
    sees, in its own frame, computes its command there from its own measurements and
    its own desired distances, and rotates the command back
    (:mod:`formationlab.sensing.local`); the measurement channel
    (:mod:`formationlab.sensing.channel`) adds noise, delay and losses.

    Parameters
    ----------
    frames : {"global", "local"}
        ``"local"``: robot ``i`` measures and commands in its own frame, its heading for
        unicycles, a fixed random rotation (drawn from ``seed``) for other robots.
        Frames are rotations only: every robot keeps the common sense of rotation
        (chirality) that the angle-restricted law needs.
    frame_error : float
        Standard deviation (rad) of each robot's fixed error in the common frame
        (``frames = "global"``): robot ``i`` measures and commands in the common frame
        turned by ``a_i ~ N(0, frame_error^2)``, drawn from ``seed`` (a compass with an
        error). The distance laws do not see it; the bearing law, which compares its
        measured bearings with desired ones in the common frame, does (docs/bearing.md).
    noise : float
        Standard deviation (m) of independent Gaussian noise on each coordinate of each
        measured relative position (in the measuring robot's frame).
    range : float
        Robots farther apart than this (m, centre to centre at the time of the
        measurement) do not see each other; their terms are left out. Default ``inf``.
    delay : float
        Age (s) of every measurement when it is used; a whole number of steps.
        Before the first measurement arrives (``t < delay``) a robot sees no one.
    drop : float
        Probability in ``[0, 1)`` that a measurement is lost at a step; the robot then
        uses the last one it received.
    mismatch : float
        Standard deviation (m) of each robot's own error in each of its desired
        distances: robot ``i`` steers ``r_ij`` to ``d_ij + e_ij``, robot ``j`` to
        ``d_ij + e_ji``, with ``e_ij`` and ``e_ji`` independent (Mou et al., IEEE TAC
        61(10), 2016); each error is clipped to half the margin ``d_ij - a_ij``.
    seed : int
        Seed of a single run's noise, drops, frames and mismatch (a study gives every
        trial its own seed).
    """

    frames: Literal["global", "local"] = "global"
    frame_error: float = 0.0
    noise: float = 0.0
    range: float = math.inf
    delay: float = 0.0
    drop: float = 0.0
    mismatch: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.frames not in FRAMES:
            known = ", ".join(f'"{f}"' for f in FRAMES)
            raise ParameterError(
                f"sensing.frames must be one of {known}, got {self.frames!r}", key="sensing.frames"
            )
        number(self.frame_error, "sensing.frame_error", low=0.0, strict=False)
        if self.frame_error > 0 and self.frames == "local":
            raise ParameterError(
                'sensing.frame_error turns the common frame (frames = "global"); local frames '
                "are turned at random already: remove one of the two",
                key="sensing.frame_error",
            )
        number(self.noise, "sensing.noise", low=0.0, strict=False)
        number(self.range, "sensing.range", low=0.0, strict=True, allow_inf=True)
        number(self.delay, "sensing.delay", low=0.0, strict=False)
        number(self.drop, "sensing.drop", low=0.0, strict=False, below=1.0)
        number(self.mismatch, "sensing.mismatch", low=0.0, strict=False)
        check_seed(self.seed, "sensing.seed")

    @property
    def ideal(self) -> bool:
        """Whether this is the paper's sensing (the defaults): the closed loop is unchanged."""
        return (
            self.frames == "global" and self.frame_error == 0 and self.noise == 0
            and math.isinf(self.range)
            and self.delay == 0 and self.drop == 0 and self.mismatch == 0
        )  # fmt: skip

    @property
    def sampled(self) -> bool:
        """Whether measurements change only once per step (noise, delay or drops).

        Then a robot samples its sensors at the start of each step and holds its
        command over the step (a digital controller); otherwise the sensed control is
        a field like the law's and is evaluated at every stage of a scheme.
        """
        return self.noise > 0 or self.delay > 0 or self.drop > 0

    def describe(self) -> dict[str, object]:
        """JSON-ready (``range`` ``None`` when infinite)."""
        return {
            "frames": self.frames, "frame_error": self.frame_error, "noise": self.noise,
            "range": None if math.isinf(self.range) else self.range, "delay": self.delay,
            "drop": self.drop, "mismatch": self.mismatch, "seed": int(self.seed),
        }  # fmt: skip


def delay_steps(delay: float, dt: float) -> int:
    """``delay / dt`` as a whole number of steps; a clear error when it is not one."""
    m = delay / dt
    k = round(m)
    if abs(m - k) > _WHOLE * max(1.0, m):
        raise ParameterError(
            f"sensing.delay = {delay:g} s is not a multiple of the step dt = {dt:g} s "
            f"({m:.6g} steps); use {max(k, 1) * dt:g} s (or a dt that divides the delay)",
            key="sensing.delay",
        )
    return int(k)


#: bytes a delayed step holds per pair of robots and trial: the measurement and whether the
#: other robot was in range (the channel's ring, and the compiled loop's)
RING_BYTES = 17


def delay_ring(delay: float, dt: float, n: int, trials: int = 1) -> int:
    """:func:`delay_steps`, once the memory of what the delay holds is known to fit: each of
    its ``m + 1`` steps keeps every robot's measurement of every other, for each trial
    (a :class:`~formationlab.errors.FormationError` with key ``sensing.delay`` otherwise)."""
    m = delay_steps(delay, dt)
    check_memory(
        float(m + 1) * n * n * RING_BYTES * max(trials, 1),
        f"sensing.delay = {delay:g} s ({float(m):.3g} steps of dt = {dt:g} s, {n} robots"
        + (f", {trials:,} trials)" if trials > 1 else ")"),
        key="sensing.delay",
        fix="use a shorter delay (each step of delay holds every robot's measurement of "
        "every other)",
    )
    return m


@dataclass(frozen=True, kw_only=True)
class Stop:
    """Robot ``robot`` (1-based) stops moving at time ``at`` (s) and stays where it is.

    ``at = inf`` never comes: the robot that a study's ``stop_at`` sweep stops.
    """

    robot: int
    at: float = 0.0

    def __post_init__(self) -> None:
        if not (isinstance(self.robot, int | np.integer) and not isinstance(self.robot, bool)
                and self.robot >= 1):  # fmt: skip
            raise ParameterError(
                f"faults.stop robot must be a robot number >= 1 (robots are numbered from "
                f"1), got {self.robot!r}", key="faults.stop",
            )  # fmt: skip
        try:
            number(self.at, "faults.stop at", low=0.0, strict=False, allow_inf=True)
        except ParameterError as exc:  # (the key of the line: the list's, not "stop at")
            raise ParameterError(str(exc), key="faults.stop") from None


@dataclass(frozen=True, kw_only=True)
class Faults:
    """Robot faults: robots that stop moving (``stop``, a sequence of :class:`Stop`)."""

    stop: Sequence[Stop] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "stop", tuple(self.stop))
        seen = [s.robot for s in self.stop]
        if len(set(seen)) != len(seen):
            twice = sorted({r for r in seen if seen.count(r) > 1})
            raise ParameterError(
                f"faults.stop names robot {twice[0]} more than once; give each robot one "
                "stop time", key="faults.stop",
            )  # fmt: skip

    @property
    def any(self) -> bool:
        return bool(self.stop)

    def check(self, n: int) -> None:
        """Every faulty robot exists in a formation of ``n`` robots."""
        for s in self.stop:
            if s.robot > n:
                raise ParameterError(
                    f"faults.stop robot {s.robot} does not exist: the formation has {n} "
                    f"robots, numbered 1 to {n}", key="faults.stop",
                )  # fmt: skip

    def later(self) -> tuple[Stop, ...]:
        """The stops at a finite ``t > 0``: they make the field depend on the time (a stop
        at 0 holds the robot from the start; one at ``inf`` never comes)."""
        return tuple(s for s in self.stop if 0 < s.at < math.inf)

    def stopped(self, n: int, t: float) -> NDArray[np.bool_]:
        """Which of ``n`` robots have stopped at time ``t``; ``(n,)``."""
        out = np.zeros(n, dtype=bool)
        for s in self.stop:
            if t >= s.at:  # (never for at = inf)
                out[s.robot - 1] = True
        return out

    def describe(self) -> dict[str, object]:
        return {"stop": [{"robot": int(s.robot), "at": float(s.at)} for s in self.stop]}
